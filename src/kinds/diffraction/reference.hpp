#pragma once
// The double-precision reference of the diffraction maths: the very functions the OpenCL
// kernels run (kernels/diffraction/diffraction.cl), compiled as C++ with real = double.
#include <cmath>
#include <stdexcept>

namespace specbake::diffraction::ref {
using real = double;
using std::cos, std::fabs, std::fmax, std::fmod, std::sin, std::sqrt;
#include "diffraction/diffraction.cl"
}  // namespace specbake::diffraction::ref
