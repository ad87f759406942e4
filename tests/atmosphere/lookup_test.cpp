// The μ_s blend of the shipped lookups (kernels/atmosphere/lookup.cl, mu_s_blend), compiled as the
// host compiles the shader (double): geometric between two positive texels within a factor 1000,
// linear otherwise, and exact at both ends.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "kinds/atmosphere/shader/shader_host.hpp"

namespace glsl = specbake::atmosphere::glsl;

namespace {

// Relative bound of a·(b/a)^g against its closed form in double: pow's and the division's
// rounding (a few ulps) times the exponent's size; 1e-14 is ~45 ulps.
constexpr double kRel = 1e-14;

TEST(MuSBlend, GeometricBetweenPositiveTexels) {
  // an exponential in the sun's elevation is reproduced exactly where a linear blend overstates it
  const double a = std::exp(-3.0), b = std::exp(-4.5);  // two texels 1.5° apart at e per degree
  for (double g : {0.0, 0.25, 0.5, 0.75, 1.0}) {
    const double want = std::exp(-3.0 - 1.5 * g);
    EXPECT_NEAR(glsl::mu_s_blend(a, b, g), want, kRel * want) << g;
    if (g > 0.0 && g < 1.0) EXPECT_GT(a + (b - a) * g, 1.05 * want) << "the chord lies above the exponential";
  }
  // the ends are the texels themselves, and the blend is symmetric in its two texels
  EXPECT_EQ(glsl::mu_s_blend(a, b, 0.0), a);
  EXPECT_NEAR(glsl::mu_s_blend(a, b, 1.0), b, kRel * b);
  EXPECT_NEAR(glsl::mu_s_blend(a, b, 0.3), glsl::mu_s_blend(b, a, 0.7), kRel * a);
  // at the factor-1000 edge (just inside) it is still geometric
  EXPECT_NEAR(glsl::mu_s_blend(1.0, 1.001e-3, 0.5), std::sqrt(1.001e-3), kRel);
}

TEST(MuSBlend, LinearWhereAGeometricBlendWouldMislead) {
  // a zero texel (a ray that sees no sunlit air): the geometric blend would be 0 all the way
  EXPECT_DOUBLE_EQ(glsl::mu_s_blend(0.0, 2.0, 0.25), 0.5);
  EXPECT_DOUBLE_EQ(glsl::mu_s_blend(2.0, 0.0, 0.25), 1.5);
  EXPECT_DOUBLE_EQ(glsl::mu_s_blend(0.0, 0.0, 0.5), 0.0);
  // more than a factor 1000 apart: the shadow's edge, where the smaller texel is ~0
  EXPECT_DOUBLE_EQ(glsl::mu_s_blend(1.0, 1e-4, 0.5), 0.5 * (1.0 + 1e-4));
  EXPECT_DOUBLE_EQ(glsl::mu_s_blend(1e-4, 1.0, 0.5), 0.5 * (1.0 + 1e-4));
  // a negative value (float rounding of a value near zero) stays linear, never NaN
  const double v = glsl::mu_s_blend(-1e-9, 1.0, 0.5);
  EXPECT_TRUE(std::isfinite(v));
  EXPECT_DOUBLE_EQ(v, 0.5 * (1.0 - 1e-9));
}

}  // namespace
