#include "kinds/atmosphere/model/model.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/colour_space.hpp"
#include "core/spectral_data.hpp"
#include "kinds/atmosphere/model/kernel_maths.hpp"

namespace specbake::atmosphere {

namespace {

// The profiles' maths (atmosphere.cl's profile_density) in double.
namespace maths {
SPECBAKE_ATMOSPHERE_REF_PROLOGUE
#define NCH 3
#include "atmosphere/atmosphere.cl"
#undef NCH
}  // namespace maths

// Provenance: the bin means published with E. Bruneton's precomputed_atmospheric_scattering
// demo (atmosphere/demo/demo.cc): the ASTM G-173 extraterrestrial spectrum averaged over each
// 10 nm bin [λ, λ + 10), and the 233 K ozone absorption cross-sections of the University of
// Bremen IUP reference spectra (Serdyuchenko et al. 2014) averaged the same way.
constexpr double kFirstNm = 360.0, kStepNm = 10.0;
constexpr double kSolar[48] = {
    1.11776, 1.14259, 1.01249, 1.14716, 1.72765, 1.73054, 1.6887,  1.61253, 1.91198, 2.03474, 2.02042, 2.02212,
    1.93377, 1.95809, 1.91686, 1.8298,  1.8685,  1.8931,  1.85149, 1.8504,  1.8341,  1.8345,  1.8147,  1.78158,
    1.7533,  1.6965,  1.68194, 1.64654, 1.6048,  1.52143, 1.55622, 1.5113,  1.474,   1.4482,  1.41018, 1.36775,
    1.34188, 1.31429, 1.28303, 1.26758, 1.2367,  1.2082,  1.18737, 1.14683, 1.12362, 1.1058,  1.07124, 1.04992};
constexpr double kOzone[48] = {
    1.18e-27,  2.182e-28, 2.818e-28, 6.636e-28, 1.527e-27, 2.763e-27, 5.52e-27,  8.451e-27, 1.582e-26, 2.316e-26,
    3.669e-26, 4.924e-26, 7.752e-26, 9.016e-26, 1.48e-25,  1.602e-25, 2.139e-25, 2.755e-25, 3.091e-25, 3.5e-25,
    4.266e-25, 4.672e-25, 4.398e-25, 4.701e-25, 5.019e-25, 4.305e-25, 3.74e-25,  3.215e-25, 2.662e-25, 2.238e-25,
    1.852e-25, 1.473e-25, 1.209e-25, 9.423e-26, 7.455e-26, 6.566e-26, 5.105e-26, 4.15e-26,  4.228e-26, 3.237e-26,
    2.451e-26, 2.801e-26, 2.534e-26, 1.624e-26, 1.465e-26, 2.078e-26, 1.383e-26, 7.105e-27};

double table_at(const double* t, double nm) {
  const double x = (nm - kFirstNm) / kStepNm;
  if (x <= 0.0) return t[0];
  if (x >= 47.0) return t[47];
  const int i = static_cast<int>(std::floor(x));
  const double f = x - i;
  return t[i] * (1.0 - f) + t[i + 1] * f;
}

// ∫ profile dh over the atmosphere (km), trapezoid at 1 m steps (exact for piecewise-linear
// profiles whose kinks sit on whole metres, such as the ozone tent).
double profile_column_km(const DensityLayer* layers, double thickness_km) {
  maths::DensityProfile p;
  fill_profile(p, layers);
  const long n = std::max(1L, std::lround(thickness_km * 1000.0));
  const double dh = thickness_km / static_cast<double>(n);
  double s = 0.0;
  for (long i = 0; i <= n; ++i) {
    const double h = i * dh;
    const double y = maths::profile_density(&p, h);
    s += (i == 0 || i == n) ? 0.5 * y : y;
  }
  return s * dh;
}

// The GPU model's radiance → luminance factors: Σ_λ (M·CMF(λ))_c E(λ)/E(λ_c) (λ/λ_c)^p · 683,
// over 1 nm steps 360..829 nm.
std::array<double, 3> radiance_to_luminance(double lambda_power, double solar_scale) {
  const CmfTable& cmf = cmf_table(CmfSet::cie1931_2deg);
  const Mat3 M = xyz_to_srgb();
  const double lc[3] = {kLambdaR, kLambdaG, kLambdaB};
  std::array<double, 3> k{};
  for (int l = 360; l < 830; ++l) {
    const auto xyz = cmf.at(l);
    const double e = solar_irradiance_at(l) * solar_scale;
    for (int c = 0; c < 3; ++c) {
      const double bar = M[3 * c] * xyz[0] + M[3 * c + 1] * xyz[1] + M[3 * c + 2] * xyz[2];
      k[c] += bar * e / (solar_irradiance_at(lc[c]) * solar_scale) * std::pow(l / lc[c], lambda_power);
    }
  }
  for (double& v : k) v *= kMaxLuminousEfficacy;
  return k;
}

}  // namespace

double solar_irradiance_at(double nm) { return table_at(kSolar, nm); }
double ozone_cross_section_at(double nm) { return table_at(kOzone, nm); }

std::string spectra_table_text() {
  std::string s = "nm,solar_irradiance_W_m2_nm,ozone_cross_section_m2\n";
  char buf[96];
  for (int i = 0; i < 48; ++i) {
    std::snprintf(buf, sizeof buf, "%g,%.17g,%.17g\n", kFirstNm + kStepNm * i, kSolar[i], kOzone[i]);
    s += buf;
  }
  return s;
}

Sizes sizes_of(const AtmosphereSpec& s) {
  Sizes z;
  z.transmittance_w = s.transmittance_mu;
  z.transmittance_h = s.transmittance_r;
  z.irradiance_w = s.irradiance_mu_s;
  z.irradiance_h = s.irradiance_r;
  z.r = s.scattering_r;
  z.mu = s.scattering_mu;
  z.mu_s = s.scattering_mu_s;
  z.nu = s.scattering_nu;
  return z;
}

SkyView sky_view_of(const AtmosphereSpec& s) {
  SkyView v;
  const AtmosphereScene& sc = s.scene;
  const double thickness = s.top_radius_km - s.bottom_radius_km;
  if (s.sky_view == AtmosphereSpec::SkyViewMode::none || !sc.check || sc.sun_elevation_min_deg >= 0.0 ||
      sc.camera_altitude_min_km > thickness)
    return v;
  v.altitude_min_km = sc.camera_altitude_min_km;
  v.altitude_max_km = std::min(sc.camera_altitude_max_km, thickness);
  // where the density falls by e per degree of the local sun and the rays' far points see suns
  // below the camera's (docs/atmosphere-method.md, "Deep twilight: the sky-view table's density
  // reads"); above −6° the linear reads cost less and lose little (−6…0°: p99 1.36 → 1.22 ΔE of
  // the textures' part, for 1.6× (rgb) to 3.5× (16 wavelengths) the table's time)
  v.geometric_density = s.mu_s_geometric && reaches_deep_twilight(s);
  v.sun_min_deg = sc.sun_elevation_min_deg;
  v.sun_max_deg = std::max(std::min(sc.sun_elevation_max_deg, kSkyViewSunMaxDeg), v.sun_min_deg);
  const auto nodes = [](double range, double step, int most) {
    return range > 0.0 ? std::clamp(1 + static_cast<int>(std::ceil(range / step - 1e-9)), 2, most) : 1;
  };
  if (s.sky_view == AtmosphereSpec::SkyViewMode::sized) {
    v.altitude = s.sky_view_altitude;
    v.sun = s.sky_view_sun;
    v.view = s.sky_view_view;
    v.azimuth = s.sky_view_azimuth;
  } else {
    v.altitude = nodes(v.altitude_max_km - v.altitude_min_km, kSkyViewAltitudeStepKm, kSkyViewMaxAltitudes);
    v.sun = nodes(v.sun_max_deg - v.sun_min_deg, kSkyViewSunStepDeg, 1 << 10);
    v.view = kSkyViewViews;
    v.azimuth = kSkyViewAzimuths;
  }
  if (v.altitude_max_km <= v.altitude_min_km) v.altitude = 1;
  if (v.sun_max_deg <= v.sun_min_deg) v.sun = 1;
  return v;
}

Model model_of(const AtmosphereSpec& s) {
  Model m;
  m.bottom_radius_km = s.bottom_radius_km;
  m.top_radius_km = s.top_radius_km;
  m.sun_angular_radius_rad = s.sun_angular_radius_rad;
  m.mu_s_min = std::cos(s.max_sun_zenith_deg * M_PI / 180.0);
  m.density_theta = s.density_theta;
  m.density_theta_power = s.density_horizon ? 2.0 : 1.0;
  m.ray_simpson = s.ray_simpson;
  m.phase_nu_slice = s.phase_nu_slice;
  m.phase_weights_normalised = s.phase_weights_normalised;
  m.mu_s_geometric = s.mu_s_geometric;
  m.mie_g = s.mie_phase_g;
  for (int i = 0; i < 2; ++i) {
    m.rayleigh_density[i] = s.rayleigh_density[i];
    m.mie_density[i] = s.mie_density[i];
    m.absorption_density[i] = s.ozone_density[i];
  }
  if (s.ozone) {
    const double column_km = profile_column_km(s.ozone_density, s.top_radius_km - s.bottom_radius_km);
    m.ozone_peak_number_density_per_m3 = column_km > 0 ? s.ozone_column_du * kDobsonUnit / (column_km * 1000.0) : 0.0;
  }
  m.sizes = sizes_of(s);
  m.sky_view = sky_view_of(s);
  return m;
}

double vertical_scattering_depth(const AtmosphereSpec& spec, const std::vector<double>& lambda_nm) {
  if (lambda_nm.empty()) return 0.0;
  const Channels ch = channels_at(spec, lambda_nm);
  const double thickness = spec.top_radius_km - spec.bottom_radius_km;
  const double rayleigh = profile_column_km(spec.rayleigh_density, thickness),
               mie = profile_column_km(spec.mie_density, thickness);
  double tau = 0.0;
  for (std::size_t c = 0; c < lambda_nm.size(); ++c)
    tau += ch.rayleigh_scattering[c] * rayleigh + ch.mie_scattering[c] * mie;  // per km × km
  return tau / static_cast<double>(lambda_nm.size());
}

namespace {
// The aerosol's extinction at the bottom of its profile (per m): e · λ_µm^−α, 0 without one.
double mie_extinction_per_m(const AtmosphereSpec& s, double nm) {
  return s.mie ? s.mie_extinction_per_m * std::pow(nm * 1e-3, -s.mie_angstrom_alpha) : 0.0;
}
}  // namespace

double mie_vertical_scattering_depth(const AtmosphereSpec& spec, double lambda_nm) {
  return mie_extinction_per_m(spec, lambda_nm) * spec.mie_single_scattering_albedo * 1e3 *
         profile_column_km(spec.mie_density, spec.top_radius_km - spec.bottom_radius_km);
}

Channels channels_at(const AtmosphereSpec& s, const std::vector<double>& lambda_nm) {
  const Model m = model_of(s);
  Channels c;
  for (double nm : lambda_nm) {
    const double um = nm * 1e-3, mie_ext = mie_extinction_per_m(s, nm);
    c.lambda_nm.push_back(nm);
    c.solar_irradiance.push_back(solar_irradiance_at(nm) * s.solar_irradiance_scale);
    c.rayleigh_scattering.push_back(s.rayleigh ? s.rayleigh_scattering_per_m_at_1um * std::pow(um, -4.0) * 1e3 : 0.0);
    c.mie_extinction.push_back(mie_ext * 1e3);
    c.mie_scattering.push_back(mie_ext * s.mie_single_scattering_albedo * 1e3);
    c.absorption_extinction.push_back(s.ozone ? m.ozone_peak_number_density_per_m3 * ozone_cross_section_at(nm) * 1e3
                                              : 0.0);
    c.ground_albedo.push_back(s.ground_albedo);
  }
  return c;
}

Channels Channels::slice(std::size_t first, std::size_t count) const {
  auto cut = [&](const std::vector<double>& v) {
    return std::vector<double>(v.begin() + first, v.begin() + std::min(v.size(), first + count));
  };
  return {cut(lambda_nm), cut(solar_irradiance), cut(rayleigh_scattering), cut(mie_scattering),
          cut(mie_extinction), cut(absorption_extinction), cut(ground_albedo)};
}

Channels Channels::subset(const std::vector<std::size_t>& channels) const {
  auto pick = [&](const std::vector<double>& v) {
    std::vector<double> out;
    for (std::size_t c : channels) out.push_back(v.at(c));
    return out;
  };
  return {pick(lambda_nm), pick(solar_irradiance), pick(rayleigh_scattering), pick(mie_scattering),
          pick(mie_extinction), pick(absorption_extinction), pick(ground_albedo)};
}

Spectrum spectrum_of(const AtmosphereSpec& s) {
  Spectrum sp;
  sp.spectral = s.spectral;
  sp.sun_radiance_to_luminance = radiance_to_luminance(0.0, s.solar_irradiance_scale);
  if (!s.spectral) {
    sp.lambda_nm = {kLambdaR, kLambdaG, kLambdaB};
    sp.sky_radiance_to_luminance = radiance_to_luminance(-3.0, s.solar_irradiance_scale);
    return sp;
  }
  sp.sky_radiance_to_luminance = {kMaxLuminousEfficacy, kMaxLuminousEfficacy, kMaxLuminousEfficacy};
  sp.bin_nm = (s.max_nm - s.min_nm) / s.count;
  const CmfTable& cmf = cmf_table(CmfSet::cie1931_2deg);
  const Mat3 M = xyz_to_srgb();
  const int n = s.count;
  sp.to_rgb.assign(3 * n, 0.0);
  sp.to_xyz.assign(3 * n, 0.0);
  for (int i = 0; i < n; ++i) {
    const double l = s.min_nm + (i + 0.5) * sp.bin_nm;
    sp.lambda_nm.push_back(l);
    const auto xyz = cmf.at(l);
    for (int c = 0; c < 3; ++c) {
      sp.to_xyz[c * n + i] = xyz[c] * sp.bin_nm;
      sp.to_rgb[c * n + i] = (M[3 * c] * xyz[0] + M[3 * c + 1] * xyz[1] + M[3 * c + 2] * xyz[2]) * sp.bin_nm;
    }
  }
  return sp;
}

}  // namespace specbake::atmosphere
