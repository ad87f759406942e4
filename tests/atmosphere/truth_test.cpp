// The path-traced truth of the atmosphere (kernels/atmosphere/path_tracer.cl): its random
// numbers, the device against the C++ double walks, single scattering against an independent
// quadrature, the optically thin limit, a constant-density shell's closed form, energy
// balance, honest standard errors, determinism, the baked LUTs, and the CSV / scene / bundle
// plumbing. Every Monte Carlo assertion is in standard errors (se) of the traced estimate.
#include <gtest/gtest.h>

#include <array>
#include <cfloat>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <random>

#include <nlohmann/json.hpp>

#include "atmosphere/npy.hpp"
#include "atmosphere/single_scattering.hpp"
#include "atmosphere/spec_of.hpp"
#include "registry/registry.hpp"
#include "kinds/atmosphere/atmosphere_job.hpp"
#include "kinds/atmosphere/model/model.hpp"
#include "kinds/atmosphere/bake/pass.hpp"
#include "kinds/atmosphere/truth/truth.hpp"
#include "kinds/atmosphere/truth/truth_reference.hpp"
#include "kinds/atmosphere/truth/scene_check.hpp"
#include "support/testing.hpp"

using namespace specbake;
using namespace specbake::atmosphere;
using namespace specbake::atmosphere::quadrature;

namespace {

cl_util::Device& device() { return specbake::testing::shared_device(); }

using specbake::testing::spec_of;
// The default Earth at Bruneton's texture sizes (refdata/textures; without `sizes:` its default
// scene, which reaches twilight, would bake 64 μ_s texels).
AtmosphereSpec earth() { return spec_of("    preset: earth\n    sizes: 100%\n"); }
AtmosphereSpec mars() {  // configs/mars.yaml's planet and media
  return spec_of(
      "    preset: earth\n    bottom_radius_km: 3389.5\n    top_radius_km: 3469.5\n"
      "    sun_angular_radius_rad: 0.00307\n    solar_irradiance_scale: 0.431\n    ground_albedo: 0.25\n"
      "    max_sun_zenith_deg: 110\n    rayleigh: {scale_height_km: 11.1, scattering_per_m_at_1um: 2.0e-8}\n"
      "    mie: {scale_height_km: 11.0, extinction_per_m: 4.5e-5, angstrom_alpha: 0.0,\n"
      "          single_scattering_albedo: 0.95, phase_g: 0.7}\n    ozone: false\n");
}

// A shell of constant density between 6360 and 6360.1 km (thin: curvature effects are
// O(thickness / radius) = 1.6e-5), 3 channels at 680/550/440 nm.
AtmosphereSpec thin_shell(bool ozone, double mie_albedo, double ground_albedo) {
  AtmosphereSpec s = earth();
  s.top_radius_km = 6360.1;
  const DensityLayer constant{0.0, 0.0, 0.0, 0.0, 1.0};
  for (int i = 0; i < 2; ++i) s.rayleigh_density[i] = s.mie_density[i] = s.ozone_density[i] = constant;
  s.rayleigh_scattering_per_m_at_1um = 1.83e-4;  // β_R(550 nm) = 2 km⁻¹
  s.mie_extinction_per_m = 1e-3;                 // 1 km⁻¹
  s.mie_single_scattering_albedo = mie_albedo;
  s.ozone = ozone;
  s.ozone_column_du = 300.0;                     // β_A(550 nm) = 0.28 km⁻¹
  s.ground_albedo = ground_albedo;
  return s;
}

// The standard normal quantile-free χ² bound: Wilson–Hilferty, χ²_ν(z) ≈ ν (1 − 2/(9ν) + z √(2/(9ν)))³.
double chi2_quantile(double nu, double z) {
  const double k = 2.0 / (9.0 * nu);
  return nu * std::pow(1.0 - k + z * std::sqrt(k), 3.0);
}

// The same integral by the bake's own rule for single scattering (atmosphere.cl: a trapezoid
// of `steps` intervals over the ray to its boundary), with exact transmittances (optical
// depths by Simpson, 40 intervals between nodes, 200 on each sun ray): what the LUT's rule
// gives before any texture is involved. Its difference from single_scattering_quadrature is
// the rule's own error.
std::array<double, 3> single_scattering_trapezoid(const Medium& M, const TruthPoint& p, int steps) {
  const Medium::Ray R = M.ray(p);
  const double nu = R.v[0] * R.s[0] + R.v[1] * R.s[1] + R.v[2] * R.s[2];
  std::array<double, 3> out{};
  for (int c = 0; c < 3; ++c) {
    const double pr = ref3::rayleigh_phase(nu), pm = ref3::mie_phase(M.a.mie_g, nu), dt = R.length / steps;
    double tau = 0.0, sum = 0.0;
    for (int i = 0; i <= steps; ++i) {
      const double t = i * dt, y[3] = {R.x[0] + t * R.v[0], R.x[1] + t * R.v[1], R.x[2] + t * R.v[2]};
      if (i > 0) {
        const double y0[3] = {y[0] - dt * R.v[0], y[1] - dt * R.v[1], y[2] - dt * R.v[2]};
        tau += M.depth(c, y0, R.v, dt, 40);
      }
      const double h = M.altitude(y);
      const double sr = M.ch.rayleigh_scattering[c] * ref3::profile_density(&M.a.rayleigh_density, h);
      const double sm = M.ch.mie_scattering[c] * ref3::profile_density(&M.a.mie_density, h);
      const double t_sun = std::exp(-M.depth(c, y, R.s, Medium::exit_sphere(y, R.s, M.a.top_radius), 200));
      sum += (i == 0 || i == steps ? 0.5 : 1.0) * std::exp(-tau) * (sr * pr + sm * pm) * M.ch.solar_irradiance[c] * t_sun;
    }
    out[c] = sum * dt;
  }
  return out;
}

// Reference textures of Bruneton's implementation (full size, 4 orders, rgb).
std::string ref(const std::string& name) { return (specbake::testing::refdata_dir() / "atmosphere" / name).string(); }

// A test ray: from altitude h (km) above the pole, zenith cosine mu, in the x–z plane: whether it
// meets the ground, its length D to the ground or the top (km), its start x and direction v.
struct TestRay {
  int ground;
  double D;
  double x[3], v[3];
};
TestRay test_ray(const ref3::AtmosphereParameters& a, double h, double mu) {
  const int ground = ref3::ray_hits_ground(&a, h, mu);
  return {ground, ref3::distance_to_nearest_boundary(&a, h, mu, ground), {0, 0, a.bottom_radius + h},
          {std::sqrt(1 - mu * mu), 0, mu}};
}

}  // namespace

// ---- random numbers -------------------------------------------------------------------------

// The published known-answer vectors of Philox4x32-10 (Random123's kat_vectors), and the
// stream's word order.
TEST(TruthPhilox, KnownAnswerVectors) {
  const philox_u32 cases[3][10] = {
      {0, 0, 0, 0, 0, 0, 0x6627e8d5, 0xe169c58d, 0xbc57ac4c, 0x9b00dbd8},
      {0xffffffff, 0xffffffff, 0xffffffff, 0xffffffff, 0xffffffff, 0xffffffff, 0x408f276d, 0x41c83b0e, 0xa20bc7c6,
       0x6d5451fd},
      {0x243f6a88, 0x85a308d3, 0x13198a2e, 0x03707344, 0xa4093822, 0x299f31d0, 0xd16cfe09, 0x94fdcceb, 0x5001e420,
       0x24126ea1}};
  for (const auto& k : cases) {
    philox_u32 out[4];
    philox4x32_10(k, k + 4, out);
    for (int i = 0; i < 4; ++i) EXPECT_EQ(out[i], k[6 + i]);
  }
  // draw i of a stream = word i % 4 of the block of counter {i / 4, c1, c2, c3}
  PhiloxStream s;
  philox_stream_init(&s, 7, 9, 11, 13, 17);
  std::vector<philox_u32> draws;
  for (int i = 0; i < 8; ++i) draws.push_back(philox_next(&s));
  for (philox_u32 block = 0; block < 2; ++block) {
    const philox_u32 counter[4] = {block, 11, 13, 17}, key[2] = {7, 9};
    philox_u32 out[4];
    philox4x32_10(counter, key, out);
    for (int i = 0; i < 4; ++i) EXPECT_EQ(draws[block * 4 + i], out[i]);
  }
}

// The majorant table rests on profile_max_over(): it must bound every density of the
// interval, and be attained (it is the maximum, not a loose bound).
TEST(TruthMajorant, ProfileMaximaBoundTheDensities) {
  ref3::DensityProfile profiles[4];
  const auto a = ref3::make_parameters(model_of(earth()), Channels{});
  profiles[0] = a.rayleigh_density;
  profiles[1] = a.mie_density;
  profiles[2] = a.absorption_density;
  // a concave layer (a < 0) with an interior maximum, and a jump at the layer boundary
  profiles[3] = a.rayleigh_density;
  profiles[3].width[0] = 20.0;
  profiles[3].exp_term[0] = -1.0;
  profiles[3].exp_scale[0] = -0.2;
  profiles[3].linear_term[0] = -0.05;
  profiles[3].constant_term[0] = 1.2;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0.0, 60.0);
  for (const auto& p : profiles)
    for (int trial = 0; trial < 200; ++trial) {
      double lo = u(rng), hi = u(rng);
      if (lo > hi) std::swap(lo, hi);
      const double bound = ref3::profile_max_over(&p, lo, hi);
      double seen = 0.0;
      for (int i = 0; i <= 2000; ++i) {
        const double h = lo + (hi - lo) * i / 2000.0;
        const double d = ref3::profile_density(&p, h);
        seen = std::max(seen, d);
        ASSERT_LE(d, bound * (1 + 1e-15)) << "h=" << h;
      }
      // attained: the sampled maximum is within one sample step of slope ≤ 1 km⁻¹ of it
      EXPECT_LE(bound - seen, (hi - lo) / 2000.0 + 1e-15);
    }
}

// ---- the device against the C++ double walks -----------------------------------------------

// Same points, seed and walks on the device and in C++ double (path_tracer.cl compiled by
// both). With a float64 device the arithmetic differs only by libm and FMA rounding (≤ 1 ulp
// per operation, ~1e-14 relative after a walk's ~100 operations); a walk could only diverge
// if a uniform fell within ~1e-14 of a decision threshold (probability ~1e-14 per decision,
// ~1e5 decisions here), so 1e-9 relative is a wide bound. A float32 device follows the same
// walks with 23-bit uniforms: then the two agree statistically, within 4 combined se. The last
// point has the sun 5° below the horizon: its walks take the twilight estimate.
TEST(Truth, DeviceMatchesHostReference) {
  const std::vector<TruthPoint> points = {{0, 30, 40, 60}, {5, 110, 35, 120}, {100, 98, 30, 20}, {0.5, 60, 95, 90}};
  TruthOptions o;
  o.paths = 256;
  o.paths_per_batch = 32;
  const TruthResult d = trace_truth(earth(), device(), points, o);
  const TruthResult h = trace_truth_reference(earth(), points, o);
  ASSERT_EQ(d.radiance.size(), h.radiance.size());
  double worst = 0.0;
  for (std::size_t i = 0; i < d.radiance.size(); ++i) worst = std::max(worst, std::fabs(d.radiance[i] / h.radiance[i] - 1));
  std::printf("device (%s) against the C++ double walks: worst relative difference %.3g\n", d.precision.c_str(), worst);
  for (std::size_t i = 0; i < d.radiance.size(); ++i) {
    ASSERT_GT(h.radiance[i], 0.0);
    if (d.precision == "float64") {
      EXPECT_NEAR(d.radiance[i], h.radiance[i], 1e-9 * h.radiance[i]) << i;
      EXPECT_NEAR(d.standard_error[i], h.standard_error[i], 1e-9 * h.radiance[i]) << i;
    } else {
      EXPECT_NEAR(d.radiance[i], h.radiance[i], 4 * std::hypot(d.standard_error[i], h.standard_error[i])) << i;
    }
  }
  EXPECT_EQ(d.truncated, 0);
  EXPECT_EQ(h.paths, d.paths);
}

