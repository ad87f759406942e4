#pragma once
// Linear sRGB ↔ CIE XYZ (D65), built in double from the BT.709 primaries and the D65
// chromaticity (0.3127, 0.3290) with Y_white = 1, the inverse computed exactly (to double
// rounding) rather than taken from a printed 4-digit table, so Σ K_n = I holds.
#include <array>

namespace specbake {

using Mat3 = std::array<double, 9>;  // row-major

Mat3 srgb_to_xyz();
Mat3 xyz_to_srgb();
Mat3 inverse(const Mat3& m);
Mat3 multiply(const Mat3& a, const Mat3& b);
// m·v for a 3-vector v (v[0], v[1], v[2]).
std::array<double, 3> apply(const Mat3& m, const double* v);
// The luminance Y of a linear sRGB colour (the middle row of srgb_to_xyz).
double srgb_luminance(const std::array<double, 3>& rgb);

}  // namespace specbake
