#pragma once
// The interface every job kind implements, and what the runner hands it. A kind is one folder
// (src/kinds/<kind>/) that fills in a `Kind` — its name, config parser, plan, cost and memory
// estimates, bake, and OpenCL programs — and is listed in the registry (src/registry/). Kinds
// read typed specs (their own KindSpec), never YAML after parsing, and return files, never
// write them.
//
// A bake runs in four steps, reported through `Stage`:
//   plan     resolve `auto` parameters (what `specbake plan` shows)
//   compute  the kernels on the device
//   check    self-checks against the double reference and error measurements (accuracy records)
//   files    encode the bundle's files and previews
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "cl/device.hpp"
#include "core/config.hpp"
#include "io/bundle.hpp"
#include "io/result_store.hpp"

namespace specbake {

enum class Stage { plan, compute, check, files };
const char* to_string(Stage s);

// Progress inside a step: a short description ("order 3", "FFT terms", ...) and the fraction
// in [0, 1] of the whole job done.
using Progress = std::function<void(std::string_view what, double fraction)>;

// Results a kind may reuse between bakes that differ only in settings the result does not
// depend on (the atmosphere's path-traced scene is the same for every texture size): keyed by
// the kind with everything the value depends on. `sweep` and auto searches share one in a
// process; with a `store`, `kept` values also outlive the process (io/result_store.hpp).
struct Memo {
  std::map<std::string, std::shared_ptr<const void>> items;
  const ResultStore* store = nullptr;  // none: this process only
  // The `store` entries this memo read or wrote (file names): a bundle's manifest lists them as
  // `results_kept`, and `gc` keeps the entries some bundle lists.
  std::set<std::string> store_used;

  // Whether a value is held under `key`, here or in `store` (which may still fail to read it).
  bool has(const std::string& key) const { return items.count(key) > 0 || (store && store->has(key)); }
  template <class T, class Make>
  std::shared_ptr<const T> get(const std::string& key, Make make) {
    auto it = items.find(key);
    if (it == items.end()) it = items.emplace(key, std::make_shared<const T>(make())).first;
    return std::static_pointer_cast<const T>(it->second);
  }
  // As `get`, and through `store`: a value an earlier run kept under `key` is decoded instead of
  // made (decode(bytes) -> T throws on bytes it cannot read: then it is made again), and a made
  // one is encoded (encode(const T&) -> std::string) and kept. `key` must name everything the
  // value depends on, the programs' sources, the device and the tool's version included.
  template <class T, class Make, class Encode, class Decode>
  std::shared_ptr<const T> kept(const std::string& key, Make make, Encode encode, Decode decode) {
    return get<T>(key, [&]() -> T {
      if (!store) return make();
      const std::string name = ResultStore::name_of(key);
      if (const std::optional<std::string> bytes = store->get(key)) {
        try {
          T value = decode(*bytes);
          store_used.insert(name);
          return value;
        } catch (const std::exception& e) {
          spdlog::warn("{}: not used ({}); computing it again", (store->dir() / name).string(), e.what());
        }
      }
      T value = make();
      if (store->put(key, encode(value))) store_used.insert(name);
      return value;
    });
  }
};

struct JobContext {
  cl_util::Device& device;
  Progress progress = [](std::string_view, double) {};
  std::function<void(Stage)> on_stage = [](Stage) {};  // called as each step begins
  Stage stage = Stage::plan;
  // false: a measured error above the job's tolerance is a warning, not a failure (`sweep`
  // measures every setting; `run` judges).
  bool judge = true;
  Memo* memo = nullptr;  // none: nothing is reused beyond this bake
  // The bundle's hash (config, inputs, programs, device), for files that record it (KTX2's
  // key/value data); empty where no bundle is published (`sweep`).
  std::string bundle_hash{};

  void enter(Stage s) {
    stage = s;
    if (on_stage) on_stage(s);
  }
};

// One measured accuracy figure, the same shape for every kind. The manifest's `accuracy` is the
// list of these (the first is the job's headline figure); the run summary, `--report`, `diff`
// and sweeps read them without knowing the kind.
struct Accuracy {
  std::string name;                 // e.g. "self_check", "sum_K_minus_I", "prism_de2000"
  std::string metric;               // what `value` is, e.g. "max relative error"
  std::string unit;                 // optional, short, shown after the value: e.g. "p99 CIEDE2000"
  double value = 0.0;
  std::optional<double> tolerance;  // none: reported, not judged
  std::string reference;            // what it is measured against
  bool passed = true;               // value <= tolerance (true without a tolerance)
  nlohmann::json details = nlohmann::json::object();  // the kind's own breakdown

