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
// The 8-bit sRGB code of a linear value in [0, 1] (clipped; NaN → 0): round(255 · sRGB(v)) with the
// sRGB curve in float (srgb8_formula), and the same codes from a table of the values where each
// code starts (srgb8, what the previews use: a search of 255 floats instead of a pow).
std::uint8_t srgb8_formula(float linear);
std::uint8_t srgb8(float linear);

}  // namespace specbake
