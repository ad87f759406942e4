#pragma once
// The sampling side of the baked LUTs, on the host in double: the reference's rendering
// functions (GetSkyRadiance, GetSkyRadianceToPoint, GetSunAndSkyIrradiance) over the final
// textures, the tiled-2D layout and its GLSL-equivalent lookup, the shipped GLSL, previews.
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "io/bundle.hpp"
#include "kinds/atmosphere/model.hpp"

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

// [R][MU][NU·MU_S][3] → [MU][R·NU·MU_S][3], column = r·NU·MU_S + ν·MU_S + μ_s.
std::vector<double> to_tiled2d(const std::vector<double>& tex3d, const Sizes& s);
// Lookup in the tiled-2D layout exactly as sampling.glsl's GetScatteringTiled2D does it
// (4 bilinear fetches with clamp-to-edge, lerps in r and ν).
Vec3 sample_tiled2d(const Model& m, const std::vector<double>& tiled, double r, double mu, double mu_s, double nu,
                    bool ground);

std::string sampling_glsl(const Model& m, const Channels& rgb, bool layout_3d, bool layout_tiled2d,
                          const std::string& units_note);

// Fisheye skies (with the sun's disc) from the ground at several sun elevations and the planet
// seen from space, n × n pixels each at a fixed exposure per view, and a contact sheet of all;
// rendered through the shipped shader's functions (shader_host.hpp). k_sky, k_sun: radiance →
// luminance factors (lm/W per channel).
std::vector<OutputFile> preview_files(const Luts& luts, const std::array<double, 3>& k_sky,
                                      const std::array<double, 3>& k_sun, int n);

}  // namespace specbake::atmosphere
