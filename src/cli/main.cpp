// specbake — command line. A thin layer over the library (runner/runner.hpp): parse
// arguments, set up logging and progress, print results, map errors to the documented exit codes.
#include <CLI/CLI.hpp>
#include <spdlog/sinks/base_sink.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <mutex>
#include <optional>
#include <sstream>
#include <set>

#include "cl/device.hpp"
#include "core/hash.hpp"
#include "core/version.hpp"
#include "io/bundle.hpp"
#include "io/bundle_diff.hpp"
#include "io/inspect.hpp"
#include "io/output_folder.hpp"
#include "kinds/atmosphere/truth/truth.hpp"
#include "runner/html_report.hpp"
#include "runner/night_report.hpp"
#include "runner/runner.hpp"
#include "runner/sweep.hpp"

using namespace specbake;
using nlohmann::json;

namespace {

// ---- progress and logging on the terminal ---------------------------------------------------

// A live status line on a terminal (redrawn in place, cleared around log lines), or plain
// progress lines when stderr is not a terminal (at step changes and every few seconds).
class ProgressLine {
 public:
  explicit ProgressLine(bool tty) : tty_(tty) {}

  void show(const ProgressEvent& e) {
    std::lock_guard lock(m_);
    char eta[32] = "";
    if (e.eta_s >= 0.0) std::snprintf(eta, sizeof eta, ", ETA %s", duration(e.eta_s).c_str());
    char buf[256];
    // "files" while in the files step is said once
    const std::string what = e.what == to_string(e.stage) ? "" : ", " + e.what;
    std::snprintf(buf, sizeof buf, "[%d/%d] %s: %s%s %3.0f %%%s", e.index, e.count, e.job.c_str(), to_string(e.stage),
                  what.c_str(), 100.0 * e.fraction, eta);
    if (tty_) {
      line_ = buf;
      draw();
      return;
    }
    // Plain lines: a job's step changes once it has run a couple of seconds, and every 10 s.
    const auto now = std::chrono::steady_clock::now();
    if (e.job != job_) job_ = e.job, job_start_ = now, last_key_.clear();
    const std::string key = to_string(e.stage);
    if ((key != last_key_ && now - job_start_ > std::chrono::seconds(2)) || now - last_ > std::chrono::seconds(10)) {
      std::fprintf(stderr, "%s\n", buf);
      last_key_ = key;
      last_ = now;
    }
  }
  void done() {
    std::lock_guard lock(m_);
    clear();
    line_.clear();
  }
  // Around other output to stderr.
  void clear() {
    if (tty_ && !line_.empty()) std::fputs("\r\033[K", stderr);
  }
  void draw() {
    if (tty_ && !line_.empty()) {
      std::fprintf(stderr, "\r\033[K%s", line_.c_str());
      std::fflush(stderr);
    }
  }
  std::mutex& mutex() { return m_; }

  static std::string duration(double s) {
    char b[32];
    if (s < 10) std::snprintf(b, sizeof b, "%.1f s", s);
    else if (s < 60) std::snprintf(b, sizeof b, "%.0f s", s);
    else std::snprintf(b, sizeof b, "%d min %02d s", static_cast<int>(s) / 60, static_cast<int>(s) % 60);
    return b;
  }

 private:
  bool tty_;
  std::mutex m_;
  std::string line_, last_key_, job_;
  std::chrono::steady_clock::time_point last_{}, job_start_{};
};

// spdlog sink writing "[level] message" to stderr without tearing the progress line.
class StderrSink : public spdlog::sinks::base_sink<std::mutex> {  // a bundle's writer thread logs too
 public:
  explicit StderrSink(ProgressLine& p) : progress_(p) {}

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    spdlog::memory_buf_t out;
    formatter_->format(msg, out);
    std::lock_guard lock(progress_.mutex());
    progress_.clear();
    std::fwrite(out.data(), 1, out.size(), stderr);
    progress_.draw();
  }
  void flush_() override { std::fflush(stderr); }

 private:
  ProgressLine& progress_;
};

// ---- signals ---------------------------------------------------------------------------------

extern "C" void on_stop_signal(int sig) {
  request_stop(sig);
  std::signal(sig, SIG_DFL);  // a second Ctrl-C ends the process at once
}

// ---- printing ---------------------------------------------------------------------------------

std::string fmt_number(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.3g", v);
  return b;
}

std::string headline(const json& accuracy) { return accuracy_headline(accuracy); }

std::string describe(const JobReport& r) {
  if (r.parameters.is_null() || r.parameters.empty()) return "";
  for (const auto& k : kinds())
    if (k.name == r.kind && k.describe) return k.describe(r.parameters);
  return "";
}

std::string pad(std::string s, std::size_t w) {
  if (s.size() < w) s.append(w - s.size(), ' ');
  return s;
}

void print_table(const std::vector<std::vector<std::string>>& rows) {
  std::vector<std::size_t> w;
  for (const auto& r : rows)
    for (std::size_t i = 0; i < r.size(); ++i) {
      if (w.size() <= i) w.push_back(0);
      w[i] = std::max(w[i], r[i].size());
    }
  for (const auto& r : rows) {
    std::string line;
    for (std::size_t i = 0; i < r.size(); ++i) line += i + 1 < r.size() ? pad(r[i], w[i] + 2) : r[i];
    while (!line.empty() && line.back() == ' ') line.pop_back();
    std::cout << line << "\n";
  }
}

