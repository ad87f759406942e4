#include "runner/shard.hpp"

#include <algorithm>
#include <cstdlib>
#include <numeric>

#include "core/errors.hpp"

namespace specbake {

namespace {

// A non-negative decimal integer (the whole text), else nullopt.
std::optional<long> whole_number(const std::string& text) {
  if (text.empty() || text.size() > 9 ||
      !std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; }))
    return std::nullopt;
  return std::stol(text);
}

const std::string kAutoHelp =
    "--shard auto reads the shard from a Slurm array (SLURM_ARRAY_TASK_ID), a Kubernetes Indexed Job "
    "(JOB_COMPLETION_INDEX, with --shard auto/N) or SPECBAKE_SHARD_INDEX and SPECBAKE_SHARD_COUNT";

// The shard one source of the environment gives, if it is set. `count` is auto/N's N (0: none).
class Sources {
 public:
  Sources(const Environment& env, int count) : env_(env), count_(count) {}

  std::optional<Shard> slurm() const {
    const auto id = get("SLURM_ARRAY_TASK_ID");
    if (!id) return std::nullopt;
    const long i = number("SLURM_ARRAY_TASK_ID", *id);
    const auto min = get("SLURM_ARRAY_TASK_MIN"), max = get("SLURM_ARRAY_TASK_MAX"), n = get("SLURM_ARRAY_TASK_COUNT");
    const std::string where = "SLURM_ARRAY_TASK_ID=" + *id;
    if (min && max) {
      const long lo = number("SLURM_ARRAY_TASK_MIN", *min), hi = number("SLURM_ARRAY_TASK_MAX", *max);
      if (hi < lo || i < lo || i > hi)
        throw UsageError("--shard auto: " + where + " is not within SLURM_ARRAY_TASK_MIN=" + *min +
                         " .. SLURM_ARRAY_TASK_MAX=" + *max);
      const long span = hi - lo + 1;
      if (n && number("SLURM_ARRAY_TASK_COUNT", *n) != span)
        throw UsageError("--shard auto: the Slurm array " + *min + "-" + *max + " has SLURM_ARRAY_TASK_COUNT=" + *n +
                         " tasks, not " + std::to_string(span) +
                         "; expected a contiguous array (sbatch --array=0-" + std::to_string(span - 1) +
                         ", no step or list) so that task IDs map onto shards");
      return make(i - lo, span, where + " of SLURM_ARRAY_TASK_MIN=" + *min + "..SLURM_ARRAY_TASK_MAX=" + *max);
    }
    if (n) return make(i, number("SLURM_ARRAY_TASK_COUNT", *n), where + " of SLURM_ARRAY_TASK_COUNT=" + *n);
    throw UsageError("--shard auto: " + where + " is set but neither SLURM_ARRAY_TASK_MIN/MAX nor "
                     "SLURM_ARRAY_TASK_COUNT is, so the number of shards is unknown");
  }

  std::optional<Shard> kubernetes() const {
    const auto index = get("JOB_COMPLETION_INDEX");
    if (!index) return std::nullopt;
    const long i = number("JOB_COMPLETION_INDEX", *index);
    if (count_ == 0)
      throw UsageError("--shard auto: JOB_COMPLETION_INDEX=" + *index +
                       " is set (a Kubernetes Indexed Job), which does not give the number of shards; "
                       "expected --shard auto/N with N the Job's completions");
    return make(i, count_, "JOB_COMPLETION_INDEX=" + *index);
  }

  std::optional<Shard> specbake() const {
    const auto index = get("SPECBAKE_SHARD_INDEX"), n = get("SPECBAKE_SHARD_COUNT");
    if (!index && !n) return std::nullopt;
    if (!index)
      throw UsageError("--shard auto: SPECBAKE_SHARD_COUNT=" + *n + " is set but SPECBAKE_SHARD_INDEX is not");
    const long i = number("SPECBAKE_SHARD_INDEX", *index);
    if (n) return make(i, number("SPECBAKE_SHARD_COUNT", *n), "SPECBAKE_SHARD_INDEX=" + *index + " of SPECBAKE_SHARD_COUNT=" + *n);
    if (count_ == 0)
      throw UsageError("--shard auto: SPECBAKE_SHARD_INDEX=" + *index +
                       " is set but SPECBAKE_SHARD_COUNT is not; expected both, or --shard auto/N");
    return make(i, count_, "SPECBAKE_SHARD_INDEX=" + *index);
  }