// A device without cl_khr_fp64 (PoCL with the capability masked) traces in float32: single
// scattering against the quadrature as above, within 4 se + 1e-4 L. float32 costs ≤ 2e-6 in
// T (the τ table, ≤ 30, at 6e-8 relative), ≤ 2e-5 in the view vertex's probabilities (23-bit
// uniforms against the segment table), ~1e-7 in altitudes: 1e-4 bounds them with room.
TEST(Truth, FloatOnlyDeviceTracesInFloat32) {
  cl_util::DeviceInfo info = cl_util::select_device("auto");
  info.fp64 = false;
  cl_util::Device float_only(info);
  const AtmosphereSpec s = earth();
  const Medium M(s);
  const std::vector<TruthPoint> points = {{0, 60, 45, 90}, {0.2, 89.5, 35, 40}, {100, 100, 30, 20}};
  TruthOptions o;
  o.paths = 16384;
  o.orders = 1;
  const TruthResult r = trace_truth(s, float_only, points, o);
  EXPECT_EQ(r.precision, "float32");
  for (std::size_t p = 0; p < points.size(); ++p) {
    const auto q = single_scattering_quadrature(M, points[p], 2000, 400);
    for (int c = 0; c < 3; ++c) EXPECT_LE(std::fabs(r.L(p, c) - q[c]), 4 * r.se(p, c) + 1e-4 * q[c]) << p << " " << c;
  }
}

// ---- single scattering against an independent quadrature -------------------------------------

// orders = 1 against composite Simpson (2000 intervals on the view ray, 400 on each sun ray;
// its error is bounded by its change from 1000/200 intervals, ≤ 1e-7 here), at the zenith,
// mid-sky, near the horizon (2° and 0.5° above it), two rays that end on the ground, and a
// camera above the atmosphere looking through its limb. Each value within 4 se + the
// quadrature's error (21 values: P(any |z| > 4) ≈ 1e-3), and Σ z² within the χ²₂₁ 99.9 %
// quantile (a bias of ~1 se common to many values fails it).
TEST(Truth, SingleScatteringMatchesQuadrature) {
  const AtmosphereSpec s = earth();
  const Medium M(s);
  const std::vector<TruthPoint> points = {{0, 0, 30, 0},     {0, 60, 45, 90},  {0, 88, 20, 150},  {0.2, 89.5, 35, 40},
                                          {10, 95, 40, 60},  {5, 120, 30, 0},  {100, 100, 30, 20}};
  TruthOptions o;
  o.paths = 32768;
  o.orders = 1;
  o.order1 = TruthOptions::Order1::walked;  // the walks' own order 1 (next-event estimation at the view ray's vertex)
  o.seed = 11;
  const TruthResult r = trace_truth(s, device(), points, o);
  double chi2 = 0.0;
  for (std::size_t p = 0; p < points.size(); ++p) {
    const auto q = single_scattering_quadrature(M, points[p], 2000, 400);
    const auto q_half = single_scattering_quadrature(M, points[p], 1000, 200);
    for (int c = 0; c < 3; ++c) {
      const double q_err = std::fabs(q[c] - q_half[c]);
      EXPECT_LE(q_err, 1e-6 * q[c]);
      const double z = (r.L(p, c) - q[c]) / r.se(p, c);
      chi2 += z * z;
      EXPECT_LE(std::fabs(r.L(p, c) - q[c]), 4 * r.se(p, c) + q_err) << "point " << p << " channel " << c;
      std::printf("single scattering p%zu %s: traced %.6g ± %.2g, quadrature %.6g, z = %+.2f\n", p,
                  r.channel_names[c].c_str(), r.L(p, c), r.se(p, c), q[c], z);
    }
  }
  EXPECT_LE(chi2, chi2_quantile(21, 3.09));
}

// Order 1 as the truth gives it by default (TruthOptions::Order1::quadrature: adaptive
// Gauss–Legendre with exact optical depths, asked for 1e-6 of each channel's value) against the
// same Simpson quadrature at the same points: within Simpson's own error (its change from
// 1000/200 intervals) + 1e-5 of the value (the adaptive rule's tolerance, 1e-6 per channel
// against its first estimate, seen ≤ 3.2e-6 against a run asking 1e-9 over 512 points of all
// views, sun −12…90°, cameras 0–10 km). No walk contributes (orders = 1), so se = 0.
TEST(Truth, SingleScatteringQuadratureMatchesSimpson) {
  const AtmosphereSpec s = earth();
  const Medium M(s);
  const std::vector<TruthPoint> points = {{0, 0, 30, 0},     {0, 60, 45, 90},  {0, 88, 20, 150},  {0.2, 89.5, 35, 40},
                                          {10, 95, 40, 60},  {5, 120, 30, 0},  {100, 100, 30, 20}, {0, 70, 94, 10},
                                          {10, 85, 98, 0},   {0, 80, 96, 0}};
  TruthOptions o;
  o.paths = 64;
  o.orders = 1;
  const TruthResult r = trace_truth(s, device(), points, o);
  EXPECT_EQ(r.order1, "quadrature");
  for (std::size_t p = 0; p < points.size(); ++p) {
    const auto q = single_scattering_quadrature(M, points[p], 2000, 400);
    const auto q_half = single_scattering_quadrature(M, points[p], 1000, 200);
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(r.se(p, c), 0.0);
      const double q_err = std::fabs(q[c] - q_half[c]);
      EXPECT_LE(std::fabs(r.L(p, c) - q[c]), q_err + 1e-5 * q[c]) << "point " << p << " channel " << c;
      std::printf("single scattering p%zu %s: quadrature %.8g, Simpson %.8g ± %.1g (relative difference %.1e)\n", p,
                  r.channel_names[c].c_str(), r.L(p, c), q[c], q_err, r.L(p, c) / q[c] - 1.0);
    }
  }
}

// The two ways to order 1 over a scene (cameras 0–10 km, every view, sun −12…90°: twilight, the
// shadow's edge, limb and ground rays): the quadrature against 16384 walks a channel of the
// walked estimator, every value within 4.5 se (up to 288 values: P(any |z| > 4.5) ≈ 2e-3) and Σ z²
// within the χ²₂₈₈ 99.9 % quantile — a bias of a fraction of a se shared by many values fails it.
TEST(Truth, SingleScatteringQuadratureMatchesTheWalks) {
  const AtmosphereSpec s = earth();
  const auto points = scene_points(TruthScene{0.0, 10.0, -12.0, 90.0, TruthViews::all, 96}, s);
  TruthOptions q;
  q.orders = 1;
  q.paths = 64;
  const TruthResult a = trace_truth(s, device(), points, q);
  TruthOptions w = q;
  w.order1 = TruthOptions::Order1::walked;
  w.paths = 16384;
  w.seed = 5;
  const TruthResult b = trace_truth(s, device(), points, w);
  double chi2 = 0.0;
  int n = 0;
  for (std::size_t p = 0; p < points.size(); ++p)
    for (int c = 0; c < 3; ++c) {
      if (b.se(p, c) == 0.0) {  // no light at all (no walk's order 1 saw the sun)
        EXPECT_LE(a.L(p, c), 1e-9 * a.L(0, c)) << "point " << p << " channel " << c;
        continue;
      }
      const double z = (a.L(p, c) - b.L(p, c)) / b.se(p, c);
      chi2 += z * z;
      ++n;
      EXPECT_LE(std::fabs(z), 4.5) << "point " << p << " channel " << c << ": quadrature " << a.L(p, c) << ", walks "
                                   << b.L(p, c) << " ± " << b.se(p, c);
    }
  std::printf("order 1: quadrature against walks at %d values, chi2 %.1f\n", n, chi2);
  EXPECT_GE(n, 250);
  EXPECT_LE(chi2, chi2_quantile(n, 3.09));
}

// ---- the optically thin limit ---------------------------------------------------------------

// Every coefficient × ε (no ground reflection): L → ε E Σ_i β_i P_i(ν) ∫ρ_i dt along the view
// ray, all orders traced. The corrections are relative O(τ) with τ the largest optical depth
// a path crosses (view ray, sun ray, and a second scattering anywhere: the horizontal ray
// from the ground, ≈ 40 × vertical): for ε = 1e-5, τ ≤ 1.6e-5 · 0.3 · 40 < 2e-4. Bound:
// 4 se + 1e-3 L₀; at two ε, L ∝ ε.
TEST(Truth, OpticallyThinLimit) {
  const std::vector<TruthPoint> points = {{0, 0, 30, 0}, {0, 70, 40, 120}, {20, 120, 35, 60}, {0, 85, 20, 10}};
  for (double eps : {1e-5, 2e-5}) {
    AtmosphereSpec s = earth();
    s.rayleigh_scattering_per_m_at_1um *= eps;
    s.mie_extinction_per_m *= eps;
    s.ozone_column_du *= eps;
    s.ground_albedo = 0.0;
    const Medium M(s);
    TruthOptions o;
    o.paths = 16384;
    const TruthResult r = trace_truth(s, device(), points, o);
    for (std::size_t p = 0; p < points.size(); ++p) {
      const Medium::Ray R = M.ray(points[p]);
      const double nu = R.v[0] * R.s[0] + R.v[1] * R.s[1] + R.v[2] * R.s[2];
      auto column = [&](const ref3::DensityProfile* prof) {
        return Medium::simpson(R.x, R.v, R.length, 20000,
                               [&](const double* x) { return ref3::profile_density(prof, M.altitude(x)); });
      };
      const double cr = column(&M.a.rayleigh_density), cm = column(&M.a.mie_density);
      for (int c = 0; c < 3; ++c) {
        const double L0 = M.ch.solar_irradiance[c] * (M.ch.rayleigh_scattering[c] * ref3::rayleigh_phase(nu) * cr +
                                                      M.ch.mie_scattering[c] * ref3::mie_phase(M.a.mie_g, nu) * cm);
        EXPECT_LE(std::fabs(r.L(p, c) - L0), 4 * r.se(p, c) + 1e-3 * L0) << "eps " << eps << " point " << p;
      }
    }
  }
}

// ---- a constant-density shell: the closed form of single scattering --------------------------

// In a plane-parallel layer of constant σ_t, thickness H, single scattering seen from height
// z0 along μ with the sun at μ_s > 0 is
//   L = E (β_R P_R(ν) + β_M P_M(ν)) e^{−σ_t (H − z0)/μ_s} (1 − e^{−σ_t D k}) / (σ_t k),
//   k = 1 − μ/μ_s, D = (H − z0)/μ (μ > 0) or z0/|μ| (μ < 0).
// The 0.1 km shell on a 6360 km sphere departs from the layer by the rays' sagitta
// D²(1 − μ²)/(2 r) ≤ 5e-6 km here, i.e. ≤ σ_t · 5e-6 · (1 + 1/μ_s) ≲ 5e-5 in the optical
// depths: the bound 4 se + 1e-3 L covers it 20 times.
TEST(Truth, ConstantDensityShellMatchesClosedForm) {
  const AtmosphereSpec s = thin_shell(true, 0.9, 0.3);
  const Medium M(s);
  const double H = s.top_radius_km - s.bottom_radius_km;
  const std::vector<TruthPoint> points = {{0, 0, 30, 0},     {0, 45, 50, 90},    {0, 66, 30, 180},
                                          {0.05, 127, 30, 60}, {0.1, 154, 50, 20}};
  TruthOptions o;
  o.paths = 32768;
  o.orders = 1;
  const TruthResult r = trace_truth(s, device(), points, o);
  for (std::size_t p = 0; p < points.size(); ++p) {
    const TruthPoint& q = points[p];
    const double mu = std::cos(q.view_zenith_deg * M_PI / 180), mu_s = std::cos(q.sun_zenith_deg * M_PI / 180);
    const double nu = mu * mu_s + std::sqrt((1 - mu * mu) * (1 - mu_s * mu_s)) * std::cos(q.view_sun_azimuth_deg * M_PI / 180);
    const double z0 = q.altitude_km, D = mu > 0 ? (H - z0) / mu : z0 / -mu, k = 1 - mu / mu_s;
    for (int c = 0; c < 3; ++c) {
      const double sigma = M.ch.rayleigh_scattering[c] + M.ch.mie_extinction[c] + M.ch.absorption_extinction[c];
      const double phase = M.ch.rayleigh_scattering[c] * ref3::rayleigh_phase(nu) +
                           M.ch.mie_scattering[c] * ref3::mie_phase(M.a.mie_g, nu);
      const double path = std::fabs(k) < 1e-12 ? D : -std::expm1(-sigma * D * k) / (sigma * k);
      const double L = M.ch.solar_irradiance[c] * phase * std::exp(-sigma * (H - z0) / mu_s) * path;
      EXPECT_LE(std::fabs(r.L(p, c) - L), 4 * r.se(p, c) + 1e-3 * L) << "point " << p << " channel " << c;
    }
  }
}

