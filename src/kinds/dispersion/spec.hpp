#pragma once
// The typed spec of a dispersion job (parsed in config.cpp; keys in docs/dispersion.md).
#include <optional>
#include <string>
#include <vector>

#include "core/config.hpp"
#include "core/spectral_data.hpp"

namespace specbake {

enum class Sampling { uniform, gauss_legendre, visible_pdf, inverse_square };
enum class AbbeLines { d, D };

struct Material {
  enum class Kind { abbe, glass, sellmeier } kind = Kind::abbe;
  double n_ref = 0.0;            // abbe kind: index at the reference line of abbe_lines
  double v = 0.0;                // abbe kind: Abbe number on abbe_lines
  std::string glass;             // catalogue id when kind == glass
  std::optional<Sellmeier> sellmeier;  // known for glass and sellmeier kinds
  std::optional<RangeNm> valid_nm;     // catalogue validity range of the Sellmeier fit
};

struct DispersionSpec : KindSpec {
  std::optional<int> samples;  // nullopt: auto
  Sampling sampling = Sampling::uniform;
  RangeNm range_nm;
  CmfSet cmf = CmfSet::cie1931_2deg;
  Material material;
  AbbeLines abbe_lines = AbbeLines::d;
  double tolerance_de2000 = 1.0;
  // prism_de2000 is judged against tolerance_de2000 under samples: auto, and with fixed samples
  // when the config gives tolerance_de2000 (else it is reported only)
  bool judge_de2000 = false;
  double spread = 4.0;
  // `formats:`: the .bin tables and/or dispersion.json (dispersion.glsl and the preview always)
  bool write_bin = true, write_json = true;
};

inline constexpr int kMaxSamples = 4096;

const char* to_string(Sampling);
const char* to_string(AbbeLines);

namespace dispersion {
// Reads a `kind: dispersion` job entry (yaml::At of the entry); fills the canonical config and inputs.
DispersionSpec parse_spec(const yaml::At& job, nlohmann::json& norm, Inputs& inputs);
}  // namespace dispersion

}  // namespace specbake