std::string summary_line(const std::vector<JobReport>& reports, bool plan) {
  std::map<std::string, int> n;
  int warnings = 0;
  for (const auto& r : reports) {
    ++n[r.status];
    warnings += static_cast<int>(r.warnings.size());
  }
  std::string s;
  if (plan) {
    s = std::to_string(n["planned"]) + " planned, " + std::to_string(n["failed"]) + " failed";
  } else {
    s = std::to_string(n["built"]) + " built, " + std::to_string(n["up-to-date"]) + " up to date, " +
        std::to_string(n["failed"]) + " failed";
    if (n["interrupted"]) s += ", " + std::to_string(n["interrupted"]) + " interrupted";
    if (n["not-run"]) s += ", " + std::to_string(n["not-run"]) + " not run";
  }
  if (n["invalid"]) s += ", " + std::to_string(n["invalid"]) + " invalid";
  s += ", " + std::to_string(warnings) + " warning" + (warnings == 1 ? "" : "s");
  return s;
}

void print_reports(const std::vector<JobReport>& reports, bool plan, int verbose) {
  std::vector<std::vector<std::string>> rows;
  if (plan) {
    rows.push_back({"job", "kind", "status", "est. time", "device mem", "host mem", "settings"});
  } else {
    rows.push_back({"job", "kind", "status", "time", "accuracy (headline)", "warnings", "settings"});
  }
  for (const auto& r : reports) {
    if (plan) {
      std::string est = "-", dmem = "-", hmem = "-";
      if (r.estimate.is_object()) {
        est = "~" + ProgressLine::duration(r.estimate.value("seconds", 0.0));
        if (r.estimate.contains("calibrated_on")) est += "*";
        auto mib = [](std::uint64_t bytes) { return bytes < (1u << 20) ? std::string("<1 MiB") : std::to_string(bytes >> 20) + " MiB"; };
        dmem = mib(r.estimate.value("device_bytes", std::uint64_t{0}));
        hmem = mib(r.estimate.value("host_bytes", std::uint64_t{0}));
      }
      rows.push_back({r.name, r.kind, r.status == "planned" ? r.reason : r.status, est, dmem, hmem, describe(r)});
    } else {
      // a job that ran (built, failed, interrupted, up to date) took its time; invalid, not run: "-"
      const bool timed = r.timings.is_object() && r.timings.contains("total_s");
      rows.push_back({r.name, r.kind.empty() ? "-" : r.kind, r.status,
                      timed ? ProgressLine::duration(r.timings["total_s"].get<double>()) : "-", headline(r.accuracy),
                      std::to_string(r.warnings.size()), describe(r)});
    }
  }
  print_table(rows);
  if (plan) {
    const auto calibrated = [](const JobReport& r) {
      return r.estimate.is_object() && r.estimate.contains("calibrated_on");
    };
    if (std::any_of(reports.begin(), reports.end(), calibrated))
      std::cout << "* est. time scaled to this device by the job's last bake on it"
                << (std::all_of(reports.begin(), reports.end(), calibrated) ? "" : "; others: the 2-core CPU model")
                << "\n";
  }
  // Why jobs failed, each reason once (a missing device fails every job alike), naming its jobs.
  std::vector<std::pair<std::string, std::string>> why;  // (status: reason, jobs)
  for (const auto& r : reports) {
    if (r.code == ExitCode::ok) continue;
    const std::string text = r.status + ": " + r.reason;
    auto it = std::find_if(why.begin(), why.end(), [&](const auto& w) { return w.first == text; });
    if (it == why.end()) why.emplace_back(text, r.name);
    else it->second += ", " + r.name;
  }
  for (const auto& [text, jobs] : why) std::cout << jobs << ": " << text << "\n";
  for (const auto& r : reports) {
    const bool bad = r.code != ExitCode::ok;
    for (const auto& w : r.warnings) std::cout << "warning: " << r.name << ": " << w << "\n";
    if (verbose > 0) {
      std::cout << r.name << " (" << r.kind << ", " << r.config << ")\n";
      if (!r.hash.empty()) std::cout << "  hash:       " << r.hash.substr(0, 12) << "\n";
      if (!r.bundle.empty()) std::cout << "  bundle:     " << r.bundle.string() << "\n";
      if (!r.reason.empty() && !bad) std::cout << "  status:     " << r.status << " — " << r.reason << "\n";
      // one line per key (its whole value as JSON) or accuracy record
      const auto per_key = [](const char* label, const json& block) {
        if (!block.is_object()) return;
        std::cout << "  " << label << ":\n";
        for (const auto& [k, v] : block.items()) std::cout << "    " << k << ": " << v.dump() << "\n";
      };
      per_key("parameters", r.parameters);
      if (r.accuracy.is_array() && !r.accuracy.empty()) {
        std::cout << "  accuracy:\n";
        for (const auto& a : r.accuracy) std::cout << "    " << headline(json::array({a})) << "\n";
      }
      per_key("timings", r.timings);
    }
  }
  std::cout << summary_line(reports, plan) << "\n";
}

int cmd_devices() {
  const auto devices = cl_util::list_devices();
  if (devices.empty()) {
    std::cout << "no OpenCL platform found (install pocl-opencl-icd for the CPU device)\n";
    return static_cast<int>(ExitCode::device);
  }
  std::string chosen;
  try {
    chosen = cl_util::select_device("auto").name;
  } catch (const Error&) {
  }
  for (const auto& d : devices) {
    std::cout << (d.name == chosen ? "* " : "  ") << "[" << d.platform_index << "." << d.device_index << "] " << d.name
              << "\n      platform: " << d.platform << "\n      type: " << d.type << ", " << d.version
              << ", fp64: " << (d.fp64 ? "yes" : "no") << ", compute units: " << d.compute_units
              << ", memory: " << (d.global_mem_bytes >> 20) << " MiB\n";
  }
  std::cout << "* = what --device auto picks\n";
  return 0;
}

