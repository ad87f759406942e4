#pragma once
// Checking a bundle as it lies on disk (`specbake inspect`): its manifest, and every file it
// lists against the recorded sha256.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace specbake {

namespace fs = std::filesystem;

struct InspectedFile {
  std::string path;
  std::string status;  // ok | missing | sha256-mismatch
  std::uint64_t bytes = 0;
  std::string dtype;        // "" when the manifest gives none (images, text)
  nlohmann::json shape;     // null when the manifest gives none
};

struct Inspection {
  fs::path bundle;          // the bundle folder (a job folder's `latest` followed)
  nlohmann::json manifest;
  std::vector<InspectedFile> files;
  int bad = 0;              // files missing or altered
  nlohmann::json to_json() const;
};

// The bundle folder `path` names: itself when it holds manifest.json, else a job folder's `latest`
// followed. InputError if it is neither.
fs::path resolve_bundle(const fs::path& path);

// `path` is a bundle folder (holding manifest.json) or a job folder (holding `latest`).
// InputError if it is neither or the manifest is not JSON; IoError if it cannot be read.
Inspection inspect_bundle(const fs::path& path);

}  // namespace specbake
