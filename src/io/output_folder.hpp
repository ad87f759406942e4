#pragma once
// An output folder as a whole (`specbake inspect OUT`, `specbake report OUT`): its jobs, each
// with the bundle `latest` points at and the newest earlier complete bundle of the same job.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace specbake {

namespace fs = std::filesystem;

struct OutputJob {
  std::string name;          // the job folder's name
  fs::path bundle;           // the bundle `latest` points at
  nlohmann::json manifest;   // its manifest
  std::uint64_t bytes = 0;   // its files (as the manifest lists them) and the manifest itself
  double age_s = -1.0;       // now − the manifest's created_utc; < 0 when unreadable
  fs::path previous;         // the newest other bundle of the job with a readable manifest; empty if none
  nlohmann::json to_json() const;  // name, kind, bundle, hash, bytes, created_utc, age_s, headline, previous
};

// The newest other bundle beside `bundle` (same job folder, by manifest created_utc), skipping
// temporaries and unreadable manifests; empty if none.
fs::path previous_bundle(const fs::path& bundle);

// A bundle's size: the files its manifest lists and the manifest itself.
std::uint64_t bundle_bytes(const fs::path& bundle, const nlohmann::json& manifest);

// Whether `dir` holds at least one job folder (a folder with a `latest` bundle).
bool is_output_folder(const fs::path& dir);

// The job folders of an output folder, sorted by name. InputError naming the folder if it holds
// none; a job whose manifest cannot be read is an InputError naming the manifest.
std::vector<OutputJob> scan_output_folder(const fs::path& dir);

// "self_check 5.6e-06 <= 0.002" from the first accuracy record of a manifest's list; "-" if none.
std::string accuracy_headline(const nlohmann::json& accuracy);
// Seconds since an ISO 8601 UTC time "YYYY-MM-DDTHH:MM:SSZ"; < 0 if it does not parse.
double seconds_since_utc(const std::string& utc);
// "3.2 MiB", "512 B", "1.0 GiB".
std::string human_bytes(std::uint64_t bytes);
// "45 s", "12 min", "3.5 h", "2.0 d".
std::string human_age(double seconds);

}  // namespace specbake
