#include "core/text.hpp"

#include <cstdio>

namespace specbake {

std::string format_g(double v, int digits) {
  char b[40];
  std::snprintf(b, sizeof b, "%.*g", digits, v);
  return b;
}

}  // namespace specbake
