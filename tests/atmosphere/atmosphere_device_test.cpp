// The OpenCL kernels: against the reference textures (full size, once), against the double
// reference path (small sizes), analytic cases, hard cases, layouts, and the CLI.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>

#include "atmosphere/npy.hpp"
#include "atmosphere/max_rel.hpp"
#include "atmosphere/sized.hpp"
#include "io/exr.hpp"
#include "kinds/atmosphere/atmosphere_job.hpp"
#include "kinds/atmosphere/bake/reference.hpp"
#include "support/testing.hpp"

using namespace specbake;
using namespace specbake::atmosphere;

namespace {

using specbake::testing::sized;

cl_util::Device& device() { return specbake::testing::shared_device(); }
const Progress kQuiet = [](std::string_view, double) {};

AtmosphereSpec earth() {
  AtmosphereSpec s;
  set_earth_profiles(s);  // Bruneton's demo Earth, as `preset: earth`
  return s;
}
AtmosphereSpec small(AtmosphereSpec s) { return sized(s, {32, 8}, {16, 4}, {5, 16, 8, 4}); }
// s at 16 wavelengths (one pass of 16 channels), `orders` orders.
AtmosphereSpec sixteen_wavelengths(AtmosphereSpec s, int orders) {
  s.spectral = true;
  s.count = 16;
  s.orders = orders;
  return s;
}

using specbake::testing::max_rel;
// The same over a scattering texture, split into the two rows of exactly tangent rays (the
// horizon: index 0 of the ground half and index MU − 1 of the sky half)
// and all other rows.
struct SplitError {
  double horizon = 0.0, rest = 0.0;
};
SplitError split_rel(const std::vector<double>& a, const std::vector<double>& b, const Sizes& s, double floor) {
  double mx[3] = {0, 0, 0};
  for (std::size_t i = 0; i < b.size(); ++i) mx[i % 3] = std::max(mx[i % 3], std::fabs(b[i]));
  SplitError e;
  const std::size_t wd = s.scattering_width();
  for (std::size_t i = 0; i < b.size(); ++i) {
    const int y = static_cast<int>((i / 3 / wd) % s.mu);
    const double v = std::fabs(a[i] - b[i]) / (std::fabs(b[i]) + floor * mx[i % 3] + 1e-300);
    double& slot = (y == 0 || y == s.mu - 1) ? e.horizon : e.rest;
    slot = std::max(slot, v);
  }
  return e;
}
// Every texture of a float32 bake within the float32 chain bound of another (reference) one.
void expect_within_float32_chain(double et, double ee, const SplitError& es, const SplitError& em, double bound) {
  EXPECT_LE(et, bound);
  EXPECT_LE(ee, bound);
  EXPECT_LE(es.rest, bound);
  EXPECT_LE(em.rest, bound);
  EXPECT_LE(es.horizon, bound);
  EXPECT_LE(em.horizon, bound);
}
void expect_finite(const std::vector<double>& v, const char* what) {
  for (std::size_t i = 0; i < v.size(); ++i)
    ASSERT_TRUE(std::isfinite(v[i])) << what << "[" << i << "] = " << v[i];
}
void expect_all_finite(const Baked& b) {
  expect_finite(b.luts.transmittance, "transmittance");
  expect_finite(b.luts.irradiance, "irradiance");
  expect_finite(b.luts.scattering, "scattering");
  expect_finite(b.luts.single_mie, "single_mie");
}

// float32 kernels against the double path (same functions, same inputs), relative to
// |value| + 1e-3 × the channel maximum. Per stage: transmittance sums 500 terms of one sign
// (≤ 500 · 2⁻²⁴ ≈ 3e-5 relative) and exponentiates optical depths up to ~20 (× 20: 6e-4);
// every other stage is a quadrature of ≤ 1024 non-negative terms (≤ 6e-5) of bilinear or
// trilinear lookups whose coordinates carry a few ulps of the altitude-based geometry (the
// header of atmosphere.cl: no cancellation larger than ~10 ulps, so ~1e-6 in a coordinate,
// times a texture's relative change per texel ≲ 10: 1e-5). The full bake chains transmittance,
// single scattering and three orders: ≤ 6e-4 + 7 · 1e-4 ≈ 1.3e-3; 3e-3 leaves a factor 2.
constexpr double kFloat32Chain = 3e-3;
// The job's self-check bound (bake/bake.cpp): one stage, float32 against double.
constexpr double kSelfCheckTolerance = 2e-3;
// float64 kernels against the double host path: the same maths in the same precision, but a
// different libm (exp: ≤ 1 ulp) and FMA contraction, so ~1e-15 per operation; amplified by the
// optical depths (≤ 30) and by lookups near the horizon rows, where a coordinate's rounding
// moves along the steepest texel gradients (≲ 1e6 per unit of coordinate): 1e-15 · 30 · 1e6
// ≈ 3e-8 relative, with the floor 1e-6 × the channel maximum.
constexpr double kFloat64Kernels = 3e-8;

std::string ref(const std::string& name) { return (specbake::testing::refdata_dir() / "atmosphere" / name).string(); }

}  // namespace

// One full-size Earth bake (rgb, 4 orders) against Bruneton's reference textures (double
// precision), relative to |value| + 1e-3 × the channel maximum: the float32 chain bound
// (kFloat32Chain), the two rows of exactly tangent rays included (their ray lengths come from
// the parameterisation, not from a discriminant that is 0 ± rounding; reported separately).
TEST(AtmosphereDevice, FullSizeEarthMatchesReferenceTextures) {
  AtmosphereSpec s = earth();  // with the reference's quadratures (`quadrature: reference`)
  s.use_reference_quadrature();
  const Baked b = bake_luts(s, device(), kQuiet, 0);
  expect_all_finite(b);
  const auto T = specbake::testing::read_npy(ref("textures/transmittance.npy"));
  const auto E = specbake::testing::read_npy(ref("textures/irradiance.npy"));
  const auto S = specbake::testing::read_npy(ref("textures/scattering.npy"));
  const auto M = specbake::testing::read_npy(ref("textures/single_mie_scattering.npy"));
  const double et = max_rel(b.luts.transmittance, T.data, 1e-3), ee = max_rel(b.luts.irradiance, E.data, 1e-3);
  const Sizes sz = model_of(earth()).sizes;
  const SplitError es = split_rel(b.luts.scattering, S.data, sz, 1e-3), em = split_rel(b.luts.single_mie, M.data, sz, 1e-3);
  std::printf("full size vs reference: T %.3g  E %.3g  S %.3g (horizon rows %.3g)  M %.3g (horizon rows %.3g)\n",
              et, ee, es.rest, es.horizon, em.rest, em.horizon);
  expect_within_float32_chain(et, ee, es, em, kFloat32Chain);
  EXPECT_EQ(b.orders_used, 4);
}