// Gauss–Legendre nodes and weights on [-1, 1] (Newton on P_n).
void gauss_legendre(int n, std::vector<double>& x, std::vector<double>& w) {
  x.assign(n, 0.0);
  w.assign(n, 0.0);
  for (int i = 0; i < n; ++i) {
    double z = std::cos(M_PI * (i + 0.75) / (n + 0.5)), dp = 0.0;
    for (int it = 0; it < 100; ++it) {
      double p0 = 1.0, p1 = 0.0;
      for (int k = 1; k <= n; ++k) {
        const double p2 = p1;
        p1 = p0;
        p0 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p2) / k;
      }
      dp = n * (z * p0 - p1) / (z * z - 1.0);
      const double dz = p0 / dp;
      z -= dz;
      if (std::fabs(dz) < 1e-16) break;
    }
    x[i] = z;
    w[i] = 2.0 / ((1.0 - z * z) * dp * dp);
  }
}

// Orders 1 and 2 in the plane-parallel layer of constant density (the thin shell), by
// quadrature of closed forms: single scattering L₁(z, ω) as in the test above, then
//   L₂ = ∫₀^D e^{−σt} [ ∫_4π Φ(v·ω) L₁(z_t, ω) dω + ∫_{μ<0} Φ(v·ω) e^{−σ z_t/|μ|} (a/π) E μ_s e^{−σH/μ_s} dω ] dt,
// Φ(c) = β_R P_R(c) + β_M,s P_M(c): the sky scattered twice, and the sun reflected by the
// ground then scattered. Gauss–Legendre: n_t in t, n_mu in μ on each hemisphere (L₁ has a
// kink at μ = 0), 2 n_mu in φ (periodic: trapezoid).
std::array<double, 3> layer_orders_1_2(const Medium& M, double H, double albedo, const TruthPoint& p, int n_t, int n_mu) {
  const double mu_v = std::cos(p.view_zenith_deg * M_PI / 180), mu_s = std::cos(p.sun_zenith_deg * M_PI / 180);
  const double az = p.view_sun_azimuth_deg * M_PI / 180;
  const double v[3] = {std::sqrt(1 - mu_v * mu_v), 0, mu_v};
  const double sn[3] = {std::sqrt(1 - mu_s * mu_s) * std::cos(az), std::sqrt(1 - mu_s * mu_s) * std::sin(az), mu_s};
  const double z0 = p.altitude_km, D = mu_v > 0 ? (H - z0) / mu_v : z0 / -mu_v;
  std::vector<double> xt, wt, xm, wm;
  gauss_legendre(n_t, xt, wt);
  gauss_legendre(n_mu, xm, wm);
  const int n_phi = 2 * n_mu;
  std::array<double, 3> out{};
  for (int c = 0; c < 3; ++c) {
    const double sigma = M.ch.rayleigh_scattering[c] + M.ch.mie_extinction[c] + M.ch.absorption_extinction[c];
    const double E = M.ch.solar_irradiance[c];
    auto phi_of = [&](double cs) {
      return M.ch.rayleigh_scattering[c] * ref3::rayleigh_phase(cs) + M.ch.mie_scattering[c] * ref3::mie_phase(M.a.mie_g, cs);
    };
    // single scattering at height z along a direction of cosine mu, phase value ph
    auto L1 = [&](double z, double mu, double ph) {
      const double Dw = mu > 0 ? (H - z) / mu : z / -mu, k = 1 - mu / mu_s;
      const double path = std::fabs(k) < 1e-12 ? Dw : -std::expm1(-sigma * Dw * k) / (sigma * k);
      return E * ph * std::exp(-sigma * (H - z) / mu_s) * path;
    };
    double l1 = 0.0, l2 = 0.0;
    for (int it = 0; it < n_t; ++it) {
      const double t = 0.5 * D * (xt[it] + 1), wt_t = 0.5 * D * wt[it], z = z0 + t * mu_v;
      double inner = 0.0;
      for (int hemi = 0; hemi < 2; ++hemi)
        for (int im = 0; im < n_mu; ++im) {
          const double mu = hemi == 0 ? 0.5 * (xm[im] + 1) : -0.5 * (xm[im] + 1), w_mu = 0.5 * wm[im];
          const double st = std::sqrt(1 - mu * mu);
          for (int ip = 0; ip < n_phi; ++ip) {
            const double ph = 2 * M_PI * (ip + 0.5) / n_phi;
            const double w[3] = {st * std::cos(ph), st * std::sin(ph), mu};
            const double cv = v[0] * w[0] + v[1] * w[1] + v[2] * w[2], cs = w[0] * sn[0] + w[1] * sn[1] + w[2] * sn[2];
            double incoming = L1(z, mu, phi_of(cs));
            if (mu < 0) incoming += std::exp(-sigma * z / -mu) * albedo / M_PI * E * mu_s * std::exp(-sigma * H / mu_s);
            inner += w_mu * (2 * M_PI / n_phi) * phi_of(cv) * incoming;
          }
        }
      l2 += wt_t * std::exp(-sigma * t) * inner;
    }
    l1 = L1(z0, mu_v, phi_of(v[0] * sn[0] + v[1] * sn[1] + v[2] * sn[2]));
    out[c] = l1 + l2;
  }
  return out;
}

// orders = 2 in the constant-density shell against layer_orders_1_2 (24 × 96 × 192 nodes;
// its error bounded by its change from 16 × 64 × 128), with a grey-ish ground of albedo 0.3:
// the second order's two kinds of paths, both phase functions, the Henyey–Greenstein
// sampling weights and the ground's next-event estimate. Curvature as above (≤ 1e-3 L).
TEST(Truth, ConstantDensityShellSecondOrderMatchesQuadrature) {
  const AtmosphereSpec s = thin_shell(true, 0.9, 0.3);
  const Medium M(s);
  const double H = s.top_radius_km - s.bottom_radius_km;
  const std::vector<TruthPoint> points = {{0, 0, 30, 0}, {0, 66, 30, 180}, {0.05, 127, 30, 60}, {0.1, 154, 50, 20},
                                          {0.02, 80, 60, 90}};
  std::vector<std::array<double, 3>> q(points.size()), q_err(points.size());
  for (std::size_t p = 0; p < points.size(); ++p) {
    q[p] = layer_orders_1_2(M, H, s.ground_albedo, points[p], 24, 96);
    const auto q_coarse = layer_orders_1_2(M, H, s.ground_albedo, points[p], 16, 64);
    for (int c = 0; c < 3; ++c) q_err[p][c] = std::fabs(q[p][c] - q_coarse[c]);
  }
  // both estimates of the second vertex's sun: at the free path's end (what `automatic` picks
  // for a high sun) and its expectation along the ray (the twilight estimate: here its table,
  // lit segments and ground term, with the sun everywhere above the horizon)
  for (const auto next_sun : {TruthOptions::NextSun::automatic, TruthOptions::NextSun::along_ray}) {
    TruthOptions o;
    o.paths = 32768;
    o.orders = 2;
    o.next_sun = next_sun;
    const TruthResult r = trace_truth(s, device(), points, o);
    for (std::size_t p = 0; p < points.size(); ++p)
      for (int c = 0; c < 3; ++c) {
        std::printf("orders 1-2, layer, next sun %d, p%zu %s: traced %.6g ± %.2g, quadrature %.6g (± %.1g), z = %+.2f\n",
                    static_cast<int>(next_sun), p, r.channel_names[c].c_str(), r.L(p, c), r.se(p, c), q[p][c],
                    q_err[p][c], (r.L(p, c) - q[p][c]) / r.se(p, c));
        EXPECT_LE(std::fabs(r.L(p, c) - q[p][c]), 4 * r.se(p, c) + q_err[p][c] + 1e-3 * q[p][c])
            << "next sun " << static_cast<int>(next_sun) << " point " << p << " channel " << c;
      }
  }
}

// Twilight on Bruneton's Earth (sun 3° to 6° below the horizon, cameras at 0.5–1.5 km): the
// later vertices' sun by its expectation along the ray (what `automatic` picks here) and at the
// free path's end are two unbiased estimates of the same orders 1–3 (order 3 includes paths
// through the ground); they agree within 4 √(se₁² + se₂²) (independent streams: other seeds).
// The plain estimate needs ~16× the walks for its se here (the reason for the other): it gets
// 8× the walks and still sets the bound.
TEST(Truth, TwilightSunAlongTheRayAgreesWithTheSunAtTheVertex) {
  const AtmosphereSpec s = earth();
  const std::vector<TruthPoint> points = {{0.5, 30, 95, 90}, {0.5, 80, 95, 180}, {1.5, 60, 93, 45}, {1.5, 10, 96, 120}};
  TruthOptions line;
  line.paths = 16384;
  line.orders = 3;
  line.next_sun = TruthOptions::NextSun::along_ray;
  TruthOptions plain = line;
  plain.paths = 8 * line.paths;
  plain.next_sun = TruthOptions::NextSun::at_vertex;
  plain.seed = 2;
  const TruthResult a = trace_truth(s, device(), points, line), b = trace_truth(s, device(), points, plain);
  for (std::size_t p = 0; p < points.size(); ++p)
    for (int c = 0; c < 3; ++c) {
      const double se = std::hypot(a.se(p, c), b.se(p, c));
      std::printf("twilight p%zu %s: along the ray %.5g ± %.2g, at the vertex %.5g ± %.2g, z = %+.2f\n", p,
                  a.channel_names[c].c_str(), a.L(p, c), a.se(p, c), b.L(p, c), b.se(p, c), (a.L(p, c) - b.L(p, c)) / se);
      EXPECT_LE(std::fabs(a.L(p, c) - b.L(p, c)), 4 * se) << "point " << p << " channel " << c;
      EXPECT_GT(a.L(p, c), 0.0);
    }
}

// ---- energy balance ------------------------------------------------------------------------

