#pragma once
// The host side of kernels/dispersion/combine.glsl (the shipped dispersion.glsl's
// specbake_dispersion_combine): the same text compiled in double with GLM over a bundle's K_n.
#include <array>
#include <vector>

#include <glm/glm.hpp>

namespace specbake::dispersion {

class Combiner {
 public:
  // Per-sample colours, [n][h][w][3] (row 0 first), as the shader's 2D array texture holds them.
  struct sampler2DArray {
    const double* rgb;
    int w, h;
  };
  // K: [n][3][3], row-major, applied as K_n · rgb (matrices.bin).
  explicit Combiner(const std::vector<double>& K);
  // Σ_n K_n · rgb_n at texel (x, y).
  std::array<double, 3> combine(const sampler2DArray& renders, int x, int y);

 private:
  using vec3 = glm::dvec3;
  using ivec2 = glm::ivec2;
  static vec3 texel_rgb(const sampler2DArray& s, ivec2 p, int n) {
    const double* v = s.rgb + 3 * ((static_cast<long long>(n) * s.h + p.y) * s.w + p.x);
    return {v[0], v[1], v[2]};
  }
  int SPECBAKE_SAMPLES = 0;
  std::vector<glm::dmat3> SPECBAKE_K;
#define TEXEL_RGB(s, p, n) texel_rgb(s, p, n)
#include "dispersion/combine.glsl"
#undef TEXEL_RGB
};

}  // namespace specbake::dispersion