// float32 OpenCL against the double host path at small sizes, and float64 OpenCL against it.
TEST(AtmosphereDevice, SmallSizesMatchDoubleReference) {
  const AtmosphereSpec s = small(earth());
  const Baked host = bake_luts_reference(s);
  const Baked dev = bake_luts(s, device(), kQuiet, 8);
  expect_all_finite(dev);
  const Sizes sz = model_of(s).sizes;
  const double et = max_rel(dev.luts.transmittance, host.luts.transmittance, 1e-3),
               ee = max_rel(dev.luts.irradiance, host.luts.irradiance, 1e-3);
  const SplitError es = split_rel(dev.luts.scattering, host.luts.scattering, sz, 1e-3),
                   em = split_rel(dev.luts.single_mie, host.luts.single_mie, sz, 1e-3);
  std::printf("float32 vs double: T %.3g  E %.3g  S %.3g (horizon rows %.3g)  M %.3g (horizon rows %.3g)  "
              "self-check %.3g\n", et, ee, es.rest, es.horizon, em.rest, em.horizon, dev.self_check_worst);
  expect_within_float32_chain(et, ee, es, em, kFloat32Chain);
  EXPECT_LE(dev.self_check_worst, kSelfCheckTolerance);
  if (device().info().fp64) {
    AtmosphereSpec d = s;
    d.double_precision = true;
    const Baked dd = bake_luts(d, device(), kQuiet, 0);
    const double dt = max_rel(dd.luts.transmittance, host.luts.transmittance, 1e-6),
                 de = max_rel(dd.luts.irradiance, host.luts.irradiance, 1e-6),
                 ds = max_rel(dd.luts.scattering, host.luts.scattering, 1e-6),
                 dm = max_rel(dd.luts.single_mie, host.luts.single_mie, 1e-6);
    std::printf("float64 device vs double host: T %.3g  E %.3g  S %.3g  M %.3g\n", dt, de, ds, dm);
    EXPECT_LE(dt, kFloat64Kernels);
    EXPECT_LE(de, kFloat64Kernels);
    EXPECT_LE(ds, kFloat64Kernels);
    EXPECT_LE(dm, kFloat64Kernels);
  }
}

// On a CPU device the density kernel takes the suns of a ν row in lanes of 8 and the single-
// and multiple-scattering kernels 8 texels of a row per work item (LANES in atmosphere.cl); the
// double host path takes one at a time. A row of 11 slices × 4 (44 texels: full
// chunks of lanes and a partial one, whose unused lanes are discarded) gives the same textures:
// float64 device against the double host within kFloat64Kernels, float32 within the chain bound.
TEST(AtmosphereDevice, RowsOfSeveralLaneChunksMatchDoubleReference) {
  AtmosphereSpec s = small(earth());
  s.scattering_mu_s = 4;
  s.scattering_nu = 11;
  const Baked host = bake_luts_reference(s);
  const Sizes sz = model_of(s).sizes;
  const Baked dev = bake_luts(s, device(), kQuiet, 4);
  const SplitError es = split_rel(dev.luts.scattering, host.luts.scattering, sz, 1e-3),
                   em = split_rel(dev.luts.single_mie, host.luts.single_mie, sz, 1e-3);
  std::printf("NU = 11, float32 vs double: S %.3g (horizon rows %.3g)  M %.3g (horizon rows %.3g)\n", es.rest,
              es.horizon, em.rest, em.horizon);
  for (const double e : {es.rest, es.horizon, em.rest, em.horizon}) EXPECT_LE(e, kFloat32Chain);
  if (device().info().fp64) {
    s.double_precision = true;
    const Baked dd = bake_luts(s, device(), kQuiet, 0);
    const double ds = max_rel(dd.luts.scattering, host.luts.scattering, 1e-6),
                 dm = max_rel(dd.luts.single_mie, host.luts.single_mie, 1e-6);
    std::printf("NU = 11, float64 device vs double host: S %.3g  M %.3g\n", ds, dm);
    EXPECT_LE(ds, kFloat64Kernels);
    EXPECT_LE(dm, kFloat64Kernels);
  }
}

// Other devices get LANES = 1: one texel per work item, one sun at a time in the density (the
// code a GPU runs). Per texel the operations and their order do not depend on LANES (the
// compiler fuses multiply-adds per source expression, before any vectorisation), so the same
// device told it is a GPU must bake the same textures bit for bit, rows of 44 texels and 11
// suns included (a partial chunk of 8 lanes).
TEST(AtmosphereDevice, OneLaneAsOnAGpuBakesTheSameBits) {
  cl_util::DeviceInfo info = cl_util::select_device("auto");
  if (info.type != "cpu") GTEST_SKIP() << "the test device already runs one lane (" << info.type << ")";
  AtmosphereSpec s = small(earth());
  s.scattering_mu_s = 4;
  s.scattering_nu = 11;
  s.orders = 3;
  const Baked lanes = bake_luts(s, device(), kQuiet, 0);
  info.type = "gpu";
  cl_util::Device one_lane(info);
  const Baked one = bake_luts(s, one_lane, kQuiet, 0);
  EXPECT_EQ(one.luts.transmittance, lanes.luts.transmittance);
  EXPECT_EQ(one.luts.scattering, lanes.luts.scattering);
  EXPECT_EQ(one.luts.single_mie, lanes.luts.single_mie);
  EXPECT_EQ(one.luts.irradiance, lanes.luts.irradiance);
}

// Beer–Lambert: constant density, Rayleigh only: T(r, mu) = exp(−β d(r, mu)); the trapezoid
// of a constant is exact, so only float32 rounding remains (β d ≤ ~30: ≤ 30 · 500 · 2^-24).
TEST(AtmosphereDevice, BeerLambertConstantShell) {
  AtmosphereSpec s = small(earth());
  s.mie = false;
  s.ozone = false;
  s.rayleigh_density[0] = DensityLayer{};
  s.rayleigh_density[1] = DensityLayer{0, 0, 0, 0, 1.0};
  s.orders = 1;
  const Baked b = bake_luts(s, device(), kQuiet, 0);
  const Model m = model_of(s);
  const Channels ch = channels_at(s, {kLambdaR, kLambdaG, kLambdaB});
  const auto a = ref3::make_parameters(m, ch);
  double worst = 0.0;
  for (int j = 0; j < m.sizes.transmittance_h; ++j)
    for (int i = 0; i < m.sizes.transmittance_w; ++i) {
      double h, mu;
      ref3::h_mu_from_transmittance_uv(&a, (i + 0.5) / m.sizes.transmittance_w, (j + 0.5) / m.sizes.transmittance_h,
                                       &h, &mu);
      const double d = ref3::distance_to_top(&a, h, mu);
      for (int c = 0; c < 3; ++c) {
        const double want = std::exp(-ch.rayleigh_scattering[c] * d);
        const double got = b.luts.transmittance[(j * m.sizes.transmittance_w + i) * 3 + c];
        worst = std::max(worst, std::fabs(got - want) / want);
      }
    }
  EXPECT_LE(worst, 30 * 500 * 6e-8);
}

// No scatterers: no scattering and no sky light anywhere, exactly.
TEST(AtmosphereDevice, ZeroCoefficientsGiveZeroScattering) {
  AtmosphereSpec s = small(earth());
  s.mie = false;
  s.rayleigh = false;
  const Baked b = bake_luts(s, device(), kQuiet, 0);
  for (double v : b.luts.scattering) ASSERT_EQ(v, 0.0);
  for (double v : b.luts.single_mie) ASSERT_EQ(v, 0.0);
  for (double v : b.luts.irradiance) ASSERT_EQ(v, 0.0);
  double min_t = 1.0;
  for (double v : b.luts.transmittance) min_t = std::min(min_t, v);
  EXPECT_LT(min_t, 1.0);  // ozone still absorbs
}

