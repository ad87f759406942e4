#pragma once
// PNG encoding for previews (8-bit sRGB) and decoding of grey heightfields.
#include <cstdint>
#include <string>
#include <vector>

namespace specbake {

// An 8-bit sRGB picture, rows top to bottom, RGB innermost.
struct Rgb8 {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;  // [height][width][3]
  Rgb8() = default;
  Rgb8(int w, int h) : width(w), height(h), rgb(3 * static_cast<std::size_t>(w) * h, 0) {}
};

// rgb: [height][width][3] bytes.
std::string png_rgb8(int width, int height, const std::vector<std::uint8_t>& rgb);
// Linear sRGB floats [height][width][3] → 8-bit sRGB-encoded PNG, after multiplying by
// `exposure`; negative values clip to 0, values above 1 clip to 1.
std::string png_from_linear(int width, int height, const std::vector<float>& rgb, float exposure = 1.0f);
// The same picture's 8-bit codes (to be labelled before encoding).
Rgb8 srgb8_image(int width, int height, const std::vector<float>& rgb, float exposure = 1.0f);
// The 8-bit sRGB code of a linear value in [0, 1] (clipped; NaN → 0): round(255 · sRGB(v)) with the
// sRGB curve in float (srgb8_formula), and the same codes from a table of the values where each
// code starts (srgb8, what the previews use: a search of 255 floats instead of a pow).
std::uint8_t srgb8_formula(float linear);
std::uint8_t srgb8(float linear);

// How exposed scene values x ≥ 0 become display values in [0, 1] before the sRGB curve:
//   linear  min(x, 1): what is above 1 clips;
//   aces    Narkowicz's fit of the ACES filmic curve, x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14),
//           clamped to [0, 1]: a toe, a near-linear middle and a shoulder that reaches 97.5 % of
//           white at x ≈ 4.1 and white at x ≈ 7.24 (Narkowicz 2015, "ACES Filmic Tone Mapping Curve").
enum class ToneCurve { linear, aces };
float tone(float x, ToneCurve curve);
// The x at which `curve` reaches display value d ∈ (0, 1) (bisection; d is reached on both).
double tone_inverse(double d, ToneCurve curve);
const char* name(ToneCurve curve);

}  // namespace specbake
