#include "core/spectral_data.hpp"

#include <cmath>
#include <map>
#include <mutex>
#include <sstream>
#include <stdexcept>

#include "core/resources.hpp"

namespace specbake {

namespace cie {
using real = double;
using std::cbrt, std::cos, std::exp, std::fabs, std::floor, std::pow, std::sin, std::sqrt, std::atan2;
#include "common/colour.cl"
}  // namespace cie

std::array<double, 3> CmfTable::at(double nm) const {
  std::array<double, 3> v{};
  cie::cmf_lerp(xyz.data(), count(), first_nm, nm, v.data());
  return v;
}

std::array<double, 3> xyz_to_lab(const std::array<double, 3>& xyz, const std::array<double, 3>& w) {
  std::array<double, 3> lab{};
  cie::xyz_to_lab(xyz[0], xyz[1], xyz[2], w[0], w[1], w[2], &lab[0], &lab[1], &lab[2]);
  return lab;
}

double ciede2000(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  return cie::ciede2000(a[0], a[1], a[2], b[0], b[1], b[2]);
}

double SpdTable::at_whole_nm(double nm) const {
  const double i = nm - first_nm;
  if (!(i >= 0.0) || i > static_cast<double>(values.size() - 1) || i != std::floor(i)) return 0.0;
  return values[static_cast<std::size_t>(i)];
}

const SpdTable& d65_table() {
  static const SpdTable t = [] {
    SpdTable d;
    d.resource = "data/cie/d65_1nm.csv";
    std::istringstream in{std::string(resource(d.resource))};
    std::string line;
    std::getline(in, line);  // header
    double expected = 0.0;
    while (std::getline(in, line)) {
      if (line.empty()) continue;
      const auto comma = line.find(',');
      const double nm = std::stod(line.substr(0, comma));
      if (d.values.empty()) d.first_nm = expected = nm;
      if (nm != expected) throw std::runtime_error("D65 table " + d.resource + " is not at 1 nm steps");
      d.values.push_back(std::stod(line.substr(comma + 1)));
      expected += 1.0;
    }
    return d;
  }();
  return t;
}

const char* to_string(CmfSet c) {
  switch (c) {
    case CmfSet::cie1931_2deg: return "cie1931-2deg";
    case CmfSet::cie1964_10deg: return "cie1964-10deg";
    case CmfSet::cie2006_2deg: return "cie2006-2deg";
    case CmfSet::cie2006_10deg: return "cie2006-10deg";
  }
  return "?";
}

namespace {

std::vector<std::string> split_csv_line(const std::string& line) {
  std::vector<std::string> fields;
  std::string cur;
  bool quoted = false;
  for (char c : line) {
    if (c == '"') {
      quoted = !quoted;
    } else if (c == ',' && !quoted) {
      fields.push_back(cur);
      cur.clear();
    } else if (c != '\r') {
      cur += c;
    }
  }
  fields.push_back(cur);
  return fields;
}

CmfTable load_cmf(const std::string& path) {
  CmfTable t;
  t.resource = path;
  std::istringstream in{std::string(resource(path))};
  std::string line;
  std::getline(in, line);  // header
  double expected = 0.0;
  bool first = true;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    auto f = split_csv_line(line);
    if (f.size() != 4) throw std::runtime_error("malformed CMF table " + path);
    const double nm = std::stod(f[0]);
    if (first) {
      t.first_nm = nm;
      expected = nm;
      first = false;
    }
    if (nm != expected) throw std::runtime_error("CMF table " + path + " is not at 1 nm steps");
    expected += 1.0;
    t.last_nm = nm;
    for (int c = 1; c <= 3; ++c) t.xyz.push_back(std::stod(f[c]));
  }
  return t;
}

}  // namespace

const CmfTable& cmf_table(CmfSet set) {
  static std::mutex m;
  static std::map<CmfSet, CmfTable> cache;
  std::lock_guard lock(m);
  auto it = cache.find(set);
  if (it != cache.end()) return it->second;
  const char* path = nullptr;
  switch (set) {
    case CmfSet::cie1931_2deg: path = "data/cie/cie1931_2deg_1nm.csv"; break;
    case CmfSet::cie1964_10deg: path = "data/cie/cie1964_10deg_1nm.csv"; break;
    case CmfSet::cie2006_2deg: path = "data/cie/cie2006_2deg_1nm.csv"; break;
    case CmfSet::cie2006_10deg: path = "data/cie/cie2006_10deg_1nm.csv"; break;
  }
  return cache.emplace(set, load_cmf(path)).first->second;
}

const std::vector<GlassEntry>& glass_catalog() {
  static const std::vector<GlassEntry> catalog = [] {
    std::vector<GlassEntry> out;
    std::istringstream in{std::string(resource("data/glass/glasses.csv"))};
    std::string line;
    std::getline(in, line);
    auto header = split_csv_line(line);
    auto col = [&](const std::string& name) {
      for (std::size_t i = 0; i < header.size(); ++i)
        if (header[i] == name) return i;
      throw std::runtime_error("glass catalogue lacks column " + name);
    };
    const std::size_t iid = col("id"), iname = col("name"), imin = col("valid_min_nm"),
                      imax = col("valid_max_nm");
    const std::size_t iB[] = {col("B1"), col("B2"), col("B3"), col("B4")};
    const std::size_t iC[] = {col("C1_um2"), col("C2_um2"), col("C3_um2"), col("C4_um2")};
    while (std::getline(in, line)) {
      if (line.empty()) continue;
      auto f = split_csv_line(line);
      GlassEntry g;
      g.id = f.at(iid);
      g.description = f.at(iname);
      for (int i = 0; i < 4; ++i) {
        const double B = std::stod(f.at(iB[i])), C = std::stod(f.at(iC[i]));
        if (B == 0.0 && C == 0.0) continue;  // unused term
        g.sellmeier.B.push_back(B);
        g.sellmeier.C.push_back(C);
      }
      g.valid_nm = {std::stod(f.at(imin)), std::stod(f.at(imax))};
      out.push_back(std::move(g));
    }
    return out;
  }();
  return catalog;
}

const GlassEntry* find_glass(const std::string& id) {
  for (const auto& g : glass_catalog())
    if (g.id == id) return &g;
  return nullptr;
}

}  // namespace specbake
