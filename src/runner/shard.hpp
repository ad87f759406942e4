#pragma once
// Shards of a run: --shard I/N picks shard I (0-based) of a deterministic, balanced split of the
// selected jobs into N; --shard auto[/N] reads I and N from a scheduler's environment (a Slurm
// job array, a Kubernetes Indexed Job, or SPECBAKE_SHARD_INDEX / SPECBAKE_SHARD_COUNT).
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace specbake {

struct Shard {
  int index = 0, count = 1;
  std::string source;  // where I/N came from, for logs and reports: "--shard 1/4", "SLURM_ARRAY_TASK_ID=5 ..."
  bool operator==(const Shard& o) const { return index == o.index && count == o.count; }
};

// Reads an environment variable; nullopt when it is not set.
using Environment = std::function<std::optional<std::string>(const std::string& name)>;
Environment process_environment();

// Parses --shard's value: "I/N" (0 <= I < N), or "auto" / "auto/N", which take the shard from
// `env`, from every source that is set (they must agree):
//   Slurm array      SLURM_ARRAY_TASK_ID with SLURM_ARRAY_TASK_MIN/MAX (I = ID - MIN,
//                    N = MAX - MIN + 1; a contiguous array, step 1) or SLURM_ARRAY_TASK_COUNT
//                    (I = ID);
//   Kubernetes       JOB_COMPLETION_INDEX (I), with N from auto/N (a Job does not export its
//                    completions);
//   explicit         SPECBAKE_SHARD_INDEX and SPECBAKE_SHARD_COUNT (the count may come from auto/N).
// With auto/N every source's N must equal N. Throws UsageError (exit 2) naming the variables
// when none is set, one is malformed or out of range, or two disagree.
Shard parse_shard(const std::string& text, const Environment& env = process_environment());

// Deterministic, balanced split of jobs into `count` shards: jobs sorted by estimated cost
// (descending, ties by name) go one by one to the shard with the least total so far.
// Returns the shard of each job, in the order given.
std::vector<int> assign_shards(const std::vector<std::pair<std::string, double>>& name_cost, int count);

}  // namespace specbake
