// The sky-view table (lookup.cl, "The sky-view table"): its config keys, the float32 kernel
// against the double reference, and its lookup (render.glsl, GetSkyViewScattering) returning
// the table's own nodes. Its accuracy against the independent twilight quadrature is in
// twilight_truth_test.cpp, its GLSL on a real GL in atmosphere_gl_test.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "atmosphere/max_rel.hpp"
#include "atmosphere/sized.hpp"
#include "atmosphere/spec_of.hpp"
#include "core/errors.hpp"
#include "kinds/atmosphere/bake/bake.hpp"
// shader_host.hpp (GLM) before reference.hpp, whose kernel prelude defines R
#include "kinds/atmosphere/shader/shader_host.hpp"
#include "kinds/atmosphere/bake/reference.hpp"
#include "kinds/atmosphere/truth/truth.hpp"
#include "support/testing.hpp"

using namespace specbake;
using namespace specbake::atmosphere;

namespace {

const Progress kQuiet = [](std::string_view, double) {};

// A small Earth whose scene reaches twilight, with a small sized table (3 altitudes, 7 suns,
// 16 views, 7 azimuths).
AtmosphereSpec small_twilight() {
  AtmosphereSpec s = specbake::testing::spec_of(
      "    preset: earth\n    spectrum: rgb\n    orders: 3\n"
      "    scene: {camera_altitude_km: [0, 2], sun_elevation_deg: [-9, 6]}\n"
      "    sky_view: {altitude: 3, sun: 7, view: 16, azimuth: 7}\n");
  return specbake::testing::sized(s, {32, 8}, {16, 4}, {5, 16, 8, 4});
}

using specbake::testing::max_rel;

}  // namespace

// `sky_view:` auto (a config's default) builds the table for a scene whose sun goes below the
// horizon, over its cameras and its suns up to 10°, with a node every 0.5° and 0.5 km; none,
// daylight scenes and `scene: none` have none; node counts are checked.
TEST(SkyView, ConfigKeysAndTheAutomaticRange) {
  const SkyView twilight = model_of(specbake::testing::spec_of(
                                        "    preset: earth\n    scene: {camera_altitude_km: [0, 2], "
                                        "sun_elevation_deg: [-12, 20]}\n"))
                               .sky_view;
  ASSERT_TRUE(twilight.on());
  EXPECT_EQ(twilight.sun_min_deg, -12.0);
  EXPECT_EQ(twilight.sun_max_deg, kSkyViewSunMaxDeg);
  EXPECT_EQ(twilight.sun, 45);       // 22° in 0.5° steps, both ends
  EXPECT_EQ(twilight.altitude, 9);   // 2 km in 0.25 km steps
  EXPECT_EQ(twilight.view, kSkyViewViews);
  EXPECT_EQ(twilight.azimuth, kSkyViewAzimuths);
  const SkyView ground = model_of(specbake::testing::spec_of("    preset: earth\n")).sky_view;  // sun −6…90°
  ASSERT_TRUE(ground.on());
  EXPECT_EQ(ground.sun, 33);
  EXPECT_FALSE(model_of(specbake::testing::spec_of("    preset: earth\n    scene: {sun_elevation_deg: [0, 60]}\n"))
                   .sky_view.on());
  EXPECT_FALSE(model_of(specbake::testing::spec_of("    preset: earth\n    scene: none\n")).sky_view.on());
  EXPECT_FALSE(model_of(specbake::testing::spec_of("    preset: earth\n    sky_view: none\n")).sky_view.on());
  const SkyView one_altitude = model_of(specbake::testing::spec_of(
                                            "    preset: earth\n    scene: {camera_altitude_km: 1, "
                                            "sun_elevation_deg: [-4, -2]}\n"))
                                   .sky_view;
  EXPECT_EQ(one_altitude.altitude, 1);
  EXPECT_EQ(one_altitude.sun, 5);
  const SkyView sized = model_of(small_twilight()).sky_view;
  EXPECT_EQ(sized.texels(), 3LL * 7 * 16 * 7);
  // a twilight scene with its table stores half the μ_s texels it bakes (the table holds its
  // views); given sizes, no table or `store: radiance` store what they bake
  const auto deep = [](const std::string& more) {
    return specbake::testing::spec_of("    preset: earth\n    scene: {sun_elevation_deg: [-12, 10]}\n" + more);
  };
  EXPECT_TRUE(deep("").store_half_mu_s && deep("").store_half_nu);
  EXPECT_EQ(stored_sizes(deep("")).mu_s, kTwilightScatteringMuS / 2);
  EXPECT_EQ(sizes_of(deep("")).mu_s, kTwilightScatteringMuS);
  // ν: 15 slices baked, the default 8 stored (every other one) — the 4D textures' memory unchanged
  EXPECT_EQ(sizes_of(deep("")).nu, kTwilightScatteringNu);
  EXPECT_EQ(stored_sizes(deep("")).nu, AtmosphereSpec{}.scattering_nu);
  EXPECT_EQ(stored_sizes(deep("")).scattering_texels(), sizes_of(specbake::testing::spec_of("    preset: earth\n    scene: none\n")).scattering_texels());
  for (const char* more : {"    sky_view: none\n", "    sizes: 100%\n",
                           "    spectrum: {min_nm: 360, max_nm: 830, count: 16, store: radiance}\n"})
    EXPECT_FALSE(deep(more).store_half_mu_s || deep(more).store_half_nu) << more;
  // early twilight (sun −6…10°): 64 μ_s texels baked, 32 stored; the default 8 ν slices
  const AtmosphereSpec early = specbake::testing::spec_of("    preset: earth\n    scene: {sun_elevation_deg: [-6, 10]}\n");
  EXPECT_EQ(sizes_of(early).mu_s, kTwilightScatteringMuS);
  EXPECT_EQ(sizes_of(early).nu, AtmosphereSpec{}.scattering_nu);
  EXPECT_TRUE(early.store_half_mu_s && !early.store_half_nu);
  EXPECT_EQ(stored_sizes(early).scattering_texels(), sizes_of(specbake::testing::spec_of("    preset: earth\n    scene: none\n")).scattering_texels());
  // a scene whose sun stays above the horizon bakes the defaults
  const AtmosphereSpec day = specbake::testing::spec_of("    preset: earth\n    scene: {sun_elevation_deg: [0, 60]}\n");
  EXPECT_EQ(sizes_of(day).mu_s, AtmosphereSpec{}.scattering_mu_s);
  EXPECT_FALSE(day.store_half_mu_s || day.store_half_nu);
  for (const char* bad : {"    sky_view: {view: 15}\n", "    sky_view: {azimuth: 1}\n", "    sky_view: {sun: 0}\n",
                          "    sky_view: {altitudes: 3}\n", "    sky_view: sometimes\n"}) {
    try {
      specbake::testing::spec_of(std::string("    preset: earth\n") + bad);
      ADD_FAILURE() << "accepted " << bad;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("sky_view"), std::string::npos) << e.what();
    }
  }
}

