#pragma once
// The typed config model (schema v1) and its YAML loader. Jobs only ever see these
// structs; every value has been range-checked and every path resolved against the
// config file's folder.
#include <filesystem>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/errors.hpp"

namespace specbake {

namespace fs = std::filesystem;

struct RangeNm {
  double lo = 380.0;
  double hi = 780.0;
};

enum class Sampling { uniform, gauss_legendre, visible_pdf, inverse_square };
enum class CmfSet { cie1931_2deg, cie1964_10deg, cie2006_2deg, cie2006_10deg };
enum class AbbeLines { d, D };

// Sellmeier: n(λ)² = 1 + Σ B_i λ² / (λ² − C_i), λ in µm, C_i in µm².
struct Sellmeier {
  std::vector<double> B, C;
};

struct Material {
  enum class Kind { abbe, glass, sellmeier } kind = Kind::abbe;
  double n_ref = 0.0;            // abbe kind: index at the reference line of abbe_lines
  double v = 0.0;                // abbe kind: Abbe number on abbe_lines
  std::string glass;             // catalogue id when kind == glass
  std::optional<Sellmeier> sellmeier;  // known for glass and sellmeier kinds
  std::optional<RangeNm> valid_nm;     // catalogue validity range of the Sellmeier fit
};

struct DispersionSpec {
  std::optional<int> samples;  // nullopt: auto
  Sampling sampling = Sampling::uniform;
  RangeNm range_nm;
  CmfSet cmf = CmfSet::cie1931_2deg;
  Material material;
  AbbeLines abbe_lines = AbbeLines::d;
  double tolerance_de2000 = 1.0;
  double spread = 4.0;
};

// ---- diffraction job (parsed in config_diffraction.cpp) ----------------------------------
struct DiffractionSpec {
};

// ---- atmosphere job (parsed in config_atmosphere.cpp) ------------------------------------
struct AtmosphereSpec {
};

using KindSpec = std::variant<DispersionSpec, DiffractionSpec, AtmosphereSpec>;

struct JobSpec {
  std::string name;
  std::string kind;
  Location where;             // the job's entry in its config
  KindSpec spec;
  nlohmann::json normalised;  // canonical form of everything that defines the result
  std::vector<std::pair<std::string, std::string>> inputs;  // (label, sha256) of input data
};

struct Config {
  fs::path file;
  fs::path output;     // absolute or relative to cwd; already resolved against the file's folder
  bool output_given = false;
  std::string device = "auto";
  std::vector<JobSpec> jobs;
};

inline constexpr int kSchemaVersion = 1;
inline constexpr int kMaxSamples = 4096;

// Parses and validates; throws InputError (file:line:col + key path) or IoError.
Config load_config(const fs::path& file);
Config parse_config(const std::string& text, const fs::path& file_for_messages);

const char* to_string(Sampling);
const char* to_string(CmfSet);
const char* to_string(AbbeLines);

}  // namespace specbake
