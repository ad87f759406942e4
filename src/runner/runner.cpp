#include "runner/runner.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <ctime>
#include <map>
#include <memory>
#include <numeric>
#include <set>

#include "cl/device.hpp"
#include "core/hash.hpp"
#include "core/resources.hpp"
#include "core/version.hpp"
#include "io/bundle.hpp"
#include "job/kind.hpp"
#include "registry/registry.hpp"

namespace specbake {

using nlohmann::json;

namespace {
std::string utc_now() {
  std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}
}  // namespace

std::vector<Config> load_configs(const std::vector<fs::path>& paths) {
  std::vector<fs::path> files;
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
      files.insert(files.end(), found.begin(), found.end());
    } else {
      files.push_back(p);
    }
  }
  std::vector<Config> configs;
  std::map<std::pair<std::string, std::string>, Location> seen;  // (output, name)
  for (const auto& f : files) {
    Config c = load_config(f);
    for (const auto& j : c.jobs) {
      const auto key = std::make_pair(fs::weakly_canonical(c.output).string(), j.name);
      if (auto it = seen.find(key); it != seen.end())
        throw InputError(j.where, "job name '" + j.name + "' is also used by " + it->second.str() +
                                      " with the same output folder");
      seen.emplace(key, j.where);
    }
    configs.push_back(std::move(c));
  }
  return configs;
}

