// The atmosphere job through the CLI: bundle contents, EXR attributes, GLSL, previews, errors.
#include <gtest/gtest.h>

#include <algorithm>

#include "io/exr.hpp"
#include "job/kind.hpp"
#include "support/testing.hpp"

using namespace specbake::testing;

namespace {

const char* kSmall = R"(specbake: 1
jobs:
  - name: sky
    kind: atmosphere
    preset: earth
    orders: 3
    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}
    layout: [3d, tiled2d]
    scene: {points: 16}
)";

}  // namespace

TEST(AtmosphereCli, BakesABundleWithEveryFile) {
  TempDir dir;
  write_file(dir / "a.yaml", kSmall);
  const auto r = run_cli({"run", (dir / "a.yaml").string(), "--out", (dir / "out").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto b = dir / "out" / "sky" / "latest";
  const auto m = read_json(b / "manifest.json");
  EXPECT_EQ(m["parameters"]["orders"]["used"], 3);
  EXPECT_EQ(m["parameters"]["orders"]["per_order"].size(), 3u);
  EXPECT_EQ(m["parameters"]["wavelengths_nm"].size(), 3u);
  EXPECT_TRUE(m["parameters"]["luminance_conversion"].contains("sky_spectral_radiance_to_luminance_lm_per_W"));
  EXPECT_LE(specbake::find_accuracy(m["accuracy"], "self_check")->at("value").get<double>(), 2e-3);  // the job's bound (bake/bake.cpp)
  {
    // every moment of the compute step belongs to a stage: the kernels', the checks', the host's
    // between them, each pass's set-up (program build, allocations) and its combination. The
    // stages run back to back, so only bookkeeping between them is left out (microseconds; the
    // bound leaves room for a loaded machine's preemption)
    const auto& total = m["atmosphere"]["timings_s"]["total"];
    for (const char* stage : {"scattering_density", "setup", "combine", "self_check", "sums"})
      EXPECT_TRUE(total.contains(stage)) << stage;
    double staged = 0.0;
    for (const auto& [stage, sec] : total.items())
      if (stage != "files" && stage != "previews") staged += sec["wall_s"].get<double>();
    const double compute = m["timings_s"]["steps"]["compute"]["wall_s"].get<double>();
    EXPECT_GE(staged, 0.9 * compute - 0.05) << "stages " << staged << " s of a compute step of " << compute << " s";
    EXPECT_LE(staged, compute + 1e-3);
    // the files and previews `run` finishes on its publishing thread are still the job's: in its
    // files step and its seconds (the atmosphere's own timings of them are parts of that step)
    const double files = m["timings_s"]["steps"]["files"]["wall_s"].get<double>();
    const double listed = total["files"]["wall_s"].get<double>(), previews = total["previews"]["wall_s"].get<double>();
    EXPECT_GT(previews, 0.0);
    EXPECT_GE(files, listed + previews) << "files step " << files << " s";
    double steps = 0.0;
    for (const auto& [step, sec] : m["timings_s"]["steps"].items()) steps += sec["wall_s"].get<double>();
    EXPECT_GE(m["timings_s"]["bake"].get<double>(), steps - 1e-6);
  }
  // shapes, outermost first
  EXPECT_EQ(read_f32(b / "transmittance.bin").size(), 8u * 32 * 3);
  EXPECT_EQ(read_f32(b / "irradiance.bin").size(), 4u * 16 * 3);
  EXPECT_EQ(read_f32(b / "scattering.bin").size(), 4u * 8 * 18 * 3);
  EXPECT_EQ(read_f32(b / "single_mie_scattering.bin").size(), 4u * 8 * 18 * 3);
  const auto tiled = read_f32(b / "scattering_tiled2d.bin"), flat = read_f32(b / "scattering.bin");
  ASSERT_EQ(tiled.size(), flat.size());
  // column = r·NU·MU_S + ν·MU_S + μ_s of row mu: texel (r=2, mu=5, x=7)
  EXPECT_EQ(tiled[((5 * 4 + 2) * 18 + 7) * 3 + 1], flat[((2 * 8 + 5) * 18 + 7) * 3 + 1]);
  for (const char* f : {"transmittance.exr", "irradiance.exr", "scattering.exr", "scattering_tiled2d.exr",
                        "single_mie_scattering.exr"}) {
    const auto img = specbake::exr_read(read_file(b / f), {"R", "G", "B"});
    EXPECT_GT(img.width, 0) << f;
    EXPECT_TRUE(img.attributes.count("specbake.layout")) << f;
  }
  const std::string glsl = read_file(b / "sampling.glsl");
  // the functions (their value type is SpecbakeRadiance, vec3 in this build) and the constants
  for (const char* fn : {" GetSkyRadiance(SpecbakeAtmosphere atm,", " GetSkyRadianceToPoint(SpecbakeAtmosphere atm,",
                         " GetSunAndSkyIrradiance(SpecbakeAtmosphere atm,", "vec3 GetScattering3D(SpecbakeAtmosphere atm,",
                         " GetScatteringTiled2D(SpecbakeAtmosphere atm,", " GetTransmittance(SpecbakeAtmosphere atm,",
                         " GetTransmittanceToTopAtmosphereBoundary(SpecbakeAtmosphere atm,",
                         " GetIrradiance(SpecbakeAtmosphere atm,", "#define SpecbakeRadiance vec3",
                         "const SpecbakeAtmosphere SPECBAKE_ATMOSPHERE = SpecbakeAtmosphere("})
    EXPECT_NE(glsl.find(fn), std::string::npos) << fn;
  for (const char* png : {"planet_from_space.png", "sky_fisheye_sun_+60deg.png", "sky_fisheye_sun_+20deg.png",
                          "sky_fisheye_sun_+05deg.png", "sky_fisheye_sun_+00deg.png", "sky_fisheye_sun_-04deg.png"}) {
    const Image img = read_png(b / "preview" / png);
    EXPECT_EQ(img.width, 512) << png;  // the default `previews: {size: 512}`
    EXPECT_EQ(img.height, 512) << png;
  }
  const Image sheet = read_png(b / "preview" / "contact_sheet.png");
  EXPECT_EQ(sheet.width, 3 * 256);
  EXPECT_EQ(sheet.height, 2 * 256);
}

// The previews' exposure is fixed per view (docs/atmosphere.md, "Previews"): a sun half as bright
// gives darker pictures (an exposure adapted to each image would hide it), and `previews: none`
// writes none.
TEST(AtmosphereCli, PreviewsHaveAFixedExposure) {
  TempDir dir;
  const std::string base = "specbake: 1\njobs:\n  - name: sky\n    kind: atmosphere\n    orders: 2\n    scene: none\n"
                           "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}\n"
                           "    previews: {size: 64}\n";
  write_file(dir / "a.yaml", base);
  write_file(dir / "b.yaml", base + "    solar_irradiance_scale: 0.5\n");
  write_file(dir / "c.yaml", "specbake: 1\njobs:\n  - name: sky\n    kind: atmosphere\n    orders: 2\n    scene: none\n"
                             "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}\n"
                             "    previews: none\n");
  for (const char* c : {"a", "b", "c"}) {
    const auto r = run_cli({"run", (dir / (std::string(c) + ".yaml")).string(), "--out", (dir / c).string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  const auto mean = [](const Image& img) {
    double s = 0;
    for (std::size_t i = 0; i < img.rgba.size(); i += 4) s += img.rgba[i] + img.rgba[i + 1] + img.rgba[i + 2];
    return s / static_cast<double>(img.rgba.size());
  };
  for (const char* png : {"sky_fisheye_sun_+20deg.png", "planet_from_space.png"}) {
    const Image full = read_png(dir / "a" / "sky" / "latest" / "preview" / png);
    const Image half = read_png(dir / "b" / "sky" / "latest" / "preview" / png);
    EXPECT_EQ(full.width, 64);
    // at the same exposure half the light reads darker: sRGB codes of ACES(x) against ACES(x/2),
    // lower wherever the pixel is lit and not black (the rule raises neither view's EV100: their
    // highlights are well inside the curve's shoulder)
    EXPECT_LT(mean(half), 0.9 * mean(full)) << png;
  }
  EXPECT_FALSE(fs::exists(dir / "c" / "sky" / "latest" / "preview"));
}

// The default tone curve keeps the sky: the exposure rule (docs/atmosphere.md, "Previews") puts
// the 99.5th percentile of each view's lit pixels at most at 97.5 % of white, so at most 0.5 % of
// them reach code 255 (the sun's disc, a few pixels, among them), for the default Earth and for a
// Mars-like sky (dust scattering forward, the brightest aureole of the configs) alike, and with
// either tone curve; the labels
// (code ≤ 235) never count. Each view says what it is: the fisheye's top-left corner, black
// outside the picture's circle, carries the label's ink; the Earth at sun +20° is not washed out
// (the mean sRGB of its lit pixels was 0.79 before the fixed exposures put its median near x = 0.2).
TEST(AtmosphereCli, PreviewsKeepTheSkyAndAreLabelled) {
  TempDir dir;
  const std::string common =
      "    orders: 2\n    scene: none\n    previews: {size: 128}\n"
      "    sizes: {transmittance: [64, 16], irradiance: [32, 8], scattering: {r: 8, mu: 32, mu_s: 16, nu: 8}}\n";
  const std::string mars = "    bottom_radius_km: 3389.5\n    top_radius_km: 3469.5\n"
                           "    sun_angular_radius_rad: 0.00307\n    solar_irradiance_scale: 0.431\n"
                           "    ground_albedo: 0.25\n    max_sun_zenith_deg: 110\n"
                           "    rayleigh: {scale_height_km: 11.1, scattering_per_m_at_1um: 2.0e-8}\n"
                           "    mie: {scale_height_km: 11.0, extinction_per_m: 4.5e-5, angstrom_alpha: 0.0,\n"
                           "          single_scattering_albedo: 0.95, phase_g: 0.7}\n    ozone: false\n";
  // and with `tone: linear`, where only the raised exposures keep the Martian sky (at the fixed
  // ones 6 % of its pixels at sun +20° and 11 % at −4° would clip)
  std::string linear = common;
  linear.replace(linear.find("{size: 128}"), 11, "{size: 128, tone: linear}");
  write_file(dir / "c.yaml", "specbake: 1\njobs:\n  - name: earth\n    kind: atmosphere\n" + common +
                                 "  - name: mars\n    kind: atmosphere\n" + common + mars +
                                 "  - name: mars-linear\n    kind: atmosphere\n" + linear + mars);
  const auto r = run_cli({"run", (dir / "c.yaml").string(), "--out", (dir / "out").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* job : {"earth", "mars", "mars-linear"})
    for (const char* png : {"sky_fisheye_sun_+60deg.png", "sky_fisheye_sun_+20deg.png", "sky_fisheye_sun_+05deg.png",
                            "sky_fisheye_sun_+00deg.png", "sky_fisheye_sun_-04deg.png", "planet_from_space.png"}) {
      const Image img = read_png(dir / "out" / job / "latest" / "preview" / png);
      ASSERT_EQ(img.width, 128);
      long lit = 0, clipped = 0, ink = 0;
      double sum = 0;
      for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
          const unsigned char* p = &img.rgba[4 * (static_cast<std::size_t>(y) * img.width + x)];
          const int top = std::max({p[0], p[1], p[2]});
          lit += top > 0;
          clipped += top == 255;
          sum += (p[0] + p[1] + p[2]) / (3 * 255.0);
          // the top-left 20 × 12 pixels lie outside the fisheye's circle (radius 64 about (64, 64))
          ink += x < 20 && y < 12 && top >= 128;
        }
      EXPECT_LE(clipped, 0.005 * lit) << job << " " << png << ": " << clipped << " of " << lit;
      if (std::string(png) != "planet_from_space.png") EXPECT_GT(ink, 10) << job << " " << png << ": no label";
      if (std::string(job) == "earth" && std::string(png) == "sky_fisheye_sun_+20deg.png")
        EXPECT_LT(sum / lit, 0.65) << "washed out";
    }
}

TEST(AtmosphereCli, BadConfigsAreInputErrors) {
  TempDir dir;
  const std::string base = "specbake: 1\njobs:\n  - name: sky\n    kind: atmosphere\n";
  const std::pair<const char*, const char*> cases[] = {
      {"    colour: blue\n", "unknown key 'colour'"},
      {"    previews: {size: 31}\n", "even number of pixels in [32, 2048]"},
      {"    previews: big\n", "previews: none, or {size: N, tone: aces | linear}"},
      {"    previews: {tone: filmic}\n", "expected one of aces | linear, got 'filmic'"},
      {"    sizes: {scattering: {mu: 7}}\n", "even mu"},
      {"    sizes: {scattering: {nu: 65}}\n", "at most 64"},
      {"    orders: 0\n", "orders"},
      {"    top_radius_km: 6000\n", "top_radius_km"},
      {"    ozone: {layer: tent-40-25-10km}\n", "A < B < C"},
      {"    spectrum: {min_nm: 300}\n", "min_nm"},
  };
  for (const auto& [extra, needle] : cases) {
    write_file(dir / "bad.yaml", base + extra);
    const auto r = run_cli({"run", (dir / "bad.yaml").string(), "--out", (dir / "out").string()});
    EXPECT_EQ(r.exit_code, 3) << extra;
    EXPECT_NE((r.err + r.out).find(needle), std::string::npos) << extra << " -> " << r.err;
    EXPECT_NE((r.err + r.out).find("bad.yaml"), std::string::npos);
  }
}
