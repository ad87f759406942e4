#pragma once
// The double-precision reference of the diffraction maths: the very functions the OpenCL
// kernels run (kernels/diffraction/diffraction.cl) and the BRDF the emitted shader evaluates
// (kernels/diffraction/brdf.cl), compiled as C++ with real = double.
#include <cmath>
#include <stdexcept>

namespace specbake::diffraction::ref {
using real = double;
using std::cos, std::exp, std::fabs, std::fmax, std::fmin, std::fmod, std::pow, std::sin, std::sqrt;
#include "diffraction/diffraction.cl"
#include "diffraction/brdf.cl"
}  // namespace specbake::diffraction::ref
