#pragma once
// Helpers shared by the tests: reference data, temporary folders, running the CLI.
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace specbake::testing {

namespace fs = std::filesystem;

fs::path refdata_dir();   // SPECBAKE_REFDATA_DIR; fails the test if missing
fs::path source_dir();    // the repository root
fs::path specbake_exe();  // the built CLI

nlohmann::json read_json(const fs::path& p);
std::string read_file(const fs::path& p);
std::vector<float> read_f32(const fs::path& p);
void write_file(const fs::path& p, const std::string& text);

// A fresh folder under the system temp dir, removed when the object dies.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  const fs::path& path() const { return path_; }
  fs::path operator/(const std::string& s) const { return path_ / s; }

 private:
  fs::path path_;
};

struct CliResult {
  int exit_code = -1;
  std::string out;  // stdout
  std::string err;  // stderr
};
// Runs the specbake binary with args (no shell), capturing its output.
CliResult run_cli(const std::vector<std::string>& args, const fs::path& cwd = {});

}  // namespace specbake::testing