// Energy: a thin, non-absorbing, constant-density Rayleigh shell over a black ground, sun at
// the zenith. Single scattering removes E·(1 − T) from the vertical beam; for τ ≪ 1 that light
// leaves as the sky irradiance at the ground plus the upward flux at the top, half each for a
// symmetric phase function. Curvature of the 60 km shell (the horizon rays' paths are shorter
// than h/μ) and the 16-θ midpoint rule of the irradiance integral make the balance inexact:
// an independent integral of the curved-shell geometry bounds their effect at 3 %.
TEST(AtmosphereDevice, EnergyConservedForThinConservativeShell) {
  AtmosphereSpec s = sized(earth(), {64, 16}, {16, 4}, {8, 64, 8, 8});
  s.mie = false;
  s.ozone = false;
  s.ground_albedo = 0.0;
  s.rayleigh_density[0] = DensityLayer{};
  s.rayleigh_density[1] = DensityLayer{0, 0, 0, 0, 1.0};
  s.rayleigh_scattering_per_m_at_1um = 1e-9;  // τ ≈ 6e-5 / λ_um^4
  s.orders = 2;                                // irradiance.bin then holds order 1 exactly
  const Baked b = bake_luts(s, device(), kQuiet, 0);
  const Renderer render(b.luts);
  const Model& m = b.luts.model;
  const double rb = m.bottom_radius_km, rt = m.top_radius_km;
  const Vec3 sun{0, 0, 1};
  const int last = m.sizes.irradiance_w - 1;  // texel (r = rb, mu_s = 1)
  for (int c = 0; c < 3; ++c) {
    const double e_sun = b.luts.rgb.solar_irradiance[c];
    const double removed = e_sun * (1.0 - render.transmittance_to_top(rb, 1.0)[c]);
    const double down = b.luts.irradiance[last * 3 + c];
    // upward flux at the top: ∫ L(view down) |μ| dΩ, L from the baked LUTs (azimuthal symmetry)
    double up = 0.0;
    const int n = 4000;
    for (int k = 0; k < n; ++k) {
      const double mu = -(k + 0.5) / n;
      const Vec3 l = render.sky_radiance({0, 0, rt - 1e-6}, {std::sqrt(1 - mu * mu), 0, mu}, sun, nullptr);
      up += l[c] * -mu * 2.0 * M_PI / n;
    }
    EXPECT_NEAR((down + up) / removed, 1.0, 0.03) << "channel " << c << " down " << down << " up " << up;
  }
}

// The density of a uniform light: with L ≡ L₀ from every direction (order 3's incoming light a
// constant texture, black ground) J = (β_R ρ_R + β_M ρ_M) L₀ exactly, Σ P dω = 1 for each phase
// function. With the phase weights normalised (the default) every texel holds it to rounding
// (a double sum of 16 × 64 terms, each rounded to ~1e-16 relative: ≤ 1e-13); as the 16-node horizon rule
// gives them ("plain", the reference's way), the Mie phase of g 0.8 weighs 0.97–1.17 and the
// texels stray by up to ~10 % (atmosphere.cl, density_phase_factors) — at least 1 % somewhere.
TEST(AtmosphereDevice, DensityScattersAUniformLightExactly) {
  for (const bool normalised : {true, false}) {
    AtmosphereSpec s = small(earth());
    s.ground_albedo = 0.0;
    s.phase_weights_normalised = normalised;
    const Model m = model_of(s);
    const Channels ch = channels_at(s, {kLambdaR, kLambdaG, kLambdaB});
    const auto a = ref3::make_parameters(m, ch);
    const Sizes& z = m.sizes;
    const double L0 = 0.37;
    const std::vector<double> T(3LL * z.transmittance_w * z.transmittance_h, 1.0);
    const std::vector<double> E(3LL * z.irradiance_w * z.irradiance_h, 0.0);
    const std::vector<double> zero(3 * z.scattering_texels(), 0.0), uniform(3 * z.scattering_texels(), L0);
    const int stride = ref3::incidence_stride(&a);
    double worst = 0.0;
    for (int zr = 0; zr < z.r; ++zr)
      for (int y = 0; y < z.mu; ++y)
        for (int x = 0; x < z.nu * z.mu_s; ++x) {
          double h, mu, mu_s, nu;
          int ground;
          ref3::scattering_params_from_texel(&a, x, y, zr, &h, &mu, &mu_s, &nu, &ground);
          std::vector<double> incidence(static_cast<std::size_t>(a.density_theta) * stride);
          for (int l = 0; l < a.density_theta; ++l)
            ref3::density_incidence(&a, T.data(), zero.data(), zero.data(), uniform.data(), h, mu_s, 3, l,
                                    &incidence[l * stride]);
          double f_r, f_m, j[3];
          ref3::density_phase_factors(&a, mu, &f_r, &f_m);
          ref3::scattering_density(&a, incidence.data(), E.data(), h, mu, mu_s, &nu, 1, 3, f_r, f_m, j);
          const double rho_r = ref3::profile_density(&a.rayleigh_density, h);
          const double rho_m = ref3::profile_density(&a.mie_density, h);
          for (int c = 0; c < 3; ++c) {
            const double want = (a.rayleigh_scattering[c] * rho_r + a.mie_scattering[c] * rho_m) * L0;
            worst = std::max(worst, std::fabs(j[c] - want) / want);
          }
        }
    if (normalised)
      EXPECT_LE(worst, 1e-13);
    else
      EXPECT_GT(worst, 0.01);
  }
}

// Each order adds less than the previous one (Earth: single-scattering albedo < 1, ground 0.1).
TEST(AtmosphereDevice, OrdersDecrease) {
  AtmosphereSpec s = small(earth());
  s.orders = 6;
  const Baked b = bake_luts(s, device(), kQuiet, 0);
  ASSERT_EQ(b.orders.size(), 6u);
  for (std::size_t o = 2; o < b.orders.size(); ++o)
    for (int c = 0; c < 3; ++c) {
      EXPECT_LT(b.orders[o]["scattering"]["max"][c].get<double>(), b.orders[o - 1]["scattering"]["max"][c].get<double>());
      EXPECT_LT(b.orders[o]["scattering"]["mean"][c].get<double>(),
                b.orders[o - 1]["scattering"]["mean"][c].get<double>());
    }
}

TEST(AtmosphereDevice, AutoOrdersStopAtTolerance) {
  AtmosphereSpec s = small(earth());
  s.orders.reset();
  s.tolerance = 1e-2;
  const Baked b = bake_luts(s, device(), kQuiet, 0);
  EXPECT_TRUE(b.converged);
  ASSERT_GE(b.orders_used, 2);
  EXPECT_LT(b.orders.back()["relative_change"].get<double>(), 1e-2);
  EXPECT_GE(b.orders[b.orders.size() - 2]["relative_change"].get<double>(), 1e-2);
}