// A conservative shell (Rayleigh and Mie, single-scattering albedo 1, no ozone) over a white
// Lambertian ground (albedo 1), the sun at the zenith: nothing is absorbed, so the flux
// leaving the top equals the incoming E (per unit area):
//   E = F_sky,top + G · E_ground,   E_ground = E T_sun + F_sky,ground,
// F_sky,top: the traced sky radiance leaving the top (cameras at the top looking down),
// F_sky,ground: the sky irradiance on the ground (cameras on the ground looking up), both
// ∫ L |μ| dω; G = (1/π) ∫ T |μ| dω over the directions from the top that reach the ground (the
// ground's own radiance E_ground/π, which the traced sky radiance excludes, seen through the
// shell), and T_sun = e^{−σ_t H}. The flux integrals are stratified Monte Carlo over
// cosine-weighted directions (64 strata of μ², 2 random directions each: unbiased, with the
// variance estimated from the pairs, which includes each direction's own se). Sun at the
// zenith: the sky is symmetric in azimuth. The shell's curvature changes the balance by
// O(H/r) = 1.6e-5 (and the ground seen from the top varies by O((chord/r)²) ≈ 1e-4): bound
// 4 se + 1e-3 E.
TEST(Truth, EnergyBalanceOfAConservativeShellOverAWhiteGround) {
  const AtmosphereSpec s = thin_shell(false, 1.0, 1.0);
  const Medium M(s);
  const double H = s.top_radius_km - s.bottom_radius_km;
  constexpr int kStrata = 64;
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<TruthPoint> points;
  for (int side = 0; side < 2; ++side)  // 0: top looking down, 1: ground looking up
    for (int i = 0; i < kStrata; ++i)
      for (int k = 0; k < 2; ++k) {
        const double mu = std::sqrt((i + u01(rng)) / kStrata);  // cosine-weighted |μ|
        const double zenith = std::acos(mu) * 180 / M_PI;
        points.push_back({side == 0 ? H : 0.0, side == 0 ? 180.0 - zenith : zenith, 0.0, 0.0});
      }
  TruthOptions o;
  o.paths = 2048;
  const TruthResult r = trace_truth(s, device(), points, o);
  EXPECT_EQ(r.truncated, 0);
  // F = π E_cos[L] and its variance from the stratum pairs
  auto flux = [&](int side, int c, double* var) {
    double sum = 0.0, v = 0.0;
    for (int i = 0; i < kStrata; ++i) {
      const double a = r.L(side * 2 * kStrata + 2 * i, c), b = r.L(side * 2 * kStrata + 2 * i + 1, c);
      sum += 0.5 * (a + b);
      v += 0.25 * (a - b) * (a - b);
    }
    *var = M_PI * M_PI * v / (kStrata * double(kStrata));
    return M_PI * sum / kStrata;
  };
  const double mu_h = std::sqrt(1.0 - std::pow(s.bottom_radius_km / s.top_radius_km, 2));  // |μ| of the ground's edge
  for (int c = 0; c < 3; ++c) {
    const double sigma = M.ch.rayleigh_scattering[c] + M.ch.mie_extinction[c];
    ASSERT_EQ(M.ch.mie_scattering[c], M.ch.mie_extinction[c]);
    // G = 2 ∫_{μ_h}^{1} e^{−σ d(μ)} μ dμ, d the distance from the top to the ground (Simpson)
    constexpr int n = 20000;
    double G = 0.0;
    for (int i = 0; i <= n; ++i) {
      const double mu = mu_h + (1.0 - mu_h) * i / n;
      const double x[3] = {0, 0, s.top_radius_km}, d[3] = {std::sqrt(1 - mu * mu), 0, -mu};
      const double dist = Medium::hit_sphere(x, d, s.bottom_radius_km);
      const double f = dist > 0 ? std::exp(-sigma * dist) * mu : 0.0;
      G += (i == 0 || i == n ? 1.0 : (i % 2 ? 4.0 : 2.0)) * f;
    }
    G *= 2.0 * (1.0 - mu_h) / (3.0 * n);
    double var_top = 0.0, var_ground = 0.0;
    const double f_top = flux(0, c, &var_top), f_ground = flux(1, c, &var_ground);
    const double E = M.ch.solar_irradiance[c];
    const double out = f_top + G * (E * std::exp(-sigma * H) + f_ground);
    const double se = std::sqrt(var_top + G * G * var_ground);
    std::printf("energy balance %s: out/in = %.5f ± %.5f (sky at top %.4f, ground term %.4f of E)\n",
                r.channel_names[c].c_str(), out / E, se / E, f_top / E, (out - f_top) / E);
    EXPECT_LE(std::fabs(out - E), 4 * se + 1e-3 * E);
  }
}

// ---- honest standard errors -------------------------------------------------------------

// 24 seeds × 2 points × 3 channels: for each (point, channel), (K − 1) s²/σ̂² with s² the
// spread of L over the seeds and σ̂² the mean reported se²; their sum is χ² with
// 6 · 23 = 138 degrees of freedom if the se are honest. Two-sided 99.9 % bounds (Wilson–
// Hilferty): [0.65, 1.44] × 138 — an se off by a factor 1.25 in either direction fails.
TEST(Truth, StandardErrorsMatchTheSpreadOverSeeds) {
  const std::vector<TruthPoint> points = {{0, 50, 40, 30}, {2, 105, 60, 150}};
  constexpr int K = 24;
  std::vector<std::vector<double>> L(6), se2(6);
  for (int k = 0; k < K; ++k) {
    TruthOptions o;
    o.paths = 2048;
    o.seed = 1000 + k;
    const TruthResult r = trace_truth(earth(), device(), points, o);
    for (int i = 0; i < 6; ++i) {
      L[i].push_back(r.radiance[i]);
      se2[i].push_back(r.standard_error[i] * r.standard_error[i]);
    }
  }
  double chi2 = 0.0;
  for (int i = 0; i < 6; ++i) {
    double mean = 0.0, s2 = 0.0, v = 0.0;
    for (int k = 0; k < K; ++k) mean += L[i][k] / K;
    for (int k = 0; k < K; ++k) {
      s2 += (L[i][k] - mean) * (L[i][k] - mean) / (K - 1);
      v += se2[i][k] / K;
    }
    chi2 += (K - 1) * s2 / v;
    std::printf("seed spread / reported se, point %d channel %d: %.3f\n", i / 3, i % 3, std::sqrt(s2 / v));
  }
  const double dof = 6.0 * (K - 1);
  EXPECT_GE(chi2, chi2_quantile(dof, -3.29));
  EXPECT_LE(chi2, chi2_quantile(dof, 3.29));
}

// ---- determinism ---------------------------------------------------------------------------

// Same seed → the same bytes (values and RESULT.csv); another seed → other values; a walk
// depends only on (seed, walk, point, channel): other batch sizes regroup the same walks
// (equal up to the rounding of the sums: 1e-12 relative in float64, 1e-5 in float32).
TEST(Truth, DeterministicForASeed) {
  const std::vector<TruthPoint> points = {{0, 30, 40, 60}, {5, 110, 35, 120}, {1, 89, 80, 10}};
  TruthOptions o;
  o.paths = 1024;
  o.seed = 42;
  const AtmosphereSpec s = earth();
  const TruthResult a = trace_truth(s, device(), points, o), b = trace_truth(s, device(), points, o);
  ASSERT_EQ(a.radiance.size(), b.radiance.size());
  EXPECT_EQ(0, std::memcmp(a.radiance.data(), b.radiance.data(), a.radiance.size() * sizeof(double)));
  EXPECT_EQ(0, std::memcmp(a.standard_error.data(), b.standard_error.data(), a.radiance.size() * sizeof(double)));
  EXPECT_EQ(truth_result_csv(s, points, a), truth_result_csv(s, points, b));
  o.seed = 43;
  const TruthResult c = trace_truth(s, device(), points, o);
  for (std::size_t i = 0; i < a.radiance.size(); ++i) EXPECT_NE(a.radiance[i], c.radiance[i]) << i;
  o.seed = 42;
  o.paths_per_batch = 16;
  const TruthResult d = trace_truth(s, device(), points, o);
  const double tol = a.precision == "float64" ? 1e-12 : 1e-5;
  for (std::size_t i = 0; i < a.radiance.size(); ++i) EXPECT_NEAR(a.radiance[i], d.radiance[i], tol * a.radiance[i]);
}

// More points than one chunk of view-ray tables holds (4153 for rgb): every row is traced, and
// 4200 copies of one point (each with its own streams, 64 walks each) average to a separate
// 65536-walk trace of it, within 4 combined se.
TEST(Truth, ManyPointsAreTracedInChunks) {
  const TruthPoint q{1, 50, 40, 30};
  const std::vector<TruthPoint> points(4200, q);
  TruthOptions o;
  o.paths = 64;
  o.orders = 1;
  o.order1 = TruthOptions::Order1::walked;  // walks to average (order 1 by quadrature has no noise)
  const TruthResult r = trace_truth(earth(), device(), points, o);
  o.paths = 65536;
  const TruthResult one = trace_truth(earth(), device(), {q}, o);
  for (int c = 0; c < 3; ++c) {
    double mean = 0.0, var = 0.0;
    for (std::size_t p = 0; p < points.size(); ++p) {
      ASSERT_GT(r.L(p, c), 0.0) << p;
      mean += r.L(p, c) / points.size();
      var += r.se(p, c) * r.se(p, c) / (double(points.size()) * points.size());
    }
    EXPECT_NEAR(mean, one.L(0, c), 4 * std::sqrt(var + one.se(0, c) * one.se(0, c)));
  }
}

// The precision target: every channel of every point ends at or below it (the last top-up
// asks for 10 % more walks than the estimate), continuing each point's streams. Each channel
// walks its own share: it stops once its own se is the target, and at a high sun the red
// channel's walks are less noisy than the blue's (~0.13 against ~0.31 relative variance a
// walk), so the three channels walk different counts (a uniform count, every channel the
// most-walked one's, fails), and the point's walks are those of its most-walked channel.
TEST(Truth, TargetRelativeStandardError) {
  const std::vector<TruthPoint> points = {{0, 0, 30, 0}, {3, 100, 50, 90}, {0, 85, 75, 170}};
  TruthOptions o;
  o.paths = 512;
  o.target_relative_se = 0.01;
  const TruthResult r = trace_truth(earth(), device(), points, o);
  long long walked = 0, most = 0;
  for (std::size_t p = 0; p < points.size(); ++p) {
    long long top = 0;
    for (int c = 0; c < 3; ++c) {
      const long long n = r.channel_paths[p * 3 + c];
      EXPECT_LE(r.se(p, c), 0.01 * r.L(p, c)) << p << " " << c;
      EXPECT_EQ(n % o.paths_per_batch, 0) << p << " " << c;
      EXPECT_GE(n, o.paths) << p << " " << c;
      top = std::max(top, n);
      walked += n;
    }
    EXPECT_EQ(r.paths[p], top) << p;
    most += 3 * top;
  }
  EXPECT_GT(*std::max_element(r.paths.begin(), r.paths.end()), 512);  // someone needed more
  std::printf("rgb: %lld channel walks, %lld if every channel walked its point's most\n", walked, most);
  EXPECT_LT(walked, 0.9 * static_cast<double>(most));
}

// With weights (CIE X, Y, Z over 48 wavelengths, as the scene check's spectral reference) the
// walks go where the colour's variance is (Neyman's allocation): the ends of the spectrum, whose
// colour matching weights are ~10⁻⁴ of the peak's, walk a few of the walks of 551 nm, and each
// row's se still meets the target. A uniform allocation fails.
TEST(Truth, WeightedTargetWalksWhereTheColoursVarianceIs) {
  const std::vector<TruthPoint> points = {{0, 20, 30, 40}, {1, 60, 20, 120}, {0.5, 80, 45, 10}};
  const AtmosphereSpec ref = spectral_reference_of(earth());
  TruthOptions so = scene_truth_options(ref, 3);  // 64 walks a wavelength first
  so.target_relative_se = 0.004;  // enough walks at these easy views for the first 64 to be few
  const TruthResult s = trace_truth(ref, device(), points, so);
  const std::size_t C = s.channels, i551 = 19;  // bins of 9.79 nm from 360 nm: 19 is centred at 551 nm
  ASSERT_EQ(C, 48u);
  for (std::size_t p = 0; p < points.size(); ++p) {
    ASSERT_FALSE(s.at_cap[p]) << p;
    for (int row = 0; row < 3; ++row) {
      double L = 0.0, var = 0.0;
      for (std::size_t c = 0; c < C; ++c) {
        const double w = so.target_weights[row * C + c];
        L += w * s.L(p, c);
        var += w * w * s.se(p, c) * s.se(p, c);
      }
      EXPECT_LE(std::sqrt(var), so.target_relative_se * L) << p << " row " << row;
    }
    const long long peak = s.channel_paths[p * C + i551];
    std::printf("48 wavelengths, point %zu: walks at 365 nm %lld, 551 nm %lld, 825 nm %lld\n", p,
                s.channel_paths[p * C], peak, s.channel_paths[p * C + C - 1]);
    EXPECT_LE(4 * s.channel_paths[p * C], peak) << p;
    EXPECT_LE(4 * s.channel_paths[p * C + C - 1], peak) << p;
  }
}

// A kept truth reads back as it was traced, walks per channel included; one kept before the
// channels walked their own shares (no `channel_paths`) reads with every channel at its point's
// walks, which is what each of its channels walked.
TEST(Truth, KeptResultsReadBackWithTheirWalksPerChannel) {
  TruthOptions o;
  o.paths = 256;
  o.target_relative_se = 0.05;
  const TruthResult r = trace_truth(earth(), device(), {{0, 30, 40, 0}, {1, 80, 60, 90}}, o);
  const TruthResult back = truth_result_from_bytes(truth_result_bytes(r));
  EXPECT_EQ(back.channel_paths, r.channel_paths);
  EXPECT_EQ(back.paths, r.paths);
  EXPECT_EQ(back.radiance, r.radiance);
  nlohmann::json older = nlohmann::json::from_cbor(truth_result_bytes(r));
  older.erase("channel_paths");
  const std::vector<std::uint8_t> cbor = nlohmann::json::to_cbor(older);
  const TruthResult old = truth_result_from_bytes(std::string(cbor.begin(), cbor.end()));
  ASSERT_EQ(old.channel_paths.size(), r.points * r.channels);
  for (std::size_t p = 0; p < r.points; ++p)
    for (std::size_t c = 0; c < r.channels; ++c) EXPECT_EQ(old.channel_paths[p * r.channels + c], r.paths[p]);
}

