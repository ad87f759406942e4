#pragma once
// Tabulated inputs embedded from data/: CIE colour-matching functions and the glass
// catalogue (see data/*/PROVENANCE.md).
#include <string>
#include <vector>

#include "core/config.hpp"

namespace specbake {

// A colour-matching function table at 1 nm steps starting at first_nm.
struct CmfTable {
  std::string resource;  // embedded path, e.g. "data/cie/cie1931_2deg_1nm.csv"
  double first_nm = 0.0;
  double last_nm = 0.0;
  std::vector<double> xyz;  // [count][3]: x̄, ȳ, z̄ at first_nm + i
  int count() const { return static_cast<int>(xyz.size() / 3); }
};

const CmfTable& cmf_table(CmfSet set);

struct GlassEntry {
  std::string id, description;
  Sellmeier sellmeier;
  RangeNm valid_nm;
};

const std::vector<GlassEntry>& glass_catalog();
const GlassEntry* find_glass(const std::string& id);  // nullptr if unknown

}  // namespace specbake