// geometric_tail (atmosphere.cl) on a geometric sequence J_k = ρ^k is exactly the series from
// k = n on: ρ^n / (1 − ρ), to rounding (a few ulps of double); its ratio is clamped to [0, 0.9]
// and it adds nothing where the order before is not positive.
TEST(AtmosphereOrdersTail, GeometricTailSumsAGeometricSeries) {
  for (double rho : {0.05, 0.3, 0.51, 0.85})
    for (int n : {3, 4, 6}) {
      double series = 0.0;
      for (int k = n; k < 4000; ++k) series += std::pow(rho, k);
      EXPECT_NEAR(ref3::geometric_tail(std::pow(rho, n), std::pow(rho, n - 1)), series, 1e-13 * series)
          << "rho " << rho << ", n " << n;
    }
  EXPECT_DOUBLE_EQ(ref3::geometric_tail(2.0, 1.0), 2.0 / (1.0 - 0.9));  // a ratio above 0.9: clamped
  EXPECT_DOUBLE_EQ(ref3::geometric_tail(-1e-9, 1.0), -1e-9);            // a negative ratio: 0
  EXPECT_DOUBLE_EQ(ref3::geometric_tail(0.5, 0.0), 0.5);                 // nothing before it: no tail
}

// orders_tail: geometric on the device against the double reference's tailed bake (the same
// tail after the same stages). The tail divides by 1 − ρ, ρ = J_n / J_(n−1): a relative error ε
// in each density becomes ≤ 2ε in ρ and ≤ 2ε ρ/(1 − ρ) more in the result, ≤ 18ε at the clamp
// ρ ≤ 0.9 — so the float32 chain bound times 19. And it stands for the orders beyond the last:
// the small Earth's 4 orders + tail against 40 orders (the series converged far below float32)
// must leave at most a quarter of what 4 plain orders leave, in the scattering and the
// irradiance, relative to the channel's largest value (from order 5 on this Earth's orders fall
// by a nearly constant ratio at each texel, so a series from order 4's own ratio is within a few
// per cent of their sum; a tail that missed its texels' ratios, or added nothing, fails this).
// Where 4 plain orders are below the converged value, the tailed bake is not further below.
TEST(AtmosphereOrdersTail, TheTailMatchesTheReferenceAndStandsForTheOrdersBeyond) {
  AtmosphereSpec s = small(earth());
  s.orders = 4;
  s.orders_tail = true;
  const Baked host = bake_luts_reference(s);
  const Baked dev = bake_luts(s, device(), kQuiet, 8);
  expect_all_finite(dev);
  const Sizes sz = model_of(s).sizes;
  const double ee = max_rel(dev.luts.irradiance, host.luts.irradiance, 1e-3);
  const SplitError es = split_rel(dev.luts.scattering, host.luts.scattering, sz, 1e-3);
  std::printf("tail, float32 vs double: E %.3g  S %.3g (horizon rows %.3g)  self-check %.3g\n", ee, es.rest,
              es.horizon, dev.self_check_worst);
  EXPECT_LE(ee, 19 * kFloat32Chain);
  EXPECT_LE(es.rest, 19 * kFloat32Chain);
  EXPECT_LE(es.horizon, 19 * kFloat32Chain);
  EXPECT_LE(dev.self_check_worst, kSelfCheckTolerance);

  AtmosphereSpec plain = s, all = s;
  plain.orders_tail = false;
  all.orders_tail = false;
  all.orders = 40;
  const Baked p = bake_luts_reference(plain), a = bake_luts_reference(all);
  // the largest |x − a| over texels and channels, relative to the channel's largest value of a
  auto off = [](const std::vector<double>& x, const std::vector<double>& a) {
    std::array<double, 3> mx{};
    for (std::size_t i = 0; i < a.size(); ++i) mx[i % 3] = std::max(mx[i % 3], std::fabs(a[i]));
    double e = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i) e = std::max(e, std::fabs(x[i] - a[i]) / mx[i % 3]);
    return e;
  };
  const double plain_s = off(p.luts.scattering, a.luts.scattering), tail_s = off(host.luts.scattering, a.luts.scattering),
               plain_e = off(p.luts.irradiance, a.luts.irradiance), tail_e = off(host.luts.irradiance, a.luts.irradiance);
  std::printf("against 40 orders: scattering 4 orders %.3g, + tail %.3g; irradiance %.3g, + tail %.3g\n", plain_s,
              tail_s, plain_e, tail_e);
  EXPECT_LE(tail_s, 0.25 * plain_s);
  EXPECT_LE(tail_e, 0.25 * plain_e);
  for (std::size_t i = 0; i < a.luts.scattering.size(); ++i)
    ASSERT_GE(host.luts.scattering[i], p.luts.scattering[i] - 1e-12 * std::fabs(p.luts.scattering[i])) << i;
}

// Tiny and odd sizes work and give finite values everywhere.
TEST(AtmosphereDevice, TinyAndOddSizes) {
  AtmosphereSpec s = earth();
  s.transmittance_mu = s.transmittance_r = s.irradiance_mu_s = s.irradiance_r = 2;
  s.scattering_r = s.scattering_mu = s.scattering_mu_s = s.scattering_nu = 2;
  expect_all_finite(bake_luts(s, device(), kQuiet, 4));
  s = sized(s, {7, 5}, {5, 3}, {3, 6, 5, 3});
  const Baked b = bake_luts(s, device(), kQuiet, 4);
  expect_all_finite(b);
  EXPECT_LE(b.self_check_worst, kSelfCheckTolerance);
}

// Many items, wide channels, many ν slices: 16 channels at NU = 20 with 16 × 54 (r, μ_s) give
// the density's incidence table 55296 items; a CPU device left to choose its work group took 3456
// of them, whose private copies (~2.8 KB each) overran the worker thread's 8 MiB stack and killed
// the process (SIGSEGV). A larger NU (the limit, 64) holds the most private memory per item.
TEST(AtmosphereDevice, WideSpectralPassesWithManyNuSlicesBake) {
  AtmosphereSpec s = sixteen_wavelengths(sized(earth(), {32, 8}, {16, 4}, {16, 8, 54, 20}), 2);
  const Baked b = bake_luts(s, device(), kQuiet, 4);
  expect_all_finite(b);
  EXPECT_LE(b.self_check_worst, kSelfCheckTolerance);
  s = sized(s, {32, 8}, {16, 4}, {4, 8, 16, ATMOSPHERE_NU_LIMIT});
  expect_all_finite(bake_luts(s, device(), kQuiet, 4));
}

