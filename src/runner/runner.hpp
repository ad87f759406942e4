#pragma once
// The job runner: configs in, bundles out. The CLI is a thin layer over this.
//   load → (all configs validated before anything runs) → per job: hash, skip if up to
//   date, open device, bake, write bundle. One failing job does not stop the others.
#include <chrono>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/config.hpp"
#include "core/errors.hpp"
#include "registry/registry.hpp"

namespace specbake {

struct RunOptions {
  std::optional<fs::path> out;          // overrides every config's output
  std::optional<std::string> device;    // overrides every config's device
  std::vector<std::string> only;        // job names; empty = all
  bool force = false;                   // rebuild bundles that are up to date
  int shard_index = 0, shard_count = 1; // --shard I/N: run only shard I (0-based) of N
};

// Parses "I/N" (0 <= I < N); throws UsageError.
std::pair<int, int> parse_shard(const std::string& text);

// Deterministic, balanced split of jobs into `count` shards: jobs sorted by estimated cost
// (descending, ties by name) go one by one to the shard with the least total so far.
// Returns the shard of each job, in the order given.
std::vector<int> assign_shards(const std::vector<std::pair<std::string, double>>& name_cost, int count);


struct JobReport {
  std::string config;
  std::string name;
  std::string kind;
  std::string status;  // built | up-to-date | failed | planned
  std::string reason;  // why it failed, or why it is (not) up to date
  ExitCode code = ExitCode::ok;
  std::string hash;
  fs::path bundle;
  nlohmann::json parameters, accuracy, timings;
  std::vector<std::string> warnings;
};

// JSON summary of a run (what --report writes).
nlohmann::json report_json(const std::vector<JobReport>& reports);

// (job name, stage, fraction of that job done)
using RunProgress = std::function<void(const std::string& job, std::string_view stage, double fraction)>;

// Loads configs from files and folders (every *.yaml / *.yml inside, sorted). Throws on the
// first invalid config, and on job names that would share a bundle folder.
std::vector<Config> load_configs(const std::vector<fs::path>& paths);


class Runner {
 public:
  Runner(std::vector<Config> configs, RunOptions options, RunProgress progress = {});
  // Validates --only and output folders, then bakes. Throws Error for problems that stop
  // everything (usage, unwritable output); job failures are in the reports.
  std::vector<JobReport> run();
  // What run() would do, with resolved parameters; writes nothing.
  std::vector<JobReport> plan();

 private:
  struct Item {
    const Config* config;
    const JobSpec* job;
    fs::path output;
    std::string device;
    std::string hash;
  };
  std::vector<Item> select() const;
  std::vector<Config> configs_;
  RunOptions options_;
  RunProgress progress_;
};

// Exit code for a set of reports: ok, or the code of the first failed job.
ExitCode exit_code(const std::vector<JobReport>& reports);

}  // namespace specbake
