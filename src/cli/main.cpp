// specbake — command line. A thin layer over the library (core/runner.hpp): parse
// arguments, set up logging, print results, map errors to the documented exit codes.
#include <CLI/CLI.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <fstream>
#include <iostream>

#include "cl/device.hpp"
#include "core/hash.hpp"
#include "runner/runner.hpp"
#include "core/version.hpp"
#include "io/bundle.hpp"
#include "io/bundle_diff.hpp"

using namespace specbake;
using nlohmann::json;

namespace {

std::vector<std::string> split_commas(const std::vector<std::string>& in) {
  std::vector<std::string> out;
  for (const auto& s : in) {
    std::size_t start = 0;
    while (start <= s.size()) {
      const auto comma = s.find(',', start);
      const auto part = s.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
      if (!part.empty()) out.push_back(part);
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
  }
  return out;
}

void print_reports(const std::vector<JobReport>& reports, bool plan) {
  for (const auto& r : reports) {
    std::cout << r.name << " (" << r.kind << ", " << r.config << ")\n"
              << "  status:  " << r.status << (r.reason.empty() ? "" : " — " + r.reason) << "\n"
              << "  hash:    " << r.hash.substr(0, 12) << "\n"
              << "  bundle:  " << r.bundle.string() << "\n";
    if (!r.parameters.is_null()) {
      json shown = r.parameters;
      if (!plan) shown.erase("quadrature_weights_nm");
      std::cout << "  parameters: " << shown.dump() << "\n";
    }
    if (!r.accuracy.is_null()) std::cout << "  accuracy: " << r.accuracy.dump() << "\n";
  }
  int built = 0, current = 0, failed = 0;
  for (const auto& r : reports) {
    built += r.status == "built";
    current += r.status == "up-to-date";
    failed += r.status == "failed";
  }
  if (!plan) std::cout << built << " built, " << current << " up to date, " << failed << " failed\n";
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

int cmd_inspect(const fs::path& dir) {
  std::ifstream in(dir / "manifest.json");
  if (!in) throw IoError("cannot read " + (dir / "manifest.json").string());
  json m;
  try {
    m = json::parse(in);
  } catch (const json::exception& e) {
    throw InputError({dir / "manifest.json", 0, 0, ""}, std::string("expected a JSON manifest: ") + e.what());
  }
  std::cout << "bundle:   " << fs::weakly_canonical(dir).string() << "\n"
            << "job:      " << m["job"].value("name", "?") << " (" << m["job"].value("kind", "?") << ")\n"
            << "hash:     " << m["job"].value("hash", "?") << "\n"
            << "tool:     specbake " << m["tool"].value("version", "?") << ", created " << m.value("created_utc", "?")
            << "\n"
            << "device:   " << m["device"].value("name", "?") << " (" << m["device"].value("platform", "?") << ")\n";
  json params = m.value("parameters", json::object());
  params.erase("quadrature_weights_nm");
  std::cout << "parameters: " << params.dump() << "\n"
            << "accuracy:   " << m.value("accuracy", json::object()).dump() << "\n";
  for (const auto& w : m.value("warnings", json::array())) std::cout << "warning:  " << w.get<std::string>() << "\n";
  int bad = 0;
  std::cout << "files:\n";
  for (const auto& f : m.at("files")) {
    const std::string path = f.at("path");
    std::string status = "ok";
    try {
      if (sha256_file(dir / path) != f.at("sha256").get<std::string>()) status = "SHA256 MISMATCH";
    } catch (const IoError&) {
      status = "MISSING";
    }
    bad += status != "ok";
    std::cout << "  " << status << "  " << path << "  " << f.value("bytes", 0);
    if (f.contains("shape")) std::cout << "  " << f["dtype"].get<std::string>() << f["shape"].dump();
    std::cout << "\n";
  }
  if (bad) {
    std::cout << bad << " file(s) failed their check\n";
    return static_cast<int>(ExitCode::job_failed);
  }
  std::cout << "all " << m.at("files").size() << " files match their sha256\n";
  return 0;
}

void write_report(const fs::path& path, const std::vector<JobReport>& reports) {
  // Written beside its final name and renamed, so readers never see half a report.
  const fs::path tmp = path.string() + ".tmp";
  {
    std::ofstream o(tmp);
    o << report_json(reports).dump(2) << "\n";
    if (!o.flush()) throw IoError("cannot write report " + tmp.string());
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) throw IoError("cannot write report " + path.string() + ": " + ec.message());
}

std::string index_text(const std::vector<std::int64_t>& idx) {
  std::string s = "[";
  for (std::size_t i = 0; i < idx.size(); ++i) s += (i ? "," : "") + std::to_string(idx[i]);
  return s + "]";
}

int cmd_diff(const fs::path& a, const fs::path& b, double fail_abs, double fail_rel) {
  const BundleDiff d = diff_bundles(a, b, fail_abs, fail_rel);
  for (const auto& f : d.files) {
    std::cout << "  " << f.status << "  " << f.path;
    if (f.numeric && f.status == "differs")
      std::cout << "  max abs " << f.max_abs << " at " << index_text(f.at_abs) << ", max rel " << f.max_rel << " at "
                << index_text(f.at_rel) << ", " << f.exceeding << " beyond thresholds";
    std::cout << "\n";
  }
  if (!d.changed.empty()) {
    std::cout << "manifest changes:\n";
    for (auto it = d.changed.begin(); it != d.changed.end(); ++it)
      std::cout << "  " << it.key() << ": " << it.value()[0].dump() << " -> " << it.value()[1].dump() << "\n";
  }
  const bool ok = diff_passes(d);
  std::cout << (ok ? "within thresholds" : "DIFFERS beyond thresholds") << " (fail-abs " << fail_abs << ", fail-rel "
            << fail_rel << ")\n";
  return ok ? 0 : static_cast<int>(ExitCode::job_failed);
}

}  // namespace

int main(int argc, char** argv) {
  auto logger = spdlog::stderr_color_mt("specbake");
  spdlog::set_default_logger(logger);
  spdlog::set_pattern("[%l] %v");

  CLI::App app{"specbake — bakes lookup tables for real-time spectral rendering (OpenCL)"};
  app.set_version_flag("--version", std::string("specbake ") + kVersion);
  app.require_subcommand(1);
  app.fallthrough();  // -v/-q also after the sub-command
  app.option_defaults()->always_capture_default();
  int verbose = 0;
  bool quiet = false;
  app.add_flag("-v,--verbose", verbose, "more log output: -v debug (kernel build logs, auto searches), -vv trace");
  app.add_flag("-q,--quiet", quiet, "only errors");

  std::vector<std::string> configs, only;
  std::string out, device, inspect_dir, report, shard, gc_dir, diff_old, diff_new;
  bool force = false;
  int keep = 3;
  double fail_abs = 0.0, fail_rel = 0.0;

  // `run` and `plan` select jobs the same way.
  auto add_selection = [&](CLI::App* sub) {
    sub->add_option("configs", configs, "config files (YAML) or folders of them")->required();
    sub->add_option("--out", out, "output folder for every job (default: each config's `output`, else ./assets)");
    sub->add_option("--device", device, "OpenCL device: auto | cpu | gpu | part of a device name (default: config's, else auto)");
    sub->add_option("--only", only, "only these jobs (comma-separated names)");
    sub->add_flag("--force", force, "rebuild bundles that are up to date");
    sub->add_option("--shard", shard, "only shard I of N (I/N, 0-based): a deterministic, balanced split of the jobs");
  };
  auto* run = app.add_subcommand("run", "bake every job of the configs into versioned bundles");
  add_selection(run);
  run->add_option("--report", report, "write a JSON summary of every job (status, reason, parameters, accuracy, timings, bundle)");
  add_selection(app.add_subcommand("plan", "show what `run` would do and the resolved parameters; writes nothing"));

  app.add_subcommand("devices", "list OpenCL platforms and devices, and which one `auto` picks");

  auto* gc = app.add_subcommand("gc", "prune old bundles in an output folder, never the one `latest` points at");
  gc->add_option("output", gc_dir, "output folder (holding <job>/<hash12>/ bundles)")->required();
  gc->add_option("--keep", keep, "bundles to keep per job (newest first)")->check(CLI::Range(1, 1000000));

  auto* diff = app.add_subcommand("diff", "compare two bundles file by file; non-zero exit past the thresholds");
  diff->add_option("old", diff_old, "old bundle folder")->required();
  diff->add_option("new", diff_new, "new bundle folder")->required();
  diff->add_option("--fail-abs", fail_abs, "allowed absolute difference per float32 element (element fails if |a-b| > abs + rel*max(|a|,|b|))")->check(CLI::NonNegativeNumber);
  diff->add_option("--fail-rel", fail_rel, "allowed relative difference per float32 element")->check(CLI::NonNegativeNumber);

  auto* inspect = app.add_subcommand("inspect", "summarise a bundle and check its files' sha256");
  inspect->add_option("bundle", inspect_dir, "bundle folder (e.g. assets/bk7-prism/latest)")->required();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : static_cast<int>(ExitCode::usage);
  }
  spdlog::set_level(quiet ? spdlog::level::err
                    : verbose >= 2 ? spdlog::level::trace
                    : verbose == 1 ? spdlog::level::debug
                                   : spdlog::level::info);

  try {
    if (app.got_subcommand("devices")) return cmd_devices();
    if (app.got_subcommand("inspect")) return cmd_inspect(inspect_dir);
    if (app.got_subcommand("gc")) {
      const auto removed = BundleStore(gc_dir).gc(keep);
      std::cout << "removed " << removed.size() << " bundle(s)\n";
      return 0;
    }
    if (app.got_subcommand("diff")) return cmd_diff(diff_old, diff_new, fail_abs, fail_rel);

    RunOptions opts;
    if (!out.empty()) opts.out = fs::path(out);
    if (!device.empty()) opts.device = device;
    opts.only = split_commas(only);
    opts.force = force;
    if (!shard.empty()) std::tie(opts.shard_index, opts.shard_count) = parse_shard(shard);
    std::vector<fs::path> paths(configs.begin(), configs.end());
    Runner runner(load_configs(paths), opts);
    const bool is_plan = app.got_subcommand("plan");
    const auto reports = is_plan ? runner.plan() : runner.run();
    print_reports(reports, is_plan);
    if (!report.empty()) write_report(report, reports);
    return static_cast<int>(exit_code(reports));
  } catch (const Error& e) {
    spdlog::error("{}", e.what());
    return static_cast<int>(e.exit_code());
  } catch (const std::exception& e) {
    spdlog::error("internal error: {}", e.what());
    return static_cast<int>(ExitCode::job_failed);
  }
}
