#pragma once
// Numbers in messages, summaries and text files.
#include <string>

namespace specbake {

// printf's %.<digits>g: the shortest readable form ("0.001", "3.614", "1e+06"). 17 digits give
// back the double exactly.
std::string format_g(double v, int digits = 4);
// A GLSL float literal: %.9g (float32 exactly), with ".0" where it would read as an integer.
std::string glsl_float(double v);

}  // namespace specbake
