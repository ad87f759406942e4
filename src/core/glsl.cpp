#include "core/glsl.hpp"

#include <sstream>

#include "core/resources.hpp"

namespace specbake {

std::string glsl_subset_prelude() {
  return "// real.h's vocabulary in GLSL: the shared files below are C/C++/GLSL common subset.\n"
         "#define real float\n#define FN\n#define R(x) float(x)\n#define REQUIRE(condition)\n"
         "#define fmax max\n#define fmin min\n#define fabs abs\n";
}

std::string glsl_subset_epilogue() {
  return "#undef real\n#undef FN\n#undef R\n#undef REQUIRE\n#undef fmax\n#undef fmin\n#undef fabs\n";
}

std::string glsl_shared_source(std::string_view resource_path) {
  std::istringstream in{std::string(resource(resource_path))};
  std::string out = "// ---- " + std::string(resource_path) + ", verbatim ----\n", line;
  while (std::getline(in, line))
    if (line.rfind("#include ", 0) != 0) out += line + "\n";
  return out + "// ---- end of " + std::string(resource_path) + " ----\n";
}

}  // namespace specbake