// The events budget (what bounds the scene check in an optically thick atmosphere): in a
// Rayleigh layer 100× the Earth's (walks of tens to hundreds of events), a point's walks stop at
// the budget, whatever max_paths and the precision target ask, and the point says it stopped at
// its cap; the first batch (which measures the events) is always traced. A budget of 20 events
// a walk leaves these points their first batch alone; the default Earth's points (~2 events a
// walk) meet a 5 % target within it.
TEST(Truth, EventsBudgetBoundsLongWalks) {
  AtmosphereSpec thick = earth();
  thick.rayleigh_scattering_per_m_at_1um *= 100.0;
  const std::vector<TruthPoint> points = {{0, 45, 30, 0}, {1, 80, 60, 90}};
  TruthOptions o;
  o.paths = 1024;
  o.max_paths = 1 << 15;
  o.target_relative_se = 1e-4;  // unreachable: only a cap stops the walks
  o.max_events_per_point = 20.0 * o.paths_per_batch;
  const TruthResult r = trace_truth(thick, device(), points, o);
  EXPECT_GT(r.mean_events, 20.0);
  for (std::size_t p = 0; p < points.size(); ++p) {
    EXPECT_TRUE(r.at_cap[p]) << p;
    EXPECT_EQ(r.paths[p], o.paths_per_batch) << p;
  }
  o.target_relative_se = 0.05;
  o.paths = 256;
  const TruthResult e = trace_truth(earth(), device(), points, o);
  EXPECT_LT(e.mean_events, 20.0);
  for (std::size_t p = 0; p < points.size(); ++p) {
    EXPECT_FALSE(e.at_cap[p]) << p;
    EXPECT_GT(e.paths[p], o.paths_per_batch) << p;
  }
}

// Points whose sun is below low_sun_elevation_deg walk to their own target and cap (the scene
// check asks 1.5 × relative_se below −6°, scene_truth_options). Targets 5 % and, below −6°,
// 10 %: the sun −3° point meets 5 % in every channel, the sun −9° point 10 % and stops there
// (a twilight walk's relative standard deviation is 2–5, so from 64 walks the top-ups aim at
// 10 % and leave some channel above 5 %: had it walked to 5 % it would hold ~4× the walks).
// With a low-sun cap of 128 walks only the −9° point stops at a cap.
TEST(Truth, LowSunPointsWalkToTheirOwnTargetAndCap) {
  const std::vector<TruthPoint> points = {{0, 70, 93, 30}, {0, 70, 99, 30}};
  TruthOptions o;
  o.paths = 64;
  o.max_paths = 1 << 16;
  o.target_relative_se = 0.05;
  o.low_sun_elevation_deg = -6.0;
  o.low_sun_relative_se = 0.1;
  o.low_sun_max_paths = 1 << 16;
  const TruthResult r = trace_truth(earth(), device(), points, o);
  double deep_worst = 0.0;
  for (std::size_t c = 0; c < r.channels; ++c) {
    ASSERT_GT(r.L(0, c), 0.0);
    ASSERT_GT(r.L(1, c), 0.0);
    EXPECT_LE(r.se(0, c), 0.05 * r.L(0, c)) << c;
    EXPECT_LE(r.se(1, c), 0.10 * r.L(1, c)) << c;
    deep_worst = std::max(deep_worst, r.se(1, c) / r.L(1, c));
  }
  EXPECT_GT(deep_worst, 0.05);
  EXPECT_FALSE(r.at_cap[0]);
  EXPECT_FALSE(r.at_cap[1]);
  o.low_sun_max_paths = 128;
  const TruthResult capped = trace_truth(earth(), device(), points, o);
  EXPECT_FALSE(capped.at_cap[0]);
  EXPECT_TRUE(capped.at_cap[1]);
  EXPECT_EQ(capped.paths[1], 128);
  EXPECT_EQ(capped.paths[0], r.paths[0]);  // the other point walks as before
  // the options are part of a kept trace's key
  EXPECT_NE(truth_options_json(o).dump(), truth_options_json(TruthOptions{}).dump());
  o.low_sun_relative_se = -1.0;
  EXPECT_THROW(trace_truth(earth(), device(), points, o), InputError);
}

// A trace's progress is the share of the walks its precision target will ask for, as the walks
// so far predict it (plan_of after the first batch of every point and channel, then each round's
// plan), each batch weighted by its point's events a walk. Twilight points at a fine target take
// most of their walks in top-ups: the fraction of the first round's walks alone read 1 at that
// round's end (what a user saw as a bar at its end, or stuck, for minutes of top-ups). Three
// twilight points of like cost: the report after the first round (its 512 walks a channel) is
// within 3× of those walks' share of all the trace's walks (the prediction from one batch of 64
// walks is an estimate of a variance: low or high by tens of %, not 3×), no report falls more
// than 0.25 below the highest before it, and the last is 1.
TEST(Truth, ProgressCountsTheTopUpsTheTargetWillAsk) {
  const std::vector<TruthPoint> points = {{0.5, 80, 95, 180}, {1, 85, 97, 10}, {0.5, 60, 93, 60}};
  TruthOptions o;
  o.paths = 512;
  o.max_paths = 1 << 15;
  o.target_relative_se = 0.02;
  std::vector<double> f;
  const TruthResult r = trace_truth(earth(), device(), points, o, [&](std::string_view, double x) { f.push_back(x); });
  ASSERT_GE(f.size(), 3u);
  double high = 0.0, fall = 0.0;
  for (double x : f) {
    high = std::max(high, x);
    fall = std::max(fall, high - x);
  }
  long long walks = 0;
  for (long long n : r.channel_paths) walks += n;
  const double first_round = static_cast<double>(o.paths * static_cast<long long>(r.channel_paths.size())) /
                             static_cast<double>(walks);
  std::printf("%zu progress reports (%.3f after the first round, whose walks are %.3f of all %lld), largest fall "
              "%.3f, last %.3f\n",
              f.size(), f[1], first_round, walks, fall, f.back());
  ASSERT_LT(first_round, 0.3);  // the top-ups are most of the walks
  EXPECT_LE(f[1], 3.0 * first_round);
  EXPECT_GE(f[1], first_round / 3.0);
  EXPECT_LE(fall, 0.25);
  EXPECT_NEAR(f.back(), 1.0, 1e-12);
}

// ---- against the baked LUTs ------------------------------------------------------------------

// High-sun points (sun zenith 15–45°; views from 0–3 km, at least 15° from the horizon, sky
// and ground) against LUTs through GetSkyRadiance: Bruneton's full-size reference textures
// (REF, 4 orders, double) and our float32 bake at half size (HALF, orders until the auto
// tolerance 1e-3, its state kept after orders 1 and 4). The LUTs' errors, each measured
// without the truth:
//  - resolution: e_res = the worst |HALF₁ − REF₁| / REF₁ over the points (single scattering;
//    the half-size LUT's deviation, an upper estimate of the full-size one's);
//  - the bake's ray rule: single scattering is a 50-interval trapezoid over the ray (part of
//    the model, atmosphere.cl), which overestimates the Mie layer's e^{−h/1.2 km} along steep
//    rays by up to (Δ/H)²/12 ≈ 8 %; e_rule = that trapezoid with exact transmittances minus
//    the converged integral, per point (single_scattering_trapezoid);
//  - the multiple scattering's method: J_n by a 16 × 32 midpoint rule over the sphere
//    against phase functions as sharp as Mie's (g = 0.8, ~11° wide), plus the same ray rules;
//    refining the sphere rule alone to 48 × 96 moved the second order by up to 42 % at
//    sample points (docs/atmosphere.md): allowance half the LUT's multiple-scattering part m.
// Asserted: single scattering (orders = 1) within e_res of REF₁ − e_rule (+ 4 se); all orders
// (against REF + HALF's orders ≥ 5) within (e_res + |e_rule|/L + m/2) of it (+ 4 se).
TEST(Truth, AgainstBakedLutsAtHighSun) {
  const AtmosphereSpec s = earth();
  const Medium M(s);
  auto read = [](const char* name) { return specbake::testing::read_npy(::ref(std::string("textures/") + name)).data; };
  Luts ref_luts{model_of(s), channels_at(s, {kLambdaR, kLambdaG, kLambdaB}), read("transmittance.npy"),
                read("irradiance.npy"), read("scattering.npy"), read("single_mie_scattering.npy")};
  Luts ref1_luts = ref_luts;
  ref1_luts.scattering = read("single_rayleigh_scattering.npy");

  AtmosphereSpec half = s;
  half.transmittance_mu = 128;
  half.transmittance_r = 32;
  half.irradiance_mu_s = 32;
  half.irradiance_r = 8;
  half.scattering_r = 16;
  half.scattering_mu = 64;
  half.scattering_mu_s = 16;
  half.scattering_nu = 4;
  half.ray_simpson = half.phase_nu_slice = false;  // REF's rules: e_res measures the resolution alone
  const Model hm = model_of(half);
  // the scattering of all orders (auto, as the bundle bakes it) and of the first 1 and 4 orders
  auto scattering_of = [&](int orders, bool auto_orders) {
    auto backend = make_device_backend(device(), hm, ref_luts.rgb, 3, false);
    PassPlan plan;
    plan.orders = orders;
    plan.auto_orders = auto_orders;
    plan.tolerance = 1e-3;
    return run_pass(*backend, plan, [](std::string_view, double) {}, 0, 1);
  };
  const PassResult pr = scattering_of(kMaxAutoOrders, true);
  const std::vector<double> scattering_1 = scattering_of(1, false).scattering,
                            scattering_4 = scattering_of(4, false).scattering;
  ASSERT_FALSE(scattering_4.empty());
  const Luts half_luts{hm, ref_luts.rgb, pr.transmittance, pr.irradiance, pr.scattering, pr.single_mie};
  Luts half1_luts = half_luts, half4_luts = half_luts;
  half1_luts.scattering = scattering_1;
  half4_luts.scattering = scattering_4;

  const std::vector<TruthPoint> points = {{0, 0, 20, 0},     {0, 30, 30, 90},   {0, 55, 45, 180}, {0, 70, 15, 45},
                                          {0.5, 40, 35, 135}, {1, 65, 25, 10},  {3, 20, 40, 160}, {3, 75, 30, 100},
                                          {1, 110, 30, 60},   {2, 130, 20, 120}, {3, 160, 45, 0},  {0.5, 105, 40, 170}};
  const auto ref_all = lut_sky_radiance(ref_luts, points), ref_1 = lut_sky_radiance(ref1_luts, points);
  const auto half_all = lut_sky_radiance(half_luts, points), half_1 = lut_sky_radiance(half1_luts, points),
             half_4 = lut_sky_radiance(half4_luts, points);
  TruthOptions o;
  o.paths = 4096;
  o.target_relative_se = 0.003;
  o.orders = 1;
  const TruthResult t1 = trace_truth(s, device(), points, o);
  o.orders = 0;
  o.seed = 2;
  const TruthResult t_all = trace_truth(s, device(), points, o);

  double e_res = 0.0, worst_1 = 0.0, worst_all = 0.0, sq_all = 0.0;
  for (std::size_t p = 0; p < points.size(); ++p)
    for (int c = 0; c < 3; ++c) e_res = std::max(e_res, std::fabs(half_1[p][c] / ref_1[p][c] - 1));
  for (std::size_t p = 0; p < points.size(); ++p) {
    const auto exact = single_scattering_quadrature(M, points[p], 1000, 200);
    const auto rule = single_scattering_trapezoid(M, points[p], 50);
    for (int c = 0; c < 3; ++c) {
      const double e_rule = rule[c] - exact[c], ref_1_corrected = ref_1[p][c] - e_rule;
      const double d1 = t1.L(p, c) / ref_1_corrected - 1;
      worst_1 = std::max(worst_1, std::fabs(d1));
      EXPECT_LE(std::fabs(t1.L(p, c) - ref_1_corrected), e_res * ref_1[p][c] + 4 * t1.se(p, c)) << p << " " << c;
      const double lut = ref_all[p][c] + half_all[p][c] - half_4[p][c];
      const double m = (lut - ref_1[p][c]) / lut, d_all = t_all.L(p, c) / lut - 1;
      worst_all = std::max(worst_all, std::fabs(d_all));
      sq_all += d_all * d_all;
      EXPECT_LE(std::fabs(t_all.L(p, c) - lut), (e_res + 0.5 * m) * lut + std::fabs(e_rule) + 4 * t_all.se(p, c))
          << p << " " << c;
      std::printf("LUT p%zu %s: single: truth vs REF %+.2f%% (se %.2f%%), the rule's error %+.2f%%, HALF vs REF "
                  "%+.2f%%; all orders: truth vs LUT %+.2f%% (se %.2f%%), multiple part %.0f%%\n",
                  p, t1.channel_names[c].c_str(), 100 * (t1.L(p, c) / ref_1[p][c] - 1), 100 * t1.se(p, c) / t1.L(p, c),
                  100 * e_rule / exact[c], 100 * (half_1[p][c] / ref_1[p][c] - 1), 100 * d_all,
                  100 * t_all.se(p, c) / t_all.L(p, c), 100 * m);
    }
  }
  std::printf("single scattering: resolution error %.2f%%, truth vs REF corrected for the rule: worst %.2f%%; "
              "all orders: truth vs LUT RMS %.2f%%, worst %.2f%%\n",
              100 * e_res, 100 * worst_1, 100 * std::sqrt(sq_all / (3.0 * points.size())), 100 * worst_all);
}