// inspect OUT: one line per job folder (its latest bundle).
int cmd_inspect_output(const fs::path& dir, bool as_json) {
  const auto jobs = scan_output_folder(dir);
  if (as_json) {
    json j = json::array();
    for (const auto& o : jobs) j.push_back(o.to_json());
    std::cout << json{{"output", fs::weakly_canonical(dir).string()}, {"jobs", j}}.dump(2) << "\n";
    return 0;
  }
  std::vector<std::vector<std::string>> rows{{"job", "kind", "bundle", "size", "age", "accuracy (headline)"}};
  for (const auto& o : jobs) {
    const json j = o.to_json();
    rows.push_back({o.name, j["kind"], j["hash"].get<std::string>().substr(0, 12), human_bytes(o.bytes),
                    human_age(o.age_s), j["headline"]});
  }
  print_table(rows);
  std::cout << jobs.size() << " job(s) in " << fs::weakly_canonical(dir).string()
            << "; `specbake inspect " << (dir / "JOB").string() << "` checks one bundle's files\n";
  return 0;
}

int cmd_inspect(const fs::path& path, bool as_json) {
  std::error_code ec;
  if (!fs::exists(path / "manifest.json", ec) && !fs::exists(path / "latest", ec)) {
    if (is_output_folder(path)) return cmd_inspect_output(path, as_json);
    throw InputError({path, 0, 0, ""}, "expected a bundle folder (with manifest.json), a job folder (with a `latest` "
                                       "bundle) or an output folder (job folders with `latest` bundles)");
  }
  const Inspection in = inspect_bundle(path);
  const int rc = in.bad ? static_cast<int>(ExitCode::job_failed) : 0;
  if (as_json) {
    std::cout << in.to_json().dump(2) << "\n";
    return rc;
  }
  const json& m = in.manifest;
  auto field = [&](const char* block, const char* key) {
    return m.contains(block) && m[block].is_object() && m[block].contains(key) ? m[block][key].dump() : "?";
  };
  auto text = [&](const char* block, const char* key) {
    const std::string s = field(block, key);
    return s.size() >= 2 && s.front() == '"' ? s.substr(1, s.size() - 2) : s;
  };
  std::cout << "bundle:   " << fs::weakly_canonical(in.bundle).string() << "\n"
            << "job:      " << text("job", "name") << " (" << text("job", "kind") << ")\n"
            << "hash:     " << text("job", "hash") << "\n"
            << "tool:     specbake " << text("tool", "version") << ", created " << m.value("created_utc", "?") << "\n"
            << "device:   " << text("device", "name") << " (" << text("device", "platform") << ")\n";
  std::cout << "accuracy:\n";
  for (const auto& a : m.value("accuracy", json::array())) std::cout << "  " << headline(json::array({a})) << "\n";
  for (const auto& w : m.value("warnings", json::array())) std::cout << "warning:  " << w.dump() << "\n";
  std::cout << "files:\n";
  for (const auto& f : in.files) {
    const std::string status = f.status == "ok" ? "ok" : f.status == "missing" ? "MISSING" : "SHA256 MISMATCH";
    std::cout << "  " << status << "  " << f.path << "  " << f.bytes;
    if (!f.shape.is_null()) std::cout << "  " << f.dtype << f.shape.dump();
    std::cout << "\n";
  }
  if (in.bad) {
    std::cout << in.bad << " file(s) failed their check\n";
    return rc;
  }
  std::cout << "all " << in.files.size() << " files match their sha256\n";
  return 0;
}

// A file a command will write (`option` names it), checked before any work: a folder is a usage
// error, a place that cannot be written an I/O error.
void check_output_file(const std::string& path, const std::string& option) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw UsageError(option + " " + path + " is a folder; expected a file path");
  const fs::path parent = fs::absolute(path).parent_path();
  if (!fs::is_directory(parent, ec)) throw IoError("cannot write " + option + " " + path + ": no folder " + parent.string());
  if (::access(parent.c_str(), W_OK) != 0 || (fs::exists(path, ec) && ::access(path.c_str(), W_OK) != 0))
    throw IoError("cannot write " + option + " " + path + ": permission denied");
}

// --report: checked when the run starts (a folder, or a path that cannot be written, stops the
// run before any work), written atomically at the end — also when the run stops early.
class ReportFile {
 public:
  explicit ReportFile(std::string path) : path_(std::move(path)) {
    if (!path_.empty()) check_output_file(path_, "--report");
  }
  void write(const std::vector<JobReport>& reports, const std::string& error = "",
             const std::optional<Shard>& shard = std::nullopt) const {
    if (path_.empty()) return;
    const fs::path tmp = path_ + ".tmp";
    {
      std::ofstream o(tmp);
      o << report_json(reports, error, shard).dump(2) << "\n";
      if (!o.flush()) {
        std::error_code ec;
        fs::remove(tmp, ec);
        throw IoError("cannot write report " + tmp.string());
      }
    }
    std::error_code ec;
    fs::rename(tmp, path_, ec);
    if (ec) {
      fs::remove(tmp, ec);
      throw IoError("cannot write report " + path_ + ": " + ec.message());
    }
  }

 private:
  std::string path_;
};

std::string index_text(const std::vector<std::int64_t>& idx) {
  std::string s = "[";
  for (std::size_t i = 0; i < idx.size(); ++i) s += (i ? "," : "") + std::to_string(idx[i]);
  return s + "]";
}

