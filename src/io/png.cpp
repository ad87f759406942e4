#include "io/png.hpp"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "core/errors.hpp"

namespace specbake {

namespace {
void write_to_string(png_structp png, png_bytep data, png_size_t len) {
  static_cast<std::string*>(png_get_io_ptr(png))->append(reinterpret_cast<const char*>(data), len);
}
void flush_nothing(png_structp) {}

}  // namespace

std::uint8_t srgb8_formula(float v) {
  v = v > 0.0f ? std::min(v, 1.0f) : 0.0f;  // NaN → 0
  const float e = v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
  return static_cast<std::uint8_t>(std::lround(e * 255.0f));
}

namespace {

// srgb8_formula without a pow per value: it is non-decreasing in v, so code k is taken by
// every v from the smallest float in [0, 1] that encodes to ≥ k on (found once by bisection over
// the floats' bit patterns, which order non-negative floats as their values); the same bytes.
class SrgbEncoder {
 public:
  SrgbEncoder() {
    for (int k = 1; k < 256; ++k) {
      std::uint32_t lo = 0, hi = bits(1.0f);  // encode(lo) < k ≤ encode(hi)
      while (hi - lo > 1) {
        const std::uint32_t mid = lo + (hi - lo) / 2;
        (srgb8_formula(value(mid)) >= k ? hi : lo) = mid;
      }
      first_[k - 1] = value(hi);
    }
    first_[255] = std::numeric_limits<float>::infinity();
    // the code at the start of each of kBins equal bins of [0, 1]; a bin holds at most one code
    // edge (the curve's steepest, 12.92 · 255 codes per unit near 0, is < kBins)
    for (int i = 0; i < kBins; ++i) start_[i] = slow(static_cast<float>(i) / kBins);
  }
  std::uint8_t operator()(float v) const {
    if (!(v > 0.0f)) return 0;  // ≤ 0 and NaN, as the formula maps them
    if (v >= 1.0f) return 255;
    int code = start_[static_cast<int>(v * kBins)];
    while (v >= first_[code]) ++code;  // first_[code]: where code + 1 starts
    return static_cast<std::uint8_t>(code);
  }

 private:
  static std::uint32_t bits(float f) {
    std::uint32_t u;
    std::memcpy(&u, &f, sizeof u);
    return u;
  }
  static float value(std::uint32_t u) {
    float f;
    std::memcpy(&f, &u, sizeof f);
    return f;
  }
  int slow(float v) const { return static_cast<int>(std::upper_bound(first_, first_ + 255, v) - first_); }
  static constexpr int kBins = 4096;
  float first_[256];  // first_[k − 1]: the smallest float whose code is ≥ k; first_[255] = ∞
  std::uint8_t start_[kBins];
};

}  // namespace

std::uint8_t srgb8(float v) {
  static const SrgbEncoder encoder;
  return encoder(v);
}

float tone(float x, ToneCurve curve) {
  if (!(x > 0.0f)) return 0.0f;  // ≤ 0 and NaN
  if (curve == ToneCurve::linear) return std::min(x, 1.0f);
  const float d = x * (2.51f * x + 0.03f) / (x * (2.43f * x + 0.59f) + 0.14f);
  return std::min(d, 1.0f);
}

double tone_inverse(double d, ToneCurve curve) {
  double lo = 0.0, hi = 16.0;  // the curves are non-decreasing and reach 1 by x = 7.25
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (tone(static_cast<float>(mid), curve) >= d ? hi : lo) = mid;
  }
  return hi;
}

const char* name(ToneCurve curve) { return curve == ToneCurve::aces ? "aces" : "linear"; }

std::string png_rgb8(int width, int height, const std::vector<std::uint8_t>& rgb) {
  if (width <= 0 || height <= 0 || rgb.size() != static_cast<std::size_t>(width) * height * 3)
    throw JobError("PNG image has inconsistent size");
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) throw JobError("PNG encoder could not start");
  std::string out;
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    throw JobError("PNG encoding failed");
  }
  png_set_write_fn(png, &out, write_to_string, flush_nothing);
  png_set_IHDR(png, info, width, height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_set_sRGB(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
  // zlib level 1: an atmosphere bundle's preview PNGs 44 % larger than at the default 6 (0.9 MB against
  // its ~50 MB of textures), their encoding 2.6× faster
  png_set_compression_level(png, 1);
  png_write_info(png, info);
  for (int y = 0; y < height; ++y)
    png_write_row(png, const_cast<png_bytep>(rgb.data() + static_cast<std::size_t>(y) * width * 3));
  png_write_end(png, info);
  png_destroy_write_struct(&png, &info);
  return out;
}

Rgb8 srgb8_image(int width, int height, const std::vector<float>& rgb, float exposure) {
  Rgb8 img(width, height);
  if (img.rgb.size() != rgb.size()) throw JobError("PNG image has inconsistent size");
  for (std::size_t i = 0; i < rgb.size(); ++i) img.rgb[i] = srgb8(rgb[i] * exposure);
  return img;
}

std::string png_from_linear(int width, int height, const std::vector<float>& rgb, float exposure) {
  return png_rgb8(width, height, srgb8_image(width, height, rgb, exposure).rgb);
}

}  // namespace specbake