// The aerosol's vertical scattering optical depth against its closed form for an exponential
// profile, β ω H (1 − e^(−T/H)) at 1 µm scaled by λ^−α (the column's trapezoid at 1 m steps is
// within (1 m)² / (12 H²) ≈ 6e-8 relative of it), and the rule it drives: a twilight scene with
// thick aerosol bakes 15 ν slices and stores 8; thin aerosol, or a sun that stays up, does not.
TEST(SkyView, ThickAerosolTwilightScenesBakeFifteenNuSlices) {
  const auto spec = [](const std::string& media, const std::string& sun) {
    return specbake::testing::spec_of("    preset: earth\n" + media + "    scene: {sun_elevation_deg: [" + sun + "]}\n");
  };
  const std::string hazy = "    mie: {scale_height_km: 2.0, extinction_per_m: 3.5e-5, single_scattering_albedo: 0.95}\n";
  const std::string dusty = "    mie: {scale_height_km: 11.0, extinction_per_m: 4.5e-5, angstrom_alpha: 1.3}\n";
  const double thickness = 60.0;  // the Earth preset's atmosphere, km
  EXPECT_NEAR(mie_vertical_scattering_depth(spec(hazy, "-6, 10"), 550.0),
              3.5e-2 * 0.95 * 2.0 * (1.0 - std::exp(-thickness / 2.0)), 1e-6 * 0.067);
  const double dusty_depth = 4.5e-2 * std::pow(0.55, -1.3) * 0.9 * 11.0 * (1.0 - std::exp(-thickness / 11.0));
  EXPECT_NEAR(mie_vertical_scattering_depth(spec(dusty, "-6, 10"), 550.0), dusty_depth, 1e-6 * dusty_depth);
  const double earth_depth = 4.44e-3 * 0.9 * 1.2 * (1.0 - std::exp(-thickness / 1.2));
  EXPECT_NEAR(mie_vertical_scattering_depth(spec("", "-6, 10"), 550.0), earth_depth, 1e-6 * earth_depth);
  EXPECT_EQ(mie_vertical_scattering_depth(spec("    mie: false\n", "-6, 10"), 550.0), 0.0);

  const AtmosphereSpec thick = spec(hazy, "-6, 10");
  EXPECT_TRUE(has_thick_aerosol(thick));
  EXPECT_EQ(sizes_of(thick).nu, kTwilightScatteringNu);
  EXPECT_EQ(sizes_of(thick).mu_s, kTwilightScatteringMuS);
  EXPECT_TRUE(thick.store_half_mu_s && thick.store_half_nu);
  EXPECT_EQ(stored_sizes(thick).nu, AtmosphereSpec{}.scattering_nu);
  EXPECT_FALSE(has_thick_aerosol(spec("", "-6, 10")));
  EXPECT_EQ(sizes_of(spec("", "-6, 10")).nu, AtmosphereSpec{}.scattering_nu);
  for (const char* day : {"0, 60", "10, 90"}) {  // no twilight: the default counts
    EXPECT_EQ(sizes_of(spec(hazy, day)).nu, AtmosphereSpec{}.scattering_nu) << day;
    EXPECT_EQ(sizes_of(spec(hazy, day)).mu_s, AtmosphereSpec{}.scattering_mu_s) << day;
  }
  const AtmosphereSpec given = spec(hazy + "    sizes: 100%\n", "-6, 10");  // sizes given: baked as given, stored whole
  EXPECT_EQ(sizes_of(given).nu, AtmosphereSpec{}.scattering_nu);
  EXPECT_FALSE(given.store_half_mu_s || given.store_half_nu);
}

