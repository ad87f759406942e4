#include "kinds/dispersion/combine.hpp"

namespace specbake::dispersion {

Combiner::Combiner(const std::vector<double>& K) : SPECBAKE_SAMPLES(static_cast<int>(K.size() / 9)) {
  for (int n = 0; n < SPECBAKE_SAMPLES; ++n) {
    glm::dmat3 m;  // GLM, as GLSL, indexes m[column][row]
    for (int row = 0; row < 3; ++row)
      for (int col = 0; col < 3; ++col) m[col][row] = K[9 * n + 3 * row + col];
    SPECBAKE_K.push_back(m);
  }
}

std::array<double, 3> Combiner::combine(const sampler2DArray& renders, int x, int y) {
  const vec3 v = specbake_dispersion_combine(renders, ivec2(x, y));
  return {v.x, v.y, v.z};
}

}  // namespace specbake::dispersion