// Hard cases on the sampling side: the horizon from both sides, r at both ends, the sun below
// mu_s_min, nu at its limits, tangent rays: finite, non-negative, and continuous where the
// geometry is (a hair above and at the horizon on the sky side).
TEST(AtmosphereDevice, HardCasesOnTheSamplingSide) {
  const Baked b = bake_luts(small(earth()), device(), kQuiet, 0);
  const Renderer render(b.luts);
  const Model& m = b.luts.model;
  const double rb = m.bottom_radius_km, rt = m.top_radius_km;
  for (double r : {rb, rb + 1e-6, rb + 0.5, 0.5 * (rb + rt), rt - 1e-6, rt}) {
    const double mu_h = -std::sqrt(std::max(0.0, 1.0 - (rb / r) * (rb / r)));
    for (double dmu : {-1e-3, -1e-6, 0.0, 1e-6, 1e-3})
      for (double mu_s : {-1.0, -0.5, m.mu_s_min - 1e-3, m.mu_s_min, 0.0, 0.3, 1.0}) {
        const double mu = std::clamp(mu_h + dmu, -1.0, 1.0);
        const double s_mu = std::sqrt((1 - mu * mu) * (1 - mu_s * mu_s));
        for (double nu : {mu * mu_s - s_mu, mu * mu_s, mu * mu_s + s_mu}) {
          for (bool ground : {false, true}) {
            const Vec3 v = render.scattering_3d(r, mu, mu_s, nu, ground, false);
            const Vec3 w = render.scattering_3d(r, mu, mu_s, nu, ground, true);
            for (int c = 0; c < 3; ++c) {
              ASSERT_TRUE(std::isfinite(v[c]) && v[c] >= 0.0) << r << " " << mu << " " << mu_s << " " << nu;
              ASSERT_TRUE(std::isfinite(w[c]) && w[c] >= 0.0);
            }
          }
          const Vec3 camera{0, 0, r};
          const Vec3 sun{std::sqrt(1 - mu_s * mu_s), 0, mu_s};
          Vec3 t{};
          const Vec3 l = render.sky_radiance(camera, {std::sqrt(1 - mu * mu), 0, mu}, sun, &t);
          for (int c = 0; c < 3; ++c) ASSERT_TRUE(std::isfinite(l[c]) && std::isfinite(t[c]));
        }
      }
  }
  // Sun below mu_s_min clamps to the mu_s_min texels: the lookups are equal.
  const Vec3 a = render.scattering_3d(rb + 1, 0.2, -0.9, 0.0, false, false);
  const Vec3 c = render.scattering_3d(rb + 1, 0.2, m.mu_s_min - 0.05, 0.0, false, false);
  for (int k = 0; k < 3; ++k) EXPECT_DOUBLE_EQ(a[k], c[k]);
}

// The tiled-2D layout sampled through the GLSL-equivalent host code equals the 3D layout
// (both are exact interpolations of the same texels; double rounding only).
TEST(AtmosphereDevice, Tiled2dSamplesEqual3d) {
  const Baked b = bake_luts(small(earth()), device(), kQuiet, 0);
  const Renderer render(b.luts);
  const Model& m = b.luts.model;
  const auto tiled = to_tiled2d(b.luts.scattering, m.sizes);
  unsigned state = 12345;
  auto uniform = [&] {
    state = state * 1664525u + 1013904223u;
    return (state >> 8) / 16777216.0;
  };
  const auto pa = ref3::make_parameters(m, Channels{});
  double worst = 0.0, scale = 0.0;
  for (double v : b.luts.scattering) scale = std::max(scale, v);
  for (int i = 0; i < 2000; ++i) {
    const double r = m.bottom_radius_km + uniform() * (m.top_radius_km - m.bottom_radius_km);
    const double mu = 2 * uniform() - 1, mu_s = 2 * uniform() - 1;
    const double s_mu = std::sqrt((1 - mu * mu) * (1 - mu_s * mu_s));
    const double nu = mu * mu_s + (2 * uniform() - 1) * s_mu;
    const bool ground = ref3::ray_hits_ground(&pa, r - m.bottom_radius_km, mu);
    const Vec3 a = render.scattering_3d(r, mu, mu_s, nu, ground, false);
    const Vec3 t = sample_tiled2d(m, tiled, r, mu, mu_s, nu, ground);
    for (int c = 0; c < 3; ++c) worst = std::max(worst, std::fabs(a[c] - t[c]));
  }
  EXPECT_LE(worst, 1e-12 * scale);
}

// Sizes an auto search chose for the default ground scene (16 wavelengths, 144 μ and 54 μ_s
// texels): at the ground with the sun just below the horizon the indirect irradiance of order
// 1 is ~0, and the float32 lookups near the sun's edge move it by ~2e-6 of the channel's
// maximum, which the self-check's floor (1 % of the maximum, bake/bake.cpp) must allow; a
// floor of 1e-3 failed this bake (2.3e-3 > 2e-3).
TEST(AtmosphereDevice, SelfCheckAllowsTheSunsEdgeAtFineSizes) {
  const AtmosphereSpec s = sixteen_wavelengths(sized(earth(), {128, 32}, {72, 18}, {16, 144, 54, 6}), 4);
  const Baked b = bake_luts(s, device(), kQuiet, 4);
  std::printf("self-check worst %.3g\n", b.self_check_worst);
  EXPECT_LE(b.self_check_worst, kSelfCheckTolerance);
}

TEST(AtmosphereDevice, SpectralBakeRunsAndIsFinite) {
  AtmosphereSpec s = small(earth());
  s.spectral = true;
  s.count = 6;
  s.orders = 2;
  const Baked b = bake_luts(s, device(), kQuiet, 4);
  expect_all_finite(b);
  EXPECT_EQ(channels_per_pass(s), 8);
  EXPECT_EQ(b.passes.size(), 1u);  // 6 wavelengths in one pass of 8 (two dark channels)
  std::printf("spectral self-check worst %.3g\n", b.self_check_worst);
  EXPECT_LE(b.self_check_worst, kSelfCheckTolerance);
  double sum = 0.0;
  for (double v : b.luts.scattering) sum += v;
  EXPECT_GT(sum, 0.0);
}

// A channel's values must not depend on the width of the pass it is baked in (the widths
// share the geometry, never the channels): the same 3 wavelengths baked in passes of 3, 4, 8
// and 16 channels. Every channel is computed by the same float32 operations whatever the
// width, so the only freedom is the compiler's choice of fused multiply-adds and vector
// lanes; a stage is a sum of ≤ 1024 terms of one sign, each off by a few ulps at most, so a
// texel moves by ≤ 1024 · 4 · 2⁻²⁴ ≈ 2.4e-4 relative per stage in the worst case (3 orders
// compound to < 1e-3; measured: see the printed figure). The channels past the wavelengths
// have no sun and must stay exactly 0. A width mixing channels up gives O(1) differences.
TEST(AtmosphereDevice, PassWidthDoesNotChangeAChannel) {
  AtmosphereSpec s = small(earth());
  s.spectral = true;
  s.count = 3;
  const Model m = model_of(s);
  const Channels ch = channels_at(s, spectrum_of(s).lambda_nm);
  ASSERT_EQ(ch.size(), 3u);
  const PassPlan plan{3, false, 1e-3};
  std::vector<PassResult> results;
  for (int w : kPassWidths) {
    auto b = make_device_backend(device(), m, ch, w, false);
    results.push_back(run_pass(*b, plan, kQuiet, 0.0, 1.0));
  }
  auto channels = [](const std::vector<double>& v, int w) {
    std::vector<double> out;
    for (std::size_t i = 0; i < v.size(); i += w)
      for (int c = 0; c < 3; ++c) out.push_back(v[i + c]);
    return out;
  };
  double worst = 0.0;
  for (std::size_t k = 1; k < results.size(); ++k) {
    const PassResult& r = results[k];
    const int w = r.width;
    ASSERT_EQ(w, kPassWidths[k]);
    using Texture = std::vector<double> PassResult::*;
    for (Texture tex : {&PassResult::transmittance, &PassResult::irradiance, &PassResult::scattering,
                        &PassResult::single_mie}) {
      const std::vector<double>& v = r.*tex;
      const std::vector<double>& base = results[0].*tex;
      worst = std::max(worst, max_rel(channels(v, w), base, 1e-3));
      if (tex == &PassResult::transmittance) continue;  // no sun in a dark channel, but T is 1 there
      for (std::size_t i = 0; i < v.size(); i += w)
        for (int c = 3; c < w; ++c) ASSERT_EQ(v[i + c], 0.0) << "dark channel " << c << " of width " << w;
    }
  }
  std::printf("pass widths 4, 8, 16 against 3: worst relative difference %.3g\n", worst);
  EXPECT_LE(worst, 1e-3);
}

