#pragma once
// What every job kind offers the runner: resolve its parameters (plan) and bake its files.
// Jobs read typed specs (core/config.hpp), never YAML, and return files, never write them.
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "cl/device.hpp"
#include "core/config.hpp"
#include "io/bundle.hpp"

namespace specbake {

// stage: short text ("sampling", "matrices", ...); fraction in [0, 1] of the job.
using Progress = std::function<void(std::string_view stage, double fraction)>;

struct JobContext {
  cl_util::Device& device;
  Progress progress = [](std::string_view, double) {};
};

struct BakeResult {
  nlohmann::json parameters;  // resolved values (auto → number, ...)
  nlohmann::json accuracy;    // measured error figures
  std::vector<std::string> warnings;
  std::vector<OutputFile> files;
  // Kind-specific top-level manifest blocks named in a kind's contract (e.g. "diffraction").
  nlohmann::json manifest_blocks = nlohmann::json::object();
};

// Resolved parameters only (what `specbake plan` shows); may use the device.
nlohmann::json plan_job(const JobSpec& job, JobContext& ctx);
BakeResult bake_job(const JobSpec& job, JobContext& ctx);

// Relative cost of a job (arbitrary units, comparable across kinds) for balancing shards.
double estimated_cost(const JobSpec& job);

// Device memory a job will need, estimated from its spec before anything is allocated.
struct MemoryEstimate {
  std::uint64_t total_bytes = 0;    // all device buffers alive at once
  std::uint64_t largest_buffer = 0; // the biggest single allocation
};
MemoryEstimate estimated_device_memory(const JobSpec& job);
// Refuses (InputError at the job's config entry) a job whose estimate exceeds the device's
// global memory or its largest allocation, before anything is allocated.
void check_device_memory(const JobSpec& job, const cl_util::DeviceInfo& device);

// Embedded kernel files a kind depends on (their contents enter the bundle hash).
std::vector<std::string> kernel_files(const std::string& kind);

}  // namespace specbake
