#include "runner/sweep.hpp"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <optional>
#include <regex>
#include <set>
#include <sstream>

#include "core/resources.hpp"
#include "core/text.hpp"

namespace specbake {

using nlohmann::json;
namespace fs = std::filesystem;

namespace {

// Splits at commas outside [] and {} (so `[128,32],[256,64]` is two values).
std::vector<std::string> split_values(const std::string& s) {
  std::vector<std::string> out;
  std::string cur;
  int depth = 0;
  for (char c : s) {
    if (c == '[' || c == '{') ++depth;
    if (c == ']' || c == '}') --depth;
    if (c == ',' && depth == 0) {
      out.push_back(cur);
      cur.clear();
    } else {
      cur += c;
    }
  }
  out.push_back(cur);
  return out;
}

std::string trimmed(std::string s) {
  const auto b = s.find_first_not_of(" \t");
  if (b == std::string::npos) return "";
  return s.substr(b, s.find_last_not_of(" \t") - b + 1);
}

// Writes `bytes` to `path` through a temporary file and a rename: a reader never sees half a file.
void write_whole(const fs::path& path, const std::string& bytes) {
  const fs::path tmp = path.string() + ".tmp";
  {
    std::ofstream o(tmp, std::ios::binary);
    if (!o) throw IoError("cannot write " + tmp.string());
    o << bytes;
    o.close();
    if (!o) throw IoError("cannot write " + tmp.string());
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) throw IoError("cannot rename " + tmp.string() + " to " + path.string() + ": " + ec.message());
}

std::string shell_quoted(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// The Python that draws sweep.png: $SPECBAKE_PYTHON, else Debian's /usr/bin/python3 (where
// python3-matplotlib installs), else python3 on PATH.
std::string python_command() {
  if (const char* p = std::getenv("SPECBAKE_PYTHON"); p && *p) return p;
  if (::access("/usr/bin/python3", X_OK) == 0) return "/usr/bin/python3";
  return "python3";
}

// The job's entry in the YAML tree, by name, and its key path (jobs[i]).
std::pair<YAML::Node, std::string> job_entry(YAML::Node& root, const std::string& name, const fs::path& file) {
  std::vector<std::string> names;
  if (root.IsMap() && root["jobs"] && root["jobs"].IsSequence())
    for (std::size_t i = 0; i < root["jobs"].size(); ++i) {
      YAML::Node j = root["jobs"][i];
      if (j.IsMap() && j["name"] && j["name"].IsScalar()) {
        if (j["name"].Scalar() == name) return {j, "jobs[" + std::to_string(i) + "]"};
        names.push_back(j["name"].Scalar());
      }
    }
  const std::string near = closest_word(name, names);
  throw UsageError("--job names '" + name + "', which " + file.string() + " does not define" +
                   (near.empty() ? "" : " (did you mean '" + near + "'?)"));
}

// Sets `key` (dotted path) of the job entry to `value` (YAML text). A mapping on the way that
// is missing or a scalar (`table: none`, `spectrum: rgb`) becomes a mapping; a percentage given
// for a key that holds a mapping goes to its `scale` (`sizes: {...}` + `sizes=50%`).
void set_key(YAML::Node entry, const std::string& key, const std::string& value) {
  std::vector<std::string> parts;
  std::stringstream ss(key);
  for (std::string p; std::getline(ss, p, '.');) parts.push_back(p);
  YAML::Node node = entry;
  for (std::size_t i = 0; i + 1 < parts.size(); ++i) {
    YAML::Node next = node[parts[i]];
    if (!next.IsMap()) {
      node[parts[i]] = YAML::Node(YAML::NodeType::Map);
      next = node[parts[i]];
    }
    node.reset(next);
  }
  YAML::Node v = YAML::Load(value);
  const std::string& last = parts.back();
  if (!value.empty() && value.back() == '%' && node[last] && node[last].IsMap())
    node[last]["scale"] = v;
  else
    node[last] = v;
}

constexpr double kShortBake_s = 1.0, kRepeatBudget_s = 3.0;
constexpr int kMaxRuns = 5;

bool is_unknown_key(const InputError& e) { return std::string(e.what()).find(": unknown key '") != std::string::npos; }

std::string fmt(double v) { return format_g(v, 6); }
// Errors and tolerances: every digit (a CSV reader gets the JSON's value).
std::string exact(double v) { return format_g(v, 17); }

std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

std::string label_of(const std::vector<Vary>& varies, const std::vector<std::string>& values) {
  std::string s;
  for (std::size_t i = 0; i < varies.size(); ++i) s += (i ? " " : "") + varies[i].key + "=" + values[i];
  return s;
}

}  // namespace

Vary parse_vary(const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos)
    throw UsageError("--vary expects KEY=V1,V2,... (e.g. orders=1..6 or sizes=50%,100%), got '" + text + "'");
  Vary v;
  v.key = trimmed(text.substr(0, eq));
  static const std::regex key_re("[A-Za-z_][A-Za-z0-9_]*(\\.[A-Za-z_][A-Za-z0-9_]*)*");
  if (!std::regex_match(v.key, key_re))
    throw UsageError("--vary '" + text + "': expected a key path such as orders or sizes.scattering.mu_s before '='");
  static const std::regex range_re("(-?[0-9]+)\\.\\.(-?[0-9]+)");
  for (const auto& raw : split_values(text.substr(eq + 1))) {
    const std::string s = trimmed(raw);
    if (s.empty()) throw UsageError("--vary '" + text + "': an empty value (expected V1,V2,...)");
    std::smatch m;
    if (std::regex_match(s, m, range_re)) {
      const long long a = std::stoll(m[1]), b = std::stoll(m[2]);
      if (b < a) throw UsageError("--vary '" + text + "': the range " + s + " is empty (expected A..B with A <= B)");
      if (b - a >= static_cast<long long>(kMaxSweepPoints))
        throw UsageError("--vary '" + text + "': the range " + s + " has more than " +
                         std::to_string(kMaxSweepPoints) + " values");
      for (long long i = a; i <= b; ++i) v.values.push_back(std::to_string(i));
    } else if (s.find("..") != std::string::npos) {
      throw UsageError("--vary '" + text + "': '" + s + "' is not a range of integers A..B");
    } else {
      try {
        (void)YAML::Load(s);
      } catch (const YAML::Exception& e) {
        throw UsageError("--vary '" + text + "': '" + s + "' is not a YAML value (" + e.msg + ")");
      }
      v.values.push_back(s);
    }
  }
  std::set<std::string> seen;
  for (const auto& x : v.values)
    if (!seen.insert(x).second) throw UsageError("--vary '" + text + "': the value '" + x + "' is given twice");
  return v;
}

std::vector<std::vector<std::string>> sweep_combinations(const std::vector<Vary>& varies) {
  if (varies.empty()) throw UsageError("sweep needs at least one --vary KEY=V1,V2,...");
  std::set<std::string> keys;
  std::size_t n = 1;
  for (const auto& v : varies) {
    if (!keys.insert(v.key).second) throw UsageError("--vary " + v.key + " is given twice; list all its values in one");
    for (const auto& other : keys)
      if (other != v.key && (v.key.rfind(other + ".", 0) == 0 || other.rfind(v.key + ".", 0) == 0))
        throw UsageError("--vary " + v.key + " and --vary " + other + " set the same part of the job");
    n *= v.values.size();
    if (n > kMaxSweepPoints)
      throw UsageError("the --vary values make more than " + std::to_string(kMaxSweepPoints) +
                       " combinations; sweep fewer values at once");
  }
  std::vector<std::vector<std::string>> out{{}};
  for (const auto& v : varies) {
    std::vector<std::vector<std::string>> next;
    for (const auto& prefix : out)
      for (const auto& value : v.values) {
        next.push_back(prefix);
        next.back().push_back(value);
      }
    out = std::move(next);
  }
  return out;
}

std::vector<std::size_t> bake_order(std::size_t n) {
  std::vector<std::size_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = i;
  std::uint64_t state = 0x9e3779b97f4a7c15ULL;  // splitmix64 from a fixed seed: the same order everywhere
  auto next = [&state] {
    std::uint64_t z = (state += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  };
  for (std::size_t i = n; i > 1; --i) std::swap(order[i - 1], order[next() % i]);  // Fisher–Yates
  return order;
}

void mark_pareto(std::vector<SweepPoint>& points) {
  for (auto& p : points) {
    p.pareto = false;
    if (p.status != "measured" || !std::isfinite(p.error)) continue;
    p.pareto = std::none_of(points.begin(), points.end(), [&](const SweepPoint& q) {
      return &q != &p && q.status == "measured" && q.bake_s <= p.bake_s && q.error <= p.error &&
             (q.bake_s < p.bake_s || q.error < p.error);
    });
  }
}

json SweepResult::json() const {
  nlohmann::json varies_j = nlohmann::json::array(), pts = nlohmann::json::array();
  for (const auto& v : varies) varies_j.push_back({{"key", v.key}, {"values", v.values}});
  for (const auto& p : points) {
    nlohmann::json values = nlohmann::json::object();
    for (std::size_t i = 0; i < varies.size(); ++i) values[varies[i].key] = p.values[i];
    nlohmann::json j = {{"values", values},   {"label", label_of(varies, p.values)},
                        {"status", p.status}, {"bake_s", p.bake_s},
                        {"bake_s_spread", {p.bake_s_min, p.bake_s_max}},
                        {"wall_s", p.wall_s}, {"device_s", p.device_s},
                        {"host_s", p.host_s}, {"check_s", p.check_s},
                        {"files_s", p.files_s}, {"runs", p.runs},
                        {"order", p.order},
                        {"bundle_bytes", p.bundle_bytes}, {"pareto", p.pareto}};
    if (p.status == "measured") {
      j["error"] = p.error;
      j["record"] = p.record;
      j["metric"] = p.metric;
      j["unit"] = p.unit;
      j["tolerance"] = p.tolerance ? nlohmann::json(*p.tolerance) : nlohmann::json(nullptr);
      j["passed"] = p.passed;
      j["settings"] = p.settings;
      j["parameters"] = p.parameters;
      j["accuracy"] = p.accuracy;
    } else {
      j["reason"] = p.reason;
    }
    j["warnings"] = p.warnings;
    pts.push_back(std::move(j));
  }
  return {{"schema", "specbake.sweep/1"},
          {"job", job},
          {"kind", kind},
          {"varies", varies_j},
          {"x", "bake_s: wall seconds of the plan and compute steps (what the varied settings cost; the check and "
                "the files with their previews are timed apart: check_s, files_s); after one untimed warm-up bake, "
                "points are baked in a shuffled order (order); bakes under 1 s are repeated (runs), the fastest "
                "kept and bake_s_spread giving the range over the runs; device_s and host_s of plan and compute"},
          {"warmup", {{"point", warmup}, {"seconds", warmup_s}}},
          {"y", "error: the value of the kind's ground-truth accuracy record (see each point's record and unit)"},
          {"points", pts}};
}

std::string sweep_csv(const SweepResult& r) {
  std::string s;
  for (const auto& v : r.varies) s += csv_field(v.key) + ",";
  s += "status,bake_s,wall_s,device_s,host_s,error,unit,record,tolerance,passed,pareto,settings,check_s,files_s,"
       "bake_s_min,bake_s_max,order\n";
  for (const auto& p : r.points) {
    for (const auto& v : p.values) s += csv_field(v) + ",";
    const bool m = p.status == "measured";
    s += p.status + "," + fmt(p.bake_s) + "," + fmt(p.wall_s) + "," + fmt(p.device_s) + "," + fmt(p.host_s) + "," +
         (m ? exact(p.error) : "") + "," + csv_field(p.unit) + "," + p.record + "," +
         (p.tolerance ? exact(*p.tolerance) : "") + "," + (m ? (p.passed ? "1" : "0") : "") + "," +
         (p.pareto ? "1" : "0") + "," + csv_field(m ? p.settings : p.reason) + "," + fmt(p.check_s) + "," +
         fmt(p.files_s) + "," + fmt(p.bake_s_min) + "," + fmt(p.bake_s_max) + "," + std::to_string(p.order) + "\n";
  }
  return s;
}

SweepResult run_sweep(const SweepOptions& o, const RunProgress& progress) {
  const auto combos = sweep_combinations(o.varies);
  const YAML::Node root = load_yaml(o.config);
  const Config base = parse_config(root, o.config);  // the config as written must be valid
  {
    YAML::Node copy = YAML::Clone(root);
    (void)job_entry(copy, o.job, o.config);  // UsageError for an unknown job
  }
  const JobSpec* base_job = nullptr;
  for (const auto& j : base.jobs)
    if (j.name == o.job) base_job = &j;
  const Kind& kind = kind_named(base_job->kind);
  if (kind.truth_records.empty())
    throw UsageError("job '" + o.job + "' is a " + kind.name + " job, which measures no error against ground truth");
  if (base_job->normalised.contains("scene") && base_job->normalised["scene"] == "none")
    throw InputError(base_job->where, "job '" + o.job + "' has scene: none; a sweep measures the atmosphere "
                                      "against its scene's path-traced truth (remove scene: none or give a scene)");

  SweepResult res;
  res.job = o.job;
  res.kind = kind.name;
  res.varies = o.varies;
  res.out = o.out.empty() ? fs::path("sweep-" + o.job) : o.out;

  // Every combination is validated before anything runs: a refused value stops the sweep at once.
  std::vector<JobSpec> jobs;
  for (const auto& values : combos) {
    YAML::Node tree = YAML::Clone(root);
    auto [entry, entry_path] = job_entry(tree, o.job, o.config);
    const std::string label = label_of(o.varies, values);
    try {
      for (std::size_t i = 0; i < o.varies.size(); ++i) set_key(entry, o.varies[i].key, values[i]);
      Config cfg = parse_config(tree, o.config);
      for (auto& j : cfg.jobs)
        if (j.name == o.job) jobs.push_back(std::move(j));
    } catch (const InputError& e) {
      Location where = e.where();
      std::string what = e.what();
      if (what.rfind(where.str() + ": ", 0) == 0) what = what.substr(where.str().size() + 2);
      // a value set by --vary has no line in the file: name the key alone
      for (const auto& v : o.varies)
        if (where.key.rfind(entry_path + "." + v.key, 0) == 0) where.line = where.column = 0;
      if (is_unknown_key(e)) throw UsageError("--vary " + label + ": " + where.str() + ": " + what);
      throw InputError(where, what + " (from --vary " + label + ")");
    }
  }

  // every combination fits the device and the host before the first bake
  const cl_util::DeviceInfo info = cl_util::select_device(o.device ? *o.device : base.device);
  for (const auto& job : jobs) {
    check_device_memory(job, info);
    check_host_memory(job, kind.memory(job));
  }
  spdlog::info("sweep: {} ({} job), {} combination(s) on {}", o.job, kind.name, combos.size(), info.name);
  cl_util::Device dev(info);
  std::error_code ec;
  fs::create_directories(res.out, ec);
  if (ec || !fs::is_directory(res.out)) throw IoError("cannot create the sweep folder " + res.out.string());
  // e.g. the atmosphere's path-traced scene: traced once for every size, and kept in the sweep's
  // folder for the next sweep of the same scene
  const ResultStore results(results_dir(res.out));
  Memo memo;
  memo.store = &results;

  // Points are kept in the order they are listed, whatever the order they are baked in.
  std::vector<std::optional<SweepPoint>> baked(jobs.size());
  auto write_files = [&] {
    res.points.clear();
    for (auto& p : baked)
      if (p) res.points.push_back(*p);
    mark_pareto(res.points);
    write_whole(res.out / "sweep.json", res.json().dump(2) + "\n");
    write_whole(res.out / "sweep.csv", sweep_csv(res));
  };
  const std::vector<std::size_t> order = bake_order(jobs.size());
  ProgressEvent ev;
  ev.count = static_cast<int>(jobs.size());
  {
    // One untimed bake first: the device started, the kernels its settings need built and the
    // truth traced (kept for every point), so the first timed point is not charged for them.
    const std::size_t w = order.front();
    ev.index = 0;
    ev.job = o.job + " [warm-up: " + label_of(o.varies, combos[w]) + "]";
    res.warmup = label_of(o.varies, combos[w]);
    try {
      res.warmup_s = bake_timed(kind, jobs[w], dev, ev, progress, /*judge=*/false, &memo).bake_s;
    } catch (const Interrupted&) {
      write_files();
      throw;
    } catch (const DeviceError&) {
      throw;
    } catch (const Error& e) {
      spdlog::warn("sweep: the warm-up bake ({}) failed: {}", res.warmup, e.what());  // its point says so again
    }
  }
  for (std::size_t k = 0; k < order.size(); ++k) {
    const std::size_t i = order[k];
    const JobSpec& job = jobs[i];
    SweepPoint p;
    p.values = combos[i];
    p.order = static_cast<int>(k) + 1;
    const std::string label = label_of(o.varies, combos[i]);
    ev.index = static_cast<int>(k) + 1;
    ev.job = o.job + " [" + label + "]";
    try {
      // A bake shorter than kShortBake_s is repeated (while the repeats stay under kRepeatBudget_s)
      // and its fastest run kept: timer noise decides the order of short bakes otherwise.
      TimedBake b = bake_timed(kind, job, dev, ev, progress, /*judge=*/false, &memo);
      auto measure = [&p](const TimedBake& t) {
        double device = 0, host = 0, bake = 0, check = 0, files = 0;
        for (const auto& [step, sec] : t.steps) {
          if (step == to_string(Stage::check)) {
            check += sec.wall_s;
          } else if (step == to_string(Stage::files)) {
            files += sec.wall_s;
          } else {
            bake += sec.wall_s;
            device += sec.device_s;
            host += sec.host_s();
          }
        }
        if (p.runs == 0 || bake < p.bake_s)
          p.bake_s = bake, p.wall_s = t.bake_s, p.device_s = device, p.host_s = host, p.check_s = check,
          p.files_s = files;
        p.bake_s_min = p.runs == 0 ? bake : std::min(p.bake_s_min, bake);
        p.bake_s_max = p.runs == 0 ? bake : std::max(p.bake_s_max, bake);
        ++p.runs;
      };
      measure(b);
      for (const auto& f : b.result.files) p.bundle_bytes += f.bytes.size();
      for (double spent = b.bake_s; b.bake_s < kShortBake_s && spent < kRepeatBudget_s && p.runs < kMaxRuns;) {
        const TimedBake again = bake_timed(kind, job, dev, ev, progress, /*judge=*/false, &memo);
        spent += again.bake_s;
        measure(again);
      }
      const Accuracy* truth = nullptr;
      for (const auto& name : kind.truth_records)
        for (const auto& a : b.result.accuracy)
          if (!truth && a.name == name) truth = &a;
      p.warnings = b.result.warnings;
      if (!truth) {
        p.status = "failed";
        p.reason = "the bake recorded no error against ground truth";
      } else {
        p.status = "measured";
        p.error = truth->value;
        p.record = truth->name;
        p.metric = truth->metric;
        p.unit = truth->unit;
        p.tolerance = o.tolerance ? o.tolerance : truth->tolerance;
        // a record reported without judging may name the job's tolerance in its details
        for (const char* key : {"tolerance_de2000", "tolerance"})
          if (!p.tolerance && truth->details.is_object() && truth->details.contains(key) &&
              truth->details[key].is_number())
            p.tolerance = truth->details[key].get<double>();
        p.passed = std::isfinite(p.error) && (!p.tolerance || p.error <= *p.tolerance);
        p.parameters = b.result.parameters;
        p.accuracy = accuracy_json(b.result.accuracy);
        p.settings = kind.describe ? kind.describe(b.result.parameters) : "";
      }
      spdlog::info("sweep: [{}/{}] {}: {} in {:.2f} s", k + 1, jobs.size(), label,
                   p.status == "measured" ? fmt(p.error) + (p.unit.empty() ? "" : " " + p.unit) : p.reason, p.bake_s);
    } catch (const Interrupted&) {
      write_files();
      throw;
    } catch (const DeviceError&) {
      write_files();
      throw;
    } catch (const Error& e) {
      p.status = "failed";
      p.reason = e.what();
      spdlog::warn("sweep: [{}/{}] {}: failed: {}", k + 1, jobs.size(), label, e.what());
    }
    baked[i] = std::move(p);
    write_files();  // after every point: an interrupted sweep keeps what it measured
  }

  // The picture: scripts/sweep_plot.py, written next to the data so it can be re-run or edited.
  const fs::path script = res.out / "sweep_plot.py";
  write_whole(script, std::string(resource("scripts/sweep_plot.py")));
  const fs::path log = res.out / "sweep_plot.log";
  const std::string cmd = python_command() + " " + shell_quoted(script.string()) + " " +
                          shell_quoted((res.out / "sweep.json").string()) + " " +
                          shell_quoted((res.out / "sweep.png").string()) + " > " + shell_quoted(log.string()) + " 2>&1";
  fs::remove(res.out / "sweep.png", ec);
  const int rc = std::system(cmd.c_str());
  if (rc == 0 && fs::is_regular_file(res.out / "sweep.png")) {
    res.plotted = true;
    fs::remove(log, ec);
  } else {
    std::ifstream in(log);
    std::string line, last;
    while (std::getline(in, line))
      if (!line.empty()) last = line;
    res.plot_note = "sweep.png was not drawn (" + python_command() + " " + script.filename().string() + ": " +
                    (last.empty() ? "exit status " + std::to_string(rc) : last) +
                    "); sweep.json and sweep.csv hold the data. It needs python3-matplotlib.";
  }
  return res;
}

}  // namespace specbake
