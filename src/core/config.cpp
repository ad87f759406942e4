#include "core/config.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>

#include "core/hash.hpp"
#include "core/resources.hpp"
#include "core/spectral_data.hpp"

namespace specbake {

const char* to_string(Sampling s) {
  switch (s) {
    case Sampling::uniform: return "uniform";
    case Sampling::gauss_legendre: return "gauss-legendre";
    case Sampling::visible_pdf: return "visible-pdf";
    case Sampling::inverse_square: return "inverse-square";
  }
  return "?";
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
const char* to_string(AbbeLines l) { return l == AbbeLines::d ? "d" : "D"; }

namespace {

constexpr std::size_t kMaxConfigBytes = 1 << 20;  // a config is a few kB; refuse huge documents

// A YAML node with the path used to reach it, so errors name file, line, column and key.
struct At {
  YAML::Node node;
  std::string key;
  const fs::path* file;

  Location loc() const {
    const auto m = node.Mark();
    Location l{*file, 0, 0, key};
    if (m.line >= 0) {
      l.line = m.line + 1;
      l.column = m.column + 1;
    }
    return l;
  }
  [[noreturn]] void fail(const std::string& expected) const { throw InputError(loc(), expected); }

  std::string shown() const {
    if (node.IsScalar()) return "'" + node.Scalar() + "'";
    if (node.IsSequence()) return "a list";
    if (node.IsMap()) return "a mapping";
    return "nothing";
  }

  At child(const std::string& k) const { return {node[k], key.empty() ? k : key + "." + k, file}; }
  At item(std::size_t i) const { return {node[i], key + "[" + std::to_string(i) + "]", file}; }
  bool has(const std::string& k) const { return node.IsMap() && node[k]; }

  void expect_map(const char* what) const {
    if (!node.IsMap()) fail(std::string("expected ") + what + " (a mapping), got " + shown());
  }
  // Rejects unknown and duplicate keys.
  void allow_keys(std::initializer_list<const char*> allowed) const {
    std::set<std::string> seen;
    for (auto it = node.begin(); it != node.end(); ++it) {
      const std::string k = it->first.Scalar();
      At key_at{it->first, key.empty() ? k : key + "." + k, file};
      if (!seen.insert(k).second) key_at.fail("duplicate key '" + k + "'");
      bool ok = false;
      std::string list;
      for (const char* a : allowed) {
        ok = ok || k == a;
        list += std::string(list.empty() ? "" : ", ") + a;
      }
      if (!ok) key_at.fail("unknown key '" + k + "'; expected one of: " + list);
    }
  }

  double number() const {
    if (!node.IsScalar()) fail("expected a number, got " + shown());
    try {
      const double v = node.as<double>();
      if (!std::isfinite(v)) fail("expected a finite number, got " + shown());
      return v;
    } catch (const YAML::Exception&) {
      fail("expected a number, got " + shown());
    }
  }
  double number_in(double lo, double hi, const char* range_text) const {
    const double v = number();
    if (!(v >= lo && v <= hi)) fail(std::string("expected a number ") + range_text + ", got " + shown());
    return v;
  }
  double positive() const {
    const double v = number();
    if (!(v > 0)) fail("expected a number > 0, got " + shown());
    return v;
  }
  long long integer() const {
    if (!node.IsScalar()) fail("expected an integer, got " + shown());
    try {
      return node.as<long long>();
    } catch (const YAML::Exception&) {
      fail("expected an integer, got " + shown());
    }
  }
  std::string string() const {
    if (!node.IsScalar()) fail("expected a string, got " + shown());
    return node.Scalar();
  }
  template <class E>
  E choice(std::initializer_list<std::pair<const char*, E>> options) const {
    const std::string s = node.IsScalar() ? node.Scalar() : "";
    std::string list;
    for (auto& [name, value] : options) {
      if (s == name) return value;
      list += std::string(list.empty() ? "" : " | ") + name;
    }
    fail("expected one of " + list + ", got " + shown());
  }
  std::vector<double> numbers(std::size_t min_len, std::size_t max_len) const {
    if (!node.IsSequence()) fail("expected a list of numbers, got " + shown());
    if (node.size() < min_len || node.size() > max_len) {
      fail(min_len == max_len ? "expected a list of " + std::to_string(min_len) + " numbers"
                              : "expected a list of " + std::to_string(min_len) + " to " +
                                    std::to_string(max_len) + " numbers");
    }
    std::vector<double> out;
    for (std::size_t i = 0; i < node.size(); ++i) out.push_back(item(i).number());
    return out;
  }
};

RangeNm parse_range_nm(const At& at, double table_lo, double table_hi) {
  auto v = at.numbers(2, 2);
  std::ostringstream domain;
  domain << "[" << table_lo << ", " << table_hi << "]";
  if (!(v[0] < v[1])) at.fail("expected [lo, hi] with lo < hi (nm)");
  if (v[0] < table_lo || v[1] > table_hi)
    at.fail("expected a range inside the colour-matching table's " + domain.str() + " nm");
  return {v[0], v[1]};
}

Material parse_material(const At& at, nlohmann::json& norm, std::vector<std::pair<std::string, std::string>>& inputs) {
  at.expect_map("a material: {n_d, v_d}, {glass: NAME} or {sellmeier: {B, C}}");
  Material m;
  if (at.has("glass")) {
    at.allow_keys({"glass"});
    const At g = at.child("glass");
    const std::string id = g.string();
    const GlassEntry* e = find_glass(id);
    if (!e) {
      std::string list;
      for (const auto& x : glass_catalog()) list += (list.empty() ? "" : ", ") + x.id;
      g.fail("unknown glass '" + id + "'; the catalogue has: " + list);
    }
    m.kind = Material::Kind::glass;
    m.glass = id;
    m.sellmeier = e->sellmeier;
    m.valid_nm = e->valid_nm;
    norm = {{"glass", id}, {"sellmeier", {{"B", e->sellmeier.B}, {"C_um2", e->sellmeier.C}}}};
    inputs.emplace_back("data/glass/glasses.csv", sha256_hex(resource("data/glass/glasses.csv")));
  } else if (at.has("sellmeier")) {
    at.allow_keys({"sellmeier"});
    const At s = at.child("sellmeier");
    s.expect_map("Sellmeier coefficients {B: [..], C: [..]} (C in µm²)");
    s.allow_keys({"B", "C"});
    if (!s.has("B") || !s.has("C")) s.fail("expected both B and C lists");
    Sellmeier sm{s.child("B").numbers(1, 4), s.child("C").numbers(1, 4)};
    if (sm.B.size() != sm.C.size()) s.fail("expected B and C of the same length");
    for (std::size_t i = 0; i < sm.C.size(); ++i)
      if (sm.C[i] < 0) s.child("C").item(i).fail("expected C >= 0 (µm²)");
    m.kind = Material::Kind::sellmeier;
    m.sellmeier = sm;
    norm = {{"sellmeier", {{"B", sm.B}, {"C_um2", sm.C}}}};
  } else {
    at.allow_keys({"n_d", "v_d"});
    if (!at.has("n_d") || !at.has("v_d")) at.fail("expected n_d and v_d (or glass, or sellmeier)");
    m.kind = Material::Kind::abbe;
    m.n_ref = at.child("n_d").number_in(1.0 + 1e-9, 5.0, "in (1, 5]");
    m.v = at.child("v_d").number_in(1.0, 200.0, "in [1, 200]");
    norm = {{"n_d", m.n_ref}, {"v_d", m.v}};
  }
  return m;
}

DispersionSpec parse_dispersion(const At& job, nlohmann::json& norm,
                                std::vector<std::pair<std::string, std::string>>& inputs) {
  job.allow_keys({"name", "kind", "samples", "sampling", "range_nm", "cmf", "material",
                  "abbe_lines", "tolerance_de2000", "spread"});
  DispersionSpec d;
  if (job.has("samples")) {
    const At s = job.child("samples");
    if (s.node.IsScalar() && s.node.Scalar() == "auto") {
      d.samples.reset();
    } else {
      if (!s.node.IsScalar()) s.fail("expected an integer >= 1 or 'auto', got " + s.shown());
      long long n = 0;
      try {
        n = s.node.as<long long>();
      } catch (const YAML::Exception&) {
        s.fail("expected an integer >= 1 or 'auto', got " + s.shown());
      }
      if (n < 1 || n > kMaxSamples)
        s.fail("expected an integer in [1, " + std::to_string(kMaxSamples) + "] or 'auto', got " + s.shown());
      d.samples = static_cast<int>(n);
    }
  } else {
    d.samples = 16;
  }
  if (job.has("sampling"))
    d.sampling = job.child("sampling").choice<Sampling>({{"uniform", Sampling::uniform},
                                                          {"gauss-legendre", Sampling::gauss_legendre},
                                                          {"visible-pdf", Sampling::visible_pdf},
                                                          {"inverse-square", Sampling::inverse_square}});
  if (job.has("cmf"))
    d.cmf = job.child("cmf").choice<CmfSet>({{"cie1931-2deg", CmfSet::cie1931_2deg},
                                              {"cie1964-10deg", CmfSet::cie1964_10deg},
                                              {"cie2006-2deg", CmfSet::cie2006_2deg},
                                              {"cie2006-10deg", CmfSet::cie2006_10deg}});
  const CmfTable& table = cmf_table(d.cmf);
  inputs.emplace_back(table.resource, sha256_hex(resource(table.resource)));
  if (job.has("range_nm")) d.range_nm = parse_range_nm(job.child("range_nm"), table.first_nm, table.last_nm);
  else if (d.range_nm.lo < table.first_nm)
    job.fail(std::string("range_nm must be given for ") + to_string(d.cmf) + " (its table starts at " +
             std::to_string(static_cast<int>(table.first_nm)) + " nm)");
  if (job.has("abbe_lines"))
    d.abbe_lines = job.child("abbe_lines").choice<AbbeLines>({{"d", AbbeLines::d}, {"D", AbbeLines::D}});
  if (job.has("tolerance_de2000")) d.tolerance_de2000 = job.child("tolerance_de2000").positive();
  if (job.has("spread")) d.spread = job.child("spread").number_in(1e-3, 1e3, "in [0.001, 1000]");
  nlohmann::json material_norm;
  if (!job.has("material")) job.fail("expected a 'material' key ({n_d, v_d}, {glass}, or {sellmeier})");
  d.material = parse_material(job.child("material"), material_norm, inputs);

  norm = {{"kind", "dispersion"},
          {"samples", d.samples ? nlohmann::json(*d.samples) : nlohmann::json("auto")},
          {"sampling", to_string(d.sampling)},
          {"range_nm", {d.range_nm.lo, d.range_nm.hi}},
          {"cmf", to_string(d.cmf)},
          {"material", material_norm},
          {"abbe_lines", to_string(d.abbe_lines)},
          {"tolerance_de2000", d.tolerance_de2000},
          {"spread", d.spread}};
  return d;
}

}  // namespace

Config parse_config(const std::string& text, const fs::path& file) {
  if (text.size() > kMaxConfigBytes)
    throw InputError({file, 0, 0, ""}, "config is " + std::to_string(text.size()) +
                                            " bytes; expected at most " + std::to_string(kMaxConfigBytes));
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    throw InputError({file, e.mark.line + 1, e.mark.column + 1, ""}, "malformed YAML: " + e.msg);
  }
  const At top{root, "", &file};
  if (!root.IsMap()) top.fail("expected a mapping with keys specbake, output, device, jobs");
  top.allow_keys({"specbake", "output", "device", "jobs"});

  Config cfg;
  cfg.file = file;
  if (!top.has("specbake")) top.fail("expected 'specbake: 1' (the schema version)");
  const At ver = top.child("specbake");
  if (ver.integer() != kSchemaVersion)
    ver.fail("unsupported schema version " + ver.shown() + "; this specbake reads version 1");
  if (top.has("output")) {
    const std::string out = top.child("output").string();
    if (out.empty()) top.child("output").fail("expected a folder path");
    cfg.output = file.parent_path() / out;
    cfg.output_given = true;
  } else {
    cfg.output = "assets";
  }
  if (top.has("device")) {
    cfg.device = top.child("device").string();
    if (cfg.device.empty()) top.child("device").fail("expected auto | cpu | gpu | part of a device name");
  }
  if (!top.has("jobs")) top.fail("expected a 'jobs' list");
  const At jobs = top.child("jobs");
  if (!jobs.node.IsSequence() || jobs.node.size() == 0) jobs.fail("expected a non-empty list of jobs");

  static const std::regex name_re("[a-z0-9][a-z0-9._-]*");
  std::map<std::string, Location> names;
  for (std::size_t i = 0; i < jobs.node.size(); ++i) {
    const At job = jobs.item(i);
    job.expect_map("a job");
    if (!job.has("name")) job.fail("expected a 'name'");
    if (!job.has("kind")) job.fail("expected a 'kind' (dispersion | diffraction | atmosphere)");
    const At name_at = job.child("name");
    JobSpec js;
    js.name = name_at.string();
    if (!std::regex_match(js.name, name_re) || js.name.size() > 100)
      name_at.fail("expected a job name matching [a-z0-9][a-z0-9._-]* (at most 100 characters), got " +
                   name_at.shown());
    if (auto it = names.find(js.name); it != names.end())
      name_at.fail("duplicate job name '" + js.name + "' (first used at " + it->second.str() + ")");
    names.emplace(js.name, name_at.loc());
    js.where = job.loc();
    const At kind_at = job.child("kind");
    js.kind = kind_at.string();
    if (js.kind == "dispersion") {
      js.spec = parse_dispersion(job, js.normalised, js.inputs);
    } else if (js.kind == "diffraction" || js.kind == "atmosphere") {
      kind_at.fail("job kind '" + js.kind + "' is not available in this version of specbake; available: dispersion");
    } else {
      kind_at.fail("expected kind dispersion | diffraction | atmosphere, got " + kind_at.shown());
    }
    cfg.jobs.push_back(std::move(js));
  }
  return cfg;
}

Config load_config(const fs::path& file) {
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) throw IoError("cannot read config " + file.string() + ": not a file");
  if (fs::file_size(file, ec) > kMaxConfigBytes)
    throw InputError({file, 0, 0, ""}, "config larger than " + std::to_string(kMaxConfigBytes) + " bytes");
  std::ifstream in(file, std::ios::binary);
  if (!in) throw IoError("cannot read config " + file.string());
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_config(ss.str(), file);
}

}  // namespace specbake
