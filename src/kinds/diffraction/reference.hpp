#pragma once
// The double-precision reference of the diffraction maths: the very functions the OpenCL
// kernels run (kernels/diffraction/diffraction.cl) and the BRDF the emitted shader evaluates
// (kernels/diffraction/brdf.cl) and the previews draw from a table (kernels/diffraction/table.cl),
// compiled as C++ with real = double.
#include <cmath>
#include <stdexcept>

namespace specbake::diffraction::ref {
using real = double;
using std::cos, std::exp, std::fabs, std::floor, std::fmax, std::fmin, std::fmod, std::pow, std::sin, std::sqrt;
#include "diffraction/diffraction.cl"
#include "diffraction/brdf.cl"
#include "diffraction/table.cl"
}  // namespace specbake::diffraction::ref
