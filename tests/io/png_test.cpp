// The previews' 8-bit sRGB encoding: the table's codes are the formula's, value for value.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "io/png.hpp"

namespace specbake {
namespace {

float from_bits(std::uint32_t u) {
  float f;
  std::memcpy(&f, &u, sizeof f);
  return f;
}

// Every 97th float of [0, 1] (11 million values, every code's edges among them many times over),
// each code's first value and the float just below it, and values outside [0, 1].
TEST(Png, Srgb8TableGivesTheFormulasCodes) {
  std::uint32_t one;
  const float f1 = 1.0f;
  std::memcpy(&one, &f1, sizeof one);
  long long mismatches = 0;
  for (std::uint32_t u = 0; u <= one; u += 97) mismatches += srgb8(from_bits(u)) != srgb8_formula(from_bits(u));
  EXPECT_EQ(mismatches, 0);
  int codes_seen = 0;
  for (std::uint32_t u = 1; u <= one; ++u) {  // walk the code edges: each code's first float
    const float v = from_bits(u), below = from_bits(u - 1);
    if (srgb8_formula(v) != srgb8_formula(below)) {
      ++codes_seen;
      EXPECT_EQ(srgb8(v), srgb8_formula(v)) << v;
      EXPECT_EQ(srgb8(below), srgb8_formula(below)) << below;
    }
    if (codes_seen == 255) break;
    u += srgb8_formula(v) == srgb8_formula(from_bits(std::min(u + 4096, one))) ? 4096 - 1 : 0;
  }
  EXPECT_EQ(codes_seen, 255);
  for (float v : {-1.0f, -0.0f, 0.0f, 1.0f, 1.5f, std::numeric_limits<float>::infinity(),
                  -std::numeric_limits<float>::infinity()})
    EXPECT_EQ(srgb8(v), srgb8_formula(v)) << v;
  EXPECT_EQ(srgb8(std::nanf("")), 0);
  EXPECT_EQ(srgb8_formula(std::nanf("")), 0);
  EXPECT_EQ(srgb8(1.0f), 255);
  EXPECT_EQ(srgb8(0.5f), 188);  // 1.055 · 0.5^(1/2.4) − 0.055 = 0.7354 → 187.5 → 188
}

}  // namespace
}  // namespace specbake
