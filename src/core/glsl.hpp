#pragma once
// Maths shared between kernels, the host's double reference and shipped shaders: kernels/ files
// written in the common subset of C/C++ and GLSL (kernels/common/real.h's vocabulary), pasted
// into a bundle's .glsl after one prelude.
#include <string>
#include <string_view>

namespace specbake {

// The GLSL definitions of real.h's vocabulary (real, FN, R, REQUIRE) and of the C maths names
// the shared files use (fmax, fmin, fabs).
std::string glsl_subset_prelude();
// #undef of each prelude macro, so that a shader including several shipped files (or its own
// code after them) sees none of them.
std::string glsl_subset_epilogue();

// An embedded kernels/ file as GLSL text: its `#include "common/real.h"` and other include lines
// dropped (the includer pastes what they name, in order), the rest verbatim, framed by comments
// naming the file.
std::string glsl_shared_source(std::string_view resource_path);

}  // namespace specbake