// The float32 kernel against the double reference (same functions, same inputs): each texel is
// single_scattering_ray + multiple_scattering_ray over the bake's transmittance and summed
// density, the quadratures of the 4D texture's own texels, so the 4D textures' float32 chain
// bound holds (atmosphere_device_test.cpp, kFloat32Chain: 3e-3 relative to |value| + 1e-3 × the
// channel maximum).
TEST(SkyView, DeviceMatchesTheDoubleReference) {
  const AtmosphereSpec s = small_twilight();
  const Baked host = bake_luts_reference(s);
  const Baked dev = bake_luts(s, specbake::testing::shared_device(), kQuiet, 0);
  ASSERT_EQ(host.luts.sky_view.size(), 3ULL * model_of(s).sky_view.texels());
  const double e = max_rel(dev.luts.sky_view, host.luts.sky_view, 1e-3),
               em = max_rel(dev.luts.sky_view_mie, host.luts.sky_view_mie, 1e-3);
  std::printf("sky view float32 vs double: %.3g, single Mie %.3g\n", e, em);
  EXPECT_LE(e, 3e-3);
  EXPECT_LE(em, 3e-3);
  double peak = 0.0;
  for (double v : host.luts.sky_view) peak = std::max(peak, v);
  EXPECT_GT(peak, 0.0);
}

// The lookup at a texel's own (h, μ, μ_s, ν) returns that texel: the shader's coordinates invert
// the kernel's texel parameters exactly. What rounding leaves: the azimuth comes back through
// acos of a cosine near ±1 (φ = 0 and π), which loses up to √(2 ε) ≈ 2e-8 rad, 1e-7 of a texel,
// times a change between neighbouring texels of at most ~10×: 1e-6 relative (floor 1e-6 × max).
// A half-texel slip anywhere would show as tens of percent.
TEST(SkyView, TheLookupReturnsTheTablesNodes) {
  const AtmosphereSpec s = small_twilight();
  const Baked b = bake_luts_reference(s);
  const Model& m = b.luts.model;
  const SkyView& v = m.sky_view;
  const auto a = ref3::make_parameters(m, Channels{});
  const glsl::SpecbakeAtmosphere atm = glsl::atmosphere_of(m, b.luts.rgb);
  const glsl::SkyViewSamplers sv = glsl::sky_view_samplers(b.luts);
  ASSERT_TRUE(sv.on);
  const double grid[4] = {v.altitude_min_km, v.altitude_max_km, v.sun_min_deg * M_PI / 180.0,
                          v.sun_max_deg * M_PI / 180.0};
  std::vector<double> looked, stored;
  for (int id = 0; id < v.texels(); ++id) {
    double h, mu, mu_s, nu;
    int ground;
    ref3::sky_view_texel_params(&a, grid, v.altitude, v.sun, v.view, v.azimuth, id, &h, &mu, &mu_s, &nu, &ground);
    const glsl::vec3 l = glsl::GetSkyViewScattering(atm, sv.grid, sv.radiance, sv.single_mie, h, mu, mu_s, nu, ground);
    for (int c = 0; c < 3; ++c) {
      looked.push_back(l[c]);
      stored.push_back(b.luts.sky_view[3 * id + c] + b.luts.sky_view_mie[3 * id + c] * ref3::mie_phase(m.mie_g, nu));
    }
  }
  const double e = max_rel(looked, stored, 1e-6);
  std::printf("lookup at the nodes against the nodes: %.3g\n", e);
  EXPECT_LE(e, 1e-6);
}

