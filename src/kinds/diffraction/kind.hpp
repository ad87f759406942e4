#pragma once
// The diffraction kind's entry in the kind table (src/registry/).
#include "job/kind.hpp"

namespace specbake::diffraction {
Kind kind();
}  // namespace specbake::diffraction
