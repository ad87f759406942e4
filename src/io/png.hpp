#pragma once
// PNG encoding for previews (8-bit sRGB) and decoding of grey heightfields.
#include <cstdint>
#include <string>
#include <vector>

namespace specbake {

// rgb: [height][width][3] bytes.
std::string png_rgb8(int width, int height, const std::vector<std::uint8_t>& rgb);
// Linear sRGB floats [height][width][3] → 8-bit sRGB-encoded PNG, after multiplying by
// `exposure`; negative values clip to 0, values above 1 clip to 1.
std::string png_from_linear(int width, int height, const std::vector<float>& rgb, float exposure = 1.0f);

}  // namespace specbake
