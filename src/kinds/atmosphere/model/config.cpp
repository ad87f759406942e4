// Config of the atmosphere job kind: a preset (Bruneton's demo Earth) with overrides.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <regex>

#include "core/hash.hpp"
#include "core/resources.hpp"
#include "core/spectral_data.hpp"
#include "core/text.hpp"
#include "atmosphere/limits.h"
#include "kinds/atmosphere/model/model.hpp"
#include "kinds/atmosphere/model/scene.hpp"
#include "kinds/atmosphere/model/spec.hpp"

namespace specbake::atmosphere {

namespace {

using nlohmann::json;
using yaml::At;

constexpr int kMaxAxis = kMaxAtmosphereAxis;
constexpr int kMaxNu = ATMOSPHERE_NU_LIMIT;

int size_at(const At& at) {
  const long long v = at.integer();
  if (v < 2 || v > kMaxAxis) at.fail("expected an integer in [2, " + std::to_string(kMaxAxis) + "], got " + at.shown());
  return static_cast<int>(v);
}

// "P%" → P/100 with P in (0, 1000]; anything else fails naming what was expected.
double percent_at(const At& at) {
  static const std::regex re("([0-9]+(\\.[0-9]*)?)%");
  std::smatch m;
  const std::string text = at.node.IsScalar() ? at.node.Scalar() : "";
  if (!std::regex_match(text, m, re) || !(std::stod(m[1]) > 0.0) || std::stod(m[1]) > 1000.0)
    at.fail("expected auto, or a percentage of the sizes in (0%, 1000%], e.g. 150%, got " + at.shown());
  return std::stod(m[1]) / 100.0;
}

// Every axis times `f` (scale_sizes), checked like given sizes.
void scale_sizes_at(const At& at, double f, AtmosphereSpec& s) {
  scale_sizes(s, f);
  for (auto axis : kSizeAxes)
    if (s.*axis > kMaxAxis) at.fail("the scaled sizes exceed " + std::to_string(kMaxAxis) + " texels on an axis");
  if (s.scattering_nu > kMaxNu)
    at.fail("the scaled nu size " + std::to_string(s.scattering_nu) + " exceeds " + std::to_string(kMaxNu) +
            "; give scattering.nu explicitly");
  if (1LL * s.scattering_r * s.scattering_mu * s.scattering_mu_s * s.scattering_nu > kMaxScatteringTexels)
    at.fail("the scaled sizes exceed " + std::to_string(kMaxScatteringTexels) + " scattering texels");
}

void parse_sizes(const At& at, AtmosphereSpec& s) {
  s.sizes_given = true;
  if (at.node.IsScalar() && at.node.Scalar() == "auto") {  // searched against the scene (auto_settings.hpp)
    s.auto_sizes = true;
    return;
  }
  if (at.node.IsScalar()) {  // `sizes: 150%`: the default sizes scaled
    scale_sizes_at(at, percent_at(at), s);
    return;
  }
  at.expect_map("texture sizes: auto, a percentage of the defaults (e.g. 150%) or {scale, transmittance: [mu, r], "
                "irradiance: [mu_s, r], scattering: {r, mu, mu_s, nu}}");
  at.allow_keys({"scale", "transmittance", "irradiance", "scattering"});
  auto pair = [&](const char* key, int& a, int& b) {
    if (!at.has(key)) return;
    const At p = at.child(key);
    if (!p.node.IsSequence() || p.node.size() != 2) p.fail("expected a list of 2 integers [mu, r]");
    a = size_at(p.item(0));
    b = size_at(p.item(1));
  };
  pair("transmittance", s.transmittance_mu, s.transmittance_r);
  pair("irradiance", s.irradiance_mu_s, s.irradiance_r);
  if (at.has("scattering")) {
    const At sc = at.child("scattering");
    sc.expect_map("scattering sizes {r, mu, mu_s, nu}");
    sc.allow_keys({"r", "mu", "mu_s", "nu"});
    if (sc.has("r")) s.scattering_r = size_at(sc.child("r"));
    if (sc.has("mu")) {
      s.scattering_mu = size_at(sc.child("mu"));
      if (s.scattering_mu % 2) sc.child("mu").fail("expected an even mu size (half for rays that hit the ground, half for the others)");
    }
    if (sc.has("mu_s")) s.scattering_mu_s = size_at(sc.child("mu_s"));
    if (sc.has("nu")) {
      s.scattering_nu = size_at(sc.child("nu"));
      // the kernels keep one texel row of NU slices per channel in private arrays (NU_MAX)
      if (s.scattering_nu > kMaxNu)
        sc.child("nu").fail("expected a nu size of at most " + std::to_string(kMaxNu) + ", got " +
                            std::to_string(s.scattering_nu));
    }
    const long long texels = 1LL * s.scattering_r * s.scattering_mu * s.scattering_mu_s * s.scattering_nu;
    if (texels > kMaxScatteringTexels)
      sc.fail("expected at most " + std::to_string(kMaxScatteringTexels) + " scattering texels, got " +
              std::to_string(texels));
  }
  if (at.has("scale")) scale_sizes_at(at.child("scale"), percent_at(at.child("scale")), s);  // given or default, scaled
}

// `quadrature: reference | {density_theta, density_rule, phase_weights, mu_s_blend, ray_rule,
// phase_nu}` — the scattering density's sphere rule and its phase weights, the scattering textures'
// blend along μ_s, the view rays' rule and the ν of the stored multiple scattering's 1/P_R;
// `reference` is the reference implementation's (16 uniform θ, plain weights, linear, trapezoid,
// clamped ν).
void parse_quadrature(const At& at, AtmosphereSpec& s) {
  if (at.node.IsScalar()) {
    at.choice<int>({{"reference", 0}});
    s.use_reference_quadrature();
    return;
  }
  at.expect_map(
      "quadrature settings: reference, or {density_theta, density_rule, phase_weights, mu_s_blend, ray_rule, phase_nu}");
  at.allow_keys({"density_theta", "density_rule", "phase_weights", "mu_s_blend", "ray_rule", "phase_nu"});
  if (at.has("phase_weights"))
    s.phase_weights_normalised =
        at.child("phase_weights").choice<int>({{"normalised", 1}, {"plain", 0}}) == 1;
  if (at.has("phase_nu")) s.phase_nu_slice = at.child("phase_nu").choice<int>({{"slice", 1}, {"clamped", 0}}) == 1;
  if (at.has("ray_rule")) s.ray_simpson = at.child("ray_rule").choice<int>({{"simpson", 1}, {"trapezoid", 0}}) == 1;
  if (at.has("mu_s_blend"))
    s.mu_s_geometric = at.child("mu_s_blend").choice<int>({{"geometric", 1}, {"linear", 0}}) == 1;
  if (at.has("density_theta")) {
    const At n = at.child("density_theta");
    const long long v = n.integer();
    if (v < 4 || v > DENSITY_THETA_MAX || v % 2)
      n.fail("expected an even number of θ nodes in [4, " + std::to_string(DENSITY_THETA_MAX) + "], got " + n.shown());
    s.density_theta = static_cast<int>(v);
    s.density_theta_given = true;
  }
  if (at.has("density_rule"))
    s.density_horizon = at.child("density_rule").choice<int>({{"horizon", 1}, {"uniform", 0}}) == 1;
}

std::string shown_number(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

// `scene:` — none, or {camera_altitude_km, sun_elevation_deg, views, points, relative_se,
// seed, tolerance_de2000 | tolerance_relative}; a range is [min, max] or one number.
void parse_scene(const At& at, AtmosphereSpec& s) {
  AtmosphereScene& sc = s.scene;
  if (at.node.IsScalar()) {
    at.choice<int>({{"none", 0}});
    sc.check = false;
    return;
  }
  at.expect_map("a scene {camera_altitude_km, sun_elevation_deg, views, view_elevation_deg, points, relative_se, "
                "view_sun_azimuth_deg, seed, tolerance_de2000 | tolerance_relative} or none");
  at.allow_keys({"camera_altitude_km", "sun_elevation_deg", "views", "view_elevation_deg", "view_sun_azimuth_deg",
                 "points", "relative_se", "seed", "tolerance_de2000", "tolerance_relative", "exposure"});
  auto range = [](const At& r, double lo, double hi, const char* text, double& a, double& b) {
    if (r.node.IsScalar()) {
      a = b = r.number_in(lo, hi, text);
      return;
    }
    if (!r.node.IsSequence() || r.node.size() != 2) r.fail(std::string("expected [min, max] or one number ") + text);
    a = r.item(0).number_in(lo, hi, text);
    b = r.item(1).number_in(lo, hi, text);
    if (!(a <= b)) r.fail("expected min <= max, got " + r.shown());
  };
  if (at.has("camera_altitude_km"))
    range(at.child("camera_altitude_km"), 0.0, 1e5, "in [0, 100000] km", sc.camera_altitude_min_km,
          sc.camera_altitude_max_km);
  if (at.has("sun_elevation_deg")) {
    const At e = at.child("sun_elevation_deg");
    range(e, -90.0, 90.0, "in [-90, 90] degrees", sc.sun_elevation_min_deg, sc.sun_elevation_max_deg);
    // the LUTs hold sun zenith angles up to max_sun_zenith_deg; a scene below that is not baked
    const double lowest = 90.0 - s.max_sun_zenith_deg;
    if (sc.sun_elevation_min_deg < lowest - 1e-9)
      (e.node.IsSequence() ? e.item(0) : e).fail("expected sun elevations >= " + shown_number(lowest) + " degrees (90 - max_sun_zenith_deg, the " +
             "lowest sun the textures hold); raise max_sun_zenith_deg to " +
             shown_number(90.0 - sc.sun_elevation_min_deg) + " or more to bake a sun that low");
  }
  if (at.has("views")) sc.views = at.child("views").choice<int>({{"sky", 0}, {"ground", 1}, {"all", 2}});
  if (at.has("view_elevation_deg"))
    range(at.child("view_elevation_deg"), -90.0, 90.0, "in [-90, 90] degrees", sc.view_elevation_min_deg,
          sc.view_elevation_max_deg);
  if (at.has("view_sun_azimuth_deg"))
    range(at.child("view_sun_azimuth_deg"), 0.0, 180.0, "in [0, 180] degrees", sc.view_sun_azimuth_min_deg,
          sc.view_sun_azimuth_max_deg);
  if (at.has("points")) {
    const At n = at.child("points");
    const long long v = n.integer();
    if (v < 1 || v > 65536) n.fail("expected an integer in [1, 65536], got " + n.shown());
    sc.points = static_cast<int>(v);
  }
  if (at.has("relative_se")) {
    sc.relative_se = at.child("relative_se").number_in(1e-4, 0.5, "in [1e-4, 0.5]");
    sc.relative_se_given = true;
  }
  if (at.has("seed")) {
    const At n = at.child("seed");
    const long long v = n.integer();
    if (v < 0) n.fail("expected an integer >= 0, got " + n.shown());
    sc.seed = static_cast<std::uint64_t>(v);
  }
  if (at.has("exposure")) {  // per-view | {ev100: X}
    const At e = at.child("exposure");
    if (e.node.IsScalar()) {
      e.choice<int>({{"per-view", 0}});
    } else {
      e.expect_map("an exposure: per-view, or {ev100: X}");
      e.allow_keys({"ev100"});
      if (!e.has("ev100")) e.fail("expected {ev100: X} (a fixed exposure), or per-view");
      sc.exposure_ev100 = e.child("ev100").number_in(-30.0, 30.0, "in [-30, 30] (EV100)");
    }
  }
  if (at.has("tolerance_de2000") && at.has("tolerance_relative"))
    at.child("tolerance_relative").fail("expected one of tolerance_de2000 and tolerance_relative, not both");
  if (at.has("tolerance_de2000"))
    sc.tolerance_de2000 = at.child("tolerance_de2000").number_in(1e-3, 100.0, "in [0.001, 100] (CIEDE2000)");
  if (at.has("tolerance_relative"))
    sc.tolerance_relative = at.child("tolerance_relative").number_in(1e-4, 10.0, "in [1e-4, 10]");
  // every camera altitude must leave view directions in both the views and the elevation range
  try {
    (void)scene_points_of(s);
  } catch (const InputError&) {
    (at.has("view_elevation_deg") ? at.child("view_elevation_deg") : at)
        .fail("expected view elevations that meet the " + std::string(views_name(sc.views)) +
              " views from every camera altitude of the scene (inside the atmosphere the horizon dips below the "
              "horizontal plane by acos(bottom_radius / (bottom_radius + altitude)), 1.4 degrees at 2 km on "
              "Earth; above it only views that cross the atmosphere count, below acos(top_radius / (bottom_radius "
              "+ altitude)))");
  }
}

}  // namespace

void scale_sizes(AtmosphereSpec& s, double f) {
  for (auto axis : kSizeAxes) {
    const double x = s.*axis * f;
    s.*axis = axis == &AtmosphereSpec::scattering_mu ? 2 * std::max(1, static_cast<int>(std::lround(x / 2.0)))
                                                     : std::max(2, static_cast<int>(std::lround(x)));
  }
}

bool reaches_twilight(const AtmosphereSpec& s) { return s.scene.check && s.scene.sun_elevation_min_deg < 0.0; }

bool has_thick_aerosol(const AtmosphereSpec& s) { return mie_vertical_scattering_depth(s, 550.0) >= kThickAerosolMieDepth; }

bool reaches_deep_twilight(const AtmosphereSpec& s) {
  return s.scene.check && s.scene.sun_elevation_min_deg < kDeepTwilightSunDeg;
}

void set_scene_default_sizes(AtmosphereSpec& s) {
  for (auto axis : kSizeAxes) s.*axis = AtmosphereSpec{}.*axis;
  const bool twilight = reaches_twilight(s);
  const bool fine_nu = reaches_deep_twilight(s) || (twilight && has_thick_aerosol(s));
  if (twilight) s.scattering_mu_s = kTwilightScatteringMuS;
  if (fine_nu) s.scattering_nu = kTwilightScatteringNu;
  const bool stored_apart = sky_view_of(s).on() && !s.store_radiance;
  s.store_half_mu_s = stored_apart && twilight;
  s.store_half_nu = stored_apart && fine_nu;
}

double scene_ray_reach_deg(const AtmosphereSpec& s) {
  const double top = s.top_radius_km, bottom = s.bottom_radius_km;
  const double camera = bottom + std::min(std::max(s.scene.camera_altitude_max_km, 0.0), top - bottom);
  return (std::acos(bottom / top) + std::acos(bottom / camera)) * 180.0 / M_PI;
}

bool sizes_within_limits(const AtmosphereSpec& s) {
  for (auto axis : kSizeAxes)
    if (s.*axis > kMaxAxis) return false;
  return s.scattering_nu <= kMaxNu &&
         1LL * s.scattering_r * s.scattering_mu * s.scattering_mu_s * s.scattering_nu <= kMaxScatteringTexels;
}

namespace {

// The planet: the preset, geometry, sun, ground and media (rayleigh, mie, ozone).
void parse_planet(const At& job, AtmosphereSpec& s) {
  if (job.has("preset")) job.child("preset").choice<int>({{"earth", 0}});
  set_earth_profiles(s);

  if (job.has("bottom_radius_km")) s.bottom_radius_km = job.child("bottom_radius_km").number_in(1.0, 1e6, "in [1, 1e6] km");
  if (job.has("top_radius_km")) s.top_radius_km = job.child("top_radius_km").number_in(1.0, 1e6, "in [1, 1e6] km");
  if (!(s.top_radius_km > s.bottom_radius_km))
    (job.has("top_radius_km") ? job.child("top_radius_km") : job.child("bottom_radius_km"))
        .fail("expected top_radius_km > bottom_radius_km (" + format_g(s.bottom_radius_km, 6) + ")");
  if (job.has("sun_angular_radius_rad"))
    s.sun_angular_radius_rad = job.child("sun_angular_radius_rad").number_in(1e-6, 0.1, "in [1e-6, 0.1] rad");
  if (job.has("max_sun_zenith_deg")) {
    s.max_sun_zenith_deg = job.child("max_sun_zenith_deg").number_in(90.5, 180.0, "in [90.5, 180] deg");
    s.max_sun_zenith_given = true;
  }
  if (job.has("ground_albedo")) s.ground_albedo = job.child("ground_albedo").number_in(0.0, 1.0, "in [0, 1]");
  if (job.has("solar_irradiance_scale"))
    s.solar_irradiance_scale = job.child("solar_irradiance_scale").number_in(0.0, 1e3, "in [0, 1000]");
  if (job.has("rayleigh")) parse_rayleigh(job.child("rayleigh"), s);
  if (job.has("mie")) parse_mie(job.child("mie"), s);
  if (job.has("ozone")) parse_ozone(job.child("ozone"), s);
}

// `spectrum:` rgb, auto, or {min_nm, max_nm, count, store}.
void parse_spectrum(const At& sp, AtmosphereSpec& s) {
  if (sp.node.IsScalar()) {
    s.auto_spectrum = sp.choice<int>({{"rgb", 0}, {"auto", 1}}) == 1;
    return;
  }
  sp.expect_map("rgb or {min_nm, max_nm, count, store}");
  sp.allow_keys({"min_nm", "max_nm", "count", "store"});
  s.spectral = true;
  if (sp.has("min_nm")) s.min_nm = sp.child("min_nm").number_in(360.0, 830.0, "in [360, 830] nm");
  if (sp.has("max_nm")) s.max_nm = sp.child("max_nm").number_in(360.0, 830.0, "in [360, 830] nm");
  if (!(s.min_nm < s.max_nm)) sp.fail("expected min_nm < max_nm");
  if (sp.has("count")) {
    const long long n = sp.child("count").integer();
    if (n < 3 || n > 256) sp.child("count").fail("expected an integer in [3, 256], got " + sp.child("count").shown());
    s.count = static_cast<int>(n);
  }
  if (sp.has("store"))
    s.store_radiance = sp.child("store").choice<int>({{"luminance", 0}, {"radiance", 1}}) == 1;
  if (s.store_radiance && s.count % 4 != 0)
    (sp.has("count") ? sp.child("count") : sp.child("store"))
        .fail("expected a count that is a multiple of 4 with store: radiance (four wavelengths per RGBA "
              "texel), got " + std::to_string(s.count));
}

// `orders:` a count in [1, 64], or auto (nullopt).
std::optional<int> parse_orders(const At& o) {
  if (o.node.IsScalar() && o.node.Scalar() == "auto") return std::nullopt;
  long long n = 0;
  try {
    n = o.node.IsScalar() ? o.node.as<long long>() : 0;
  } catch (const YAML::Exception&) {
    n = 0;
  }
  if (n < 1 || n > 64) o.fail("expected an integer in [1, 64] or 'auto', got " + o.shown());
  return static_cast<int>(n);
}

// `outputs:` the textures to ship (single Mie only with mie).
void parse_outputs(const At& job, AtmosphereSpec& s) {
  if (job.has("outputs")) {
    s.out_transmittance = s.out_irradiance = s.out_scattering = s.out_single_mie = false;
    job.child("outputs").each_item("outputs", [&](const At& it) {
      switch (it.choice<int>({{"transmittance", 0}, {"irradiance", 1}, {"scattering", 2}, {"single_mie_scattering", 3}})) {
        case 0: s.out_transmittance = true; break;
        case 1: s.out_irradiance = true; break;
        case 2: s.out_scattering = true; break;
        default:
          if (!s.mie)
            it.fail("expected no single_mie_scattering output when mie is false (it would be all zeros); remove it "
                    "from outputs or give mie parameters");
          s.out_single_mie = true;
          break;
      }
    });
  } else if (!s.mie) {
    s.out_single_mie = false;  // nothing to store: the default outputs leave it out
  }
}

// What to bake and how: spectrum, orders, tolerance, sizes, quadrature, layouts, outputs, precision.
void parse_bake(const At& job, AtmosphereSpec& s) {
  if (job.has("spectrum")) parse_spectrum(job.child("spectrum"), s);
  if (job.has("orders")) {
    s.orders = parse_orders(job.child("orders"));
    s.orders_given = true;
  }
  if (job.has("orders_tail")) {
    const At t = job.child("orders_tail");
    s.orders_tail = t.choice<int>({{"none", 0}, {"geometric", 1}}) == 1;
    s.orders_tail_given = true;
    if (s.orders_tail && !(s.orders && *s.orders >= kMinTailOrders))
      t.fail("expected orders_tail: geometric with a fixed count of at least " + std::to_string(kMinTailOrders) +
             " orders (the series' ratio is the last two orders' densities; orders: auto adds orders until they "
             "converge), got orders: " +
             (s.orders ? std::to_string(*s.orders) : std::string("auto")));
  }
  if (job.has("tolerance")) s.tolerance = job.child("tolerance").number_in(1e-8, 0.5, "in [1e-8, 0.5]");
  if (job.has("sizes")) parse_sizes(job.child("sizes"), s);
  if (job.has("quadrature")) parse_quadrature(job.child("quadrature"), s);
  if (job.has("layout")) {
    s.layout_3d = s.layout_tiled2d = false;
    job.child("layout").each_item("layouts (3d, tiled2d)", [&](const At& it) {
      const int v = it.choice<int>({{"3d", 0}, {"tiled2d", 1}});
      (v == 0 ? s.layout_3d : s.layout_tiled2d) = true;
    });
  }
  parse_outputs(job, s);
  if (job.has("precision"))
    s.double_precision = job.child("precision").choice<int>({{"float", 0}, {"double", 1}}) == 1;
}

// The scene, and the tolerance the searches judge by (after the bake's keys: the scene's lowest
// sun defaults to what the textures hold). Unless the config gives sizes, a scene whose sun goes
// below the horizon bakes 64 μ_s texels: the default 32 lie 1.3–1.9° of sun elevation apart there,
// where the sky falls by about e per degree, and the orders ≥ 2 computed from them come out up to
// 2.8× too bright below −8° (measured against an independent quadrature: docs/atmosphere.md,
// "Twilight"); at sun −6…0° over hazy Earth they were the largest part of the error (p99 ΔE 5.8 →
// 3.4 with 64). In deep twilight (sun below −6°) it also bakes 15 ν slices, and gets the density's
// horizon rule with 32 θ nodes unless the config gives the count: there the light of orders ≥ 2
// arrives within a few degrees of the horizontal, and 16 nodes leave it unconverged. A twilight
// scene with thick aerosol (has_thick_aerosol) bakes 15 ν slices too: the hazy Earth's sun 0…10°
// band p99 2.28 → 0.73, where the default Earth's does not move (0.89). Where the
// sky-view table holds the scene's views the bundle stores the default counts (set_scene_default_sizes).
// Scenes whose sun stays up keep 16, 32 and 8, which they do not need more of.
// Such a scene's textures also hold the suns its view rays' points see (unless the config gives
// max_sun_zenith_deg): a point up to scene_ray_reach_deg around the planet from the camera sees
// the sun that much lower, and a lookup below the textures' lowest sun reads that sun's brighter
// light (cameras at 0–2 km, the sun 12° down: the textures go to 111.3° instead of 102°).
void parse_checks(const At& job, AtmosphereSpec& s) {
  s.scene.sun_elevation_min_deg = std::max(s.scene.sun_elevation_min_deg, 90.0 - s.max_sun_zenith_deg);
  if (job.has("scene")) parse_scene(job.child("scene"), s);
  if (!s.max_sun_zenith_given && reaches_deep_twilight(s))
    s.max_sun_zenith_deg = std::max(s.max_sun_zenith_deg,
                                    std::min(180.0, 90.0 - s.scene.sun_elevation_min_deg + scene_ray_reach_deg(s)));
  if (!s.density_theta_given && s.density_horizon && reaches_deep_twilight(s))
    s.density_theta = kDeepTwilightDensityTheta;
  if (!s.sizes_given) set_scene_default_sizes(s);
  // Below the horizon the light that reaches the shadow has scattered many times: the default
  // Earth's orders beyond 4 are the largest part of its error at sun −12…0° (p99 1.6 ΔE). A
  // geometric tail from the last two orders stands for them for one more indirect irradiance,
  // and in deep twilight from order 5 (unless the config gives orders) it is within 0.2 % of 13
  // orders at every scene point (docs/atmosphere-method.md, "The orders beyond the last"); daylight
  // scenes keep the exact sum.
  // Thick aerosol keeps scattering its light forwards order after order: in Mars' twilight orders
  // ≥ 3 carry most of the light and 4 orders leave p99 11.8 ΔE (order truncation alone, sun
  // −6…10°); such a scene bakes kMinTailOrdersThickAerosol orders, whose tail is then in effect.
  if (!s.orders_given && reaches_twilight(s) && has_thick_aerosol(s)) s.orders = kMinTailOrdersThickAerosol;
  else if (!s.orders_given && reaches_deep_twilight(s)) s.orders = kDeepTwilightOrders;
  if (!s.orders_tail_given)
    s.orders_tail = s.orders && reaches_twilight(s) &&
                    *s.orders >= (has_thick_aerosol(s) ? kMinTailOrdersThickAerosol : kMinTailOrders);
  // the searches judge bakes by the scene's tolerance
  const char* no_tolerance = " searches for the cheapest bake that meets the scene's tolerance against the "
                             "path-traced truth; expected a scene with tolerance_de2000";
  if (s.auto_sizes && (!s.scene.check || (!s.scene.tolerance_de2000 && !s.scene.tolerance_relative)))
    job.child("sizes").fail(std::string("sizes: auto") + no_tolerance + " (or tolerance_relative)");
  if (s.auto_spectrum && (!s.scene.check || !s.scene.tolerance_de2000))
    job.child("spectrum").fail(std::string("spectrum: auto") + no_tolerance +
                               " (the spectral part of the error is a colour difference)");
}

// `sky_view: auto | none | {altitude: N, sun: N, view: N, azimuth: N}` (node counts; view even).
void parse_sky_view(const At& v, AtmosphereSpec& s) {
  if (v.node.IsScalar()) {
    s.sky_view = v.choice<AtmosphereSpec::SkyViewMode>(
        {{"auto", AtmosphereSpec::SkyViewMode::automatic}, {"none", AtmosphereSpec::SkyViewMode::none}});
    return;
  }
  v.expect_map("sky_view: auto, none, or {altitude: N, sun: N, view: N, azimuth: N} (node counts of the table in "
               "the viewer's frame)");
  v.allow_keys({"altitude", "sun", "view", "azimuth"});
  s.sky_view = AtmosphereSpec::SkyViewMode::sized;
  const auto count = [&](const char* key, int lo, int hi, int fallback, bool even) {
    if (!v.has(key)) return fallback;
    const At n = v.child(key);
    const long long x = n.integer();
    if (x < lo || x > hi || (even && x % 2))
      n.fail("expected " + std::string(even ? "an even number" : "a number") + " of nodes in [" + std::to_string(lo) +
             ", " + std::to_string(hi) + "], got " + n.shown());
    return static_cast<int>(x);
  };
  s.sky_view_altitude = count("altitude", 1, 64, 4, false);
  s.sky_view_sun = count("sun", 1, 1024, 33, false);
  s.sky_view_view = count("view", 4, 1024, kSkyViewViews, true);
  s.sky_view_azimuth = count("azimuth", 2, 1024, kSkyViewAzimuths, false);
}

// `previews: none` or `previews: {size: N, tone: aces | linear}`.
void parse_previews(const At& p, AtmosphereSpec& s) {
  if (p.node.IsScalar() && p.node.Scalar() == "none") {
    s.preview_size = 0;
    return;
  }
  p.expect_map("previews: none, or {size: N, tone: aces | linear} (pixels per view, an even number in [32, 2048])");
  p.allow_keys({"size", "tone"});
  if (p.has("size")) {
    const At n = p.child("size");
    const long long v = n.integer();
    if (v < 32 || v > 2048 || v % 2) n.fail("expected an even number of pixels in [32, 2048], got " + n.shown());
    s.preview_size = static_cast<int>(v);
  }
  if (p.has("tone"))
    s.preview_tone = p.child("tone").choice<ToneCurve>({{"aces", ToneCurve::aces}, {"linear", ToneCurve::linear}});
}

// `formats:` / `ktx2:` (into norm as well), and `ktx2: {scattering: rgba-combined}`.
void parse_ktx2(const At& job, AtmosphereSpec& s, json& norm) {
  const TextureFormats f = parse_texture_formats(job, norm, {"scattering"});
  s.ktx2 = f.ktx2;
  s.write_bin = f.bin;
  s.write_exr = f.exr;
  if (s.ktx2.enabled && job.has("ktx2") && job.child("ktx2").has("scattering")) {
    const At k = job.child("ktx2").child("scattering");
    s.ktx2_combined = k.choice<int>({{"rgb", 0}, {"rgba-combined", 1}}) == 1;
    if (s.ktx2_combined && !(s.out_scattering && s.out_single_mie))
      k.fail("expected rgba-combined only with both scattering and single_mie_scattering in outputs (it packs "
             "single Mie's red into the scattering texture's alpha)");
    if (s.ktx2_combined && !s.write_bin && !s.write_exr)
      k.fail("expected bin or exr in formats with rgba-combined: single Mie's green and blue are kept only "
             "there (the combined KTX2 holds its red alone)");
    if (s.ktx2_combined) norm["ktx2"]["scattering"] = "rgba-combined";  // rgb, the default, stays implicit
  }
}

// The entry as the config normalises it (the job's hash, the manifest), but for formats and ktx2.
json normalised_json(const AtmosphereSpec& s) {
  json layouts = json::array(), outputs = json::array();
  if (s.layout_3d) layouts.push_back("3d");
  if (s.layout_tiled2d) layouts.push_back("tiled2d");
  if (s.out_transmittance) outputs.push_back("transmittance");
  if (s.out_irradiance) outputs.push_back("irradiance");
  if (s.out_scattering) outputs.push_back("scattering");
  if (s.out_single_mie) outputs.push_back("single_mie_scattering");
  json norm = {{"kind", "atmosphere"},
               {"bottom_radius_km", s.bottom_radius_km},
               {"top_radius_km", s.top_radius_km},
               {"sun_angular_radius_rad", s.sun_angular_radius_rad},
               {"max_sun_zenith_deg", s.max_sun_zenith_deg},
               {"ground_albedo", s.ground_albedo},
               {"solar_irradiance_scale", s.solar_irradiance_scale},
               {"spectrum", s.auto_spectrum ? json("auto")
                            : s.spectral   ? json{{"min_nm", s.min_nm}, {"max_nm", s.max_nm}, {"count", s.count}}
                                           : json("rgb")},
               {"orders", s.orders ? json(*s.orders) : json("auto")},
               {"orders_tail", takes_geometric_tail(s) ? "geometric" : "none"},
               {"tolerance", s.tolerance},
               {"sizes", {{"transmittance", {s.transmittance_mu, s.transmittance_r}},
                          {"irradiance", {s.irradiance_mu_s, s.irradiance_r}},
                          {"scattering", {{"r", s.scattering_r}, {"mu", s.scattering_mu}, {"mu_s", s.scattering_mu_s},
                                          {"nu", s.scattering_nu}}}}},
               {"quadrature", {{"density_theta", s.density_theta},
                               {"density_rule", s.density_horizon ? "horizon" : "uniform"},
                               {"phase_weights", s.phase_weights_normalised ? "normalised" : "plain"},
                               {"mu_s_blend", s.mu_s_geometric ? "geometric" : "linear"},
                               {"ray_rule", s.ray_simpson ? "simpson" : "trapezoid"},
                               {"phase_nu", s.phase_nu_slice ? "slice" : "clamped"}}},
               {"layout", layouts},
               {"outputs", outputs},
               {"precision", s.double_precision ? "double" : "float"}};
  if (s.auto_sizes) norm["sizes"] = "auto";
  if (s.store_radiance) norm["spectrum"]["store"] = "radiance";  // luminance, the default, stays implicit
  norm["scene"] = scene_json(s.scene);
  if (s.sky_view == AtmosphereSpec::SkyViewMode::none) norm["sky_view"] = "none";  // auto stays implicit
  if (s.sky_view == AtmosphereSpec::SkyViewMode::sized)
    norm["sky_view"] = {{"altitude", s.sky_view_altitude}, {"sun", s.sky_view_sun}, {"view", s.sky_view_view},
                        {"azimuth", s.sky_view_azimuth}};
  norm["previews"] = s.preview_size ? json{{"size", s.preview_size}, {"tone", name(s.preview_tone)}} : json("none");
  norm.update(media_json(s));
  return norm;
}

}  // namespace

AtmosphereSpec parse_spec(const At& job, nlohmann::json& norm, Inputs& inputs) {
  allow_job_keys(job, {"preset", "bottom_radius_km", "top_radius_km", "sun_angular_radius_rad",
                  "max_sun_zenith_deg", "ground_albedo", "solar_irradiance_scale", "rayleigh", "mie", "ozone",
                  "spectrum", "orders", "orders_tail", "tolerance", "sizes", "layout", "outputs", "precision", "formats",
                  "ktx2", "scene", "previews", "quadrature", "sky_view"});
  AtmosphereSpec s;  // the struct's defaults are the earth preset's scalars
  s.sky_view = AtmosphereSpec::SkyViewMode::automatic;  // a config's default (`sky_view: auto`)
  parse_planet(job, s);
  parse_bake(job, s);
  if (job.has("sky_view")) parse_sky_view(job.child("sky_view"), s);
  parse_checks(job, s);
  if (job.has("previews")) parse_previews(job.child("previews"), s);
  // The CIE 1931 table converts spectra (and gives the render-time luminance factors).
  const CmfTable& cmf = cmf_table(CmfSet::cie1931_2deg);
  inputs.emplace_back(cmf.resource, sha256_hex(resource(cmf.resource)));
  norm = normalised_json(s);
  parse_ktx2(job, s, norm);
  return s;
}

}  // namespace specbake::atmosphere
