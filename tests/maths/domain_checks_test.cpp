// The shared maths states each function's domain with REQUIRE (kernels/common/real.h): live
// in the C++ reference, where an out-of-domain argument throws instead of returning a wrong
// number; compiled out of the kernels. Values on the domain's edge are accepted.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>

#include "kinds/atmosphere/bake/reference.hpp"
#include "kinds/diffraction/reference.hpp"
#include "kinds/dispersion/reference.hpp"

namespace specbake {
namespace {

const double kNaN = std::numeric_limits<double>::quiet_NaN();

TEST(DomainChecks, PhaseFunctionsNeedACosine) {
  using namespace atmosphere::ref3;
  EXPECT_NO_THROW(rayleigh_phase(1.0));
  EXPECT_NO_THROW(rayleigh_phase(-1.0));
  EXPECT_THROW(rayleigh_phase(1.5), std::domain_error);
  EXPECT_THROW(rayleigh_phase(kNaN), std::domain_error);
  EXPECT_NO_THROW(mie_phase(0.8, 0.3));
  EXPECT_THROW(mie_phase(1.0, 0.3), std::domain_error);  // g = 1: the phase function is a delta
  EXPECT_THROW(mie_phase(0.8, -1.01), std::domain_error);
}

TEST(DomainChecks, TextureMappingsNeedAPointInsideTheAtmosphere) {
  using namespace atmosphere::ref3;
  AtmosphereParameters a{};
  a.bottom_radius = 6360.0;
  a.top_radius = 6420.0;
  a.transmittance_w = 256;
  a.transmittance_h = 64;
  a.irradiance_w = 64;
  a.irradiance_h = 16;
  double u = 0.0, v = 0.0;
  EXPECT_NO_THROW(transmittance_uv(&a, 0.0, -1.0, &u, &v));
  EXPECT_NO_THROW(transmittance_uv(&a, 60.0, 1.0, &u, &v));
  EXPECT_THROW(transmittance_uv(&a, 60.5, 0.0, &u, &v), std::domain_error);  // above the top
  EXPECT_THROW(transmittance_uv(&a, -1e-3, 0.0, &u, &v), std::domain_error);  // below the ground
  EXPECT_THROW(transmittance_uv(&a, 1.0, 1.0 + 1e-9, &u, &v), std::domain_error);
  EXPECT_THROW(irradiance_uv(&a, 1.0, kNaN, &u, &v), std::domain_error);
}

// Every texel centre of the transmittance and irradiance textures decodes to a point inside
// the atmosphere whatever the size: the top row's centre is x = 1 only up to rounding (12 rows:
// 1 + 2^-52, once an abort in the self-check of `sizes: auto` tries).
TEST(DomainChecks, TexelCentresOfEverySizeDecodeInside) {
  using namespace atmosphere::ref3;
  AtmosphereParameters a{};
  a.bottom_radius = 6360.0;
  a.top_radius = 6420.0;
  for (int n = 2; n <= 300; ++n) {
    a.transmittance_w = a.irradiance_w = 5;
    a.transmittance_h = a.irradiance_h = n;
    for (int id = 0; id < 5 * n; ++id) {
      double h = 0, mu = 0, u = 0, v = 0;
      ASSERT_NO_THROW(irradiance_texel_params(&a, id, &h, &mu)) << n << " rows, texel " << id;
      EXPECT_NO_THROW(irradiance_uv(&a, h, mu, &u, &v)) << n << " rows, texel " << id << ", h " << h;
      ASSERT_NO_THROW(transmittance_texel_params(&a, id, &h, &mu)) << n << " rows, texel " << id;
      EXPECT_NO_THROW(transmittance_uv(&a, h, mu, &u, &v)) << n << " rows, texel " << id << ", h " << h;
    }
  }
}

TEST(DomainChecks, ColourAndGlassTables) {
  using namespace dispersion::ref;
  const double table[6] = {0, 0, 0, 1, 1, 1};
  double xyz[3];
  EXPECT_NO_THROW(cmf_lerp(table, 2, 400.0, 400.5, xyz));
  EXPECT_THROW(cmf_lerp(table, 1, 400.0, 400.5, xyz), std::domain_error);
  const double B[1] = {1.0}, C[1] = {0.01};
  EXPECT_NO_THROW(sellmeier_ior(B, C, 1, 550.0));
  EXPECT_THROW(sellmeier_ior(B, C, 1, 0.0), std::domain_error);
  EXPECT_THROW(sellmeier_ior(B, C, 5, 550.0), std::domain_error);
}

TEST(DomainChecks, FrequencyBinsOfAnEmptyTransform) {
  using namespace diffraction::ref;
  EXPECT_EQ(bin_index(-1, 8), 7);
  EXPECT_THROW(bin_index(1, 0), std::domain_error);
}

}  // namespace
}  // namespace specbake
