#pragma once
// The dispersion kind's entry in the kind table (src/registry/).
#include "job/kind.hpp"

namespace specbake::dispersion {
Kind kind();
}  // namespace specbake::dispersion