// The view rays' rule (`quadrature: {ray_rule: simpson}`, the default): single scattering of a
// bake against the converged integral (single_scattering_quadrature, 1000 × 200 Simpson
// intervals) at high-sun points where the reference's 50-interval trapezoid is off by several
// per cent (the Mie layer's e^{−h/1.2 km} along steep rays). Bound per value: the texture's
// resolution, taken as twice the bake's change from the same bake at 2× every size (the
// interpolation converges at second order: the coarser bake's error ≈ 4/3 of that change), plus
// Simpson's own error (dx/H)⁴/180 ≤ 6e-3 at dx = H, plus 1e-3 for float32 and the sun rays'
// 500-interval trapezoid. The trapezoid bake itself misses this bound (checked too).
TEST(Truth, SimpsonViewRaysMatchTheConvergedSingleScattering) {
  AtmosphereSpec s = earth();
  s.orders = 1;
  const Medium M(s);
  AtmosphereSpec fine = s, trapezoid = s;
  scale_sizes(fine, 2.0);
  trapezoid.ray_simpson = false;
  const auto quiet = [](std::string_view, double) {};
  const Baked b = bake_luts(s, device(), quiet, 24), bf = bake_luts(fine, device(), quiet, 24),
              bt = bake_luts(trapezoid, device(), quiet, 24);
  const std::vector<TruthPoint> points = {{0, 0, 20, 0},      {0.5, 10, 13, 26}, {0, 30, 30, 90},
                                          {0.8, 35, 37, 12}, {0.4, 67, 63, 15}, {2, 20, 40, 160}};
  const auto lut = lut_sky_radiance(b.luts, points), lut_fine = lut_sky_radiance(bf.luts, points),
             lut_trapezoid = lut_sky_radiance(bt.luts, points);
  double worst_simpson = 0.0, worst_trapezoid = 0.0;
  bool trapezoid_misses = false;
  for (std::size_t p = 0; p < points.size(); ++p) {
    const auto exact = single_scattering_quadrature(M, points[p], 1000, 200);
    for (int c = 0; c < 3; ++c) {
      const double bound = 2.0 * std::fabs(lut[p][c] / lut_fine[p][c] - 1.0) + 6e-3 + 1e-3;
      const double e = lut[p][c] / exact[c] - 1.0, e_trapezoid = lut_trapezoid[p][c] / exact[c] - 1.0;
      EXPECT_LE(std::fabs(e), bound) << p << " " << c;
      trapezoid_misses = trapezoid_misses || std::fabs(e_trapezoid) > bound;
      worst_simpson = std::max(worst_simpson, std::fabs(e));
      worst_trapezoid = std::max(worst_trapezoid, std::fabs(e_trapezoid));
    }
  }
  EXPECT_TRUE(trapezoid_misses);
  std::printf("single scattering against the converged integral: Simpson worst %.2f%%, trapezoid worst %.2f%%\n",
              100 * worst_simpson, 100 * worst_trapezoid);
}

// ---- spectral results in the bundle's units ---------------------------------------------------

// Spectral bakes store Σ_i to_rgb[c][i] L(λ_i) (the job's precomputed-luminance weights); the
// conversion uses spectrum_of() itself and combines the se of independent wavelengths. A
// traced wavelength is the same model as the rgb mode's channel at that wavelength: 550 nm
// (spectral 500–600 nm, 5 bins) against rgb G, independent streams, within 4 combined se.
TEST(Truth, SpectralResultsConvertWithTheJobsWeights) {
  const AtmosphereSpec sp = spec_of("    preset: earth\n    spectrum: {min_nm: 500, max_nm: 600, count: 5}\n");
  const std::vector<TruthPoint> points = {{0, 40, 30, 90}, {1, 100, 45, 30}};
  TruthOptions o;
  o.paths = 32768;
  const TruthResult r = trace_truth(sp, device(), points, o);
  ASSERT_EQ(r.channels, 5u);
  EXPECT_EQ(r.channel_names[2], "550");
  const TruthResult g = trace_truth(earth(), device(), points, o);
  for (std::size_t p = 0; p < points.size(); ++p)
    EXPECT_NEAR(r.L(p, 2), g.L(p, 1), 4 * std::hypot(r.se(p, 2), g.se(p, 1)));
  const Spectrum spectrum = spectrum_of(sp);
  const TruthBundleValues v = to_bundle_units(sp, r);
  for (std::size_t p = 0; p < points.size(); ++p)
    for (int c = 0; c < 3; ++c) {
      double l = 0.0, var = 0.0;
      for (int i = 0; i < 5; ++i) {
        l += spectrum.to_rgb[c * 5 + i] * r.L(p, i);
        var += std::pow(spectrum.to_rgb[c * 5 + i] * r.se(p, i), 2);
      }
      EXPECT_DOUBLE_EQ(v.radiance[p * 3 + c], l);
      EXPECT_DOUBLE_EQ(v.standard_error[p * 3 + c], std::sqrt(var));
    }
  const std::string csv = truth_result_csv(sp, points, r);
  EXPECT_EQ(csv.substr(0, csv.find('\n')),
            std::string(kTruthPointsHeader) +
                ",L_510,se_510,L_530,se_530,L_550,se_550,L_570,se_570,L_590,se_590,L_R,se_R,L_G,se_G,L_B,se_B");
}

// ---- CSV, scene and bundle plumbing -------------------------------------------------------------

TEST(TruthCsv, ReadsPointsAndNamesTheBadCell) {
  const std::string h = std::string(kTruthPointsHeader) + "\n";
  const auto ok = parse_truth_points(h + "0,10,20,30\r\n1.5, 95 ,45,-10\n\n", "points.csv");
  ASSERT_EQ(ok.size(), 2u);
  EXPECT_EQ(ok[1].altitude_km, 1.5);
  EXPECT_EQ(ok[1].view_zenith_deg, 95.0);
  EXPECT_EQ(ok[1].view_sun_azimuth_deg, -10.0);
  EXPECT_EQ(parse_truth_points(truth_points_csv(ok), "x.csv").size(), 2u);
  const std::pair<std::string, std::string> bad[] = {
      {"", "points.csv:1:1"},
      {"altitude_km,view_zenith_deg,sun_zenith,view_sun_azimuth_deg\n0,0,0,0\n", "points.csv:1:39"},
      {h, "points.csv:2:1"},
      {h + "0,10,20\n", "points.csv:2:8"},
      {h + "0,10,20,30,40\n", "points.csv:2:11"},
      {h + "0,abc,20,30\n", "points.csv:2:3: view_zenith_deg"},
      {h + "0,10,20,30\n0,190,20,30\n", "points.csv:3:3: view_zenith_deg"},
      {h + "-1,10,20,30\n", "points.csv:2:1: altitude_km"},
      {h + "0,10,20,nan\n", "points.csv:2:9: view_sun_azimuth_deg"},
      {h + "0,10,20,30\n\n0,10,20,30\n", "points.csv:3:1"},
  };
  for (const auto& [text, where] : bad) {
    try {
      parse_truth_points(text, "points.csv");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(where), std::string::npos) << e.what() << " (wanted " << where << ")";
    }
  }
  EXPECT_THROW(read_truth_points("/nonexistent/points.csv"), IoError);
  EXPECT_THROW(trace_truth(earth(), device(), {{0, 200, 0, 0}}, TruthOptions{}), InputError);
}

// Scene sets: deterministic, inside their ranges, views on the asked side of the horizon, and
// low-discrepancy: each coordinate of the first 256 Halton points (van der Corput in bases 2,
// 3, 5, 7) fills 8 equal bins to within ±2 of 32, where an i.i.d. sample would stray by ±5.3
// (one standard deviation).
TEST(TruthScene, PointSetsAreDeterministicAndStratified) {
  const AtmosphereSpec s = earth();
  for (TruthViews views : {TruthViews::sky, TruthViews::ground, TruthViews::all}) {
    const TruthScene scene{0.0, 12.0, 5.0, 70.0, views, 256};
    const auto a = scene_points(scene, s), b = scene_points(scene, s);
    ASSERT_EQ(a.size(), 256u);
    EXPECT_EQ(truth_points_csv(a), truth_points_csv(b));
    int bins[4][8] = {};
    for (const TruthPoint& p : a) {
      ASSERT_GE(p.altitude_km, 0.0);
      ASSERT_LE(p.altitude_km, 12.0);
      ASSERT_GE(90 - p.sun_zenith_deg, 5.0);
      ASSERT_LE(90 - p.sun_zenith_deg, 70.0);
      const double r = s.bottom_radius_km + p.altitude_km, mu = std::cos(p.view_zenith_deg * M_PI / 180);
      const double mu_h = -std::sqrt(1 - std::pow(s.bottom_radius_km / r, 2));
      if (views == TruthViews::sky) EXPECT_GT(mu, mu_h);
      if (views == TruthViews::ground) EXPECT_LT(mu, mu_h);
      const double x[4] = {p.altitude_km / 12.0, (90 - p.sun_zenith_deg - 5.0) / 65.0,
                           views == TruthViews::all ? (1 - mu) / 2 : 0.5, p.view_sun_azimuth_deg / 180.0};
      for (int k = 0; k < 4; ++k) ++bins[k][std::min(7, static_cast<int>(x[k] * 8))];
    }
    for (int k = 0; k < 4; ++k) {
      if (k == 2 && views != TruthViews::all) continue;
      for (int j = 0; j < 8; ++j) EXPECT_NEAR(bins[k][j], 32, 2) << "coordinate " << k << " bin " << j;
    }
  }
  EXPECT_THROW(scene_points(TruthScene{5.0, 1.0, 0.0, 90.0, TruthViews::sky, 10}, s), InputError);
}

// A bundle's textures give the same GetSkyRadiance as the bake they were written from (the
// CLI and this process bake the same textures on the same device; the bundle stores them as
// float32, 2⁻²⁴ ≈ 6e-8 relative per texel, and a lookup is a convex combination of texels
// times positive phase functions: 2e-7); bundles without the 3D textures are refused.
TEST(TruthBundle, LutRadianceFromABundleMatchesTheBake) {
  specbake::testing::TempDir dir;
  const std::string job = "    preset: earth\n    orders: 2\n"
                          "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}\n"
                          "    scene: {points: 16}\n";
  specbake::testing::write_file(dir / "a.yaml", "specbake: 1\njobs:\n  - name: sky\n    kind: atmosphere\n" + job);
  const auto run = specbake::testing::run_cli({"run", (dir / "a.yaml").string(), "--out", (dir / "out").string()});
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const Luts from_bundle = load_bundle_luts(dir / "out" / "sky" / "latest");
  const Baked baked = bake_luts(spec_of(job), device(), [](std::string_view, double) {}, 0);
  const auto points = scene_points(TruthScene{0.0, 30.0, 0.0, 80.0, TruthViews::all, 40}, earth());
  const auto a = lut_sky_radiance(from_bundle, points), b = lut_sky_radiance(baked.luts, points);
  for (std::size_t p = 0; p < points.size(); ++p)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[p][c], b[p][c], 2e-7 * std::fabs(b[p][c]) + 1e-300) << p;
  // without the .bin, the EXR copy (float32: the same texels); without any copy, an input error
  std::filesystem::remove(dir / "out" / "sky" / "latest" / "single_mie_scattering.bin");
  const auto c = lut_sky_radiance(load_bundle_luts(dir / "out" / "sky" / "latest"), points);
  for (std::size_t p = 0; p < points.size(); ++p)
    for (int ch = 0; ch < 3; ++ch) EXPECT_EQ(c[p][ch], a[p][ch]) << p;
  std::filesystem::remove(dir / "out" / "sky" / "latest" / "single_mie_scattering.exr");
  EXPECT_THROW(load_bundle_luts(dir / "out" / "sky" / "latest"), InputError);
  EXPECT_THROW(load_bundle_luts(dir / "nothing"), IoError);
}