// The stored 4D textures of a bake that bakes more μ_s texels and ν slices than it stores: each
// stored texel is the baked texture's own value where a baked slice lies at its ν coordinate
// (every other one of an odd count), else the linear blend of the two around it — the lookup
// along ν (slice k at unit coordinate k / (NU − 1)). μ_s untouched here (its counts equal).
TEST(SkyView, StoredNuSlicesAreTheBakedTexturesLookups) {
  for (const auto& [baked, stored] : {std::pair{5, 3}, {15, 8}, {6, 3}}) {
    Luts luts;
    luts.model.sizes.r = 2;
    luts.model.sizes.mu = 3;
    luts.model.sizes.mu_s = 4;
    luts.model.sizes.nu = baked;
    const Sizes from = luts.model.sizes;
    const auto value = [&](long long row, int nu, int mu_s, int c) {
      return 1.0 + row + 10.0 * nu * nu + 0.1 * mu_s + 0.01 * c;  // curved in ν: a blend is not a slice
    };
    luts.scattering.resize(3ULL * from.scattering_texels());
    for (long long row = 0; row < 1LL * from.r * from.mu; ++row)
      for (int nu = 0; nu < baked; ++nu)
        for (int mu_s = 0; mu_s < from.mu_s; ++mu_s)
          for (int c = 0; c < 3; ++c)
            luts.scattering[3 * ((row * baked + nu) * from.mu_s + mu_s) + c] = value(row, nu, mu_s, c);
    luts.single_mie = luts.scattering;
    store_sun_axes(luts, from.mu_s, stored);
    ASSERT_EQ(luts.model.sizes.nu, stored);
    ASSERT_EQ(luts.scattering.size(), 3ULL * from.r * from.mu * stored * from.mu_s);
    for (long long row = 0; row < 1LL * from.r * from.mu; ++row)
      for (int j = 0; j < stored; ++j) {
        const double x = static_cast<double>(j * (baked - 1)) / (stored - 1);
        const int i0 = std::min(static_cast<int>(x), baked - 2);
        const double g = x - i0;  // 0 or 1 at a baked slice
        for (int mu_s = 0; mu_s < from.mu_s; ++mu_s)
          for (int c = 0; c < 3; ++c) {
            const double want = (1.0 - g) * value(row, i0, mu_s, c) + g * value(row, i0 + 1, mu_s, c);
            const double got = luts.scattering[3 * ((row * stored + j) * from.mu_s + mu_s) + c];
            if (g == 0.0 || g == 1.0)  // a baked slice: its own value, unresampled
              EXPECT_EQ(got, value(row, g == 0.0 ? i0 : i0 + 1, mu_s, c)) << baked << "→" << stored << " slice " << j;
            else  // the blend: a few roundings of values ~1e3
              EXPECT_NEAR(got, want, 1e-15 * std::fabs(want)) << baked << "→" << stored << " slice " << j;
            EXPECT_EQ(luts.single_mie[3 * ((row * stored + j) * from.mu_s + mu_s) + c], got);
          }
      }
  }
}