  // passed from value and tolerance (a NaN value fails).
  static Accuracy judged(std::string name, std::string metric, double value, std::optional<double> tolerance,
                         std::string reference, nlohmann::json details = nlohmann::json::object());
};
nlohmann::json to_json(const Accuracy& a);
nlohmann::json accuracy_json(const std::vector<Accuracy>& records);
// The record called `name` in a manifest's or report's accuracy list; nullptr if absent.
const nlohmann::json* find_accuracy(const nlohmann::json& list, std::string_view name);

// A job that failed after it had resolved its parameters or measured its accuracy (an auto search
// that ends short of its tolerance, a record that misses it): what it got that far, for the
// report and the summary.
class BakeFailed : public JobError {
 public:
  BakeFailed(const std::string& what, nlohmann::json parameters, nlohmann::json accuracy = nlohmann::json::array(),
             std::vector<std::string> warnings = {})
      : JobError(what), parameters(std::move(parameters)), accuracy(std::move(accuracy)), warnings(std::move(warnings)) {}
  nlohmann::json parameters, accuracy;
  std::vector<std::string> warnings;
};

struct BakeResult {
  nlohmann::json parameters;  // resolved values (auto → number, ...)
  std::vector<Accuracy> accuracy;
  std::vector<std::string> warnings;
  std::vector<OutputFile> files;
  // Kind-specific top-level manifest blocks named in a kind's contract (e.g. "diffraction").
  nlohmann::json manifest_blocks = nlohmann::json::object();
  // Host-only work the bundle still needs once the bake is judged: the bytes of files already
  // listed in `files` (texture encodings) and files it adds (previews), and what it records of
  // its own cost in manifest_blocks. No device work and no accuracy records: it cannot change
  // whether the job passes. Empty when there is none; run it through finish_files (`run` does so
  // on the thread that publishes the bundle, while the next job bakes).
  std::function<void(std::vector<OutputFile>& files, nlohmann::json& manifest_blocks)> finish;
};
// Runs and clears result.finish (when set); its seconds on the calling thread.
double finish_files(BakeResult& result);

// Device memory a job will need, estimated from its spec before anything is allocated.
struct MemoryEstimate {
  std::uint64_t total_bytes = 0;     // all device buffers alive at once
  std::uint64_t largest_buffer = 0;  // the biggest single allocation
  std::uint64_t host_bytes = 0;      // host memory at the peak (tables, reference paths, files)
};

// A job's modelled cost given what earlier runs kept (Kind::kept_cost_s).
struct KeptCost {
  double seconds = 0.0;  // on a 2-core CPU device, as cost_s
  std::string basis;     // what it models, e.g. "2-core CPU model of the kept search's choice"
};

// A job kind: everything the runner and the config loader need, in one table entry.
struct Kind {
  std::string name;     // the config's `kind:` value
  std::string summary;  // one line for help texts
  // Reads the job's entry (see KindSyntax).
  std::function<std::shared_ptr<const KindSpec>(const yaml::At& job, nlohmann::json& norm, Inputs& inputs)> parse;
  // Resolved parameters only (what `specbake plan` shows); may use the device.
  std::function<nlohmann::json(const JobSpec& job, JobContext& ctx)> plan;
  std::function<BakeResult(const JobSpec& job, JobContext& ctx)> bake;
  // Relative cost (arbitrary units, comparable across kinds) for balancing shards, and an
  // estimate of the job's wall time in seconds on a 2-core CPU device (for `plan`).
  std::function<double(const JobSpec& job)> cost_s;
  // Optional: cost_s when results kept in ctx.memo's store change what the job costs (an
  // atmosphere's kept settings search: one bake instead of a search; its kept scene truth: no
  // trace), with the estimate's basis in words; nullopt when they do not.
  std::function<std::optional<KeptCost>(const JobSpec& job, JobContext& ctx)> kept_cost_s;
  std::function<MemoryEstimate(const JobSpec& job)> memory;
  // The OpenCL programs the kind builds (paths of embedded kernel files): their fully expanded
  // sources enter the bundle hash, so a change to any file they include makes a new bundle.
  std::vector<std::string> programs;
  // One line naming the resolved settings that decide the result and its cost (for the run
  // summary and `plan`), from the parameters `plan` or `bake` returned.
  std::function<std::string(const nlohmann::json& parameters)> describe;
  // The accuracy records that measure a bake against ground truth which does not share its
  // method (what `specbake sweep` plots), in order of preference; a bake without any of them
  // (e.g. an atmosphere with `scene: none`) cannot be swept.
  std::vector<std::string> truth_records;

  // A kind whose spec type is Spec: `parse` returns a Spec, `plan` and `bake` take one.
  template <class Spec, class Parse, class Plan, class Bake>
  static Kind of(std::string name, std::string summary, Parse parse, Plan plan, Bake bake) {
    Kind k;
    k.name = std::move(name);
    k.summary = std::move(summary);
    k.parse = [parse](const yaml::At& job, nlohmann::json& norm, Inputs& inputs) -> std::shared_ptr<const KindSpec> {
      return std::make_shared<Spec>(parse(job, norm, inputs));
    };
    k.plan = [plan](const JobSpec& j, JobContext& ctx) { return plan(j.as<Spec>(), ctx); };
    k.bake = [bake](const JobSpec& j, JobContext& ctx) { return bake(j.as<Spec>(), ctx); };
    return k;
  }
};

// Refuses (InputError at the job's config entry) a job whose estimate exceeds the device's
// global memory or its largest allocation, before anything is allocated.
void check_device_memory(const JobSpec& job, const MemoryEstimate& need, const cl_util::DeviceInfo& device);

// The bytes every `Kind::programs` entry contributes to the hash: the program's source with
// every include expanded (as the device compiles it).
std::string expanded_program(const std::string& path);

// What a device contributes to the identity of a result (a bundle's hash, a kept result's key):
// its name, platform, version and the options every program is built with there.
nlohmann::json device_identity(const cl_util::DeviceInfo& d);

}  // namespace specbake