// "old -> new" of a manifest value, short: a long array says how many of its entries differ and
// the first, other long values are cut (the manifests hold the whole).
std::string change_text(const json& a, const json& b) {
  constexpr std::size_t kLong = 120;
  const std::string da = a.dump(), db = b.dump();
  if (da.size() + db.size() <= kLong) return da + " -> " + db;
  if (a.is_array() && b.is_array() && a.size() == b.size()) {
    std::size_t first = a.size(), n = 0;
    for (std::size_t i = 0; i < a.size(); ++i)
      if (a[i] != b[i]) {
        if (first == a.size()) first = i;
        ++n;
      }
    const std::string ea = a[first].dump(), eb = b[first].dump();
    return "list of " + std::to_string(a.size()) + ", " + std::to_string(n) + " entries differ; first [" +
           std::to_string(first) + "]: " + (ea.size() + eb.size() <= kLong ? ea + " -> " + eb : "(long; see the manifests)");
  }
  const auto cut = [](const std::string& s) { return s.size() <= 50 ? s : s.substr(0, 47) + "..."; };
  return cut(da) + " -> " + cut(db) + " (cut; see the manifests)";
}

int cmd_diff(const fs::path& a, const fs::path& b, double fail_abs, double fail_rel) {
  const BundleDiff d = diff_bundles(a, b, fail_abs, fail_rel);
  for (const auto& f : d.files) {
    std::cout << "  " << f.status << "  " << f.path;
    if (f.numeric && f.status == "differs") {
      auto where = [&](const std::vector<std::int64_t>& at) {
        std::string s = index_text(at);
        if (!f.channels.empty() && !at.empty() && at.back() < static_cast<std::int64_t>(f.channels.size()))
          s += " (channel " + f.channels[at.back()] + ")";
        return s;
      };
      std::cout << "  max abs " << f.max_abs << " at " << where(f.at_abs) << ", max rel " << f.max_rel << " at "
                << where(f.at_rel) << ", " << f.exceeding << " beyond thresholds";
      if (f.nan_mismatches) std::cout << " (" << f.nan_mismatches << " NaN in one bundle only)";
    }
    std::cout << "\n";
  }
  if (!d.accuracy.empty()) {
    std::cout << "accuracy changes:\n";
    const auto shown = [](const json& r) {
      if (r.is_null()) return std::string("(none)");
      std::string s = r["value"].is_number() ? fmt_number(r["value"].get<double>()) : r["value"].dump();
      if (r["tolerance"].is_number())
        s += std::string(r.value("passed", false) ? " <= " : " > ") + fmt_number(r["tolerance"].get<double>());
      return s;
    };
    for (auto it = d.accuracy.begin(); it != d.accuracy.end(); ++it)
      std::cout << "  " << it.key() << ": " << shown(it.value()["old"]) << " -> " << shown(it.value()["new"]) << "\n";
  }
  if (!d.changed.empty()) {
    std::cout << "manifest changes:\n";
    for (auto it = d.changed.begin(); it != d.changed.end(); ++it)
      std::cout << "  " << it.key() << ": " << change_text(it.value()[0], it.value()[1]) << "\n";
  }
  const bool ok = diff_passes(d);
  std::cout << (ok ? "within thresholds" : "DIFFERS beyond thresholds") << " (fail-abs " << fail_abs << ", fail-rel "
            << fail_rel << ")\n";
  return ok ? 0 : static_cast<int>(ExitCode::job_failed);
}

// specbake truth: path-traced sky radiance of an atmosphere job at given views (the ground truth
// the bundle's textures are judged by), optionally with the bundle's own GetSkyRadiance.
struct TruthArgs {
  std::string config, job, points, out, orders = "all", bundle, device;
  long long paths = 4096;
  std::uint64_t seed = 1;
};

int cmd_truth(const TruthArgs& a) {
  const Config cfg = load_config(a.config);
  std::vector<std::string> names;
  const JobSpec* job = nullptr;
  for (const auto& j : cfg.jobs) {
    names.push_back(j.name);
    if (j.name == a.job) job = &j;
  }
  if (!job) {
    const std::string near = closest_word(a.job, names);
    throw UsageError("--job names '" + a.job + "', which " + a.config + " does not define" +
                     (near.empty() ? "" : " (did you mean '" + near + "'?)"));
  }
  if (job->kind != "atmosphere")
    throw UsageError("job '" + a.job + "' is a " + job->kind + " job; truth traces atmosphere jobs");
  const auto& spec = job->as<AtmosphereSpec>();
  atmosphere::TruthOptions o;
  o.paths = a.paths;
  o.seed = a.seed;
  if (a.orders != "all") {
    try {
      std::size_t used = 0;
      o.orders = std::stoi(a.orders, &used);
      if (used != a.orders.size() || o.orders < 1) throw std::invalid_argument("orders");
    } catch (const std::exception&) {
      throw UsageError("--orders expects a positive integer or 'all', got '" + a.orders + "'");
    }
  }
  if (a.paths < 1) throw UsageError("--paths expects a positive integer");
  // everything that can be wrong is found before the trace: the output, the points, the bundle
  check_output_file(a.out, "--out");
  const auto points = atmosphere::read_truth_points(a.points);
  const fs::path bundle = a.bundle.empty() ? fs::path() : resolve_bundle(a.bundle);  // a job folder: its latest
  std::optional<atmosphere::Luts> luts;
  if (!bundle.empty()) luts = atmosphere::load_bundle_luts(bundle);
  cl_util::Device dev(cl_util::select_device(a.device.empty() ? cfg.device : a.device));
  spdlog::info("truth: {} points, {} paths each, orders {}, seed {} on {}", points.size(), o.paths, a.orders, o.seed,
               dev.info().name);
  const auto result = atmosphere::trace_truth(spec, dev, points, o);
  std::vector<atmosphere::Vec3> lut;
  if (luts) lut = atmosphere::lut_sky_radiance(*luts, points);
  atmosphere::write_text_file(a.out, atmosphere::truth_result_csv(spec, points, result, luts ? &lut : nullptr));
  std::cout << "wrote " << a.out << " (" << points.size() << " points, " << ProgressLine::duration(result.seconds) << ")\n";
  return 0;
}

