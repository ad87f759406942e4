#include "registry/registry.hpp"

#include <mutex>
#include <stdexcept>

#include "core/hash.hpp"
#include "core/version.hpp"
#include "kinds/atmosphere/kind.hpp"
#include "kinds/diffraction/kind.hpp"
#include "kinds/dispersion/kind.hpp"

namespace specbake {

namespace {
std::vector<Kind>& table() {
  static std::vector<Kind> t = {dispersion::kind(), diffraction::kind(), atmosphere::kind()};
  return t;
}

std::vector<KindSyntax> syntax() {
  std::vector<KindSyntax> out;
  for (const auto& k : kinds()) out.push_back({k.name, k.parse});
  return out;
}
}  // namespace

const std::vector<Kind>& kinds() { return table(); }

const Kind& kind_named(const std::string& name) {
  for (const auto& k : table())
    if (k.name == name) return k;
  throw std::out_of_range("no job kind '" + name + "'");
}

void register_kind(Kind kind) {
  for (const auto& k : table())
    if (k.name == kind.name) throw std::invalid_argument("job kind '" + kind.name + "' is already registered");
  table().push_back(std::move(kind));
}

Config load_config(const fs::path& file, std::vector<InvalidJob>* job_errors) {
  return load_config(file, syntax(), job_errors);
}
Config parse_config(const std::string& text, const fs::path& file, std::vector<InvalidJob>* job_errors) {
  return parse_config(text, file, syntax(), job_errors);
}
Config parse_config(const YAML::Node& root, const fs::path& file, std::vector<InvalidJob>* job_errors) {
  return parse_config(root, file, syntax(), job_errors);
}

void check_device_memory(const JobSpec& job, const cl_util::DeviceInfo& device) {
  check_device_memory(job, kind_named(job.kind).memory(job), device);
}

std::string job_hash(const JobSpec& job, const nlohmann::json& device) {
  Sha256 h;
  nlohmann::json identity = {{"tool", "specbake"}, {"version", kVersion}, {"config", job.normalised}};
  for (const auto& [label, sha] : job.inputs) identity["inputs"][label] = sha;
  identity["device"] = device;
  h.update(identity.dump());
  for (const auto& program : kind_named(job.kind).programs) {
    h.update(program);
    h.update(expanded_program(program));
  }
  return h.hex();
}

}  // namespace specbake
