#pragma once
// The typed spec of an atmosphere job (parsed in config.cpp; keys in docs/atmosphere.md).
#include <cstdint>
#include <optional>

#include "core/config.hpp"
#include "io/png.hpp"
#include "job/ktx2_output.hpp"
#include "media/media.hpp"

namespace specbake {

// What the user's scene needs of the sky (`scene:`): after every bake its points are path-traced
// and the LUTs judged against them (docs/atmosphere.md, "The scene check").
struct AtmosphereScene {
  bool check = true;  // `scene: none`: no check
  double camera_altitude_min_km = 0.0, camera_altitude_max_km = 2.0;
  double sun_elevation_min_deg = -6.0, sun_elevation_max_deg = 90.0;
  int views = 0;      // 0 sky, 1 ground, 2 all (TruthViews)
  double view_elevation_min_deg = -90.0, view_elevation_max_deg = 90.0;  // above the horizontal plane
  double view_sun_azimuth_min_deg = 0.0, view_sun_azimuth_max_deg = 180.0;  // between view and sun
  int points = 128;
  double relative_se = 0.01;  // the truth's standard error at each point, relative (top-ups until met)
  bool relative_se_given = false;  // set by the config (an auto search may halve the default)
  std::uint64_t seed = 1;
  std::optional<double> tolerance_de2000;    // judged on the p99 CIEDE2000 of the displayed colour
  std::optional<double> tolerance_relative;  // judged on the p99 relative radiance error (worst channel)
  // the colour error's exposure: nullopt per view (a renderer's auto exposure), else fixed at EV100
  std::optional<double> exposure_ev100;
};

// Geometry, sun, ground, the media (AtmosphereMedia) and what to bake.
struct AtmosphereSpec : KindSpec, AtmosphereMedia {
  double bottom_radius_km = 6360.0, top_radius_km = 6420.0;
  double sun_angular_radius_rad = 0.004675;
  double max_sun_zenith_deg = 102.0;
  bool max_sun_zenith_given = false;  // the config gave max_sun_zenith_deg (else a deep-twilight scene widens it)
  double ground_albedo = 0.1;
  double solar_irradiance_scale = 1.0;  // multiplies the ASTM G-173 spectrum (other planets' distance)
  bool spectral = false;                  // false: rgb (680, 550, 440 nm)
  double min_nm = 360.0, max_nm = 830.0;  // spectral: midpoints of `count` equal bins
  int count = 48;
  // spectral: `store: luminance` (Bruneton's precomputed luminance in R, G, B) or `radiance`: also
  // the radiance at every wavelength, four per RGBA texel (files spectral_*; sampling_spectral.glsl)
  bool store_radiance = false;
  std::optional<int> orders = 4;  // nullopt: auto
  bool orders_given = false;       // the config gave `orders:`; else the scene decides (kDeepTwilightOrders)
  // `orders_tail: geometric`: the orders beyond the last as a geometric series at every texel
  // (atmosphere.cl, geometric_tail; fixed orders ≥ kMinTailOrders); `none`: exactly the orders' sum.
  bool orders_tail = false;
  bool orders_tail_given = false;  // the config gave it; else the scene decides (config.cpp)
  double tolerance = 1e-3;
  int transmittance_mu = 256, transmittance_r = 64, irradiance_mu_s = 64, irradiance_r = 16;
  int scattering_r = 32, scattering_mu = 128, scattering_mu_s = 32, scattering_nu = 8;
  bool sizes_given = false;  // a `sizes:` key (any form); else the scene decides the μ_s count (config.cpp)
  // The bundle stores half the baked μ_s texels / ν slices (resampled): a twilight scene whose
  // sky-view table holds its views bakes kTwilightScatteringMuS (and, in deep twilight or with
  // thick aerosol, kTwilightScatteringNu) for its densities, but its 4D textures serve only the views
  // outside the scene's range, which the default counts hold (config.cpp).
  bool store_half_mu_s = false, store_half_nu = false;
  // `quadrature:` the scattering density's sphere rule: θ nodes (even), and whether they are
  // packed towards the horizon (default) or uniform as in the reference (docs/atmosphere.md).
  int density_theta = 16;
  bool density_horizon = true;
  bool density_theta_given = false;  // `quadrature: {density_theta}` (or `reference`); else the scene decides (config.cpp)
  // the view rays' 50-interval rule of single and multiple scattering: Simpson (default) or the
  // reference's trapezoid (`quadrature: {ray_rule}`)
  bool ray_simpson = true;
  // `quadrature: {phase_nu}`: the ν at which the multiple scattering is divided by P_R(ν) when it is
  // stored — the slice's own ν (default), or its ν clamped to the texel's feasible range as the
  // reference does (docs/atmosphere-method.md, "Daylight")
  bool phase_nu_slice = true;
  // `quadrature: {phase_weights}`: the scattering density's weights of the view's phase functions
  // divided by their sum over the sphere rule, per direction (default `normalised`), or as the rule
  // gives them (`plain`, the reference; docs/atmosphere-method.md, "The density's phase weights")
  bool phase_weights_normalised = true;
  bool mu_s_geometric = true;  // the scattering textures' μ_s lookups: geometric (default) or linear
  // `quadrature: reference`: the reference implementation's rules (16 uniform θ, plain phase
  // weights, linear μ_s lookups, trapezoid rays, clamped ν)
  void use_reference_quadrature() {
    density_theta = 16;
    density_theta_given = true;
    density_horizon = mu_s_geometric = ray_simpson = phase_nu_slice = phase_weights_normalised = false;
  }
  bool layout_3d = true, layout_tiled2d = false;
  bool out_transmittance = true, out_irradiance = true, out_scattering = true, out_single_mie = true;
  // File formats of the textures: .bin and .exr always; KTX2 (2D/3D RGBA textures engines load) on request.
  Ktx2Settings ktx2;
  bool write_bin = true, write_exr = true;  // `formats:` (with ktx2 above)
  bool ktx2_combined = false;  // ktx2: {scattering: rgba-combined}: single Mie red in scattering.ktx2's alpha
  bool double_precision = false;  // device arithmetic: float32 (default) or float64
  AtmosphereScene scene;
  int preview_size = 512;  // pixels per preview view; 0: `previews: none`
  ToneCurve preview_tone = ToneCurve::aces;  // the previews' tone curve (`previews: {tone}`)
  // `sizes: auto` / `spectrum: auto`: the cheapest sizes / channel count whose bake meets the
  // scene's tolerance against the path-traced truth (auto_settings.hpp).
  bool auto_sizes = false, auto_spectrum = false;
  // `sky_view:` the table of the sky in the viewer's frame over the scene's range (lookup.cl,
  // "The sky-view table"): auto (a scene whose sun sets; a config's default, set by parse_spec),
  // none (a spec built in code, unless it asks), or its node counts.
  enum class SkyViewMode { automatic, none, sized } sky_view = SkyViewMode::none;
  int sky_view_altitude = 0, sky_view_sun = 0, sky_view_view = 0, sky_view_azimuth = 0;  // sized (else derived)
};

// Texture size limits (config errors name them; searches stay inside them).
inline constexpr int kMaxAtmosphereAxis = 4096;
inline constexpr long long kMaxScatteringTexels = 1LL << 26;
// Scenes whose sun goes below the horizon get kTwilightScatteringMuS μ_s texels unless the config
// gives sizes; those whose sun goes below kDeepTwilightSunDeg (deep twilight), or whose aerosol
// is thick (kThickAerosolMieDepth), also kTwilightScatteringNu ν slices; deep twilight also gets
// kDeepTwilightDensityTheta θ nodes in the scattering density unless the config gives them
// (config.cpp, parse_checks). 15 slices: the 8 stored are every other one of them, unresampled.
inline constexpr double kDeepTwilightSunDeg = -6.0;
// A twilight scene whose aerosol scatters at least this vertical optical depth at 550 nm (thick
// aerosol: the hazy Earth of configs/hazy-earth.yaml 0.066, Mars 0.47; the default Earth
// 0.0048) bakes kTwilightScatteringNu ν slices too: its multiply scattered light keeps the
// aerosol's forward peak, which 8 slices do not resolve (docs/atmosphere.md, "Twilight").
inline constexpr double kThickAerosolMieDepth = 0.02;
inline constexpr int kDeepTwilightDensityTheta = 32;
// The fewest orders a geometric tail (`orders_tail`) starts after: the ratio of order 3's density
// to order 2's (whose light is single scattering, of another angular shape) is far from the ratio
// later orders settle to — a tail from order 3 is 1.5× to 30× too bright in deep twilight.
inline constexpr int kMinTailOrders = 4;
// ... and the fewest a twilight scene with thick aerosol (has_thick_aerosol) takes it after by
// default: its orders settle later — Mars' 4 orders + tail are further from 30 orders than 4
// alone (p99 relative 1.76 against 0.52), 6 + tail closer than 6 (0.14 against 0.20; the largest
// difference 0.4 % of the channel's maximum against 2.6 %).
inline constexpr int kMinTailOrdersThickAerosol = 6;
// A deep-twilight scene bakes this many orders unless the config gives `orders:` (with the
// geometric tail every twilight scene gets): in the planet's shadow the ratio of one order to the
// one before still falls from order 4 to 5, so a tail from order 4 overstates the blue there.
inline constexpr int kDeepTwilightOrders = 5;
inline constexpr int kTwilightScatteringMuS = 64;
inline constexpr int kTwilightScatteringNu = 15;
// The sky-view table (`sky_view: auto`): built for a scene whose sun goes below the horizon, over its
// camera altitudes and its sun elevations up to kSkyViewSunMaxDeg (above, the sky changes slowly
// with the sun and the 4D textures hold it well), with a node every kSkyViewSunStepDeg of sun
// elevation and every kSkyViewAltitudeStepKm of altitude (2 to kSkyViewMaxAltitudes; 1 for a single
// altitude), kSkyViewViews view zeniths (half above, half below the horizon) and kSkyViewAzimuths
// view–sun azimuths over [0°, 180°].
inline constexpr double kSkyViewSunMaxDeg = 10.0, kSkyViewSunStepDeg = 0.5, kSkyViewAltitudeStepKm = 0.25;
inline constexpr int kSkyViewMaxAltitudes = 9, kSkyViewViews = 64, kSkyViewAzimuths = 32;

namespace atmosphere {
// Every texture axis of a spec: transmittance [mu, r], irradiance [mu_s, r], scattering r, mu,
// mu_s, nu (the scattering mu count stays even).
inline constexpr int AtmosphereSpec::*const kSizeAxes[] = {
    &AtmosphereSpec::transmittance_mu, &AtmosphereSpec::transmittance_r, &AtmosphereSpec::irradiance_mu_s,
    &AtmosphereSpec::irradiance_r,     &AtmosphereSpec::scattering_r,    &AtmosphereSpec::scattering_mu,
    &AtmosphereSpec::scattering_mu_s,  &AtmosphereSpec::scattering_nu};
// Every axis times f, rounded (mu to an even count), at least 2; no limit checked.
void scale_sizes(AtmosphereSpec& s, double f);
// Whether the spec's scene reaches twilight (a scene check with its sun below the horizon), and
// deep twilight (below kDeepTwilightSunDeg).
bool reaches_twilight(const AtmosphereSpec& s);
// Whether the bake takes the orders beyond its last as a geometric tail: `orders_tail:
// geometric` with a fixed count (the config refuses the tail with `orders: auto`, so this is
// orders_tail itself for every parsed spec; the one test of it everywhere).
inline bool takes_geometric_tail(const AtmosphereSpec& s) { return s.orders_tail && s.orders.has_value(); }
// Whether its aerosol's vertical scattering optical depth at 550 nm is at least kThickAerosolMieDepth.
bool has_thick_aerosol(const AtmosphereSpec& s);
bool reaches_deep_twilight(const AtmosphereSpec& s);
// Every texture axis to the scene's default: AtmosphereSpec's, with kTwilightScatteringMuS μ_s
// texels where the scene reaches twilight and kTwilightScatteringNu ν slices where it reaches
// deep twilight or twilight with thick aerosol (what a config without `sizes:` bakes; where `sizes: auto` starts from, halved).
void set_scene_default_sizes(AtmosphereSpec& s);
// Each axis at most kMaxAtmosphereAxis, nu at most ATMOSPHERE_NU_LIMIT, the scattering texture at
// most kMaxScatteringTexels.
bool sizes_within_limits(const AtmosphereSpec& s);

// The widest angle around the planet's centre between a camera of the scene and a point of one of
// its view rays inside the atmosphere: the camera's angle to its horizon plus the top of the
// atmosphere's (deg). A ray's points see the sun up to that much lower than its camera does.
double scene_ray_reach_deg(const AtmosphereSpec& s);

// Reads a `kind: atmosphere` job entry: Bruneton's demo Earth with the entry's overrides.
AtmosphereSpec parse_spec(const yaml::At& job, nlohmann::json& norm, Inputs& inputs);
}  // namespace atmosphere

}  // namespace specbake
