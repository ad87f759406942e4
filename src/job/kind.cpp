#include "job/kind.hpp"

#include <chrono>
#include <cmath>
#include <map>

#include "core/resources.hpp"

namespace specbake {

using nlohmann::json;

const char* to_string(Stage s) {
  switch (s) {
    case Stage::plan: return "plan";
    case Stage::compute: return "compute";
    case Stage::check: return "check";
    case Stage::files: return "files";
  }
  return "?";
}

double finish_files(BakeResult& result) {
  if (!result.finish) return 0.0;
  const auto t0 = std::chrono::steady_clock::now();
  const auto finish = std::move(result.finish);
  result.finish = nullptr;
  finish(result.files, result.manifest_blocks);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

Accuracy Accuracy::judged(std::string name, std::string metric, double value, std::optional<double> tolerance,
                          std::string reference, json details) {
  Accuracy a;
  a.name = std::move(name);
  a.metric = std::move(metric);
  a.value = value;
  a.tolerance = tolerance;
  a.reference = std::move(reference);
  a.passed = tolerance ? (value <= *tolerance) : !std::isnan(value);
  a.details = std::move(details);
  return a;
}

json to_json(const Accuracy& a) {
  json j = {{"name", a.name},
            {"metric", a.metric},
            {"value", std::isfinite(a.value) ? json(a.value) : json(std::to_string(a.value))},
            {"tolerance", a.tolerance ? json(*a.tolerance) : json(nullptr)},
            {"reference", a.reference},
            {"passed", a.passed}};
  if (!a.unit.empty()) j["unit"] = a.unit;
  if (!a.details.empty()) j["details"] = a.details;
  return j;
}

json accuracy_json(const std::vector<Accuracy>& records) {
  json out = json::array();
  for (const auto& a : records) out.push_back(to_json(a));
  return out;
}

const json* find_accuracy(const json& list, std::string_view name) {
  if (!list.is_array()) return nullptr;
  for (const auto& a : list)
    if (a.is_object() && a.value("name", "") == name) return &a;
  return nullptr;
}

void check_device_memory(const JobSpec& job, const MemoryEstimate& need, const cl_util::DeviceInfo& di) {
  if (need.total_bytes > di.global_mem_bytes || need.largest_buffer > di.max_alloc_bytes)
    throw InputError(job.where, "job '" + job.name + "' needs about " + std::to_string(need.total_bytes >> 20) +
                                    " MiB of device memory (largest buffer " + std::to_string(need.largest_buffer >> 20) +
                                    " MiB) but " + di.name + " has " + std::to_string(di.global_mem_bytes >> 20) +
                                    " MiB (largest buffer " + std::to_string(di.max_alloc_bytes >> 20) +
                                    " MiB); expected smaller sizes");
}

std::string expanded_program(const std::string& path) {
  // Embedded files do not change while the process runs: expand each program once (the hash
  // and the manifest both need it, for every job of its kind).
  static std::map<std::string, std::string> cache;
  auto it = cache.find(path);
  if (it == cache.end()) it = cache.emplace(path, kernel_source(path)).first;
  return it->second;
}

nlohmann::json device_identity(const cl_util::DeviceInfo& d) {
  return {{"name", d.name}, {"platform", d.platform}, {"version", d.version},
          {"build_options", cl_util::common_build_options(d)}};
}

}  // namespace specbake
