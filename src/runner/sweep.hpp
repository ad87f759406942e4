#pragma once
// `specbake sweep`: speed against error for one job of a config. Each combination of the
// `--vary` values is set into the job's YAML entry, validated like a config file, baked through
// the kind (nothing is published) and measured: the bake's wall, device and host seconds, and
// the error of its ground-truth record (Kind::truth_records: dispersion's prism against a 0.1 nm
// spectrum, diffraction's exact transform, the atmosphere's path-traced scene). The results go to
// sweep.json, sweep.csv and sweep.png (error against time, log axes, Pareto front, tolerance),
// drawn by scripts/sweep_plot.py with matplotlib. Contract: docs/sweep.md.
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "runner/runner.hpp"

namespace specbake {

// One `--vary KEY=V1,V2,...`: KEY is a dotted path inside the job's entry (e.g. `orders`,
// `sizes.scattering.mu_s`, `table.size`); values are YAML scalars or flow lists separated by
// top-level commas, `A..B` expands to the integers A, A+1, ..., B.
struct Vary {
  std::string key;
  std::vector<std::string> values;
};
// Parses one `--vary` argument; UsageError on a missing '=', an empty key or value, a bad range.
Vary parse_vary(const std::string& text);

struct SweepOptions {
  std::filesystem::path config;
  std::string job;
  std::vector<Vary> varies;
  std::filesystem::path out;          // empty: ./sweep-<job>
  std::optional<std::string> device;  // default: the config's
  std::optional<double> tolerance;    // drawn and judged; default: the truth record's own
};

struct SweepPoint {
  std::vector<std::string> values;  // one per Vary, in order
  std::string status;               // measured | failed
  std::string reason;               // why it failed
  double wall_s = 0.0;              // the whole bake: plan, compute, check, files (of the fastest run)
  double bake_s = 0.0;              // plan + compute: what the varied settings cost (the x axis)
  double device_s = 0.0, host_s = 0.0;  // of plan + compute, as bake_s
  double check_s = 0.0, files_s = 0.0;  // timed apart: the check step; files and previews
  int runs = 0;                     // bakes timed (short ones are repeated; the fastest is kept)
  double bake_s_min = 0.0, bake_s_max = 0.0;  // bake_s over the runs (equal for one run)
  int order = 0;                    // when it was baked: 1 = first after the warm-up
  std::uint64_t bundle_bytes = 0;   // the bundle's files as the bake made them (manifest aside)
  double error = 0.0;
  std::string record, unit, metric;
  std::optional<double> tolerance;
  bool passed = false, pareto = false;
  std::string settings;  // the kind's one-line description of the resolved settings
  nlohmann::json parameters, accuracy;
  std::vector<std::string> warnings;
};

struct SweepResult {
  std::string job, kind;
  std::vector<Vary> varies;
  std::vector<SweepPoint> points;
  std::filesystem::path out;
  bool plotted = false;
  std::string plot_note;  // why sweep.png is missing, if it is
  std::string warmup;      // the combination baked untimed first (label), and its seconds
  double warmup_s = 0.0;
  nlohmann::json json() const;
};

// The combinations of the varies (the first varies slowest); UsageError past kMaxSweepPoints.
std::vector<std::vector<std::string>> sweep_combinations(const std::vector<Vary>& varies);
inline constexpr std::size_t kMaxSweepPoints = 256;

// The order the points are baked in: a permutation of 0..n-1 drawn from a fixed seed (the same
// sweep bakes in the same order), so a point's time does not depend on where it is listed.
std::vector<std::size_t> bake_order(std::size_t n);

// Marks the points on the Pareto front of (bake_s, error): no other measured point is at least
// as fast and as accurate and better in one of the two.
void mark_pareto(std::vector<SweepPoint>& points);

// Runs the sweep and writes its files. Throws UsageError (bad --vary, unknown job), InputError
// (a value the schema refuses: the config's file, the key and "--vary KEY=VALUE"), DeviceError,
// Interrupted (after writing the points measured so far).
SweepResult run_sweep(const SweepOptions& options, const RunProgress& progress);

// CSV of the points: one column per varied key, then status, bake_s, wall_s, device_s, host_s,
// error, unit, record, tolerance, passed, pareto, settings.
std::string sweep_csv(const SweepResult& r);

}  // namespace specbake
