#include "core/text.hpp"

#include <cstdio>

namespace specbake {

std::string format_g(double v, int digits) {
  char b[40];
  std::snprintf(b, sizeof b, "%.*g", digits, v);
  return b;
}

std::string glsl_float(double v) {
  std::string s = format_g(v, 9);
  if (s.find_first_of(".eE") == std::string::npos) s += ".0";
  return s;
}

}  // namespace specbake
