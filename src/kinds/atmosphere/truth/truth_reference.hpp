#pragma once
// The path tracer's maths in C++ double: kernels/atmosphere/path_tracer.cl compiled into ref3
// (after atmosphere.cl, as the OpenCL program does), so that the host builds the tracer's
// tables with the very functions the kernel uses and can run the same walks.
#include <cmath>

#include "common/philox.h"  // at namespace scope: path_tracer.cl's own include is then a no-op
#include "kinds/atmosphere/bake/reference.hpp"

namespace specbake::atmosphere::ref3 {
using std::cbrt, std::fabs, std::log;
#define NCH 3
#include "atmosphere/path_tracer.cl"
inline constexpr int kTruthOutStride = TRUTH_OUT_STRIDE;
inline constexpr int kTruthChannels = NCH;
inline constexpr int kTruthCutsAt = TRUTH_CUTS_AT;
inline constexpr int kTruthMaxCuts = TRUTH_MAX_CUTS;
inline constexpr double kTruthDepthError = TRUTH_DEPTH_ERROR;
inline constexpr int kTruthMediumSize = TRUTH_MEDIUM_SIZE;
inline constexpr int kTruthSunAt = TRUTH_SUN_AT;
inline constexpr int kTruthSkyAt = TRUTH_SKY_AT;
inline constexpr double kTruthSkyNone = TRUTH_SKY_NONE;
inline constexpr double kTruthSunExactShare = TRUTH_SUN_EXACT_SHARE;
#undef NCH
}  // namespace specbake::atmosphere::ref3