// specbake sweep: speed against error for one job over combinations of --vary values.
struct SweepArgs {
  std::string config, job, out, device;
  std::vector<std::string> varies;
  double tolerance = -1.0;
};

int cmd_sweep(const SweepArgs& a, ProgressLine& progress_line, bool quiet) {
  SweepOptions o;
  o.config = a.config;
  o.job = a.job;
  for (const auto& v : a.varies) o.varies.push_back(parse_vary(v));
  if (!a.out.empty()) o.out = a.out;
  if (!a.device.empty()) o.device = a.device;
  if (a.tolerance >= 0.0) o.tolerance = a.tolerance;
  std::signal(SIGINT, on_stop_signal);
  std::signal(SIGTERM, on_stop_signal);
  RunProgress on_progress;
  if (!quiet) on_progress = [&](const ProgressEvent& e) { progress_line.show(e); };
  const SweepResult r = run_sweep(o, on_progress);
  progress_line.done();
  int failed = 0;
  std::vector<std::vector<std::string>> rows;
  std::vector<std::string> head;
  for (const auto& v : r.varies) head.push_back(v.key);
  for (const char* h : {"time", "device", "error", "front", "settings"}) head.push_back(h);
  rows.push_back(head);
  for (const auto& p : r.points) {
    std::vector<std::string> row = p.values;
    auto secs = [](double v) { return v < 60 ? fmt_number(v) + " s" : ProgressLine::duration(v); };
    row.push_back(secs(p.bake_s));
    row.push_back(secs(p.device_s));
    if (p.status == "measured") {
      std::string e = fmt_number(p.error) + (p.unit.empty() ? "" : " " + p.unit);
      if (p.tolerance) e += (p.passed ? " <= " : " > ") + fmt_number(*p.tolerance);
      row.push_back(e);
      row.push_back(p.pareto ? "*" : "");
      row.push_back(p.settings);
    } else {
      ++failed;
      row.push_back("FAILED");
      row.push_back("");
      row.push_back(p.reason);
    }
    rows.push_back(row);
  }
  if (!quiet) {
    print_table(rows);
    std::cout << r.points.size() << " point(s), " << failed
              << " failed; time: wall seconds of plan + compute (check, files and previews timed apart in "
                 "sweep.json); front: * on the Pareto front\n"
              << "wrote " << (r.out / "sweep.json").string() << ", sweep.csv" << (r.plotted ? ", sweep.png" : "")
              << "\n";
  }
  if (!r.plotted) spdlog::warn("{}", r.plot_note);
  return failed ? static_cast<int>(ExitCode::job_failed) : 0;
}

// "a,b" and repeated options → names; an empty name is a usage error.
std::vector<std::string> split_names(const std::vector<std::string>& in, const char* option) {
  std::vector<std::string> out;
  for (const auto& s : in) {
    std::size_t start = 0;
    for (;;) {
      const auto comma = s.find(',', start);
      const auto part = s.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
      if (part.empty()) throw UsageError(std::string(option) + " expects job names (a,b,...), got '" + s + "'");
      out.push_back(part);
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
  }
  return out;
}

// `report INPUT...`: a sharded night's --report files (files, or folders of them) merged into one
// table (src/runner/night_report.hpp; exit 1 when the night failed), and/or the HTML page
// (src/runner/html_report.hpp) over output and sweep folders and the night's jobs: written with
// --out, and by default when an output or sweep folder is given.
int cmd_report(const std::vector<std::string>& inputs, const std::string& out, bool as_json, bool quiet) {
  std::vector<fs::path> reports, folders;
  for (const auto& in : inputs) {
    const fs::path p(in);
    std::error_code ec;
    bool holds_reports = false;  // a folder of --report files holds *.json and no job folders
    if (fs::is_directory(p, ec) && !is_output_folder(p) && find_sweeps(p).empty())
      for (fs::directory_iterator it(p, ec), end; !ec && it != end && !holds_reports; it.increment(ec))
        holds_reports = it->path().extension() == ".json";
    if (fs::is_directory(p, ec) && !holds_reports) folders.push_back(p);  // the page says what it expected
    else reports.push_back(p);
  }
  std::optional<NightReport> night;
  if (!reports.empty()) {
    night = merge_night(reports);
    std::cout << (as_json ? night_json(*night).dump(2) + "\n" : night_text(*night));
  }
  if (!folders.empty() || !out.empty()) {
    const fs::path file = report_html_path(out);
    check_report_html_path(file, "--out");
    ReportPage page = folders.empty() ? ReportPage{} : report_page_from_output(folders);
    if (night) {
      for (const auto& shard : night->shards) page.sources.push_back(fs::absolute(shard.file).lexically_normal().string());
      // a job the output folders show already (its bundle, previews) is not listed twice
      std::set<std::string> shown;
      for (const auto& j : page.jobs) shown.insert(j.name);
      for (const auto& job : night->jobs)
        if (!shown.count(job.name)) page.jobs.push_back(page_job_from_report_entry(job.decision().job));
    }
    write_report_html(page, file);
    if (!quiet && !as_json)
      std::cout << "wrote " << file.string() << " (" << page.jobs.size() << " job(s), " << page.sweeps.size()
                << " sweep(s))\n";
  }
  return static_cast<int>(night && night->failed() ? ExitCode::job_failed : ExitCode::ok);
}

}  // namespace

