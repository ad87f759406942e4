#pragma once
// What the atmosphere GL tests' per-pixel bounds perturb: inputs rounded to float32 as the GL side
// gets them, and unit vectors turned by a small angle.
#include <cmath>
#include <vector>

#include <glm/glm.hpp>

namespace specbake::testing {

inline double f32(double x) { return static_cast<float>(x); }
inline glm::dvec3 f32(const glm::dvec3& v) { return {f32(v.x), f32(v.y), f32(v.z)}; }

// A unit vector turned by angle e towards each of two directions orthogonal to it (both ways).
inline std::vector<glm::dvec3> turned(const glm::dvec3& v, double e) {
  const glm::dvec3 a =
      glm::normalize(glm::cross(v, std::fabs(v.z) < 0.9 ? glm::dvec3{0, 0, 1} : glm::dvec3{1, 0, 0}));
  const glm::dvec3 b = glm::cross(v, a);
  return {glm::normalize(v + e * a), glm::normalize(v - e * a), glm::normalize(v + e * b), glm::normalize(v - e * b)};
}

}  // namespace specbake::testing
