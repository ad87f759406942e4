#include "core/colour_space.hpp"

#include <stdexcept>

namespace specbake {

std::array<double, 3> apply(const Mat3& m, const double* v) {
  std::array<double, 3> out{};
  for (int r = 0; r < 3; ++r) out[r] = m[3 * r] * v[0] + m[3 * r + 1] * v[1] + m[3 * r + 2] * v[2];
  return out;
}

Mat3 multiply(const Mat3& a, const Mat3& b) {
  Mat3 c{};
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k)
      for (int col = 0; col < 3; ++col) c[3 * r + col] += a[3 * r + k] * b[3 * k + col];
  return c;
}

Mat3 inverse(const Mat3& m) {
  const double a = m[0], b = m[1], c = m[2], d = m[3], e = m[4], f = m[5], g = m[6], h = m[7], i = m[8];
  const double A = e * i - f * h, B = -(d * i - f * g), C = d * h - e * g;
  const double det = a * A + b * B + c * C;
  if (det == 0.0) throw std::domain_error("singular 3x3 matrix");
  return {A / det, -(b * i - c * h) / det, (b * f - c * e) / det,
          B / det, (a * i - c * g) / det,  -(a * f - c * d) / det,
          C / det, -(a * h - b * g) / det, (a * e - b * d) / det};
}

Mat3 srgb_to_xyz() {
  // Columns: XYZ of the R, G, B primaries (x, y, 1−x−y)/y, scaled so R+G+B = white (Y = 1).
  const double xy[3][2] = {{0.64, 0.33}, {0.30, 0.60}, {0.15, 0.06}};
  const double wx = 0.3127, wy = 0.3290;
  Mat3 P{};
  for (int j = 0; j < 3; ++j) {
    P[0 * 3 + j] = xy[j][0] / xy[j][1];
    P[1 * 3 + j] = 1.0;
    P[2 * 3 + j] = (1.0 - xy[j][0] - xy[j][1]) / xy[j][1];
  }
  const double W[3] = {wx / wy, 1.0, (1.0 - wx - wy) / wy};
  const Mat3 Pinv = inverse(P);
  const std::array<double, 3> s = apply(Pinv, W);
  Mat3 M{};
  for (int r = 0; r < 3; ++r)
    for (int j = 0; j < 3; ++j) M[3 * r + j] = P[3 * r + j] * s[j];
  return M;
}

Mat3 xyz_to_srgb() { return inverse(srgb_to_xyz()); }

double srgb_luminance(const std::array<double, 3>& rgb) {
  static const Mat3 M = srgb_to_xyz();
  return M[3] * rgb[0] + M[4] * rgb[1] + M[5] * rgb[2];
}

}  // namespace specbake
