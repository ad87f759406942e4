#include "media/media.hpp"

#include <regex>

namespace specbake {

using nlohmann::json;
using yaml::At;

namespace {
bool is_false(const At& at) { return at.node.IsScalar() && (at.node.Scalar() == "false" || at.node.Scalar() == "off"); }

// `density: [{width_km, exp_term, exp_scale_per_km, linear_term_per_km, constant_term}, ...]`,
// one layer (used everywhere) or two (the first below its width).
void parse_density(const At& at, DensityLayer* out) {
  if (!at.node.IsSequence() || at.node.size() < 1 || at.node.size() > 2)
    at.fail("expected a list of 1 or 2 density layers {width_km, exp_term, exp_scale_per_km, linear_term_per_km, "
            "constant_term}");
  DensityLayer layers[2]{};
  for (std::size_t i = 0; i < at.node.size(); ++i) {
    const At l = at.item(i);
    l.expect_map("a density layer");
    l.allow_keys({"width_km", "exp_term", "exp_scale_per_km", "linear_term_per_km", "constant_term"});
    DensityLayer d;
    if (l.has("width_km")) d.width_km = l.child("width_km").number_in(0.0, 1e4, "in [0, 10000] km");
    if (l.has("exp_term")) d.exp_term = l.child("exp_term").number();
    if (l.has("exp_scale_per_km")) d.exp_scale_per_km = l.child("exp_scale_per_km").number_in(-1e3, 1e3, "in [-1000, 1000]");
    if (l.has("linear_term_per_km")) d.linear_term_per_km = l.child("linear_term_per_km").number();
    if (l.has("constant_term")) d.constant_term = l.child("constant_term").number();
    layers[i] = d;
  }
  if (at.node.size() == 1) {
    out[0] = DensityLayer{};
    out[1] = layers[0];
  } else {
    out[0] = layers[0];
    out[1] = layers[1];
  }
}

}  // namespace

DensityLayer exponential_layer(double scale_height_km) {
  DensityLayer l;
  l.exp_term = 1.0;
  l.exp_scale_per_km = -1.0 / scale_height_km;
  return l;
}

void tent_layers(double a, double b, double c, DensityLayer* out) {
  out[0] = DensityLayer{b, 0.0, 0.0, 1.0 / (b - a), -a / (b - a)};
  out[1] = DensityLayer{0.0, 0.0, 0.0, -1.0 / (c - b), c / (c - b)};
}

void set_earth_profiles(AtmosphereMedia& m) {
  m.rayleigh_density[1] = exponential_layer(8.0);
  m.mie_density[1] = exponential_layer(1.2);
  tent_layers(10.0, 25.0, 40.0, m.ozone_density);
}

void parse_rayleigh(const At& at, AtmosphereMedia& s) {
  if (is_false(at)) {
    s.rayleigh = false;
    return;
  }
  at.expect_map("Rayleigh parameters {scale_height_km, scattering_per_m_at_1um, density} or false");
  at.allow_keys({"scale_height_km", "scattering_per_m_at_1um", "density"});
  if (at.has("scale_height_km") && at.has("density")) at.fail("expected scale_height_km or density, not both");
  if (at.has("scale_height_km")) s.rayleigh_density[1] = exponential_layer(at.child("scale_height_km").number_in(0.01, 1e3, "in [0.01, 1000] km"));
  if (at.has("density")) parse_density(at.child("density"), s.rayleigh_density);
  if (at.has("scattering_per_m_at_1um"))
    s.rayleigh_scattering_per_m_at_1um = at.child("scattering_per_m_at_1um").number_in(0.0, 1.0, "in [0, 1] per m");
}

void parse_mie(const At& at, AtmosphereMedia& s) {
  if (is_false(at)) {
    s.mie = false;
    return;
  }
  at.expect_map("Mie parameters {scale_height_km, extinction_per_m, angstrom_alpha, single_scattering_albedo, "
                "phase_g, density} or false");
  at.allow_keys({"scale_height_km", "extinction_per_m", "angstrom_alpha", "single_scattering_albedo", "phase_g",
                 "density"});
  if (at.has("scale_height_km") && at.has("density")) at.fail("expected scale_height_km or density, not both");
  if (at.has("scale_height_km")) s.mie_density[1] = exponential_layer(at.child("scale_height_km").number_in(0.01, 1e3, "in [0.01, 1000] km"));
  if (at.has("density")) parse_density(at.child("density"), s.mie_density);
  if (at.has("extinction_per_m")) s.mie_extinction_per_m = at.child("extinction_per_m").number_in(0.0, 1.0, "in [0, 1] per m");
  if (at.has("angstrom_alpha")) s.mie_angstrom_alpha = at.child("angstrom_alpha").number_in(-4.0, 4.0, "in [-4, 4]");
  if (at.has("single_scattering_albedo"))
    s.mie_single_scattering_albedo = at.child("single_scattering_albedo").number_in(0.0, 1.0, "in [0, 1]");
  if (at.has("phase_g")) s.mie_phase_g = at.child("phase_g").number_in(-0.999, 0.999, "in [-0.999, 0.999]");
}

void parse_ozone(const At& at, AtmosphereMedia& s) {
  if (is_false(at)) {
    s.ozone = false;
    return;
  }
  at.expect_map("ozone parameters {column_du, layer: tent-A-B-Ckm | density} or false");
  at.allow_keys({"column_du", "layer", "density"});
  if (at.has("layer") && at.has("density")) at.fail("expected layer or density, not both");
  if (at.has("column_du")) s.ozone_column_du = at.child("column_du").number_in(0.0, 1e4, "in [0, 10000] DU");
  if (at.has("layer")) {
    const At l = at.child("layer");
    static const std::regex re(R"(tent-([0-9.]+)-([0-9.]+)-([0-9.]+)km)");
    std::smatch m;
    const std::string v = l.node.IsScalar() ? l.node.Scalar() : "";
    if (!std::regex_match(v, m, re)) l.fail("expected tent-A-B-Ckm (0 below A, 1 at B, 0 above C), got " + l.shown());
    const double a = std::stod(m[1]), b = std::stod(m[2]), c = std::stod(m[3]);
    if (!(a < b && b < c)) l.fail("expected tent-A-B-Ckm with A < B < C");
    tent_layers(a, b, c, s.ozone_density);
  }
  if (at.has("density")) parse_density(at.child("density"), s.ozone_density);
}

json media_json(const AtmosphereMedia& s) {
  return {{"rayleigh", s.rayleigh ? json{{"scattering_per_m_at_1um", s.rayleigh_scattering_per_m_at_1um},
                                         {"density", density_profile_json(s.rayleigh_density)}}
                                  : json(false)},
          {"mie", s.mie ? json{{"extinction_per_m", s.mie_extinction_per_m},
                               {"angstrom_alpha", s.mie_angstrom_alpha},
                               {"single_scattering_albedo", s.mie_single_scattering_albedo},
                               {"phase_g", s.mie_phase_g},
                               {"density", density_profile_json(s.mie_density)}}
                        : json(false)},
          {"ozone", s.ozone ? json{{"column_du", s.ozone_column_du}, {"density", density_profile_json(s.ozone_density)}}
                            : json(false)}};
}

json density_profile_json(const DensityLayer* layers) {
  json out = json::array();
  for (int i = 0; i < 2; ++i)
    out.push_back({{"width_km", layers[i].width_km},
                   {"exp_term", layers[i].exp_term},
                   {"exp_scale_per_km", layers[i].exp_scale_per_km},
                   {"linear_term_per_km", layers[i].linear_term_per_km},
                   {"constant_term", layers[i].constant_term}});
  return out;
}

}  // namespace specbake
