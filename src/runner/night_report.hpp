#pragma once
// One summary of a sharded night: the `--report` JSON files its shards wrote (`specbake run
// --shard I/N --report FILE`), merged per job. The merge is data (NightReport), so that each way
// of showing it (the text table, --json, a page) reads the same struct.
#include <cstddef>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace specbake {

// One input report.
struct NightShard {
  std::filesystem::path file;
  std::optional<int> index, count;  // none: an unsharded run, or one stopped before --shard was read
  std::string source;               // where the shard came from (--shard I/N, SLURM_ARRAY_TASK_ID=...)
  std::string created_utc, tool_version;
  std::string error;                // what stopped the whole run, if anything
  nlohmann::json summary;           // the report's own counts
  bool failed = false;              // an error, or a failed or invalid job
  std::string label() const;        // "1/3", or "-" without a shard
};

// One report's entry for a job.
struct NightEntry {
  std::size_t shard = 0;  // index into NightReport::shards
  std::string status;     // built | up-to-date | failed | invalid | interrupted | not-run | planned
  std::string reason;
  double seconds = -1.0;  // the job's total time in that run (timings.total_s); < 0: not recorded
  nlohmann::json job;     // the report's whole entry (kind, config, accuracy, warnings, bundle, ...)
};

struct NightJob {
  std::string name, kind, config;
  std::string status;            // the best outcome among its entries (below)
  std::size_t decided_by = 0;    // the entry that gives the status, index into `entries`
  std::vector<NightEntry> entries;  // every report that lists the job, in input order
  int builds = 0;                // entries that built it: more than one is flagged
  std::vector<std::string> notes;   // a job built more than once; outcomes that differ between reports
  bool ok() const;               // built, up-to-date or planned
  const NightEntry& decision() const { return entries[decided_by]; }
};

struct NightReport {
  std::vector<NightShard> shards;     // in input order
  std::vector<NightJob> jobs;         // by name
  std::map<std::string, int> counts;  // jobs per merged status
  int built_twice = 0;                // jobs built in more than one shard
  std::vector<std::string> problems;  // what fails the night: shard errors and failures, missing shards, unfinished jobs
  bool failed() const { return !problems.empty(); }
};

// Outcomes from best to worst; a job reported by several shards takes the best (a bundle built or
// found up to date anywhere is the night's), and the others are noted.
const std::vector<std::string>& night_statuses();

// Reads reports: files, and folders (every *.json directly inside, sorted by name). The night
// fails (problems) when a shard's report has an error or a failed or invalid job, when a job's
// best outcome is interrupted or not-run, or when shards of an I/N split have no report. Throws
// IoError (exit 5) for a path that cannot be read, InputError (exit 3, file:line:col) for a file
// that is not a specbake report, UsageError for a folder without any.
NightReport merge_night(const std::vector<std::filesystem::path>& inputs);

// The merge as JSON (`specbake report --json`, schema specbake.night/1).
nlohmann::json night_json(const NightReport& night);
// The merge as text: the shards, one row per job (job, kind, status, shard, time, reason), the
// notes and problems, and a summary line.
std::string night_text(const NightReport& night);

}  // namespace specbake
