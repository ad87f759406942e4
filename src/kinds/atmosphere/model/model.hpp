#pragma once
// The atmosphere of a bake, resolved from the config: geometry, density profiles (km), and
// the per-wavelength coefficients of each channel; the solar and ozone spectra; the
// spectral → linear sRGB conversion of the precomputed-luminance mode.
#include <array>
#include <string>
#include <vector>

#include "kinds/atmosphere/model/spec.hpp"

namespace specbake::atmosphere {

inline constexpr double kLambdaR = 680.0, kLambdaG = 550.0, kLambdaB = 440.0;  // nm, the rgb mode
inline constexpr double kMaxLuminousEfficacy = 683.0;                          // lm/W
inline constexpr double kDobsonUnit = 2.687e20;                                // molecules m^-2

struct Sizes {
  int transmittance_w = 256, transmittance_h = 64;  // mu, r
  int irradiance_w = 64, irradiance_h = 16;         // mu_s, r
  int r = 32, mu = 128, mu_s = 32, nu = 8;
  long long scattering_texels() const { return 1LL * r * mu * mu_s * nu; }
  int scattering_width() const { return nu * mu_s; }
};
Sizes sizes_of(const AtmosphereSpec& spec);

// The sky-view table's range and node counts (lookup.cl, "The sky-view table"); altitude == 0: none.
// Texels [sun][altitude][view][azimuth]: a 3D texture azimuth × view × (sun · altitude).
struct SkyView {
  double altitude_min_km = 0, altitude_max_km = 0, sun_min_deg = 0, sun_max_deg = 0;
  int altitude = 0, sun = 0, view = 0, azimuth = 0;
  // the summed density's two μ_s texels joined by mu_s_blend along each ray (a scene in deep
  // twilight with `mu_s_blend: geometric`), else linearly as the orders' own reads
  bool geometric_density = false;
  bool on() const { return altitude > 0; }
  long long texels() const { return 1LL * altitude * sun * view * azimuth; }
};
// The table a spec bakes (`sky_view:`; none for `sky_view: none`, no scene, or a scene in daylight).
SkyView sky_view_of(const AtmosphereSpec& spec);

// Per-channel coefficients (one entry per wavelength), lengths in km.
struct Channels {
  std::vector<double> lambda_nm;
  std::vector<double> solar_irradiance;       // W m^-2 nm^-1
  std::vector<double> rayleigh_scattering;    // km^-1
  std::vector<double> mie_scattering;         // km^-1
  std::vector<double> mie_extinction;         // km^-1
  std::vector<double> absorption_extinction;  // km^-1
  std::vector<double> ground_albedo;
  std::size_t size() const { return lambda_nm.size(); }
  Channels slice(std::size_t first, std::size_t count) const;
  Channels subset(const std::vector<std::size_t>& channels) const;  // those channels, in that order
};

struct Model {
  double bottom_radius_km = 0, top_radius_km = 0, sun_angular_radius_rad = 0, mu_s_min = 0, mie_g = 0;
  // the density's θ rule (atmosphere.cl density_theta_node): nodes, and p (1: uniform, 2: horizon)
  int density_theta = 16;
  double density_theta_power = 2.0;
  bool ray_simpson = true;      // the view rays' rule (atmosphere.cl ray_sample): Simpson, else the reference's trapezoid
  bool phase_nu_slice = true;   // 1/P_R(ν) of the stored multiple scattering at the slice's ν, else at the clamped ν
  bool phase_weights_normalised = true;  // the density's phase weights summed to 1 (atmosphere.cl scattering_density)
  bool mu_s_geometric = true;  // the shipped μ_s lookups: mu_s_blend (lookup.cl), else linear as the reference
  DensityLayer rayleigh_density[2]{}, mie_density[2]{}, absorption_density[2]{};
  double ozone_peak_number_density_per_m3 = 0;
  Sizes sizes;
  SkyView sky_view;
};
Model model_of(const AtmosphereSpec& spec);
Channels channels_at(const AtmosphereSpec& spec, const std::vector<double>& lambda_nm);
// The scattering optical depth of a vertical column from the ground to the top (Rayleigh and
// Mie), averaged over the wavelengths: how many times light scatters on its way through.
double vertical_scattering_depth(const AtmosphereSpec& spec, const std::vector<double>& lambda_nm);
// The aerosol's (Mie) part of it at one wavelength.
double mie_vertical_scattering_depth(const AtmosphereSpec& spec, double lambda_nm);

// The solar spectrum (ASTM G-173 10 nm bin means, W m^-2 nm^-1) and the ozone absorption
// cross-section (m^2), 360..830 nm at 10 nm, linearly interpolated and clamped at the ends.
double solar_irradiance_at(double nm);
double ozone_cross_section_at(double nm);
std::string spectra_table_text();  // canonical text of both tables (hashed as an input)

// Sample wavelengths of a bake and their conversion to output channels.
struct Spectrum {
  bool spectral = false;
  std::vector<double> lambda_nm;  // rgb: 680, 550, 440
  double bin_nm = 0.0;            // spectral: width of each bin
  // spectral: to_rgb[c * n + i] = (M_XYZ→sRGB · CMF(λ_i))_c · Δλ, the precomputed-luminance
  // weights (textures then hold luminance / 683); rgb: empty (identity).
  std::vector<double> to_rgb;
  // spectral: to_xyz[c * n + i] = CMF(λ_i)_c · Δλ, CIE 1931 X, Y, Z (to_rgb is M_XYZ→sRGB of it);
  // rgb: empty.
  std::vector<double> to_xyz;
  // Render-time factors (lm/W) from spectral radiance at 680/550/440 nm to luminance:
  // sky (λ^-3 weighted; 683 in spectral mode) and sun (λ^0).
  std::array<double, 3> sky_radiance_to_luminance{}, sun_radiance_to_luminance{};
};
Spectrum spectrum_of(const AtmosphereSpec& spec);

}  // namespace specbake::atmosphere
