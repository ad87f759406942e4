#pragma once
// Tabulated inputs embedded from data/: CIE colour-matching functions and the glass
// catalogue (see data/*/PROVENANCE.md).
#include <array>
#include <string>
#include <vector>


namespace specbake {

struct RangeNm {
  double lo = 380.0;
  double hi = 780.0;
};

enum class CmfSet { cie1931_2deg, cie1964_10deg, cie2006_2deg, cie2006_10deg };
const char* to_string(CmfSet);

// Sellmeier: n(λ)² = 1 + Σ B_i λ² / (λ² − C_i), λ in µm, C_i in µm².
struct Sellmeier {
  std::vector<double> B, C;
};


// A colour-matching function table at 1 nm steps starting at first_nm.
struct CmfTable {
  std::string resource;  // embedded path, e.g. "data/cie/cie1931_2deg_1nm.csv"
  double first_nm = 0.0;
  double last_nm = 0.0;
  std::vector<double> xyz;  // [count][3]: x̄, ȳ, z̄ at first_nm + i
  int count() const { return static_cast<int>(xyz.size() / 3); }
  // x̄ȳz̄ at `nm`: linear between rows, 0 outside the table (cmf_lerp of kernels/common/colour.cl,
  // the same function the kernels use).
  std::array<double, 3> at(double nm) const;
};

const CmfTable& cmf_table(CmfSet set);

// CIE standard illuminant D65, relative spectral power at 1 nm steps (data/cie/d65_1nm.csv).
struct SpdTable {
  std::string resource;
  double first_nm = 0.0;
  std::vector<double> values;
  // The value at a whole nm inside the table; 0 elsewhere (no interpolation: callers step 1 nm).
  double at_whole_nm(double nm) const;
};
const SpdTable& d65_table();

struct GlassEntry {
  std::string id, description;
  Sellmeier sellmeier;
  RangeNm valid_nm;
};

const std::vector<GlassEntry>& glass_catalog();

// kernels/common/colour.cl's colour difference on the host: CIE 1976 L*a*b* of `xyz` relative
// to the white `white_xyz`, and CIEDE2000 (kL = kC = kH = 1) between two such colours.
std::array<double, 3> xyz_to_lab(const std::array<double, 3>& xyz, const std::array<double, 3>& white_xyz);
double ciede2000(const std::array<double, 3>& lab1, const std::array<double, 3>& lab2);
const GlassEntry* find_glass(const std::string& id);  // nullptr if unknown

}  // namespace specbake