std::pair<int, int> parse_shard(const std::string& text) {
  const auto slash = text.find('/');
  try {
    if (slash == std::string::npos) throw std::invalid_argument("no slash");
    std::size_t a = 0, b = 0;
    const int i = std::stoi(text.substr(0, slash), &a), n = std::stoi(text.substr(slash + 1), &b);
    if (a != slash || b != text.size() - slash - 1 || n < 1 || i < 0 || i >= n) throw std::invalid_argument("range");
    return {i, n};
  } catch (const std::exception&) {
    throw UsageError("--shard expects I/N with 0 <= I < N (e.g. 0/4), got '" + text + "'");
  }
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

nlohmann::json report_json(const std::vector<JobReport>& reports) {
  json jobs = json::array();
  int built = 0, current = 0, failed = 0;
  for (const auto& r : reports) {
    built += r.status == "built";
    current += r.status == "up-to-date";
    failed += r.status == "failed";
    json j = {{"name", r.name},          {"kind", r.kind},
              {"config", r.config},      {"status", r.status},
              {"reason", r.reason},      {"hash", r.hash},
              {"bundle", r.bundle.string()}, {"parameters", r.parameters},
              {"accuracy", r.accuracy},  {"timings", r.timings},
              {"warnings", r.warnings}};
    if (r.status == "failed") j["exit_code"] = static_cast<int>(r.code);
    jobs.push_back(j);
  }
  return {{"schema", "specbake.report/1"},
          {"tool", {{"name", "specbake"}, {"version", kVersion}}},
          {"created_utc", utc_now()},
          {"summary", {{"built", built}, {"up_to_date", current}, {"failed", failed}}},
          {"jobs", jobs}};
}

ExitCode exit_code(const std::vector<JobReport>& reports) {
  for (const auto& r : reports)
    if (r.status == "failed") return r.code;
  return ExitCode::ok;
}

namespace {

json device_json(const cl_util::DeviceInfo& d) {
  return {{"name", d.name}, {"platform", d.platform}, {"version", d.version}, {"type", d.type}, {"fp64", d.fp64}};
}

// Opens each selected device once per run.
class Devices {
 public:
  cl_util::Device& get(const std::string& selector) {
    const cl_util::DeviceInfo info = cl_util::select_device(selector);
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

}  // namespace

Runner::Runner(std::vector<Config> configs, RunOptions options, RunProgress progress)
    : configs_(std::move(configs)), options_(std::move(options)), progress_(std::move(progress)) {}

std::vector<Runner::Item> Runner::select() const {
  std::set<std::string> known;
  for (const auto& c : configs_)
    for (const auto& j : c.jobs) known.insert(j.name);
  for (const auto& o : options_.only)
    if (!known.count(o)) throw UsageError("--only names job '" + o + "', which no given config defines");
  std::vector<Item> items;
  for (const auto& c : configs_)
    for (const auto& j : c.jobs) {
      if (!options_.only.empty() && std::find(options_.only.begin(), options_.only.end(), j.name) == options_.only.end())
        continue;
      items.push_back({&c, &j, options_.out ? *options_.out : c.output, options_.device ? *options_.device : c.device,
                       job_hash(j)});
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
  if (options_.shard_count > 1) {
    std::vector<std::pair<std::string, double>> name_cost;
    for (const auto& it : items) name_cost.emplace_back(it.config->file.string() + "\n" + it.job->name, kind_named(it.job->kind).cost_s(*it.job));
    const auto shard = assign_shards(name_cost, options_.shard_count);
    std::vector<Item> mine;
    for (std::size_t i = 0; i < items.size(); ++i)
      if (shard[i] == options_.shard_index) mine.push_back(items[i]);
    spdlog::info("shard {}/{}: {} of {} jobs", options_.shard_index, options_.shard_count, mine.size(), items.size());
    items = std::move(mine);
  }
  return items;
}

std::vector<JobReport> Runner::plan() {
  std::vector<JobReport> reports;
  Devices devices;
  for (const auto& it : select()) {
    JobReport r;
    r.config = it.config->file.string();
    r.name = it.job->name;
    r.kind = it.job->kind;
    r.status = "planned";
    r.hash = it.hash;
    BundleStore store(it.output);
    r.bundle = store.bundle_dir(it.job->name, it.hash.substr(0, 12));
    const bool current = store.is_complete(it.job->name, it.hash.substr(0, 12));
    r.reason = current ? (options_.force ? "up to date; --force rebuilds it" : "up to date; would be skipped")
                       : "would be built";
    try {
      JobContext ctx{devices.get(it.device)};
      r.parameters = kind_named(it.job->kind).plan(*it.job, ctx);
    } catch (const Error& e) {
      r.status = "failed";
      r.code = e.exit_code();
      r.reason = e.what();
    }
    reports.push_back(std::move(r));
  }
  return reports;
}

std::vector<JobReport> Runner::run() {
  const auto items = select();
  // Output folders are checked before any job runs: an unwritable one stops the run.
  std::set<fs::path> roots;
  for (const auto& it : items) roots.insert(it.output);
  for (const auto& root : roots) BundleStore(root).check_writable();

  std::vector<JobReport> reports;
  Devices devices;
  for (const auto& it : items) {
    const std::string& name = it.job->name;
    const std::string hash12 = it.hash.substr(0, 12);
    JobReport r;
    r.config = it.config->file.string();
    r.name = name;
    r.kind = it.job->kind;
    r.hash = it.hash;
    BundleStore store(it.output);
    r.bundle = store.bundle_dir(name, hash12);
    const auto t0 = std::chrono::steady_clock::now();
    try {
      JobLock lock(store.job_dir(name), name);
      store.clean_stale(name);
      if (!options_.force && store.is_complete(name, hash12)) {
        store.set_latest(name, hash12);
        r.status = "up-to-date";
        r.reason = "a complete bundle with this hash exists";
        spdlog::info("{}: up to date ({})", name, r.bundle.string());
        reports.push_back(std::move(r));
        continue;
      }
      spdlog::info("{}: baking ({} job)", name, it.job->kind);
      cl_util::Device& dev = devices.get(it.device);
      const Kind& kind = kind_named(it.job->kind);
      check_device_memory(*it.job, dev.info());
      auto last_log = std::chrono::steady_clock::now() - std::chrono::seconds(10);
      JobContext ctx{dev, [&](std::string_view stage, double f) {
                       if (progress_) progress_(name, stage, f);
                       const auto now = std::chrono::steady_clock::now();
                       if (now - last_log > std::chrono::seconds(2) || f >= 1.0) {
                         spdlog::info("{}: {} ({:.0f} %)", name, stage, 100.0 * f);
                         last_log = now;
                       }
                     }};
      const auto tb = std::chrono::steady_clock::now();
      BakeResult result = kind.bake(*it.job, ctx);
      const double bake_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - tb).count();
      for (const auto& w : result.warnings) spdlog::warn("{}: {}", name, w);

      json manifest = {
          {"schema", "specbake.bundle/1"},
          {"tool", {{"name", "specbake"}, {"version", kVersion}}},
          {"job", {{"name", name}, {"kind", it.job->kind}, {"hash", it.hash}, {"config_file", fs::absolute(it.config->file).string()}}},
          {"config", it.job->normalised},
          {"inputs", json::object()},
          {"kernels", json::object()},
          {"device", device_json(dev.info())},
          {"parameters", result.parameters},
          {"accuracy", accuracy_json(result.accuracy)},
          {"warnings", result.warnings},
          {"created_utc", utc_now()},
      };
      for (auto b = result.manifest_blocks.begin(); b != result.manifest_blocks.end(); ++b) {
        if (manifest.contains(b.key())) throw JobError("manifest block '" + b.key() + "' clashes with a standard key");
        manifest[b.key()] = b.value();
      }
      for (const auto& [label, sha] : it.job->inputs) manifest["inputs"][label] = sha;
      for (const auto& k : kind.programs) manifest["kernels"][k] = sha256_hex(expanded_program(k));
      const auto tw = std::chrono::steady_clock::now();
      manifest["timings_s"] = {{"bake", bake_s}};
      r.bundle = store.publish(name, hash12, manifest, result.files);
      const double write_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - tw).count();
      r.status = "built";
      r.parameters = result.parameters;
      r.accuracy = accuracy_json(result.accuracy);
      r.warnings = result.warnings;
      r.timings = {{"bake_s", bake_s}, {"write_s", write_s}};
      spdlog::info("{}: wrote {}", name, r.bundle.string());
    } catch (const Error& e) {
      r.status = "failed";
      r.code = e.exit_code();
      r.reason = e.what();
      spdlog::error("{}: {}", name, e.what());
    } catch (const std::exception& e) {
      r.status = "failed";
      r.code = ExitCode::job_failed;
      r.reason = e.what();
      spdlog::error("{}: {}", name, e.what());
    }
    r.timings["total_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    reports.push_back(std::move(r));
  }
  return reports;
}

}  // namespace specbake
