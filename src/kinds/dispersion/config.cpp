#include <cmath>
#include <sstream>

#include "core/hash.hpp"
#include "core/resources.hpp"
#include "core/spectral_data.hpp"
#include "core/text.hpp"
#include "job/formats.hpp"
#include "kinds/dispersion/reference.hpp"
#include "kinds/dispersion/spec.hpp"

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
const char* to_string(AbbeLines l) { return l == AbbeLines::d ? "d" : "D"; }

namespace dispersion {

using yaml::At;

namespace {

RangeNm parse_range_nm(const At& at, double table_lo, double table_hi) {
  auto v = at.numbers(2, 2);
  std::ostringstream domain;
  domain << "[" << table_lo << ", " << table_hi << "]";
  if (!(v[0] < v[1])) at.fail("expected [lo, hi] with lo < hi (nm)");
  if (v[0] < table_lo || v[1] > table_hi)
    at.fail("expected a range inside the colour-matching table's " + domain.str() + " nm");
  return {v[0], v[1]};
}

// A transparent glass: n > 1 at the d line and normal dispersion (n_F > n_C) in the visible.
// C in nm² instead of µm² (10^6 too large) gives n ≈ 1 and a negative Abbe number.
void check_glass(const At& at, const Sellmeier& sm) {
  auto n_at = [&](double nm) {
    return ref::sellmeier_ior(sm.B.data(), sm.C.data(), static_cast<int>(sm.B.size()), nm);
  };
  const double n_d = n_at(587.5618), n_F = n_at(486.1327), n_C = n_at(656.2725);
  const double abbe = (n_d - 1.0) / (n_F - n_C);
  double c_min = sm.C[0];
  for (double c : sm.C) c_min = std::min(c_min, c);
  const std::string hint = c_min > 1000.0 ? "; C looks like nm² (every C > 1000): expected µm² (divide by 10^6)" : "";
  if (!(std::isfinite(n_d) && n_d > 1.01 && n_d < 5.0))
    at.fail("expected Sellmeier coefficients of a transparent glass, but they give n = " + format_g(n_d, 6) +
            " at 587.56 nm" + hint);
  if (!(std::isfinite(abbe) && abbe > 0.0 && abbe < 200.0))
    at.fail("expected normal dispersion in the visible (Abbe number in (0, 200)), but these coefficients give " +
            format_g(abbe) + hint);
}

Material parse_material(const At& at, nlohmann::json& norm, Inputs& inputs) {
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

}  // namespace

DispersionSpec parse_spec(const At& job, nlohmann::json& norm, Inputs& inputs) {
  allow_job_keys(job, {"samples", "sampling", "range_nm", "cmf", "material",
                  "abbe_lines", "tolerance_de2000", "spread", "formats"});
  DispersionSpec d;
  d.samples = job.has("samples") ? job.child("samples").count_or_auto(1, kMaxSamples) : std::optional<int>(16);
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
  if (d.material.kind == Material::Kind::sellmeier) {
    // n² has a pole at λ = √C_i: refuse a range that contains one (the index would be infinite).
    const At c = job.child("material").child("sellmeier").child("C");
    for (std::size_t i = 0; i < d.material.sellmeier->C.size(); ++i) {
      const double pole_nm = std::sqrt(d.material.sellmeier->C[i]) * 1000.0;
      if (pole_nm >= d.range_nm.lo && pole_nm <= d.range_nm.hi)
        c.item(i).fail("expected C_i (µm²) with its pole √C_i outside range_nm; C_i = " +
                       format_g(d.material.sellmeier->C[i]) + " puts it at " + format_g(pole_nm) + " nm");
    }
    check_glass(job.child("material").child("sellmeier"), *d.material.sellmeier);
  }

  norm = {{"kind", "dispersion"},
          {"samples", d.samples ? nlohmann::json(*d.samples) : nlohmann::json("auto")},
          {"sampling", to_string(d.sampling)},
          {"range_nm", {d.range_nm.lo, d.range_nm.hi}},
          {"cmf", to_string(d.cmf)},
          {"material", material_norm},
          {"abbe_lines", to_string(d.abbe_lines)},
          {"tolerance_de2000", d.tolerance_de2000},
          {"spread", d.spread}};
  const auto formats = parse_formats(job, {"bin", "json"}, {"bin", "json"}, norm);
  d.write_bin = formats.count("bin") > 0;
  d.write_json = formats.count("json") > 0;
  d.judge_de2000 = !d.samples || job.has("tolerance_de2000");
  if (d.samples && d.judge_de2000) norm["tolerance_de2000_judged"] = true;  // absent: as before, reported only
  return d;
}


}  // namespace dispersion
}  // namespace specbake
