#pragma once
// Numbers in messages, summaries and text files.
#include <string>

namespace specbake {

// printf's %.<digits>g: the shortest readable form ("0.001", "3.614", "1e+06"). 17 digits give
// back the double exactly.
std::string format_g(double v, int digits = 4);

}  // namespace specbake
