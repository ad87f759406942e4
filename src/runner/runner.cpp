#include "runner/runner.hpp"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <ctime>
#include <fstream>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <set>

#include "core/hash.hpp"
#include "core/text.hpp"
#include "core/version.hpp"
#include "io/bundle.hpp"

namespace specbake {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

namespace {
std::string utc_now() {
  std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

std::atomic<int> g_stop{0};

void throw_if_stopped() {
  if (const int sig = g_stop.load()) throw Interrupted(sig);
}

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Physical memory the kernel reports as available to new allocations (bytes; 0 if unknown).
std::uint64_t available_host_memory() {
  std::ifstream in("/proc/meminfo");
  std::string key;
  std::uint64_t kb = 0;
  std::string unit;
  while (in >> key >> kb >> unit)
    if (key == "MemAvailable:") return kb * 1024;
  return 0;
}
}  // namespace

void request_stop(int signal) { g_stop.store(signal); }
int stop_requested() { return g_stop.load(); }
void clear_stop_request() { g_stop.store(0); }

std::vector<Config> load_configs(const std::vector<fs::path>& paths, std::vector<JobReport>* invalid) {
  std::vector<fs::path> files;
  std::set<fs::path> seen_files;
  auto add_file = [&](const fs::path& f) {
    std::error_code ec;
    const fs::path key = fs::weakly_canonical(f, ec);
    if (!seen_files.insert(ec ? f : key).second) {
      spdlog::info("{}: given more than once; read once", f.string());
      return;
    }
    files.push_back(f);
  };
  for (const auto& p : paths) {
    std::error_code ec;
    if (fs::is_directory(p, ec)) {
      std::vector<fs::path> found;
      for (const auto& e : fs::directory_iterator(p, ec)) {
        const auto ext = e.path().extension();
        if (e.is_regular_file() && (ext == ".yaml" || ext == ".yml")) found.push_back(e.path());
      }
      if (ec) throw IoError("cannot list " + p.string() + ": " + ec.message());
      if (found.empty()) throw InputError({p, 0, 0, ""}, "folder holds no *.yaml config");
      std::sort(found.begin(), found.end());
      for (const auto& f : found) add_file(f);
    } else {
      add_file(p);
    }
  }
  // Named by the job's name where it could be read, else by where it is: file:jobs[i] (the
  // file alone when the whole file is invalid).
  auto invalid_report = [](const fs::path& file, const std::string& name, const Error& e, const std::string& kind = "") {
    JobReport r;
    r.config = file.string();
    r.name = name;
    r.kind = kind;
    if (r.name.empty()) {
      const auto* input = dynamic_cast<const InputError*>(&e);
      const std::string key = input ? input->where().key : "";
      r.name = file.string() + (key.rfind("jobs[", 0) == 0 ? ":" + key.substr(0, key.find(']') + 1) : "");
    }
    r.status = "invalid";
    r.code = e.exit_code();
    r.reason = e.what();
    return r;
  };
  std::vector<Config> configs;
  std::map<std::pair<std::string, std::string>, Location> seen;  // (output, name)
  for (const auto& f : files) {
    Config c;
    std::vector<InvalidJob> job_errors;
    try {
      c = load_config(f, invalid ? &job_errors : nullptr);
    } catch (const Error& e) {
      if (!invalid || e.exit_code() == ExitCode::usage) throw;
      invalid->push_back(invalid_report(f, "", e));
      continue;
    }
    for (const auto& e : job_errors) invalid->push_back(invalid_report(f, e.name, e.error, e.kind));
    std::vector<JobSpec> kept;
    for (auto& j : c.jobs) {
      const auto key = std::make_pair(fs::weakly_canonical(c.output).string(), j.name);
      if (auto it = seen.find(key); it != seen.end()) {
        const InputError e(j.where, "job name '" + j.name + "' is also used by " + it->second.str() +
                                        " with the same output folder; expected names unique per output folder");
        if (!invalid) throw e;
        invalid->push_back(invalid_report(f, j.name, e, j.kind));
        continue;
      }
      seen.emplace(key, j.where);
      kept.push_back(std::move(j));
    }
    c.jobs = std::move(kept);
    configs.push_back(std::move(c));
  }
  return configs;
}

json report_json(const std::vector<JobReport>& reports, const std::string& error, const std::optional<Shard>& shard) {
  json jobs = json::array();
  std::map<std::string, int> counts;
  int warnings = 0;
  for (const auto& r : reports) {
    ++counts[r.status];
    warnings += static_cast<int>(r.warnings.size());
    json j = {{"name", r.name},         {"kind", r.kind},
              {"config", r.config},     {"status", r.status},
              {"reason", r.reason},     {"hash", r.hash},
              {"bundle", r.bundle.empty() ? json(nullptr) : json(r.bundle.string())},
              {"device", r.device},     {"parameters", r.parameters},
              {"accuracy", r.accuracy}, {"timings", r.timings},
              {"warnings", r.warnings}};
    if (!r.estimate.is_null()) j["estimate"] = r.estimate;
    if (r.code != ExitCode::ok) j["exit_code"] = static_cast<int>(r.code);
    jobs.push_back(j);
  }
  json out = {{"schema", "specbake.report/1"},
              {"tool", {{"name", "specbake"}, {"version", kVersion}}},
              {"created_utc", utc_now()},
              {"shard", shard ? json{{"index", shard->index}, {"count", shard->count}, {"source", shard->source}}
                              : json(nullptr)},
              {"summary",
               {{"built", counts["built"]},
                {"up_to_date", counts["up-to-date"]},
                {"failed", counts["failed"]},
                {"invalid", counts["invalid"]},
                {"interrupted", counts["interrupted"]},
                {"not_run", counts["not-run"]},
                {"planned", counts["planned"]},
                {"warnings", warnings}}},
              {"jobs", jobs}};
  if (!error.empty()) out["error"] = error;
  return out;
}

ExitCode exit_code(const std::vector<JobReport>& reports) {
  for (const auto& r : reports)
    if (r.status == "interrupted") return r.code;
  for (const auto& r : reports)
    if (r.code != ExitCode::ok) return r.code;
  return ExitCode::ok;
}

namespace {

// A failed job's report keeps what it resolved and measured before it failed (BakeFailed).
void take_what_it_got(const std::exception& e, JobReport& r) {
  const auto* failed = dynamic_cast<const BakeFailed*>(&e);
  if (!failed) return;
  if (!failed->parameters.is_null()) r.parameters = failed->parameters;
  if (!failed->accuracy.empty()) r.accuracy = failed->accuracy;
  r.warnings = failed->warnings;
}

json device_json(const cl_util::DeviceInfo& d) {
  return {{"name", d.name}, {"platform", d.platform}, {"version", d.version}, {"type", d.type}, {"fp64", d.fp64}};
}

// Opens each selected device once per run.
class Devices {
 public:
  cl_util::Device& get(const cl_util::DeviceInfo& info) {
    const auto key = std::make_pair(info.platform_index, info.device_index);
    auto it = open_.find(key);
    if (it == open_.end()) {
      spdlog::info("device: {} [{}]", info.name, info.platform);
      it = open_.emplace(key, std::make_unique<cl_util::Device>(info)).first;
    }
    return *it->second;
  }

