// `spectrum: {store: radiance}`: the radiance at every stored wavelength, four per RGBA texel.
// The files hold the per-wavelength values the luminance textures were summed from (checked
// through the CIE weights the manifest records), the Spectral OpenEXR and KTX2 copies hold the
// same texels, and sampling_spectral.glsl's ...AtWavelength functions (host build of the same
// render.glsl) are exact at stored wavelengths and linear between them.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "io/exr.hpp"
#include "io/ktx2.hpp"
#include "job/kind.hpp"
#include "kinds/atmosphere/atmosphere_job.hpp"
#include "atmosphere/radiance_earth.hpp"
#include "support/testing.hpp"

namespace {

namespace t = specbake::testing;
namespace fs = std::filesystem;
using nlohmann::json;
using namespace specbake;
using namespace specbake::atmosphere;

using t::read_file;

TEST(AtmosphereRadiance, FilesHoldTheRadianceTheLuminanceTexturesWereSummedFrom) {
  t::TempDir tmp;
  t::write_file(tmp / "sky.yaml",
                "specbake: 1\noutput: out\njobs:\n  - name: sky\n    kind: atmosphere\n    orders: 2\n"
                "    spectrum: {min_nm: 400, max_nm: 700, count: 8, store: radiance}\n"
                "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}\n"
                "    scene: none\n    previews: none\n    formats: [bin, exr, ktx2]\n    ktx2: {format: rgba32f}\n");
  const auto run = t::run_cli({"run", (tmp / "sky.yaml").string()}, tmp.path());
  ASSERT_EQ(run.exit_code, 0) << run.out << run.err;
  const fs::path b = fs::canonical(tmp / "out" / "sky" / "latest");
  const json m = t::read_json(b / "manifest.json");
  const json& sr = m["parameters"]["spectral_radiance"];
  const auto lambda = sr["wavelengths_nm"].get<std::vector<double>>();
  ASSERT_EQ(lambda.size(), 8u);
  EXPECT_NEAR(sr["lambda_step_nm"].get<double>(), 300.0 / 8, 1e-12);
  const auto to_rgb = m["parameters"]["luminance_conversion"]["to_rgb"].get<std::vector<std::vector<double>>>();
  const int n = 8, sets = 2, R = 4, MU = 8, WD = 3 * 6;

  struct Pair {
    const char* rgb;       // the luminance texture (R, G, B innermost; 3D order for scattering)
    const char* spectral;  // its radiance per wavelength
    int texels;
    bool tiled;
  };
  for (const Pair& p : {Pair{"irradiance", "spectral_irradiance", 16 * 4, false},
                        Pair{"scattering", "spectral_scattering_tiled2d", R * MU * WD, true},
                        Pair{"single_mie_scattering", "spectral_single_mie_scattering_tiled2d", R * MU * WD, true}}) {
    SCOPED_TRACE(p.spectral);
    const std::vector<float> lum = t::read_f32(b / (std::string(p.rgb) + ".bin"));
    const std::vector<float> rad = t::read_f32(b / (std::string(p.spectral) + ".bin"));
    ASSERT_EQ(rad.size(), 4u * sets * p.texels);
    ASSERT_EQ(lum.size(), 3u * p.texels);
    double worst = 0.0;
    bool any_light = false;
    for (int i = 0; i < p.texels; ++i) {
      int at = i;  // the texel's index in the spectral file
      if (p.tiled) {
        const int x = i % WD, mu = (i / WD) % MU, r = i / (WD * MU);
        at = (mu * R + r) * WD + x;
      }
      for (int c = 0; c < 3; ++c) {
        double sum = 0.0, abs_sum = 0.0;
        for (int g = 0; g < n; ++g) {
          const double v = rad[4 * ((g / 4) * p.texels + at) + g % 4];
          sum += to_rgb[c][g] * v;
          abs_sum += std::fabs(to_rgb[c][g] * v);
        }
        any_light = any_light || abs_sum > 0.0;
        // Both sides are float32 sums over the 2 orders made on the device (pass.hpp's Sums): the
        // luminance's weighted sum and each stored radiance round once per order's addition and
        // once when stored, 2^-24 each: 3 roundings a side bound both (one rounding a side was
        // seen to be exceeded by 2 % once the density's θ rule changed the values).
        const double bound = 3.0 * std::ldexp(1.0, -23) * (std::fabs(lum[3 * i + c]) + abs_sum) + 1e-30;
        worst = std::max(worst, std::fabs(sum - lum[3 * i + c]) / bound);
      }
    }
    EXPECT_TRUE(any_light);
    EXPECT_LE(worst, 1.0);

    // The Spectral OpenEXR copy: one channel per wavelength, the same float32 values.
    std::vector<std::string> names;
    for (const auto& c : exr_channels(read_file(b / (std::string(p.spectral) + ".exr")))) names.push_back(c);
    ASSERT_EQ(names.size(), 8u);
    EXPECT_NE(std::find(names.begin(), names.end(), "S0.418,750000nm"), names.end());
    std::vector<std::string> ordered;
    char name[64];
    for (double l : lambda) {
      std::snprintf(name, sizeof name, "S0.%.6fnm", l);
      std::string s = name;
      std::replace(s.begin(), s.end(), '.', ',');
      s[2] = '.';  // "S0." keeps its dot; the wavelength's decimal point is a comma
      ordered.push_back(s);
    }
    const ExrImage exr = exr_read(read_file(b / (std::string(p.spectral) + ".exr")), ordered);
    for (int i = 0; i < p.texels; ++i)
      for (int g = 0; g < n; ++g)
        ASSERT_EQ(exr.pixels[static_cast<std::size_t>(i) * n + g], rad[4 * ((g / 4) * p.texels + i) + g % 4]);

    // The KTX2 copy: a 2D array texture of one layer per wavelength set, the .bin texels bit for bit.
    const auto k = read_ktx2(read_file(b / (std::string(p.spectral) + ".ktx2")), p.spectral);
    EXPECT_EQ(k.layer_count, 2u);
    EXPECT_EQ(k.depth, 0u);
    ASSERT_NE(k.value("specbake.wavelengths_nm"), nullptr);
    ASSERT_EQ(k.rgba.size(), rad.size());
    EXPECT_EQ(std::memcmp(k.rgba.data(), rad.data(), 4 * rad.size()), 0);
  }
  EXPECT_TRUE(fs::exists(b / "sampling_spectral.glsl"));
  const json* rec = find_accuracy(m["accuracy"], "spectral_interpolation");
  ASSERT_NE(rec, nullptr);
  EXPECT_EQ(rec->at("details").at("test_wavelengths_nm").size(), 7u);  // every gap's midpoint
  EXPECT_GT(rec->at("value").get<double>(), 0.0);
}

// The spectral lookups on the host over a double reference bake: exact at a stored wavelength,
// linear between two (also across a set's edge, where two sets are read), clamped outside.
TEST(AtmosphereRadiance, AtWavelengthIsExactAtStoredWavelengthsAndLinearBetween) {
  const Baked b = bake_luts_reference(t::radiance_earth({32, 8}, {16, 4}, {4, 8, 6, 3}));
  ASSERT_EQ(b.radiance.lambda_nm.size(), 8u);
  const SpectralRenderer sr(b.luts.model, b.radiance);
  const double rb = b.luts.model.bottom_radius_km;
  const Vec3 camera{0.0, 0.0, rb + 0.5}, sun{0.6, 0.0, 0.8}, ground{0.0, 0.0, rb}, up{0.0, 0.0, 1.0};
  const std::vector<Vec3> views = {{0.0, 0.0, 1.0}, {0.8, 0.0, 0.6}, {0.0, 0.96, 0.28}, {-0.6, 0.0, -0.8}};
  const auto& lam = b.radiance.lambda_nm;
  // The interpolation weights are (x − floor x), computed in double: ~1e-15 relative; 1e-12 is
  // far above that and far below the difference between neighbouring wavelengths (checked).
  const auto near = [](double a, double e) { return std::fabs(a - e) <= 1e-12 * std::fabs(e) + 1e-300; };
  for (const Vec3& v : views) {
    for (int i = 0; i < 8; ++i) {
      double t_at = 0.0, t_stored = 0.0;
      EXPECT_TRUE(near(sr.sky_radiance(camera, v, sun, lam[i], &t_at), sr.sky_radiance_stored(camera, v, sun, i, &t_stored)))
          << "stored wavelength " << i;
      EXPECT_TRUE(near(t_at, t_stored));
    }
    for (int i : {0, 3, 6}) {  // 3 → 4 crosses from set 0 to set 1
      const double mid = sr.sky_radiance(camera, v, sun, 0.75 * lam[i] + 0.25 * lam[i + 1], nullptr);
      const double a = sr.sky_radiance_stored(camera, v, sun, i, nullptr),
                   c = sr.sky_radiance_stored(camera, v, sun, i + 1, nullptr);
      EXPECT_TRUE(near(mid, 0.75 * a + 0.25 * c)) << "between " << i << " and " << i + 1;
      // the neighbours must differ by far more than the tolerance for this to test anything
      EXPECT_GT(std::fabs(a - c), 1e-6 * std::fabs(a));
    }
    EXPECT_TRUE(near(sr.sky_radiance(camera, v, sun, 300.0, nullptr), sr.sky_radiance_stored(camera, v, sun, 0, nullptr)));
    EXPECT_TRUE(near(sr.sky_radiance(camera, v, sun, 900.0, nullptr), sr.sky_radiance_stored(camera, v, sun, 7, nullptr)));
  }
  double sky_at = 0.0, sky_stored = 0.0;
  EXPECT_TRUE(near(sr.sun_and_sky_irradiance(ground, up, sun, lam[5], &sky_at),
                   sr.sun_and_sky_irradiance_stored(ground, up, sun, 5, &sky_stored)));
  EXPECT_TRUE(near(sky_at, sky_stored));
  // Measuring the interpolation against the stored bake itself finds no error: the measurement
  // compares like with like at stored wavelengths.
  const InterpolationError self = interpolation_error(b.luts.model, b.radiance, b.radiance);
  EXPECT_EQ(self.radiance.max, 0.0);
  EXPECT_EQ(self.irradiance.max, 0.0);
  EXPECT_GT(self.radiance.count, 1000u);
}

TEST(AtmosphereRadiance, TestWavelengthsAreGapMidpointsSpreadEvenly) {
  EXPECT_EQ(interpolation_test_wavelengths({500.0}).size(), 0u);
  EXPECT_EQ(interpolation_test_wavelengths({500.0, 510.0}), std::vector<double>{505.0});
  std::vector<double> many;
  for (int i = 0; i < 48; ++i) many.push_back(400.0 + 5.0 * i);
  const auto t = interpolation_test_wavelengths(many);
  ASSERT_EQ(t.size(), static_cast<std::size_t>(kInterpolationTests));
  EXPECT_EQ(t.front(), 402.5);
  EXPECT_EQ(t.back(), 400.0 + 5.0 * 46 + 2.5);  // the last gap's midpoint
}

}  // namespace
