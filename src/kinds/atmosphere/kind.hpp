#pragma once
// The atmosphere kind's entry in the kind table (src/registry/).
#include "job/kind.hpp"

namespace specbake::atmosphere {
Kind kind();
}  // namespace specbake::atmosphere