// A device without cl_khr_fp64 (PoCL with the capability masked): the float32 bake works and
// self-checks within the same bound, and `precision: double` is refused with a clear error.
TEST(AtmosphereDevice, FloatOnlyDeviceBakesAndRefusesDouble) {
  cl_util::DeviceInfo info = cl_util::select_device("auto");
  info.fp64 = false;
  cl_util::Device float_only(info);
  AtmosphereSpec s = small(earth());
  s.orders = 3;
  const Baked b = bake_luts(s, float_only, kQuiet, 8);
  expect_all_finite(b);
  EXPECT_LE(b.self_check_worst, kSelfCheckTolerance);
  s.double_precision = true;
  try {
    bake_luts(s, float_only, kQuiet, 0);
    ADD_FAILURE() << "double precision accepted on a device without fp64";
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("cl_khr_fp64"), std::string::npos) << e.what();
  }
}

// Multiple scattering in work groups that share each (μ, r) row's blend of J in local memory,
// against one work item per texel (the form for a device whose local memory cannot hold a
// row), and with work groups smaller than the row (items take several rounds: 3 items of a row of
// 32 texels, on a CPU device 8 texels per item, so the second round is partial). Both forms make the same operations in the same order,
// so the textures differ at most by the compiler's contraction of a multiply and add into an
// FMA (one rounding, 2⁻²⁴ relative, per operation) in sums of ≤ 51 non-negative terms of
// trilinear blends (≤ 10 operations each) carried through ≤ 3 orders of multiple scattering:
// ≤ 3 · 51 · 10 · 6e-8 ≈ 1e-4 relative; 1e-4 is the bound, what a
// different texel, slice or weight would exceed by orders of magnitude.
TEST(AtmosphereDevice, RowGroupsMatchPerTexelMultipleScattering) {
  AtmosphereSpec s = small(earth());
  s.orders = 4;
  const Baked rows = bake_luts(s, device(), kQuiet, 0);
  cl_util::DeviceInfo info = cl_util::select_device("auto");
  info.local_mem_bytes = 0;
  cl_util::Device no_local(info);
  const Baked texels = bake_luts(s, no_local, kQuiet, 0);
  info = cl_util::select_device("auto");
  info.max_work_group_size = 3;
  cl_util::Device small_groups(info);
  const Baked partial = bake_luts(s, small_groups, kQuiet, 0);
  const double per_texel = max_rel(rows.luts.scattering, texels.luts.scattering, 1e-6);
  const double two_rounds = max_rel(partial.luts.scattering, rows.luts.scattering, 1e-6);
  std::printf("multiple scattering by rows vs per texel %.3g, groups of 3 vs whole rows %.3g\n", per_texel,
              two_rounds);
  EXPECT_LE(per_texel, 1e-4);
  EXPECT_LE(two_rounds, 1e-4);
  EXPECT_LE(max_rel(rows.luts.irradiance, texels.luts.irradiance, 1e-6), 1e-4);  // fed by the same textures
}

// The self-checks judge every stage on the inputs the device actually used. A backend (the
// double reference standing in for a device) whose multiple scattering of order 2 comes out
// 1 % high: that stage's check sees ~1e-2, and every other check — including the density of
// order 3 and the indirect irradiance of order 2, which read the corrupted texture — sees only
// the reference against itself (0 up to rounding in the sums, < 1e-12). A checker that kept
// an older copy of a texture, or read a stage's inputs from the wrong generation, would flag
// those later stages too; one that skipped re-reading outputs would miss the corruption.
// The double reference standing in for a device, with `corrupt` applied to its textures after
// each stage (the stage and its order as run_pass numbers them).
class Corrupting final : public PassBackend {
 public:
  using Corrupt = std::function<void(PassStage, int, ref3::HostBackend&)>;
  Corrupting(const Model& m, const Channels& ch, Corrupt corrupt)
      : b_(m, ch), corrupt_(std::move(corrupt)), sums_(make_host_sums(*this, m)) {}
  int channels() const override { return b_.channels(); }
  void transmittance() override { run(PassStage::transmittance, 0, [&] { b_.transmittance(); }); }
  void direct_irradiance() override { run(PassStage::direct_irradiance, 0, [&] { b_.direct_irradiance(); }); }
  void single_scattering() override { run(PassStage::single_scattering, 1, [&] { b_.single_scattering(); }); }
  void scattering_density(int order) override {
    order_ = order;
    run(PassStage::scattering_density, order, [&] { b_.scattering_density(order); });
  }
  void indirect_irradiance(int order) override {
    run(PassStage::indirect_irradiance, order, [&] { b_.indirect_irradiance(order); });
  }
  void multiple_scattering() override { run(PassStage::multiple_scattering, order_, [&] { b_.multiple_scattering(); }); }
  void read_into(Tex t, std::vector<double>& out) override {
    ++reads;
    b_.read_into(t, out);
  }
  void gather(Tex t, const std::vector<int>& ids, std::vector<double>& out) override {
    gathered += static_cast<long long>(ids.size());
    b_.gather(t, ids, out);
  }
  Scan scan(Tex t) override {
    ++scans;
    return b_.scan(t);
  }
  Sums& sums() override { return *sums_; }  // the host's, reading through read_into (counted)
  void use_channels(const Channels& ch) override { b_.use_channels(ch); }
  void add_density_sum(int order) override { b_.add_density_sum(order); }
  void sky_view(int orders_used, std::vector<double>& out) override { b_.sky_view(orders_used, out); }
  void keep_density() override { b_.keep_density(); }
  void density_tail() override { b_.density_tail(); }
  int reads = 0;             // whole-texture reads, by anyone
  long long gathered = 0;    // texels gathered
  int scans = 0;             // whole-texture scans

 private:
  template <class F>
  void run(PassStage stage, int order, F&& f) {
    f();
    corrupt_(stage, order, b_);
  }
  ref3::HostBackend b_;
  Corrupt corrupt_;
  std::unique_ptr<Sums> sums_;
  int order_ = 0;
};

