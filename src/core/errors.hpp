#pragma once
// Error layers. Each class maps to one documented exit code (README, "Exit codes").
#include <filesystem>
#include <stdexcept>
#include <string>

namespace specbake {

enum class ExitCode : int {
  ok = 0,
  job_failed = 1,      // a job ran but failed (non-finite output, tolerance not met, ...)
  usage = 2,           // bad command line
  invalid_input = 3,   // invalid config or input file (heightfield, ...)
  device = 4,          // OpenCL platform/device/kernel failure
  io = 5,              // cannot read or write files/folders
  interrupted = 130,   // stopped by SIGINT (128 + 2)
  terminated = 143,    // stopped by SIGTERM (128 + 15)
};

// Where in an input a problem is: file plus 1-based line/column, and/or a key path.
struct Location {
  std::filesystem::path file;
  int line = 0;    // 0: unknown
  int column = 0;  // 0: unknown
  std::string key; // e.g. "jobs[0].range_nm[1]"
  std::string str() const;
};

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
  virtual ExitCode exit_code() const = 0;
};

// Invalid config or input: names where and what was expected.
class InputError : public Error {
 public:
  InputError(Location where, const std::string& what_expected);
  const Location& where() const { return where_; }
  ExitCode exit_code() const override { return ExitCode::invalid_input; }
 private:
  Location where_;
};

class UsageError : public Error {
 public:
  using Error::Error;
  ExitCode exit_code() const override { return ExitCode::usage; }
};

class DeviceError : public Error {
 public:
  using Error::Error;
  ExitCode exit_code() const override { return ExitCode::device; }
};

class IoError : public Error {
 public:
  using Error::Error;
  ExitCode exit_code() const override { return ExitCode::io; }
};

// A job that ran and cannot ship its result.
class JobError : public Error {
 public:
  using Error::Error;
  ExitCode exit_code() const override { return ExitCode::job_failed; }
};

// A run stopped by a signal at a safe point (no half-written bundle).
class Interrupted : public Error {
 public:
  explicit Interrupted(int signal)
      : Error(signal == 15 ? "stopped by SIGTERM" : "stopped by SIGINT (Ctrl-C)"), signal_(signal) {}
  ExitCode exit_code() const override { return signal_ == 15 ? ExitCode::terminated : ExitCode::interrupted; }
  int signal() const { return signal_; }
 private:
  int signal_;
};

}  // namespace specbake