// ---- the samplers ---------------------------------------------------------------------------

// Delta tracking (free paths of orders >= 2) and ratio tracking (sun rays), on their own, in
// the Earth's profiles: along rays that rise, fall to the ground, pass a tangent point, or
// graze the horizon, the fraction of delta-tracking walks that pass a distance d without a
// collision is T(0, d) (exact quadrature), and the mean ratio-tracking estimate is T to the
// top. N = 40000 walks per ray: binomial se √(T(1 − T)/N) ≤ 2.5e-3; ratio tracking's se
// from its sample variance; each within 4 se.
TEST(TruthTracking, FreePathsAndShadowRaysFollowTheTransmittance) {
  const AtmosphereSpec s = earth();
  const Medium M(s);
  const auto a = ref3::make_parameters(model_of(s), M.ch);
  const std::vector<double> maj = medium_table(model_of(s), M.ch);  // as the tracer builds it
  const double rays[][2] = {{0.0, 1.0}, {0.0, 0.05}, {3.0, -0.2}, {8.0, -0.04}, {20.0, -0.05}, {0.5, 0.0}, {12.0, 0.3}};
  constexpr int N = 40000;
  for (const auto& ray : rays) {
    const double h = ray[0], mu = ray[1];
    const auto& [ground, D, x, v] = test_ray(a, h, mu);
    for (int c = 0; c < 3; ++c) {
      for (double f : {0.25, 1.0}) {
        const double d = f * D;
        const double T = std::exp(-M.depth(c, x, v, d, 20000));
        int passed = 0, violations = 0;
        for (int i = 0; i < N; ++i) {
          PhiloxStream rng;
          philox_stream_init(&rng, 3, 5, i, c, static_cast<philox_u32>(f * 4));
          double sd, hs;
          const int what = ref3::truth_free_path(&a, c, maj.data(), h, mu, &rng, &sd, &hs, &violations);
          if (what != 1 || sd >= d) ++passed;
        }
        const double se = std::sqrt(std::max(T * (1 - T), 1e-4) / N);
        EXPECT_NEAR(passed / double(N), T, 4 * se) << "h " << h << " mu " << mu << " channel " << c << " to " << d;
        EXPECT_EQ(violations, 0);
      }
      if (ground) continue;
      // ratio tracking towards the top along (h, mu)
      double sum = 0.0, sum2 = 0.0;
      int violations = 0;
      for (int i = 0; i < N; ++i) {
        PhiloxStream rng;
        philox_stream_init(&rng, 7, 5, i, c, 9);
        const double e = ref3::truth_sun_transmittance(&a, c, maj.data(), h, mu, 0, &rng, &violations);
        sum += e;
        sum2 += e * e;
      }
      const double mean = sum / N, se = std::sqrt(std::max(sum2 / N - mean * mean, 0.0) / N);
      const double T = std::exp(-M.depth(c, x, v, D, 20000));
      EXPECT_NEAR(mean, T, 4 * se + 1e-12) << "ratio tracking h " << h << " mu " << mu << " channel " << c;
      EXPECT_EQ(violations, 0);
    }
  }
}

// The free paths of twilight walks (truth_guided_free_path: one sample of the mixture of delta
// tracking and a table along the ray ∝ σ_s T̂ S̄, weighted by σ_t T / the mixture's pdf) keep
// the expectation of delta tracking whatever the table: E[factor g(end)] = ∫₀^D σ_t T g ds +
// T(D) g_ground for a test function g. The table is built as the walk builds it
// (truth_next_sun_term, guided) from a medium whose sky table is an arbitrary positive function
// (log S̄ = h/4 km − 3 μ_s, not the light: unbiasedness must not depend on it). Rays rise and
// graze from 10 km (the table in use: S̄ grows along them by more than TRUTH_FREE_PATH_GAIN), or
// descend to the ground (S̄ falls: delta tracking alone). The truth: a cumulative trapezoid of the
// tests' own σ_t over 200 000 steps (relative error ≲ 1e-8). The estimate is bounded (factor ≤
// 1/(1 − β)), so its sample se is reliable (24 seeds of the first ray: z-scores of mean −0.1,
// spread 1.0): bound 4 se.
TEST(TruthTracking, GuidedFreePathsKeepTheExpectationWhateverTheirTable) {
  const AtmosphereSpec s = earth();
  const Medium M(s);
  const auto a = ref3::make_parameters(model_of(s), M.ch);
  std::vector<double> medium = medium_table(model_of(s), M.ch);
  for (int i = 0; i < TRUTH_SKY_H; ++i)
    for (int j = 0; j < TRUTH_SKY_MU; ++j) {
      double h, mu_s;
      ref3::truth_sky_node(&a, i, j, &h, &mu_s);
      for (int c = 0; c < 3; ++c) medium[ref3::kTruthSkyAt + (i * TRUTH_SKY_MU + j) * 3 + c] = h / 4.0 - 3.0 * mu_s;
    }
  const double sun_el = -10.0 * M_PI / 180.0;
  const double sun[3] = {std::cos(sun_el), 0.0, std::sin(sun_el)};
  const double rays[][2] = {{0.0, 0.3}, {2.0, 0.05}, {10.0, -0.02}, {5.0, -0.3}};
  constexpr int N = 40000, steps = 200000;
  int tabled = 0;
  for (const auto& ray : rays) {
    const double h = ray[0], mu = ray[1];
    const auto& [ground, D, x, v] = test_ray(a, h, mu);
    const double z[3] = {0, 0, 1};
    auto g = [&](double sd, double h_s) { return 1.0 + sd / D + std::exp(h_s / 10.0); };
    const double g_ground = 3.0;
    for (int c = 0; c < 3; ++c) {
      // the truth
      double tau = 0.0, integral = 0.0, prev = 0.0;
      const double ds = D / steps;
      for (int k = 0; k <= steps; ++k) {
        const double sd = ds * k, p[3] = {x[0] + sd * v[0], x[1] + sd * v[1], x[2] + sd * v[2]};
        const double sigma = M.sigma_t(c, p);
        if (k > 0) tau += 0.5 * (prev + sigma) * ds;
        const double f = sigma * std::exp(-tau) * g(sd, M.altitude(p));
        integral += (k == 0 || k == steps ? 0.5 : 1.0) * f * ds;
        prev = sigma;
      }
      const double expected = integral + (ground ? std::exp(-tau) * g_ground : 0.0);
      // the walks' estimate
      ref3::TruthRayTable table;
      {
        PhiloxStream rng;
        philox_stream_init(&rng, 11, 3, 0, c, 0);
        int violations = 0;
        ref3::truth_next_sun_term(&a, c, medium.data(), h, z, v, sun, 1, 1, &table, &rng, &violations);
      }
      tabled += table.sum > 0.0;
      double sum = 0.0, sum2 = 0.0;
      int violations = 0;
      for (int i = 0; i < N; ++i) {
        PhiloxStream rng;
        philox_stream_init(&rng, 13, 3, i, c, 1);
        double sd = 0.0, h_s = 0.0, factor = 0.0;
        const int what =
            ref3::truth_guided_free_path(&a, c, medium.data(), h, mu, &table, &rng, &sd, &h_s, &factor, &violations);
        const double e = what == 1 ? factor * g(sd, h_s) : what == 2 ? factor * g_ground : 0.0;
        sum += e;
        sum2 += e * e;
      }
      const double mean = sum / N, se = std::sqrt(std::max(sum2 / N - mean * mean, 0.0) / N);
      std::printf("guided free path h %.1f mu %+.2f channel %d (table %s): %.6g ± %.2g, expected %.6g, z = %+.2f\n", h,
                  mu, c, table.sum > 0.0 ? "on" : "off", mean, se, expected, (mean - expected) / se);
      EXPECT_NEAR(mean, expected, 4 * se) << "h " << h << " mu " << mu << " channel " << c;
      EXPECT_EQ(violations, 0);
    }
  }
  EXPECT_GE(tabled, 6);  // the rising and grazing rays draw from their tables
}

// The exact optical depth twilight walks use (truth_optical_depth: pieces between cut
// altitudes, 8-point Gauss–Legendre) against the independent composite Simpson of the tests'
// Medium in 3D vectors with 200 000 intervals (its error, ~(Δ/H)⁴/180 with Δ ≤ 5 m, H ≥ 0.3
// km, is below 1e-9 relative). Rays that rise, descend to the ground, pass a tangent point low
// and high, graze the ground and run along the horizon from 40 km, over the whole ray and part
// of it, for the Earth (ozone's tent: three kinks), Mars, a thin haze (Mie scale height 0.3
// km: the steep layer dominates near the ground) and a high one (Mie scale height 3 km, with
// 10× Earth's aerosols: a steep layer that stays a large share of σ_t up high), so that the
// cut rule meets pieces where a steep layer is all of σ_t, a part of it and a trace of it.
// The rule places cuts so that its error estimate (truth_depth_piece_error) stays within
// TRUTH_DEPTH_ERROR = 4e-8 relative; asserted at 1e-7 relative (seen ≤ 5e-9).
TEST(TruthTracking, ExactOpticalDepthMatchesAFineQuadrature) {
  const AtmosphereSpec haze = spec_of("    preset: earth\n    mie: {scale_height_km: 0.3}\n");
  const AtmosphereSpec high = spec_of("    preset: earth\n    mie: {scale_height_km: 3.0, extinction_per_m: 4.4e-5}\n");
  for (const AtmosphereSpec& s : {earth(), mars(), haze, high}) {
    const Medium M(s);
    const auto a = ref3::make_parameters(model_of(s), M.ch);
    const std::vector<double> medium = medium_table(model_of(s), M.ch);
    double worst = 0.0;
    const double rays[][2] = {{0.0, 1.0},    {0.0, 0.05},   {3.0, -0.2},  {8.0, -0.04}, {20.0, -0.05},
                              {0.5, 0.0},    {12.0, 0.3},   {0.0, 0.0},   {40.0, -0.11}, {1.0, -0.017},
                              {10.0, -0.056}, {0.2, 0.002}, {25.0, -0.09}, {15.0, -0.068}};
    for (const auto& ray : rays) {
      const double h = ray[0], mu = ray[1];
      const auto& [ground, D, x, v] = test_ray(a, h, mu);
      for (double f : {0.3, 1.0})
        for (int c = 0; c < 3; ++c) {
          const double want = M.depth(c, x, v, f * D, 200000);
          const double got = ref3::truth_optical_depth(&a, c, medium.data(), h, mu, f * D);
          EXPECT_NEAR(got, want, 1e-7 * want + 1e-12) << " h " << h << " mu " << mu << " f " << f << " c " << c;
          worst = std::max(worst, std::fabs(got - want) / want);
        }
    }
    std::string cuts;  // each cut, with the points of the piece below it
    for (int k = 0; k < medium[ref3::kTruthCutsAt]; ++k)
      cuts += (k ? " " : "") + std::to_string(medium[ref3::kTruthCutsAt + 1 + k]).substr(0, 5) + "(" +
              std::to_string(static_cast<int>(medium[ref3::kTruthCutsAt + 1 + ref3::kTruthMaxCuts + k])) + ")";
    std::printf("exact optical depth (bottom radius %.1f km, cuts at %s km): worst relative error %.2g\n",
                s.bottom_radius_km, cuts.c_str(), worst);
  }
}