TEST(AtmosphereSelfCheck, EachStageIsJudgedOnTheInputsTheDeviceUsed) {
  const AtmosphereSpec s = small(earth());
  const Model m = model_of(s);
  const Channels ch = channels_at(s, {680.0, 550.0, 440.0});
  Corrupting b(m, ch, [](PassStage stage, int order, ref3::HostBackend& h) {
    if (stage != PassStage::multiple_scattering || order != 2) return;
    for (double& x : h.texture(Tex::delta_multiple)) x *= 1.01;
  });
  auto checker = make_stage_checker(m, ch, 3, 64, 1e-3);
  std::vector<StageCheck> checks;
  run_pass(b, PassPlan{4, false, 1e-3}, kQuiet, 0.0, 1.0, checker.get(),
           [&](const StageCheck& c) { checks.push_back(c); });
  int corrupted = 0;
  for (const StageCheck& c : checks) {
    SCOPED_TRACE(c.stage + " order " + std::to_string(c.order));
    if (c.stage == "multiple_scattering" && c.order == 2) {
      ++corrupted;
      // |1.01 x − x| / (|x| + 1e-3 max) ≤ 0.01, and = 0.01/(1 + 1e-3 max/|x|) at the texels checked
      EXPECT_GT(c.max_rel, 0.005);
      EXPECT_LE(c.max_rel, 0.0100001);
    } else {
      EXPECT_LT(c.max_rel, 1e-12);
    }
  }
  EXPECT_EQ(corrupted, 1);
}

// The checks read no whole texture: per stage they scan its outputs where they are and gather
// the sampled texels and the input texels their recomputations read. A pass of 3 orders with 16
// texels checked per stage: 9 checks, 10 scans (single scattering has two outputs), no reads
// beyond the sums' own, fewer gathered texels than one scattering texture has, and a result
// bit-identical to a pass run without checks.
TEST(AtmosphereSelfCheck, ChecksGatherWhatTheyRecomputeAndReadNoWholeTexture) {
  const AtmosphereSpec s = small(earth());
  const Model m = model_of(s);
  const Channels ch = channels_at(s, {680.0, 550.0, 440.0});
  const auto none = [](PassStage, int, ref3::HostBackend&) {};
  Corrupting checked(m, ch, none), plain(m, ch, none);
  auto checker = make_stage_checker(m, ch, 3, 16, 1e-3);
  int checks = 0;
  const PassPlan plan{3, false, 1e-3};
  const PassResult a = run_pass(checked, plan, kQuiet, 0.0, 1.0, checker.get(), [&](const StageCheck&) { ++checks; });
  const PassResult b = run_pass(plain, plan, kQuiet, 0.0, 1.0);
  EXPECT_EQ(checks, 9);  // 3 stages, then 3 per order n = 2, 3
  EXPECT_EQ(checked.scans, 10);
  EXPECT_EQ(checked.reads, plain.reads);
  // the host sums' own reads: T and the direct ΔE kept, ΔR, ΔE and ΔS per order n = 2, 3, ΔM into
  // the R,G,B sums and kept
  EXPECT_EQ(plain.reads, 9);
  EXPECT_EQ(plain.gathered, 0);
  EXPECT_GT(checked.gathered, 9 * 16);  // the sampled texels and the inputs they read
  // against reading each texture once per stage that writes it (T, ΔE, ΔR, ΔM, then J, ΔE, ΔS
  // per order): at these tiny sizes (2560 scattering texels) a fraction; at the default sizes the
  // same 16 texels read the same few thousand input texels out of 10⁶
  const long long n_t = 1LL * m.sizes.transmittance_w * m.sizes.transmittance_h,
                  n_e = 1LL * m.sizes.irradiance_w * m.sizes.irradiance_h, n_s = m.sizes.scattering_texels();
  EXPECT_LT(checked.gathered, (n_t + 3 * n_e + 6 * n_s) / 2);
  EXPECT_EQ(a.transmittance, b.transmittance);
  EXPECT_EQ(a.direct_irradiance, b.direct_irradiance);
  EXPECT_EQ(a.irradiance, b.irradiance);
  EXPECT_EQ(a.scattering, b.scattering);
  EXPECT_EQ(a.single_mie, b.single_mie);
  ASSERT_EQ(a.orders.size(), b.orders.size());
  for (std::size_t i = 0; i < a.orders.size(); ++i) EXPECT_EQ(a.orders[i].relative, b.orders[i].relative);
}

// The device's sums (kernels.cl, "The sums") against the same sums in double on the host
// (make_host_sums) over the same device textures: a spectral bake of 6 wavelengths in two passes
// of 4 channels (the second with two dark channels), 3 orders, CIE weights into R,G,B. The device
// adds in float: a pass's sum of ≤ 3 non-negative terms (× 1/P_R rounded to float) carries ≤ ~4
// roundings, ≤ 4 · 2⁻²⁴ ≈ 2.4e-7 relative; the maxima, means and relative changes are taken from
// such values (the means' partial sums of ≤ 2560 / 4096 texels each) and keep that size. An R,G,B
// value is a 4-term dot product per pass with CIE weights of both signs, summed over 2 passes: its
// error is ≲ 6 · 2⁻²⁴ Σ|w x|, which cancels to ~0 in places, so it is judged against the
// channel's largest value (Σ|w x| stays within ~2× that for these weights: ≲ 7e-7). 2e-6
// bounds every comparison with room; a wrong texel, weight or pass gives O(1).
class HostSummed final : public PassBackend {
 public:
  HostSummed(std::unique_ptr<PassBackend> b, const Model& m) : b_(std::move(b)), sums_(make_host_sums(*this, m)) {}
  int channels() const override { return b_->channels(); }
  void transmittance() override { b_->transmittance(); }
  void direct_irradiance() override { b_->direct_irradiance(); }
  void single_scattering() override { b_->single_scattering(); }
  void scattering_density(int order) override { b_->scattering_density(order); }
  void indirect_irradiance(int order) override { b_->indirect_irradiance(order); }
  void multiple_scattering() override { b_->multiple_scattering(); }
  void read_into(Tex t, std::vector<double>& out) override { b_->read_into(t, out); }
  void gather(Tex t, const std::vector<int>& ids, std::vector<double>& out) override { b_->gather(t, ids, out); }
  Scan scan(Tex t) override { return b_->scan(t); }
  Sums& sums() override { return *sums_; }
  void use_channels(const Channels& ch) override { b_->use_channels(ch); }
  void add_density_sum(int order) override { b_->add_density_sum(order); }
  void sky_view(int orders_used, std::vector<double>& out) override { b_->sky_view(orders_used, out); }
  void keep_density() override { b_->keep_density(); }
  void density_tail() override { b_->density_tail(); }

 private:
  std::unique_ptr<PassBackend> b_;
  std::unique_ptr<Sums> sums_;
};

