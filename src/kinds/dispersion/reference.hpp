#pragma once
// The double-precision reference of the dispersion maths: the very functions the OpenCL
// kernels run (kernels/dispersion/dispersion.cl, kernels/common/colour.cl), compiled as C++
// with real = double.
#include <cmath>
#include <stdexcept>

namespace specbake::dispersion::ref {
using real = double;
using std::atan2, std::cbrt, std::cos, std::exp, std::fabs, std::floor, std::fmax, std::fmin, std::pow, std::sin,
    std::sqrt;
#include "common/colour.cl"
#include "dispersion/dispersion.cl"
}  // namespace specbake::dispersion::ref
