#pragma once
// The sampling side of the baked LUTs, on the host in double: the reference's rendering
// functions (GetSkyRadiance, GetSkyRadianceToPoint, GetSunAndSkyIrradiance) over the final
// textures, the tiled-2D layout and its GLSL-equivalent lookup, the shipped GLSL, previews.
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "io/bundle.hpp"
#include "io/png.hpp"
#include "kinds/atmosphere/model/model.hpp"

namespace specbake::atmosphere {

using Vec3 = std::array<double, 3>;

// Final textures, 3 channels (R, G, B) innermost; lengths in km.
struct Luts {
  Model model;
  Channels rgb;  // coefficients at 680/550/440 nm (solar irradiance, phase g, ...)
  std::vector<double> transmittance;  // [th][tw][3]
  std::vector<double> irradiance;     // [ih][iw][3], indirect only
  std::vector<double> scattering;     // [R][MU][NU·MU_S][3]
  std::vector<double> single_mie;     // same
  // The sky-view table where model.sky_view is on (else empty), [sun][altitude][view][azimuth][3]:
  // radiance without single Mie, and single Mie without its phase (lookup.cl, "The sky-view table").
  std::vector<double> sky_view, sky_view_mie;
};

class Renderer {
 public:
  explicit Renderer(const Luts& luts);
  ~Renderer();
  // Radiance along `view` from `camera` (km, planet centre at 0), sun along `sun`.
  Vec3 sky_radiance(const Vec3& camera, const Vec3& view, const Vec3& sun, Vec3* transmittance) const;
  Vec3 sky_radiance_to_point(const Vec3& camera, const Vec3& point, const Vec3& sun, Vec3* transmittance) const;
  Vec3 sun_and_sky_irradiance(const Vec3& point, const Vec3& normal, const Vec3& sun, Vec3* sky) const;
  // GetScattering on the 3D `scattering` (or `single_mie`) texture.
  Vec3 scattering_3d(double r, double mu, double mu_s, double nu, bool ground, bool mie) const;
  Vec3 transmittance_to_top(double r, double mu) const;
  Vec3 irradiance(double r, double mu_s) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// `spectrum: {store: radiance}`: the textures at every stored wavelength, float32 as the files
// hold them, four wavelengths (a set) per texel and the sets outermost: transmittance
// [set][th][tw][4], irradiance [set][ih][iw][4], scattering and single_mie tiled 2D
// [set][MU][R·NU·MU_S][4] (the layers of sampling_spectral.glsl's 2D array textures).
struct SpectralLuts {
  std::vector<double> lambda_nm;         // stored wavelengths (nm)
  std::vector<double> solar_irradiance;  // at each
  std::vector<float> transmittance, irradiance, scattering, single_mie;
  int sets() const { return static_cast<int>((lambda_nm.size() + 3) / 4); }
  // The stored wavelengths' spacing (1 for a single one: any step keeps its index 0).
  double step_nm() const { return lambda_nm.size() > 1 ? lambda_nm[1] - lambda_nm[0] : 1.0; }
};

// The spectral lookups of sampling_spectral.glsl (render.glsl built with SPECBAKE_SPECTRAL) on
// the host in double over the float32 texels: radiance at any wavelength between the stored
// ones (interpolated), or at stored wavelength i exactly. Cameras and points as Renderer's.
class SpectralRenderer {
 public:
  SpectralRenderer(const Model& m, const SpectralLuts& luts);  // luts stays alive
  ~SpectralRenderer();
  double sky_radiance(const Vec3& camera, const Vec3& view, const Vec3& sun, double lambda_nm,
                      double* transmittance) const;
  double sky_radiance_stored(const Vec3& camera, const Vec3& view, const Vec3& sun, int i, double* transmittance) const;
  double sun_and_sky_irradiance(const Vec3& point, const Vec3& normal, const Vec3& sun, double lambda_nm,
                                double* sky) const;
  double sun_and_sky_irradiance_stored(const Vec3& point, const Vec3& normal, const Vec3& sun, int i, double* sky) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// [R][MU][NU·MU_S][3] → [MU][R·NU·MU_S][3], column = r·NU·MU_S + ν·MU_S + μ_s.
std::vector<double> to_tiled2d(const std::vector<double>& tex3d, const Sizes& s);
// The tiled 2D index of the 3D layout's texel t ([R][MU][NU·MU_S] → [MU][R][NU·MU_S]).
inline std::size_t tiled2d_index(std::size_t t, const Sizes& s) {
  const std::size_t wd = static_cast<std::size_t>(s.scattering_width()), x = t % wd, j = (t / wd) % s.mu,
                    k = t / (wd * s.mu);
  return (j * s.r + k) * wd + x;
}
// Lookup in the tiled-2D layout exactly as sampling.glsl's GetScatteringTiled2D does it
// (4 bilinear fetches with clamp-to-edge, lerps in r and ν).
Vec3 sample_tiled2d(const Model& m, const std::vector<double>& tiled, double r, double mu, double mu_s, double nu,
                    bool ground);

std::string sampling_glsl(const Model& m, const Channels& rgb, bool layout_3d, bool layout_tiled2d,
                          const std::string& units_note);
// sampling_spectral.glsl: render.glsl built with SPECBAKE_SPECTRAL for the stored wavelengths.
std::string sampling_spectral_glsl(const Model& m, const SpectralLuts& luts, const std::string& units_note);

// The preview views' geometry, shared by the previews and the GL test that draws them with the
// shipped shader. Fisheyes: from kFisheyeAltitudeKm above the ground, equidistant, zenith at the
// centre, sun at azimuth 0 (the picture's right) at each elevation, with a fixed exposure (EV100)
// that puts the default Earth's median sky pixel (its brightest channel) near x = 0.2 before the tone curve.
struct FisheyeView {
  double sun_elevation_deg, ev100;
};
inline constexpr FisheyeView kFisheyeViews[] = {{60.0, 14.5}, {20.0, 14.0}, {5.0, 13.0}, {0.0, 11.5}, {-4.0, 7.5}};
inline constexpr double kFisheyeAltitudeKm = 0.001;
Vec3 fisheye_sun(const FisheyeView& v);
// The view direction of picture point (x, y) ∈ (−1, 1)² (x right, y up); false outside the circle.
bool fisheye_direction(double x, double y, Vec3& view);
// The planet from 3.2 radii: camera (km, planet centre at 0), sun, and the view direction of
// picture point (x, y) ∈ (−1, 1)²; the whole atmosphere in frame with a 15 % margin.
struct PlanetView {
  Vec3 camera, sun;
  double ev100 = 14.0;
  Vec3 direction(double x, double y) const;
  Vec3 fwd, right, up;
  double half = 0.0;
};
PlanetView planet_view(const Model& m);

// Fisheye skies (with the sun's disc) from the ground at several sun elevations and the planet
// seen from space, n × n pixels each at its view's exposure through `curve`, labelled, and a
// contact sheet of all (docs/atmosphere.md, "Previews");
// rendered through the shipped shader's functions (shader_host.hpp). k_sky, k_sun: radiance →
// luminance factors (lm/W per channel).
std::vector<OutputFile> preview_files(const Luts& luts, const std::array<double, 3>& k_sky,
                                      const std::array<double, 3>& k_sun, int n, ToneCurve curve);

}  // namespace specbake::atmosphere