TEST(AtmosphereDevice, DeviceSumsMatchTheHostsDoubleSums) {
  AtmosphereSpec s = small(earth());
  s.spectral = true;
  s.count = 6;
  const Model m = model_of(s);
  const Spectrum sp = spectrum_of(s);
  const Channels all = channels_at(s, sp.lambda_nm);
  constexpr int kWidth = 4;
  auto on_device = make_device_backend(device(), m, all.slice(0, kWidth), kWidth, false);
  HostSummed on_host(make_device_backend(device(), m, all.slice(0, kWidth), kWidth, false), m);
  const int n = static_cast<int>(all.size());
  // relative to |value| + floor × the channel's largest |value|
  auto rel = [](const std::vector<double>& a, const std::vector<double>& b, int w, double floor = 1e-6) {
    EXPECT_EQ(a.size(), b.size());
    std::vector<double> mx(w, 0.0);
    for (std::size_t i = 0; i < b.size(); ++i) mx[i % w] = std::max(mx[i % w], std::fabs(b[i]));
    double e = 0.0;
    for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i)
      e = std::max(e, std::fabs(a[i] - b[i]) / (std::fabs(b[i]) + floor * mx[i % w] + 1e-300));
    return e;
  };
  double worst = 0.0, worst_relative = 0.0;
  for (int first = 0; first < n; first += kWidth) {
    const int count = std::min(kWidth, n - first);
    PassPlan plan{3, false, 1e-3};
    plan.last_pass = first + kWidth >= n;
    plan.to_rgb.assign(3 * kWidth, 0.0);
    for (int k = 0; k < 3; ++k)
      for (int i = 0; i < count; ++i) plan.to_rgb[k * kWidth + i] = sp.to_rgb[k * n + first + i];
    if (first > 0) {
      on_device->use_channels(all.slice(first, count));
      on_host.use_channels(all.slice(first, count));
    }
    const PassResult d = run_pass(*on_device, plan, kQuiet, 0.0, 1.0);
    const PassResult h = run_pass(on_host, plan, kQuiet, 0.0, 1.0);
    EXPECT_EQ(d.transmittance, h.transmittance);  // the same kernels: the textures are the same bits
    worst = std::max({worst, rel(d.scattering, h.scattering, kWidth), rel(d.irradiance, h.irradiance, kWidth),
                      rel(d.single_mie, h.single_mie, kWidth)});
    ASSERT_EQ(d.orders.size(), h.orders.size());
    for (std::size_t i = 0; i < d.orders.size(); ++i)
      worst_relative = std::max(worst_relative, std::fabs(d.orders[i].relative - h.orders[i].relative) /
                                                    std::max(h.orders[i].relative, 1e-30));
  }
  for (Sum sum : {Sum::scattering, Sum::irradiance, Sum::single_mie}) {
    SCOPED_TRACE(to_string(sum));
    std::vector<double> d, h;
    on_device->sums().read_rgb(sum, d);
    on_host.sums().read_rgb(sum, h);
    worst = std::max(worst, rel(d, h, 3, 1.0));
  }
  for (int order = 1; order <= 3; ++order) {
    const OrderRgb d = on_device->sums().order_rgb(order), h = on_host.sums().order_rgb(order);
    for (auto field : {&OrderRgb::scattering_max, &OrderRgb::scattering_mean, &OrderRgb::irradiance_max,
                       &OrderRgb::irradiance_mean}) {
      ASSERT_EQ((d.*field).size(), (h.*field).size()) << "order " << order;
      worst = std::max(worst, rel(d.*field, h.*field, 1));
    }
    EXPECT_EQ(d.irradiance_max.empty(), order == 3);  // the last order's light lights nothing yet
  }
  std::printf("device sums against the host's double: %.3g (relative changes %.3g)\n", worst, worst_relative);
  EXPECT_LE(worst, 2e-6);
  EXPECT_LE(worst_relative, 2e-6);
}

// The job's verdict on its self-checks: a stage that wrote values that are not finite stops the
// bake (at once, from the check hook) with a message naming the stage, its order and pass and the
// count; a stage beyond the tolerance stops it naming that stage; otherwise the record carries
// the worst value.
TEST(AtmosphereSelfCheck, TheJobStopsOnANonFiniteOrInaccurateStage) {
  Baked b;
  b.self_checks = nlohmann::json::array({{{"stage", "transmittance"}, {"max_relative_error", 1e-6}},
                                         {{"stage", "multiple_scattering"}, {"max_relative_error", 3e-5}}});
  b.self_check_worst = 3e-5;
  const Accuracy ok = judge_self_checks(b);
  EXPECT_TRUE(ok.passed);
  EXPECT_EQ(ok.value, 3e-5);
  EXPECT_EQ(ok.name, "self_check");

  Baked inaccurate = b;
  inaccurate.self_checks[1]["max_relative_error"] = 0.01;
  inaccurate.self_check_worst = 0.01;
  try {
    judge_self_checks(inaccurate);
    ADD_FAILURE() << "an inaccurate stage passed";
  } catch (const JobError& e) {
    EXPECT_NE(std::string(e.what()).find("self-check failed in multiple_scattering"), std::string::npos) << e.what();
  }

  const std::string message = non_finite_error(NonFiniteStage{"scattering_density", 3, 1, 5}).what();
  EXPECT_NE(message.find("scattering_density (order 3, pass 1) wrote 5 non-finite values"), std::string::npos)
      << message;
}

// A value that is not finite anywhere in a stage's output fails that stage's check, wherever it
// is (not only at the sampled texels): one NaN in one channel of one texel of J of order 3 —
// texel 1, which the 64 sampled texels do not include — is counted, and the check reads +inf.
// The stages before it are clean; the multiple scattering that reads it is flagged too.
TEST(AtmosphereSelfCheck, NonFiniteValuesAnywhereFailTheStage) {
  const AtmosphereSpec s = small(earth());
  const Model m = model_of(s);
  const Channels ch = channels_at(s, {680.0, 550.0, 440.0});
  Corrupting b(m, ch, [](PassStage stage, int order, ref3::HostBackend& h) {
    if (stage == PassStage::scattering_density && order == 3) h.texture(Tex::density)[1 * 3 + 2] = std::nan("");
  });
  constexpr int kSampled = 64;
  const long long n = m.sizes.scattering_texels();
  for (long long k = 0; k < kSampled; ++k) ASSERT_NE((k * 2654435761LL + 12345) % n, 1) << "texel 1 is sampled";
  auto checker = make_stage_checker(m, ch, 3, kSampled, 1e-3);
  std::vector<StageCheck> checks;
  run_pass(b, PassPlan{3, false, 1e-3}, kQuiet, 0.0, 1.0, checker.get(),
           [&](const StageCheck& c) { checks.push_back(c); });
  bool seen = false;
  for (const StageCheck& c : checks) {
    SCOPED_TRACE(c.stage + " order " + std::to_string(c.order));
    if (c.stage == "scattering_density" && c.order == 3) {
      seen = true;
      EXPECT_EQ(c.non_finite, 1);
      EXPECT_EQ(c.max_rel, std::numeric_limits<double>::infinity());
    } else if (!seen) {
      EXPECT_EQ(c.non_finite, 0);
      EXPECT_LT(c.max_rel, 1e-12);
    } else if (c.stage == "multiple_scattering") {
      EXPECT_GT(c.non_finite, 0);
    }
  }
  EXPECT_TRUE(seen);
}