// The cut rule's error estimate is a bound: for e^{−E u} on [0, 1] the n-point rule's relative
// error (n = 5 and 8, computed here in long double against the exact (1 − e^{−E})/E) never
// exceeds truth_gauss_relative_error(n, E), and the estimate is no more than 1e3× pessimistic
// where the rule is used (the levels are not needlessly dense).
TEST(TruthTracking, DepthPieceErrorBoundsTheGaussRule) {
  struct Rule {
    int n;
    std::vector<long double> x, w;  // nodes and weights on [−1, 1]
  };
  const Rule rules[] = {
      {5,
       {-0.9061798459386639927976269L, -0.5384693101056830910363144L, 0.0L, 0.5384693101056830910363144L,
        0.9061798459386639927976269L},
       {0.2369268850561890875142640L, 0.4786286704993664680412915L, 0.5688888888888888888888889L,
        0.4786286704993664680412915L, 0.2369268850561890875142640L}},
      {8,
       {-0.9602898564975362316835609L, -0.7966664774136267395915539L, -0.5255324099163289858177390L,
        -0.1834346424956498049394761L, 0.1834346424956498049394761L, 0.5255324099163289858177390L,
        0.7966664774136267395915539L, 0.9602898564975362316835609L},
       {0.1012285362903762591525314L, 0.2223810344533744705443560L, 0.3137066458778872873379622L,
        0.3626837833783619829651504L, 0.3626837833783619829651504L, 0.3137066458778872873379622L,
        0.2223810344533744705443560L, 0.1012285362903762591525314L}}};
  for (const Rule& r : rules)
    for (double E = 0.25; E <= (r.n == 5 ? 6.0 : 14.0); E += 0.25) {
      long double sum = 0.0L;
      for (std::size_t i = 0; i < r.x.size(); ++i)
        sum += r.w[i] * std::exp(-static_cast<long double>(E) * (0.5L + 0.5L * r.x[i]));
      const long double exact = (1.0L - std::exp(-static_cast<long double>(E))) / E;
      const double seen = static_cast<double>(std::fabs(0.5L * sum - exact) / exact);
      const double bound = ref3::truth_gauss_relative_error(r.n, E);
      // the long-double sums' own rounding: ≤ 8 terms of ≤ 1, 64 ulps
      EXPECT_LE(seen, bound + 64.0 * static_cast<double>(LDBL_EPSILON)) << " n " << r.n << " E " << E;
      if (bound > 1e-15) EXPECT_GT(seen, 1e-3 * bound) << " n " << r.n << " E " << E;
    }
}

// The tracer builds its channel groups' sun tables from the profiles' optical lengths (the
// medium table of unit_channels()): at every node the sum Σ_i coefficient_i · length_i must be
// the group's own exact quadrature. Both are quadratures of ~1e-7 relative error (what
// ExactOpticalDepthMatchesAFineQuadrature asserts of truth_optical_depth on its rays; the cut
// rule's 4e-8 is an estimate per piece); at these nodes they differ by up to 2.2e-7.
// The table only shapes a pdf, whose own interpolation error is 0.05 + 0.02 τ (the test
// below), so 1e-6 relative is asserted: far below anything a walk sees, and an indexing slip
// (profile, channel or node order) is off by O(1).
TEST(TruthTracking, GroupSunTablesFromTheProfilesLengthsMatchTheirQuadrature) {
  for (const AtmosphereSpec& s : {earth(), mars()}) {
    const Medium M(s);
    const std::vector<double> lengths = medium_table(model_of(s), unit_channels());
    const std::vector<double> own = medium_table(model_of(s), M.ch);
    const std::vector<double> summed = medium_table(model_of(s), M.ch, &lengths);
    ASSERT_EQ(own.size(), summed.size());
    constexpr int G = ref3::kTruthChannels;  // the table's [node][channel] stride
    for (int n = 0; n < TRUTH_SUN_H * TRUTH_SUN_MU; ++n)
      for (int c = 0; c < 3; ++c) {
        const double want = own[ref3::kTruthSunAt + n * G + c], got = summed[ref3::kTruthSunAt + n * G + c];
        EXPECT_NEAR(got, want, 1e-6 * want + 1e-12) << "node " << n << " channel " << c;
      }
    // everything before the sun table (majorants, cuts) is the group's own
    EXPECT_TRUE(std::equal(own.begin(), own.begin() + ref3::kTruthSunAt, summed.begin()));
  }
}

// The sky-light table integrates a spectrum's channels at most 40 nm apart and interpolates log S̄
// of the others linearly in λ⁻⁴. Against each channel integrated alone, at every node with
// light: the integrated channels are the same numbers, and the interpolated ones within a factor
// 1.25 (measured: 1.17 on Earth, where the ozone bands add to Rayleigh's λ⁻⁴, 1.0004 on Mars;
// linear in λ instead gave 5.4 at the darkest nodes). The table only shapes pdfs, where a factor
// of 2 only moves noise; an index or weight slip (a neighbour's channel, x outside [0, 1]) is off
// by far more on Earth, whose neighbouring channels at the blue end (365, 375 nm) differ by up to
// e^7.9 where the sun's light grazes the ground (3 % in daylight; Mars 8 %). 13–16 integrated: the
// subset is a subset.
TEST(TruthTracking, SkyLightOfASpectrumInterpolatesLogSBetweenChannelsIntegratedAlone) {
  for (const AtmosphereSpec& base : {earth(), mars()}) {
    AtmosphereSpec s = base;
    s.spectral = true;
    s.min_nm = 360.0;
    s.max_nm = 830.0;
    s.count = 48;
    const Channels ch = channels_at(s, spectrum_of(s).lambda_nm);
    const Model m = model_of(s);
    const std::vector<double> lengths = medium_table(m, unit_channels());
    const std::vector<double> all = sky_light_table(m, ch, lengths);
    const std::size_t N = static_cast<std::size_t>(TRUTH_SKY_H) * TRUTH_SKY_MU, C = ch.size();
    ASSERT_EQ(all.size(), N * C);
    double worst = 0.0;
    int exact = 0;
    for (std::size_t c = 0; c < C; ++c) {
      const std::vector<double> alone = sky_light_table(m, ch.subset({c}), lengths);
      bool same = true;
      for (std::size_t n = 0; n < N; ++n) {
        if (alone[n] == ref3::kTruthSkyNone) continue;
        ASSERT_NE(all[n * C + c], ref3::kTruthSkyNone) << "node " << n << " channel " << c;
        worst = std::max(worst, std::abs(all[n * C + c] - alone[n]));
        same = same && all[n * C + c] == alone[n];
      }
      exact += same;
    }
    EXPECT_LE(worst, std::log(1.25));
    EXPECT_GE(exact, 13);  // the first, the last and one at most every 40 nm between: 360–830 nm
    EXPECT_LE(exact, 16);
    std::printf("sky light of 48 channels: %d integrated, worst interpolated factor %.3f\n", exact, std::exp(worst));
  }
}

// The line estimate's view transmittance (truth_view_transmittance, exact mode: T̂ + [u < q]
// (T − T̂)/q from the trapezoid's depth T̂ = e^{−τ̂} and the exact depth) keeps the expectation
// T = e^{−τ} whatever τ̂: the trapezoid at the line's 9 nodes as the walk takes it (the tests' own
// σ_t), and τ̂ halved and doubled. Rays that rise from the ground, graze it, descend to it from
// 10 km and pass a tangent point from 30 km, Earth and Mars, over the whole ray and to a point
// inside its fifth segment. The estimate takes two values, so its sample se is exact up to
// O(1/N): bound 4 se. Beside it, what the trapezoid leaves: the correction's relative variance
// (1/q − 1)(T − T̂)²/T² on these rays (printed; a twilight walk's own is ~1–2).
TEST(TruthTracking, LineViewTransmittanceKeepsItsExpectationWhateverItsTrapezoid) {
  for (const AtmosphereSpec& s : {earth(), mars()}) {
    const Medium M(s);
    const auto a = ref3::make_parameters(model_of(s), M.ch);
    const std::vector<double> medium = medium_table(model_of(s), M.ch);
    const double rays[][2] = {{0.0, 0.3}, {0.0, 0.01}, {10.0, -0.1}, {30.0, -0.08}, {2.0, 0.002}};
    constexpr int N = 20000, kSeg = 8;
    double worst_var = 0.0;
    for (const auto& ray : rays) {
      const double h = ray[0], mu = ray[1];
      const auto& [ground, D, x, v] = test_ray(a, h, mu);
      for (int c = 0; c < 3; ++c) {
        double tau_k[kSeg + 1], prev = 0.0;
        for (int k = 0; k <= kSeg; ++k) {
          const double sd = D * k / kSeg, p[3] = {x[0] + sd * v[0], x[1] + sd * v[1], x[2] + sd * v[2]};
          const double sigma = M.sigma_t(c, p);
          tau_k[k] = k == 0 ? 0.0 : tau_k[k - 1] + 0.5 * (prev + sigma) * D / kSeg;
          prev = sigma;
        }
        for (const double s_end : {D, D * 4.37 / kSeg}) {
          const double exact = std::exp(-ref3::truth_optical_depth(&a, c, medium.data(), h, mu, s_end));
          const double trapezoid = s_end == D ? tau_k[kSeg] : tau_k[4] + 0.37 * (tau_k[5] - tau_k[4]);
          worst_var = std::max(worst_var, (1.0 / ref3::kTruthSunExactShare - 1.0) *
                                              std::pow((exact - std::exp(-trapezoid)) / exact, 2.0));
          for (const double scale : {1.0, 0.5, 2.0}) {
            double sum = 0.0, sum2 = 0.0;
            int violations = 0;
            for (int i = 0; i < N; ++i) {
              PhiloxStream rng;
              philox_stream_init(&rng, 17, 5, i, c, 0);
              const double e = ref3::truth_view_transmittance(&a, c, medium.data(), h, mu, ground, s_end,
                                                              scale * trapezoid, 1, &rng, &violations);
              sum += e;
              sum2 += e * e;
            }
            const double mean = sum / N, se = std::sqrt(std::max(sum2 / N - mean * mean, 0.0) / N);
            EXPECT_NEAR(mean, exact, 4 * se + 1e-12) << "h " << h << " mu " << mu << " c " << c << " s " << s_end
                                                     << " scale " << scale;
          }
        }
      }
    }
    std::printf("line view transmittance: worst relative variance the trapezoid leaves %.3g\n", worst_var);
  }
}

// The sun depths of the medium table (truth_sun_depth_table), which shape the twilight line's
// pdf only: between the nodes, against the exact optical depth towards the sun (the horizon's
// ray when the sun is below it), for the Earth and Mars, where the sun is not blocked beyond
// any use (T > 1e-6). Its error only costs variance, never bias; asserted loosely (|Δτ| ≤
// 0.05 + 0.02 τ: within ~5 % in T, where the pdf's other factors are coarser) so that an
// indexing slip — axes, channels, the node map — fails (those are off by O(1) in τ).
TEST(TruthTracking, SunDepthTableFollowsTheExactDepth) {
  for (const AtmosphereSpec& s : {earth(), mars()}) {
    const Medium M(s);
    const auto a = ref3::make_parameters(model_of(s), M.ch);
    const std::vector<double> medium = medium_table(model_of(s), M.ch);
    const double t = a.top_radius - a.bottom_radius;
    double worst = 0.0;
    int n = 0;
    for (int i = 0; i < 37; ++i)
      for (int j = 0; j < 53; ++j) {
        const double h = t * std::pow((i + 0.37) / 37.0, 2.0);
        const double mu_h = -ref3::horizon_distance(&a, h) / ref3::radius_of(&a, h);
        const double mu_s = mu_h - 0.05 + (1.05 - mu_h) * std::pow((j + 0.61) / 53.0, 2.0);
        const double mu = std::max(mu_s, mu_h);
        for (int c = 0; c < 3; ++c) {
          const double exact = ref3::truth_optical_depth(&a, c, medium.data(), h, mu, ref3::distance_to_top(&a, h, mu));
          if (!(exact < 13.8)) continue;
          const double got = ref3::truth_sun_depth_table(&a, medium.data(), c, h, mu_s);
          worst = std::max(worst, std::fabs(got - exact) / (0.05 + 0.02 * exact));
          ++n;
          EXPECT_NEAR(got, exact, 0.05 + 0.02 * exact) << "h " << h << " mu_s " << mu_s << " c " << c;
        }
      }
    std::printf("sun depth table: %d points, worst |Δτ| %.3g of its bound\n", n, worst);
    EXPECT_GT(n, 3000);
  }
}