int main(int argc, char** argv) {
  const bool tty = ::isatty(STDERR_FILENO);
  ProgressLine progress_line(tty);
  auto logger = std::make_shared<spdlog::logger>("specbake", std::make_shared<StderrSink>(progress_line));
  spdlog::set_default_logger(logger);
  spdlog::set_pattern("[%l] %v");

  CLI::App app{"specbake — bakes lookup tables for real-time spectral rendering (OpenCL)"};
  app.name("specbake");  // parse() gets the arguments without argv[0]
  app.set_version_flag("--version", std::string("specbake ") + kVersion);
  app.require_subcommand(1);
  app.fallthrough();  // -v/-q also after the sub-command
  app.option_defaults()->always_capture_default();
  int verbose = 0;
  bool quiet = false;
  app.add_flag("-v,--verbose", verbose,
               "more output: -v full parameters/accuracy per job and debug logs (kernel build logs, auto searches), "
               "-vv trace logs");
  app.add_flag("-q,--quiet", quiet, "only warnings and errors (no progress, no summary)");

  std::vector<std::string> configs, only;
  std::string out, device, inspect_dir, report, shard, gc_dir, diff_old, diff_new;
  bool force = false, keep_going = false, inspect_json = false, gc_dry_run = false;
  int keep = 3;
  double fail_abs = 0.0, fail_rel = 0.0;

  // `run` and `plan` select jobs the same way.
  auto add_selection = [&](CLI::App* sub) {
    sub->add_option("configs", configs, "config files (YAML) or folders of them")->required();
    sub->add_option("-o,--out", out, "output folder for every job (default: each config's `output`, else ./assets)")
        ->allow_extra_args(false);
    sub->add_option("--device", device, "OpenCL device: auto | cpu | gpu | part of a device name (default: config's, else auto)")
        ->allow_extra_args(false);
    sub->add_option("--only", only, "only these jobs (comma-separated names; repeatable)")->allow_extra_args(false);
    sub->add_flag("--force", force, "rebuild bundles that are up to date");
    sub->add_option("--shard", shard,
                    "only shard I of N (I/N, 0-based): a deterministic, balanced split of the jobs; auto or auto/N: "
                    "I and N from a Slurm array, a Kubernetes Indexed Job or SPECBAKE_SHARD_INDEX/COUNT")
        ->allow_extra_args(false);
    sub->add_flag("--keep-going", keep_going,
                  "report invalid configs and jobs, run every valid job, exit 3 if any was invalid");
    sub->add_option("--report", report,
                    "write a JSON summary of every job (status, reason, parameters, accuracy, timings, bundle)")
        ->allow_extra_args(false);
  };
  auto* run = app.add_subcommand("run", "bake every job of the configs into versioned bundles");
  add_selection(run);
  std::string report_html_file;
  run->add_option("--report-html", report_html_file, "write the run's HTML page (as `specbake report` makes) to FILE")
      ->allow_extra_args(false);

  add_selection(app.add_subcommand("plan", "show what `run` would do, resolved settings and estimates; writes no bundle"));

  app.add_subcommand("devices", "list OpenCL platforms and devices, and which one `auto` picks");

  auto* gc = app.add_subcommand("gc", "prune old bundles in an output folder, never the one `latest` points at");
  gc->add_option("output", gc_dir, "output folder (holding <job>/<hash12>/ bundles)")->required();
  gc->add_option("--keep", keep, "bundles to keep per job (newest first)")->check(CLI::Range(1, 1000000));
  gc->add_flag("--dry-run", gc_dry_run, "list what would be removed; change nothing");

  auto* diff = app.add_subcommand("diff", "compare two bundles file by file; non-zero exit past the thresholds");
  diff->add_option("old", diff_old, "old bundle, or a job folder (its latest)")->required();
  diff->add_option("new", diff_new, "new bundle, or a job folder (its latest)")->required();
  const CLI::Validator non_negative(
      [](std::string& v) {
        try {
          if (std::stod(v) >= 0.0) return std::string();
        } catch (const std::exception&) {
        }
        return "expected a number >= 0, got '" + v + "'";
      },
      "NUMBER >= 0");
  diff->add_option("--fail-abs", fail_abs, "allowed absolute difference per float32 element (element fails if |a-b| > abs + rel*max(|a|,|b|))")->check(non_negative);
  diff->add_option("--fail-rel", fail_rel, "allowed relative difference per float32 element")->check(non_negative);

  TruthArgs truth_args;
  auto* truth = app.add_subcommand("truth", "path-traced sky radiance of an atmosphere job at given views (CSV in, CSV out)");
  truth->add_option("config", truth_args.config, "config file (YAML)")->required();
  truth->add_option("--job", truth_args.job, "the atmosphere job to trace")->required();
  truth->add_option("--points", truth_args.points,
                    "POINTS.csv: altitude_km,view_zenith_deg,sun_zenith_deg,view_sun_azimuth_deg")->required();
  truth->add_option("-o,--out", truth_args.out, "RESULT.csv: the four columns, then L_<c>,se_<c> per channel")->required();
  truth->add_option("--paths", truth_args.paths, "random walks per point and channel (they carry orders 2 and above)");
  truth->add_option("--orders", truth_args.orders,
                    "scattering orders traced: N (1..N) or all; order 1 is integrated by quadrature (no noise: se 0 "
                    "with --orders 1)");
  truth->add_option("--seed", truth_args.seed, "seed of the counter-based random streams (same seed: same bytes)");
  truth->add_option("--bundle", truth_args.bundle, "also lut_<c>: that bundle's (or job folder's latest) GetSkyRadiance at the points");
  truth->add_option("--device", truth_args.device, "OpenCL device (default: the config's, else auto)");

  SweepArgs sweep_args;
  auto* sweep = app.add_subcommand(
      "sweep", "speed against error: bake one job over combinations of settings (nothing published); "
               "sweep.json, sweep.csv, sweep.png");
  sweep->add_option("config", sweep_args.config, "config file (YAML)")->required();
  sweep->add_option("--job", sweep_args.job, "the job to sweep")->required();
  sweep->add_option("--vary", sweep_args.varies,
                    "KEY=V1,V2,... (repeatable; every combination is baked): a key path in the job "
                    "(orders, sizes.scattering.mu_s, table.size, samples, ...); A..B for integer ranges, "
                    "P% for sizes")
      ->required()
      ->allow_extra_args(false);
  sweep->add_option("-o,--out", sweep_args.out, "folder for sweep.json, sweep.csv, sweep.png (default ./sweep-<job>)");
  sweep->add_option("--device", sweep_args.device, "OpenCL device (default: the config's, else auto)");
  sweep->add_option("--tolerance", sweep_args.tolerance,
                    "the tolerance drawn and judged (default: the job's own, where it has one)")
      ->check(CLI::NonNegativeNumber)
      ->default_str("the job's");

  std::vector<std::string> report_inputs;
  std::string report_out;
  bool report_json = false;
  auto* report_cmd = app.add_subcommand(
      "report", "one summary of a sharded night's --report files (exit 1 if a shard or job failed), and an HTML page "
                "over output folders and the night: status, accuracy, previews, what changed (opens from disk)");
  report_cmd->add_option("inputs", report_inputs,
                         "--report JSON files or folders of them (merged into one table), output folders (holding "
                         "<job>/latest bundles) or sweep folders (on the page)")
      ->required();
  report_cmd->add_option("-o,--out", report_out, "the page's file, or a folder to write report.html into (default "
                                              "./report.html; written when a folder is given or with --out)")
      ->allow_extra_args(false);
  report_cmd->add_flag("--json", report_json, "print the merged night as JSON");

  auto* inspect = app.add_subcommand("inspect", "summarise a bundle and check its files' sha256, or list an output "
                                                "folder's jobs");
  inspect->add_option("bundle", inspect_dir, "bundle folder (e.g. assets/bk7-prism/latest), job folder (its latest) "
                                             "or output folder (its jobs: latest bundle, size, age, headline)")
      ->required();
  inspect->add_flag("--json", inspect_json, "print the summary and per-file checks as JSON");

  // `specbake help [COMMAND]` is `specbake [COMMAND] --help`
  std::vector<std::string> args(argv + 1, argv + argc);
  if (!args.empty() && args.front() == "help") {
    args.erase(args.begin());
    args.push_back("--help");
  }
  std::reverse(args.begin(), args.end());  // CLI11 takes them last first
  try {
    app.parse(args);
  } catch (const CLI::ExtrasError& e) {
    // An unknown option: suggest the nearest of the command's own.
    const CLI::App* sub = app.get_subcommands().empty() ? &app : app.get_subcommands().front();
    std::vector<std::string> names;
    for (const CLI::Option* o : sub->get_options())
      for (const auto& l : o->get_lnames()) names.push_back("--" + l);
    for (const CLI::Option* o : app.get_options())
      for (const auto& l : o->get_lnames()) names.push_back("--" + l);
    std::string unknown;  // the first unexpected --option CLI11 names ("...not expected: --frce")
    std::istringstream words(std::string(e.what()).substr(std::string(e.what()).find(':') + 1));
    for (std::string w; words >> w && unknown.empty();)
      if (w.rfind("--", 0) == 0) unknown = w.substr(0, w.find('='));
    const std::string near = unknown.empty() ? "" : closest_word(unknown, names);
    std::cerr << "specbake" << (sub == &app ? "" : " " + sub->get_name()) << ": "
              << (unknown.empty() ? std::string(e.what()) : "unknown option '" + unknown + "'")
              << (near.empty() ? "" : " (did you mean '" + near + "'?)") << "; run specbake "
              << (sub == &app ? "" : sub->get_name() + " ") << "--help\n";
    return static_cast<int>(ExitCode::usage);
  } catch (const CLI::ParseError& e) {
    // An unknown sub-command: suggest the nearest one.
    if (argc > 1 && app.get_subcommands().empty() && argv[1][0] != '-' && !dynamic_cast<const CLI::CallForHelp*>(&e)) {
      std::vector<std::string> names = {"help"};
      for (const auto* s : app.get_subcommands([](const CLI::App*) { return true; })) names.push_back(s->get_name());
      const std::string near = closest_word(argv[1], names);
      std::cerr << "specbake: unknown command '" << argv[1] << "'"
                << (near.empty() ? "" : " (did you mean '" + near + "'?)") << "; run specbake --help\n";
      return static_cast<int>(ExitCode::usage);
    }
    const int rc = app.exit(e);
    return rc == 0 ? 0 : static_cast<int>(ExitCode::usage);
  }
  // Logs: warnings and errors by default (the progress line and the summary say the rest);
  // -v adds info and debug lines, -vv trace.
  spdlog::set_level(verbose >= 2 ? spdlog::level::trace : verbose == 1 ? spdlog::level::debug : spdlog::level::warn);

  std::unique_ptr<ReportFile> report_file;
  std::vector<JobReport> reports;
  std::optional<Shard> run_shard;  // known once --shard is read
  try {
    if (app.got_subcommand("devices")) return cmd_devices();
    if (app.got_subcommand("inspect")) return cmd_inspect(inspect_dir, inspect_json);
    if (app.got_subcommand("report")) return cmd_report(report_inputs, report_out, report_json, quiet);
    if (app.got_subcommand("gc")) {
      const GcResult g = BundleStore(gc_dir).gc(keep, gc_dry_run);
      const char* verb = gc_dry_run ? "would remove" : "removed";
      for (const auto& p : g.bundles) std::cout << verb << " bundle " << p.string() << "\n";
      for (const auto& p : g.temporaries) std::cout << verb << " leftover " << p.string() << "\n";
      for (const auto& p : g.results) std::cout << verb << " kept result " << p.string() << " (no bundle lists it)\n";
      for (const auto& p : g.busy) std::cout << "skipped " << p.string() << " (a running bake holds it)\n";
      std::cout << verb << " " << g.bundles.size() << " bundle(s), " << g.results.size() << " kept result(s) and "
                << g.temporaries.size() << " leftover(s) of interrupted runs\n";
      return 0;
    }
    if (app.got_subcommand("diff")) return cmd_diff(diff_old, diff_new, fail_abs, fail_rel);
    if (app.got_subcommand("truth")) return cmd_truth(truth_args);
    if (app.got_subcommand("sweep")) return cmd_sweep(sweep_args, progress_line, quiet);

    const bool is_plan = app.got_subcommand("plan");
    const CLI::App* sub = app.get_subcommands().front();
    auto given_empty = [&](const char* name, const std::string& value) {
      if (sub->count(name) && value.empty()) throw UsageError(std::string(name) + " expects a value, got ''");
    };
    given_empty("--out", out);
    given_empty("--device", device);
    given_empty("--shard", shard);
    given_empty("--report", report);
    report_file = std::make_unique<ReportFile>(report);
    if (!is_plan) given_empty("--report-html", report_html_file);
    if (!report_html_file.empty()) check_report_html_path(report_html_file, "--report-html");

    RunOptions opts;
    if (!out.empty()) opts.out = fs::path(out);
    if (!device.empty()) opts.device = device;
    opts.only = split_names(only, "--only");
    opts.force = force;
    if (!shard.empty()) opts.shard = parse_shard(shard);
    run_shard = opts.shard;
    std::vector<fs::path> paths(configs.begin(), configs.end());
    std::vector<JobReport> invalid;
    auto loaded = load_configs(paths, &invalid);
    if (!keep_going && !invalid.empty()) {  // nothing runs; each invalid config or job said once
      for (const auto& r : invalid) spdlog::error("{}", r.reason);
      report_file->write(invalid, invalid.front().reason);
      return static_cast<int>(invalid.front().code);
    }

    std::signal(SIGINT, on_stop_signal);
    std::signal(SIGTERM, on_stop_signal);
    RunProgress on_progress;
    if (!quiet) on_progress = [&](const ProgressEvent& e) { progress_line.show(e); };
    // configs without `output:` (and no --out) put their bundles in ./assets of the working folder
    std::vector<std::string> default_output;
    for (const auto& c : loaded)
      if (!c.output_given && !opts.out && !c.jobs.empty()) default_output.push_back(c.file.string());
    Runner runner(std::move(loaded), opts, on_progress, [&](const JobReport&) { progress_line.done(); });
    reports = is_plan ? runner.plan() : runner.run();
    progress_line.done();
    reports.insert(reports.end(), invalid.begin(), invalid.end());
    if (!quiet) print_reports(reports, is_plan, verbose);
    if (!quiet && !default_output.empty()) {
      std::string files;
      for (const auto& f : default_output) files += (files.empty() ? "" : ", ") + f;
      std::cout << "bundles " << (is_plan ? "would go" : "went") << " to " << fs::absolute("assets").string()
                << " (the working folder's ./assets: " << files << " has no `output:`; set it, or --out)\n";
    }
    for (const auto& r : reports) {  // -q: no summary; its failures and warnings on stderr, once
      if (!quiet) break;
      if (r.code != ExitCode::ok) std::cerr << r.name << ": " << r.status << ": " << r.reason << "\n";
      for (const auto& w : r.warnings) std::cerr << "[warning] " << r.name << ": " << w << "\n";
    }
    std::string stopped;
    if (const int sig = stop_requested()) {
      stopped = sig == SIGTERM ? "stopped by SIGTERM" : "stopped by SIGINT";
      spdlog::error("{}: the run ended at a safe point; finished jobs are published, nothing half-written",
                    stopped);
    }
    report_file->write(reports, stopped, run_shard);
    if (!report_html_file.empty()) {
      ReportPage page;
      page.sources = configs;
      for (const auto& r : reports) page.jobs.push_back(page_job(r));
      write_report_html(page, report_html_file);
      if (!quiet) std::cout << "wrote " << report_html_file << "\n";
    }
    // An interrupted run says so (130/143); else invalid configs (--keep-going) come first.
    if (!stop_requested() && !invalid.empty()) return static_cast<int>(ExitCode::invalid_input);
    return static_cast<int>(exit_code(reports));
  } catch (const Error& e) {
    progress_line.done();
    spdlog::error("{}", e.what());
    if (report_file) {
      try {
        report_file->write(reports, e.what(), run_shard);
      } catch (const Error& w) {
        spdlog::error("{}", w.what());
      }
    }
    return static_cast<int>(e.exit_code());
  } catch (const std::exception& e) {
    progress_line.done();
    spdlog::error("internal error: {}", e.what());
    return static_cast<int>(ExitCode::job_failed);
  }
}