// Order 2 of a dusty air (Mars' media: dust g 0.7, 0.45 of the vertical scattering depth) at
// near-zenith views from 1 km, the sun 1° below and 5° above the horizon, towards and away from
// it, against the path-traced truth of the same order (the split of orders 2 walks: order 1 by
// quadrature, order 2 alone by walks; 65536 walks, relative se of order 2 ≤ 1.5 %, asserted).
// The table reads the summed densities J along each view's ray. At the ground Bruneton's μ rows
// are the zenith, then ~28° from it (here), and between rows the reference's lookup at one ν
// reads another azimuth in each: order 2 came out 0.68× the truth towards the sun, 1.36× away.
// scattering_lookup_azimuthal keeps the azimuth across the rows: towards the sun within 12 %
// (measured 0.93–0.96). Away from the sun the rows' own spacing still leaves order 2 up to ~1.38×
// at the default 128 μ rows; with 512 (and 16 r rows, which these views do not need more of:
// the same texels as the default) every point is within 12 % (measured 0.98–1.07;
// docs/atmosphere-method.md, "Near the zenith: the azimuth of a J read"). Tolerance: the worst
// measured 7 % + 3 se (4.5 %).
TEST(SkyView, DustyZenithViewsKeepTheSunsAzimuth) {
  const std::string dust =
      "    preset: earth\n    bottom_radius_km: 3389.5\n    top_radius_km: 3469.5\n"
      "    sun_angular_radius_rad: 0.00307\n    solar_irradiance_scale: 0.431\n    ground_albedo: 0.25\n"
      "    max_sun_zenith_deg: 110\n    rayleigh: {scale_height_km: 11.1, scattering_per_m_at_1um: 2.0e-8}\n"
      "    mie: {scale_height_km: 11.0, extinction_per_m: 4.5e-5, angstrom_alpha: 0.0,"
      " single_scattering_albedo: 0.95, phase_g: 0.7}\n    ozone: false\n    spectrum: rgb\n    orders_tail: none\n"
      "    scene: {sun_elevation_deg: [-6, 10], camera_altitude_km: [0, 2], views: sky}\n";
  std::vector<TruthPoint> points;
  for (double sun : {-1.0, 5.0})
    for (double azimuth : {0.0, 180.0}) points.push_back({1.0, 20.0, 90.0 - sun, azimuth});
  TruthOptions o;
  o.orders = 2;
  o.split_orders = 1;
  o.paths = 65536;
  const TruthResult truth = trace_truth(specbake::testing::spec_of(dust + "    orders: 2\n"),
                                        specbake::testing::shared_device(), points, o);
  const auto order2 = [&](std::size_t p, int c) { return truth.radiance_high[p * truth.channels + c]; };
  for (std::size_t p = 0; p < points.size(); ++p)
    for (int c = 0; c < 3; ++c)
      ASSERT_LE(truth.standard_error_high[p * truth.channels + c], 0.015 * order2(p, c)) << p << " " << c;

  // LUT order 2 alone: the orders ≤ 2 bake less the order-1 bake, over the truth's order 2
  const auto ratios = [&](const std::string& sizes) {
    const auto lut = [&](int orders) {
      const AtmosphereSpec s = specbake::testing::spec_of(dust + "    orders: " + std::to_string(orders) + "\n" + sizes);
      return lut_sky_radiance(bake_luts(s, specbake::testing::shared_device(), kQuiet, 0).luts, points);
    };
    const std::vector<Vec3> one = lut(1), two = lut(2);
    std::vector<std::array<double, 3>> q(points.size());
    for (std::size_t p = 0; p < points.size(); ++p)
      for (int c = 0; c < 3; ++c) q[p][c] = (two[p][c] - one[p][c]) / order2(p, c);
    return q;
  };
  const auto at_default = ratios(""), fine_mu = ratios("    sizes: {scattering: {r: 16, mu: 512, mu_s: 64, nu: 15}}\n");
  for (std::size_t p = 0; p < points.size(); ++p) {
    std::printf("sun %5.1f°, azimuth %5.1f°: LUT / truth, order 2: %.3f %.3f %.3f (512 μ rows: %.3f %.3f %.3f)\n",
                90.0 - points[p].sun_zenith_deg, points[p].view_sun_azimuth_deg, at_default[p][0], at_default[p][1],
                at_default[p][2], fine_mu[p][0], fine_mu[p][1], fine_mu[p][2]);
    for (int c = 0; c < 3; ++c) {
      if (points[p].view_sun_azimuth_deg == 0.0) EXPECT_NEAR(at_default[p][c], 1.0, 0.12) << p << " " << c;
      EXPECT_NEAR(fine_mu[p][c], 1.0, 0.12) << p << " " << c;
    }
  }
}