 private:
  std::map<std::pair<int, int>, std::unique_ptr<cl_util::Device>> open_;
};

// The device a selector picks, looked up once per selector.
class Selections {
 public:
  const cl_util::DeviceInfo& get(const std::string& selector) {
    auto it = picked_.find(selector);
    if (it == picked_.end()) it = picked_.emplace(selector, cl_util::select_device(selector)).first;
    return it->second;
  }

 private:
  std::map<std::string, cl_util::DeviceInfo> picked_;
};

// `seconds`: the kind's cost model (wall seconds on a 2-core CPU under PoCL) until a bake on
// the job's device calibrates it (calibrate_estimate).
json estimate_json(const Kind& kind, const JobSpec& job) {
  const MemoryEstimate m = kind.memory(job);
  const double model_s = kind.cost_s(job);
  return {{"seconds", model_s},
          {"seconds_2core_cpu", model_s},
          {"basis", "2-core CPU model"},
          {"device_bytes", m.total_bytes},
          {"host_bytes", m.host_bytes}};
}

// The cost model scaled to a device by the job's last bake on it: the manifest of `latest` records
// the bake's seconds and the model's seconds for that bake's settings; `seconds` becomes their
// ratio times the model's seconds for these settings (the bake's own time for a rebake of the
// same settings). Unchanged without such a bundle, or when it was baked on another device.
void calibrate_estimate(json& estimate, const fs::path& latest, const json& device) {
  std::error_code ec;
  if (!fs::exists(latest / "manifest.json", ec)) return;
  try {
    std::ifstream in(latest / "manifest.json");
    const json m = json::parse(in);
    const json& d = m.at("device");
    for (const char* key : {"name", "platform", "version"})
      if (d.value(key, std::string()) != device.value(key, std::string())) return;
    const json& t = m.at("timings_s");
    const double bake_s = t.value("bake", 0.0), model_s = t.value("model_2core_cpu_s", 0.0);
    if (!(bake_s > 0.0 && model_s > 0.0)) return;
    estimate["seconds"] = estimate.value("seconds_2core_cpu", 0.0) * bake_s / model_s;
    estimate["basis"] = "last bake on this device";
    const fs::path bundle = fs::canonical(latest, ec);
    estimate["calibrated_on"] = ec ? latest.string() : bundle.string();
  } catch (const json::exception& e) {
    spdlog::debug("{}: no calibration from its manifest: {}", latest.string(), e.what());
  }
}


// Warnings and accuracy of an existing bundle (an up-to-date job reports them again).
void read_bundle_summary(const fs::path& bundle, JobReport& r) {
  std::ifstream in(bundle / "manifest.json");
  try {
    const json m = json::parse(in);
    r.accuracy = m.value("accuracy", json::array());
    r.parameters = m.value("parameters", json::object());
    for (const auto& w : m.value("warnings", json::array()))
      if (w.is_string()) r.warnings.push_back(w.get<std::string>());
  } catch (const json::exception& e) {
    spdlog::warn("{}: cannot read {}: {}", r.name, (bundle / "manifest.json").string(), e.what());
  }
}

// The kind's model of the job's cost given the results kept for it (kept_cost_s), in place of
// cost_s, calibrated as estimate_json's is. Unchanged where nothing kept applies.
void apply_kept_cost(const Kind& kind, const JobSpec& job, JobContext& ctx, json& estimate, const fs::path& latest,
                     const json& device) {
  if (!kind.kept_cost_s) return;
  const std::optional<KeptCost> s = kind.kept_cost_s(job, ctx);
  if (!s) return;
  estimate["seconds"] = s->seconds;
  estimate["seconds_2core_cpu"] = s->seconds;
  estimate["basis"] = s->basis;
  calibrate_estimate(estimate, latest, device);
}

}  // namespace

Runner::Runner(std::vector<Config> configs, RunOptions options, RunProgress progress, JobDone done)
    : configs_(std::move(configs)), options_(std::move(options)), progress_(std::move(progress)), done_(std::move(done)) {}

std::vector<Runner::Item> Runner::select() const {
  std::set<std::string> known;
  std::vector<std::string> names;
  for (const auto& c : configs_)
    for (const auto& j : c.jobs)
      if (known.insert(j.name).second) names.push_back(j.name);
  for (const auto& o : options_.only)
    if (!known.count(o)) {
      const std::string near = closest_word(o, names);
      throw UsageError("--only names job '" + o + "', which no given config defines" +
                       (near.empty() ? "" : " (did you mean '" + near + "'?)"));
    }
  std::vector<Item> items;
  for (const auto& c : configs_)
    for (const auto& j : c.jobs) {
      if (!options_.only.empty() && std::find(options_.only.begin(), options_.only.end(), j.name) == options_.only.end())
        continue;
      items.push_back({&c, &j, options_.out ? *options_.out : c.output, options_.device ? *options_.device : c.device});
    }
  // load_configs rejects a job name used twice for one output folder; --out puts every
  // config's jobs into one folder, so the same check is needed again here.
  if (options_.out) {
    std::map<std::string, const JobSpec*> seen;
    for (const auto& it : items)
      if (auto [first, fresh] = seen.emplace(it.job->name, it.job); !fresh)
        throw UsageError("--out " + options_.out->string() + " would put job '" + it.job->name + "' of " +
                         first->second->where.str() + " and of " + it.job->where.str() + " into one bundle folder");
  }
  if (options_.shard.count > 1) {
    std::vector<std::pair<std::string, double>> name_cost;
    for (const auto& it : items)
      name_cost.emplace_back(it.config->file.string() + "\n" + it.job->name, kind_named(it.job->kind).cost_s(*it.job));
    const auto shard = assign_shards(name_cost, options_.shard.count);
    std::vector<Item> mine;
    for (std::size_t i = 0; i < items.size(); ++i)
      if (shard[i] == options_.shard.index) mine.push_back(items[i]);
    spdlog::info("shard {}/{} ({}): {} of {} jobs", options_.shard.index, options_.shard.count, options_.shard.source,
                 mine.size(), items.size());
    items = std::move(mine);
  }
  return items;
}

std::vector<JobReport> Runner::plan() {
  std::vector<JobReport> reports;
  Devices devices;
  Selections selections;
  for (const auto& it : select()) {
    JobReport r;
    r.config = it.config->file.string();
    r.name = it.job->name;
    r.kind = it.job->kind;
    r.status = "planned";
    const Kind& kind = kind_named(it.job->kind);
    r.estimate = estimate_json(kind, *it.job);
    try {
      const cl_util::DeviceInfo& info = selections.get(it.device);
      r.device = device_json(info);
      r.hash = job_hash(*it.job, device_identity(info));
      BundleStore store(it.output);
      const std::string hash12 = r.hash.substr(0, 12);
      const bool current = store.is_complete(it.job->name, hash12);
      r.bundle = store.bundle_dir(it.job->name, hash12);
      calibrate_estimate(r.estimate, store.job_dir(it.job->name) / "latest", r.device);
      r.reason = current ? (options_.force ? "up to date; --force rebuilds it" : "up to date; would be skipped")
                         : "would be built";
      // plan publishes nothing; what an auto search traces and chooses is kept for `run` (and
      // what earlier runs kept is read). A bundle `run` would skip is planned from its manifest:
      // its settings are what it was baked with (a search kept under an older tool's key is not
      // run again for a bundle that will not be rebuilt).
      const ResultStore results(results_dir(it.output));
      Memo memo;
      memo.store = &results;
      JobContext ctx{devices.get(info)};
      ctx.memo = &memo;
      ctx.judge = !it.job->tolerance_advisory;  // as `run` judges: a search `run` would fail with fails here
      if (current && !options_.force) {
        JobReport baked;
        read_bundle_summary(r.bundle, baked);
        r.parameters = std::move(baked.parameters);
      } else {
        r.parameters = kind.plan(*it.job, ctx);
      }
      // what `run` then costs when work is kept for it (the scene's truth, a settings search)
      apply_kept_cost(kind, *it.job, ctx, r.estimate, store.job_dir(it.job->name) / "latest", r.device);
      const MemoryEstimate need = kind.memory(*it.job);
      check_device_memory(*it.job, need, info);
      check_host_memory(*it.job, need);
    } catch (const Error& e) {
      r.code = e.exit_code();
      r.status = r.code == ExitCode::invalid_input ? "invalid" : "failed";
      r.reason = e.what();
      take_what_it_got(e, r);
    }
    if (done_) done_(r);
    reports.push_back(std::move(r));
  }
  return reports;
}


// Refuses a job whose host-memory estimate exceeds what the machine has available.
void check_host_memory(const JobSpec& job, const MemoryEstimate& need) {
  const std::uint64_t avail = available_host_memory();
  if (avail > 0 && need.host_bytes > avail)
    throw InputError(job.where, "job '" + job.name + "' needs about " + std::to_string(need.host_bytes >> 20) +
                                    " MiB of host memory but " + std::to_string(avail >> 20) +
                                    " MiB are available; expected smaller sizes");
}

TimedBake bake_timed(const Kind& kind, const JobSpec& job, cl_util::Device& dev, ProgressEvent ev,
                     const RunProgress& progress, bool judge, Memo* memo, const std::string& bundle_hash,
                     double estimate_s, bool defer_files) {
  if (estimate_s < 0.0) estimate_s = kind.cost_s(job);
  const auto tb = Clock::now();
  JobContext ctx{dev};
  ctx.judge = judge && !job.tolerance_advisory;
  ctx.memo = memo;
  ctx.bundle_hash = bundle_hash;
  // Each step is a stage of the device's profiler: device and host seconds (cl/timing.hpp). The
  // steps are chained — each opens at the instant the one before closed, the first at the bake's
  // start — so that their wall times partition the bake's.
  std::vector<cl_util::Profiler::Record> steps;
  std::optional<cl_util::Profiler::Stage> step(std::in_place, dev.profiler(), to_string(ev.stage), 0, tb);
  ctx.on_stage = [&](Stage s) {
    const auto t = Clock::now();
    steps.push_back(step->close(t));
    step.reset();
    ev.stage = s;
    step.emplace(dev.profiler(), to_string(s), 0, t);
    throw_if_stopped();
  };
  ctx.progress = [&](std::string_view what, double f) {
    throw_if_stopped();
    ev.what = std::string(what);
    ev.fraction = std::max(ev.fraction, std::clamp(f, 0.0, 1.0));  // the job's share done never goes back
    const double elapsed = seconds_since(tb);
    // ETA: from the measured rate once a few percent are done, else from the estimate (`run`: the
    // cost model scaled by the job's last bake on this device, as `plan` shows it).
    ev.eta_s = ev.fraction >= 0.05 ? elapsed * (1.0 - ev.fraction) / ev.fraction : std::max(0.0, estimate_s - elapsed);
    spdlog::trace("{}: {} {}: {:.1f} %", ev.job, to_string(ev.stage), ev.what, 100.0 * ev.fraction);
    if (progress) progress(ev);
  };
  TimedBake out{kind.bake(job, ctx), 0.0, {}};
  if (!defer_files) finish_files(out.result);  // in the step the bake ended in: files
  dev.profiler().settle();  // waiting for the commands still running is the last step's time
  const auto te = Clock::now();
  steps.push_back(step->close(te));
  step.reset();
  out.bake_s = std::chrono::duration<double>(te - tb).count();
  for (const auto& rec : steps) cl_util::accumulate(out.steps[rec->stage], *rec);
  for (const auto& [step_name, sec] : out.steps)
    spdlog::debug("{}: step {}: device {:.3f} s, host {:.3f} s (wall {:.3f} s)", ev.job, step_name, sec.device_s,
                  sec.host_s(), sec.wall_s);
  if (judge) judge_tolerances(job, out.result);
  return out;
}

void judge_tolerances(const JobSpec& job, BakeResult& result) {
  std::string missed;
  bool self_check = false;
  for (const Accuracy& a : result.accuracy) {
    if (!a.tolerance || a.passed) continue;
    missed += (missed.empty() ? "" : "; ") + a.name + " " + format_g(a.value) + (a.unit.empty() ? "" : " " + a.unit) +
              " > tolerance " + format_g(*a.tolerance) + " (" + a.metric + ")";
    self_check = self_check || a.name == "self_check";
  }
  if (missed.empty()) return;
  if (job.tolerance_advisory && !self_check) {
    result.warnings.push_back("tolerance_advisory: published although it misses its tolerance: " + missed);
    return;
  }
  throw BakeFailed("missed its tolerance: " + missed + "; nothing published" +
                       (self_check ? " (a self-check is never advisory)"
                                   : " (tolerance_advisory: true in the job publishes it with a warning)"),
                   result.parameters, accuracy_json(result.accuracy), result.warnings);
}

std::vector<JobReport> Runner::run() {
  const auto items = select();
  // Output folders are checked before any job runs: an unwritable one stops the run.
  std::set<fs::path> roots;
  for (const auto& it : items) roots.insert(it.output);
  for (const auto& root : roots) BundleStore(root).check_writable();

  std::vector<JobReport> reports;
  Devices devices;
  Selections selections;
  bool stopped = false;
  // How a job that did not finish is reported (the exception its bake or its writing threw).
  const auto record_failure = [&](const std::exception& e, JobReport& r) {
    if (const auto* interrupted = dynamic_cast<const Interrupted*>(&e)) {
      r.status = "interrupted";
      r.code = interrupted->exit_code();
      r.reason = std::string(e.what()) + "; nothing of this job was published";
      stopped = true;
    } else if (const int sig = stop_requested()) {
      // A stop came first: a failure after it is what the signal did (a system call it cut
      // short inside a library's step), not the job's.
      const Interrupted stop(sig);
      r.status = "interrupted";
      r.code = stop.exit_code();
      r.reason = std::string(stop.what()) + " (the step it stopped: " + e.what() + "); nothing of this job was published";
      stopped = true;
    } else {
      const auto* known = dynamic_cast<const Error*>(&e);
      r.code = known ? known->exit_code() : ExitCode::job_failed;
      // a job the config or its input makes impossible (too large, an unreadable input) is invalid
      r.status = r.code == ExitCode::invalid_input ? "invalid" : "failed";
      r.reason = e.what();
      take_what_it_got(e, r);
      spdlog::debug("{}: {}: {}", r.name, r.status, e.what());  // the summary (-q: stderr) says it once
    }
  };
  // The end of a job's report: a job left without a bundle leaves no empty folder; `done_` sees
  // the reports in the jobs' order.
  const auto close_report = [&](JobReport& r, const fs::path& job_dir, Clock::time_point t0, Clock::time_point end) {
    if (r.status != "built" && r.status != "up-to-date") {
      r.bundle.clear();
      std::error_code ec;
      fs::remove(job_dir, ec);  // only when empty: a job that never produced a bundle
    }
    r.timings["total_s"] = std::chrono::duration<double>(end - t0).count();
    if (done_) done_(r);
  };
  // A built job's bundle is finished (BakeResult::finish: encodings, previews), written and
  // published on a thread of its own while the next job bakes (the job's lock held until it is
  // in place); at most one is in flight, and its report is finished before the next job's report
  // or publish, and at the end of the run.
  struct Written {
    fs::path bundle;
    Clock::time_point at;
    double finish_s = 0.0;  // BakeResult::finish's seconds, part of the files step
  };
  struct Publishing {
    std::size_t report = 0;  // its index in `reports`
    std::unique_ptr<JobLock> lock;
    std::future<Written> written;
    Clock::time_point t0, start;
    fs::path job_dir;
  };
  // A step's seconds with `host_s` more host work in it (the files step and its finish).
  const auto add_host_seconds = [](json& step, double host_s) {
    if (!step.is_object()) step = {{"device_s", 0.0}, {"host_s", 0.0}, {"wall_s", 0.0}};
    for (const char* k : {"host_s", "wall_s"}) step[k] = step.value(k, 0.0) + host_s;
  };
  std::optional<Publishing> publishing;
  const auto settle_publishing = [&] {
    if (!publishing) return;
    JobReport& r = reports[publishing->report];
    Clock::time_point end = Clock::now();
    try {
      const Written w = publishing->written.get();
      end = w.at;
      r.bundle = w.bundle;
      r.timings["write_s"] = std::chrono::duration<double>(w.at - publishing->start).count();
      if (w.finish_s > 0.0) {
        add_host_seconds(r.timings["steps_s"]["files"], w.finish_s);
        r.timings["bake_s"] = r.timings.value("bake_s", 0.0) + w.finish_s;
      }
    } catch (const std::exception& e) {
      record_failure(e, r);
    }
    publishing->lock.reset();
    close_report(r, publishing->job_dir, publishing->t0, end);
    publishing.reset();
  };
  for (std::size_t index = 0; index < items.size(); ++index) {
    const Item& it = items[index];
    const std::string& name = it.job->name;
    JobReport r;
    r.config = it.config->file.string();
    r.name = name;
    r.kind = it.job->kind;
    if (stopped) {
      r.status = "not-run";
      r.reason = "the run was stopped before this job";
      reports.push_back(std::move(r));
      continue;
    }
    const Kind& kind = kind_named(it.job->kind);
    BundleStore store(it.output);
    const auto t0 = Clock::now();
    json stage_s = json::object();
    bool deferred = false;  // its bundle is being written (publishing)
    try {
      throw_if_stopped();
      const cl_util::DeviceInfo& info = selections.get(it.device);
      r.device = device_json(info);
      r.hash = job_hash(*it.job, device_identity(info));
      spdlog::trace("{}: hash {} (config, {} inputs, {} programs, device {})", name, r.hash, it.job->inputs.size(),
                    kind.programs.size(), info.name);
      const std::string hash12 = r.hash.substr(0, 12);
      {
        auto lock = std::make_unique<JobLock>(store.job_dir(name), name);
        store.clean_stale(name);
        if (!options_.force && store.is_complete(name, hash12)) {
          store.set_latest(name, hash12);
          r.status = "up-to-date";
          r.reason = "a complete bundle with this hash exists";
          r.bundle = store.bundle_dir(name, hash12);
          read_bundle_summary(r.bundle, r);
          spdlog::info("{}: up to date ({})", name, r.bundle.string());
        } else {
          spdlog::info("{}: baking ({} job)", name, it.job->kind);
          const MemoryEstimate need = kind.memory(*it.job);
          check_device_memory(*it.job, need, info);
          check_host_memory(*it.job, need);
          cl_util::Device& dev = devices.get(info);
          ProgressEvent ev;
          ev.index = static_cast<int>(index) + 1;
          ev.count = static_cast<int>(items.size());
          ev.job = name;
          // results this bake can take from earlier runs, and keeps for later ones
          const ResultStore results(results_dir(it.output));
          Memo memo;
          memo.store = &results;
          json estimate = estimate_json(kind, *it.job);
          calibrate_estimate(estimate, store.job_dir(name) / "latest", r.device);
          {
            JobContext probe{dev};
            probe.memo = &memo;
            apply_kept_cost(kind, *it.job, probe, estimate, store.job_dir(name) / "latest", r.device);
          }
          TimedBake baked = bake_timed(kind, *it.job, dev, ev, progress_, true, &memo, r.hash,
                                       estimate.value("seconds", -1.0), /*defer_files=*/true);
          BakeResult& result = baked.result;
          const double bake_s = baked.bake_s;
          for (const auto& [step_name, sec] : baked.steps) stage_s[step_name] = cl_util::seconds_json(sec);
          // the job's warnings are said once, by the summary (-q: on stderr)
          for (const auto& w : result.warnings) spdlog::debug("{}: warning: {}", name, w);
          throw_if_stopped();

          json manifest = {
              {"schema", "specbake.bundle/1"},
              {"tool", {{"name", "specbake"}, {"version", kVersion}}},
              {"job",
               {{"name", name},
                {"kind", it.job->kind},
                {"hash", r.hash},
                {"config_file", fs::absolute(it.config->file).string()}}},
              {"config", it.job->normalised},
              {"inputs", json::object()},
              {"kernels", json::object()},
              {"device", r.device},
              {"parameters", result.parameters},
              {"accuracy", accuracy_json(result.accuracy)},
              {"warnings", result.warnings},
              {"created_utc", utc_now()},
          };
          if (!memo.store_used.empty()) manifest["results_kept"] = memo.store_used;
          for (const auto& [label, sha] : it.job->inputs) manifest["inputs"][label] = sha;
          for (const auto& k : kind.programs) manifest["kernels"][k] = sha256_hex(expanded_program(k));
          // the model of what this run cost (results kept from earlier runs included), which a
          // later run's calibrate_estimate scales by
          manifest["timings_s"] = {{"bake", bake_s},
                                   {"model_2core_cpu_s", estimate.value("seconds_2core_cpu", kind.cost_s(*it.job))},
                                   {"steps", stage_s}};
          settle_publishing();
          r.status = "built";
          r.parameters = result.parameters;
          r.accuracy = accuracy_json(result.accuracy);
          r.warnings = result.warnings;
          r.timings = {{"bake_s", bake_s}, {"steps_s", stage_s}};
          const auto start = Clock::now();
          publishing = Publishing{
              reports.size(), std::move(lock),
              std::async(std::launch::async,
                         [store, name, hash12, add_host_seconds, manifest = std::move(manifest),
                          result = std::move(result)]() mutable {
                           Written w;
                           w.finish_s = finish_files(result);
                           // the job's seconds are its work's, on whichever thread it ran
                           if (w.finish_s > 0.0) {
                             add_host_seconds(manifest["timings_s"]["steps"]["files"], w.finish_s);
                             manifest["timings_s"]["bake"] = manifest["timings_s"].value("bake", 0.0) + w.finish_s;
                           }
                           for (auto b = result.manifest_blocks.begin(); b != result.manifest_blocks.end(); ++b) {
                             if (manifest.contains(b.key()))
                               throw JobError("manifest block '" + b.key() + "' clashes with a standard key");
                             manifest[b.key()] = b.value();
                           }
                           w.bundle = store.publish(name, hash12, manifest, result.files);
                           spdlog::info("{}: wrote {}", name, w.bundle.string());  // as it happens
                           w.at = Clock::now();
                           return w;
                         }),
              t0, start, store.job_dir(name)};
          deferred = true;
        }
      }
    } catch (const std::exception& e) {
      record_failure(e, r);
    }
    if (deferred) {
      reports.push_back(std::move(r));
      continue;
    }
    settle_publishing();
    close_report(r, store.job_dir(name), t0, Clock::now());
    reports.push_back(std::move(r));
  }
  settle_publishing();
  return reports;
}

}  // namespace specbake
