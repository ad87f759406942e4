#pragma once
// Comparing two bundles (`specbake diff`): per file, the largest absolute and relative
// difference and where it is; and the manifest entries that changed.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace specbake {

namespace fs = std::filesystem;

struct FileDiff {
  std::string path;
  std::string status;  // same | same-values (bytes differ, values do not) | differs | added | removed | shape-changed
  bool numeric = false;  // float32 .bin data, or EXR pixels (decoded), compared element by element
  std::vector<std::string> channels;  // EXR: the channel names, the last index of at_abs/at_rel
  double max_abs = 0.0, max_rel = 0.0;
  std::vector<std::int64_t> at_abs, at_rel;  // multi-index (manifest shape) of each maximum
  std::size_t exceeding = 0;  // elements with |a − b| > fail_abs + fail_rel·max(|a|, |b|), or NaN in one only
  std::size_t nan_mismatches = 0;  // NaN in one bundle, a number in the other (NaN in both is no change)
};

struct BundleDiff {
  std::vector<FileDiff> files;
  // Flattened manifest keys (config, inputs, kernels, parameters, tool, device) whose values
  // differ: key → [old, new].
  nlohmann::json changed;
  // Accuracy records (by name) whose value or verdict differs: name → {old, new}, each
  // {value, tolerance, passed} or null where the bundle lacks the record.
  nlohmann::json accuracy;
};

// Relative difference: |a − b| / max(|a|, |b|), 0 when both are 0. An element exceeds the
// thresholds when |a − b| > fail_abs + fail_rel·max(|a|, |b|) (numpy.allclose's rule, symmetric).
// Each path a bundle folder or a job folder (its `latest`, as inspect_bundle takes it).
BundleDiff diff_bundles(const fs::path& old_path, const fs::path& new_path, double fail_abs, double fail_rel);

// True if no float32 or EXR element exceeds the thresholds and no file was added, removed or
// reshaped. Other files (JSON/GLSL copies, PNG previews) render the numeric data and are
// reported but do not decide.
bool diff_passes(const BundleDiff& d);

}  // namespace specbake
