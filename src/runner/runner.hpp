#pragma once
// The job runner: configs in, bundles out. The CLI is a thin layer over this.
//   load → (configs validated before anything runs; with keep_going, invalid configs and jobs
//   are reported and the rest run) → per job: resolve the device, hash, skip if up to date,
//   bake, publish. One failing job does not stop the others. A stop request (SIGINT/SIGTERM)
//   ends the run at the next safe point: between jobs, or between the steps of a bake.
#include <chrono>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "cl/device.hpp"
#include "cl/timing.hpp"
#include "core/config.hpp"
#include "core/errors.hpp"
#include "job/kind.hpp"
#include "registry/registry.hpp"
#include "runner/shard.hpp"

namespace specbake {

struct RunOptions {
  std::optional<fs::path> out;          // overrides every config's output
  std::optional<std::string> device;    // overrides every config's device
  std::vector<std::string> only;        // job names; empty = all
  bool force = false;                   // rebuild bundles that are up to date
  Shard shard;                          // --shard: run only shard I (0-based) of N
};

struct JobReport {
  std::string config;
  std::string name;
  std::string kind;
  std::string status;  // built | up-to-date | failed | invalid | interrupted | planned
  std::string reason;  // why it failed, or why it is (not) up to date
  ExitCode code = ExitCode::ok;
  std::string hash;
  fs::path bundle;     // the bundle folder; empty when there is none (failed, invalid, interrupted)
  nlohmann::json device;                        // name, platform, version, type, fp64
  nlohmann::json parameters, accuracy, timings;  // accuracy: the manifest's list of records
  std::vector<std::string> warnings;
  // plan: estimated wall seconds (2-core CPU scale), device and host memory in bytes
  nlohmann::json estimate;
};

// JSON summary of a run (what --report writes). `error`: a problem that stopped the whole run
// before or between jobs (config, usage, output folder, signal), if any. `shard`: the run's
// shard (null in the report when unknown: the run stopped before --shard was read).
nlohmann::json report_json(const std::vector<JobReport>& reports, const std::string& error = "",
                           const std::optional<Shard>& shard = std::nullopt);

// Live progress of a run: the job (1-based index of `count`), its step and what it is doing,
// the fraction of the job done, and the estimated seconds left of this job (< 0: unknown).
struct ProgressEvent {
  int index = 0, count = 0;
  std::string job;
  Stage stage = Stage::plan;
  std::string what;
  double fraction = 0.0;
  double eta_s = -1.0;
};
using RunProgress = std::function<void(const ProgressEvent&)>;
// Called once per job as it ends (built, up to date, failed, ...).
using JobDone = std::function<void(const JobReport&)>;

// Loads configs from files and folders (every *.yaml / *.yml inside, sorted; a file given twice
// is read once). Throws on the first invalid config, and on job names that would share a bundle
// folder. With `invalid` set, invalid configs and jobs are reported there (status "invalid",
// exit code 3, the reason naming file:line:col) and left out instead.
std::vector<Config> load_configs(const std::vector<fs::path>& paths, std::vector<JobReport>* invalid = nullptr);

// Stop requests, e.g. from a signal handler (async-signal-safe): the run stops at the next
// safe point and throws Interrupted there.
// A bake through the kind's table entry, timed per step (plan, compute, check, files) with the
// device's profiler: what `run` publishes and `sweep` measures. `ev` names the job for progress
// events; `judge` and `memo` as in JobContext; `estimate_s` is the progress line's ETA until 5 %
// of the job is done (< 0: the kind's 2-core CPU model). The bake's host-only file work
// (BakeResult::finish) runs in its files step, unless `defer_files` leaves it to the caller.
// Throws what the bake throws, Interrupted on a stop request.
struct TimedBake {
  BakeResult result;
  double bake_s = 0.0;
  std::map<std::string, cl_util::StageSeconds> steps;
};
TimedBake bake_timed(const Kind& kind, const JobSpec& job, cl_util::Device& dev, ProgressEvent ev,
                     const RunProgress& progress, bool judge = true, Memo* memo = nullptr,
                     const std::string& bundle_hash = {}, double estimate_s = -1.0, bool defer_files = false);
// The job's accuracy records that miss their tolerance: BakeFailed (what it measured, its
// parameters and warnings), or under `tolerance_advisory: true` a warning each (a failed
// self_check is never advisory). bake_timed calls it when it judges.
void judge_tolerances(const JobSpec& job, BakeResult& result);
// Refuses (InputError at the job's entry) a job whose host-memory estimate exceeds what the
// machine has available.
void check_host_memory(const JobSpec& job, const MemoryEstimate& need);

void request_stop(int signal);
int stop_requested();  // the signal number, 0 if none
void clear_stop_request();

class Runner {
 public:
  Runner(std::vector<Config> configs, RunOptions options, RunProgress progress = {}, JobDone done = {});
  // Validates --only and output folders, then bakes. Throws Error for problems that stop
  // everything (usage, unwritable output); job failures are in the reports. On a stop request
  // the reports so far are returned with the current job marked "interrupted".
  std::vector<JobReport> run();
  // What run() would do, with resolved parameters and estimates; publishes nothing (an atmosphere's
  // auto search is kept in the output's result store for run()).
  std::vector<JobReport> plan();

 private:
  struct Item {
    const Config* config;
    const JobSpec* job;
    fs::path output;
    std::string device;
  };
  std::vector<Item> select() const;
  std::vector<Config> configs_;
  RunOptions options_;
  RunProgress progress_;
  JobDone done_;
};

// Exit code for a set of reports: ok, or the code of the first failed job (an interrupted run:
// 130 / 143).
ExitCode exit_code(const std::vector<JobReport>& reports);

}  // namespace specbake
