#pragma once
// The double-precision reference of the atmosphere maths: kernels/atmosphere/atmosphere.cl
// compiled as C++ with real = double and 3 channels (ref3: R, G, B), followed by the host
// backend and helpers of host_pass.inc. The other pass widths are in reference_widths.hpp.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <cstddef>
#include <cstring>
#include <thread>
#include <vector>

#include "core/parallel.hpp"
#include "kinds/atmosphere/pass.hpp"

namespace specbake::atmosphere {


#define SPECBAKE_ATMOSPHERE_REF_PROLOGUE                                                                    \
  using real = double;                                                                                    \
  using std::cos, std::exp, std::floor, std::fmax, std::fmin, std::sin, std::sqrt;

namespace ref3 {
SPECBAKE_ATMOSPHERE_REF_PROLOGUE
#define NCH 3
#include "atmosphere/atmosphere.cl"
#include "kinds/atmosphere/host_pass.inc"
#undef NCH
}  // namespace ref3

}  // namespace specbake::atmosphere