 private:
  std::optional<std::string> get(const std::string& name) const {
    auto v = env_(name);
    if (v && v->empty()) return std::nullopt;  // set but empty counts as not set
    return v;
  }
  static long number(const std::string& name, const std::string& value) {
    const auto n = whole_number(value);
    if (!n) throw UsageError("--shard auto: " + name + "='" + value + "'; expected a non-negative integer");
    return *n;
  }
  Shard make(long i, long n, std::string source) const {
    if (n < 1 || i >= n)
      throw UsageError("--shard auto: " + source + " gives shard " + std::to_string(i) + " of " + std::to_string(n) +
                       "; expected 0 <= index < count");
    if (count_ != 0 && n != count_)
      throw UsageError("--shard auto/" + std::to_string(count_) + ": " + source + " says " + std::to_string(n) +
                       " shards, not " + std::to_string(count_));
    return Shard{static_cast<int>(i), static_cast<int>(n), std::move(source)};
  }
  const Environment& env_;
  int count_;
};

}  // namespace

Environment process_environment() {
  return [](const std::string& name) -> std::optional<std::string> {
    const char* v = std::getenv(name.c_str());
    if (!v) return std::nullopt;
    return std::string(v);
  };
}

Shard parse_shard(const std::string& text, const Environment& env) {
  const auto slash = text.find('/');
  const std::string left = text.substr(0, slash), right = slash == std::string::npos ? "" : text.substr(slash + 1);
  if (left == "auto") {
    int count = 0;
    if (slash != std::string::npos) {
      const auto n = whole_number(right);
      if (!n || *n < 1) throw UsageError("--shard auto/N expects a count N >= 1, got '" + text + "'");
      count = static_cast<int>(*n);
    }
    const Sources sources(env, count);
    std::vector<Shard> found;
    for (auto s : {sources.slurm(), sources.kubernetes(), sources.specbake()})
      if (s) found.push_back(std::move(*s));
    if (found.empty()) {
      std::string hint;
      if (env("SLURM_JOB_ID"))
        hint = " (this Slurm job is not an array task: submit it with sbatch --array=0-N-1)";
      throw UsageError("--shard " + text + ": no shard in the environment" + hint + "; " + kAutoHelp);
    }
    for (const auto& s : found)
      if (!(s == found.front()))
        throw UsageError("--shard " + text + ": the environment disagrees: " + found.front().source + " gives shard " +
                         std::to_string(found.front().index) + "/" + std::to_string(found.front().count) + ", " +
                         s.source + " gives " + std::to_string(s.index) + "/" + std::to_string(s.count));
    Shard shard = found.front();
    for (std::size_t k = 1; k < found.size(); ++k) shard.source += ", " + found[k].source;
    return shard;
  }
  const auto i = whole_number(left), n = whole_number(right);
  if (slash == std::string::npos || !i || !n || *n < 1 || *i >= *n)
    throw UsageError("--shard expects I/N with 0 <= I < N (e.g. 0/4), or auto / auto/N; got '" + text + "'");
  return Shard{static_cast<int>(*i), static_cast<int>(*n), "--shard " + text};
}

std::vector<int> assign_shards(const std::vector<std::pair<std::string, double>>& name_cost, int count) {
  std::vector<std::size_t> order(name_cost.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    if (name_cost[a].second != name_cost[b].second) return name_cost[a].second > name_cost[b].second;
    return name_cost[a].first < name_cost[b].first;
  });
  std::vector<double> load(count, 0.0);
  std::vector<int> shard(name_cost.size(), 0);
  for (std::size_t idx : order) {
    const int s = static_cast<int>(std::min_element(load.begin(), load.end()) - load.begin());
    shard[idx] = s;
    load[s] += name_cost[idx].second;
  }
  return shard;
}

}  // namespace specbake
