#pragma once
// The table of job kinds: the built-in three plus any registered at run time (tests, plug-ins).
// The config loader reads each job's keys through this table, the runner plans and bakes
// through it. Adding a kind: its folder under src/kinds/, its kernels, one line in
// registry.cpp, docs and tests.
#include <string>
#include <vector>

#include "core/config.hpp"
#include "job/kind.hpp"

namespace specbake {

// Every kind, built-in first, in registration order.
const std::vector<Kind>& kinds();
// The kind called `name`; std::out_of_range if none (configs are checked when loaded).
const Kind& kind_named(const std::string& name);
// Adds a kind (before configs are loaded); std::invalid_argument if the name is taken.
void register_kind(Kind kind);

// Config loading with the kinds' parsers (core/config.hpp).
Config load_config(const fs::path& file, std::vector<InvalidJob>* job_errors = nullptr);
Config parse_config(const std::string& text, const fs::path& file_for_messages,
                    std::vector<InvalidJob>* job_errors = nullptr);
Config parse_config(const YAML::Node& root, const fs::path& file_for_messages,
                    std::vector<InvalidJob>* job_errors = nullptr);

// check_device_memory (job/kind.hpp) with the job kind's own estimate.
void check_device_memory(const JobSpec& job, const cl_util::DeviceInfo& device);

// sha256 over the tool version, the job's normalised config, its input data, the fully
// expanded sources of its kind's programs and the device that bakes it (`device`: name,
// platform, OpenCL version — floating-point results differ between devices and drivers).
// Same hash → same bundle folder → the job is skipped.
std::string job_hash(const JobSpec& job, const nlohmann::json& device);

}  // namespace specbake
