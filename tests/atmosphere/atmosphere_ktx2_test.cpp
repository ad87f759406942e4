// Atmosphere bundles with `formats: [bin, exr, ktx2]`: the KTX2 textures hold the same texels
// as the .bin files (float32: bit for bit; half: within the recorded, measured rounding), with
// the geometry an engine needs to sample them.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

#include "io/ktx2.hpp"
#include "job/kind.hpp"
#include "support/testing.hpp"

namespace {

namespace t = specbake::testing;
namespace fs = std::filesystem;
using nlohmann::json;

std::string read(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

std::vector<float> bin_floats(const fs::path& p) {
  const std::string b = read(p);
  std::vector<float> v(b.size() / 4);
  std::memcpy(v.data(), b.data(), b.size());
  return v;
}

fs::path bake(const t::TempDir& tmp, const std::string& ktx2) {
  t::write_file(tmp / "sky.yaml",
                "specbake: 1\noutput: out\njobs:\n  - name: sky\n    kind: atmosphere\n    orders: 2\n"
                "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}\n"
                "    scene: {points: 16}\n    formats: [bin, exr, ktx2]\n    ktx2: " + ktx2 + "\n");
  const auto r = t::run_cli({"run", (tmp / "sky.yaml").string()}, tmp.path());
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  return fs::canonical(tmp / "out" / "sky" / "latest");
}

TEST(AtmosphereKtx2, HalfTexturesCarryTheirMeasuredRounding) {
  t::TempDir tmp;
  const fs::path b = bake(tmp, "{format: rgba16f}");
  const json m = t::read_json(b / "manifest.json");
  for (const char* name : {"transmittance", "irradiance", "scattering", "single_mie_scattering"}) {
    SCOPED_TRACE(name);
    const auto k = specbake::read_ktx2(read(b / (std::string(name) + ".ktx2")), name);
    EXPECT_EQ(k.vk_format, specbake::kVkFormatR16G16B16A16Sfloat);
    const bool is3d = std::string(name).find("scattering") != std::string::npos;
    EXPECT_EQ(k.depth, is3d ? 4u : 0u);  // r = 4 slices for the 3D textures, 0 for 2D
    EXPECT_EQ(k.width, is3d ? 3u * 6u : (std::string(name) == "transmittance" ? 32u : 16u));
    ASSERT_NE(k.value("specbake.layout"), nullptr);
    // which bundle the file belongs to, and what wrote it
    ASSERT_NE(k.value("specbake.bundle_hash"), nullptr);
    EXPECT_EQ(*k.value("specbake.bundle_hash"), m["job"]["hash"].get<std::string>());
    ASSERT_NE(k.value("KTXwriter"), nullptr);
    EXPECT_EQ(k.value("KTXwriter")->rfind("specbake ", 0), 0u);
    // the same units in every copy: the manifest's for .bin, .exr and .ktx2, the KTX2's key/value
    // data and the EXR's header (transmittance is a ratio, "1"; the others radiance units)
    std::map<std::string, std::string> units;
    for (const auto& file : m["files"]) units[file["path"].get<std::string>()] = file.value("units", "?");
    const std::string bin_units = units[std::string(name) + ".bin"];
    EXPECT_EQ(units[std::string(name) + ".ktx2"], bin_units);
    EXPECT_EQ(units[std::string(name) + ".exr"], bin_units);
    ASSERT_NE(k.value("specbake.units"), nullptr);
    EXPECT_EQ(*k.value("specbake.units"), bin_units);
    EXPECT_EQ(bin_units == "1", std::string(name) == "transmittance") << bin_units;
    EXPECT_EQ(read(b / (std::string(name) + ".exr")).find("W m^-2") == std::string::npos, bin_units == "1");
    const auto f = bin_floats(b / (std::string(name) + ".bin"));  // [..][3]
    ASSERT_EQ(k.rgba.size() / 4, f.size() / 3);
    std::vector<float> widened(f.size());
    for (std::size_t i = 0; i < f.size() / 3; ++i) {
      for (int c = 0; c < 3; ++c) widened[3 * i + c] = k.rgba[4 * i + c];
      EXPECT_EQ(k.rgba[4 * i + 3], 1.0f);
    }
    const specbake::HalfPrecision h = specbake::measure_half(f, widened);
    // A half file that holds the float data unrounded is not half (its values are not all
    // binary16 numbers, so the widened data cannot be bit-identical).
    EXPECT_FALSE(h.identical_to_float);
    // Round to nearest even: relative error <= 2^-11 for normal halfs.
    EXPECT_LE(h.max_rel_error, std::ldexp(1.0, -11));
    const json* rec = specbake::find_accuracy(m["accuracy"], std::string("half:") + name + ".ktx2");
    ASSERT_NE(rec, nullptr);
    EXPECT_EQ(rec->at("value").get<double>(), h.max_rel_error);  // the manifest records what the file holds
    EXPECT_TRUE(rec->at("passed").get<bool>());
  }
}

TEST(AtmosphereKtx2, FloatTexturesAreTheBinValuesBitForBit) {
  t::TempDir tmp;
  const fs::path b = bake(tmp, "{format: rgba32f, zstd: true}");
  const auto k = specbake::read_ktx2(read(b / "scattering.ktx2"), "scattering.ktx2");
  EXPECT_EQ(k.vk_format, specbake::kVkFormatR32G32B32A32Sfloat);
  EXPECT_EQ(k.supercompression, specbake::kKtx2SupercompressionZstd);
  const auto f = bin_floats(b / "scattering.bin");
  ASSERT_EQ(k.rgba.size() / 4, f.size() / 3);
  for (std::size_t i = 0; i < f.size() / 3; ++i)
    for (int c = 0; c < 3; ++c) ASSERT_EQ(k.rgba[4 * i + c], f[3 * i + c]) << i;
}

// `scattering: rgba-combined`: Bruneton's combined texture (RGB scattering, alpha single Mie
// red), no single Mie file, and the rebuild's error measured against the float32 single Mie.
TEST(AtmosphereKtx2, CombinedScatteringCarriesSingleMieRedAndItsRebuildError) {
  t::TempDir tmp;
  const fs::path b = bake(tmp, "{format: rgba32f, scattering: rgba-combined}");
  EXPECT_FALSE(fs::exists(b / "single_mie_scattering.ktx2"));
  const auto k = specbake::read_ktx2(read(b / "scattering.ktx2"), "scattering.ktx2");
  const auto s = bin_floats(b / "scattering.bin"), m = bin_floats(b / "single_mie_scattering.bin");
  ASSERT_EQ(k.rgba.size() / 4, s.size() / 3);
  for (std::size_t i = 0; i < s.size() / 3; ++i) {
    for (int c = 0; c < 3; ++c) ASSERT_EQ(k.rgba[4 * i + c], s[3 * i + c]) << i;
    ASSERT_EQ(k.rgba[4 * i + 3], m[3 * i]) << i;
  }
  // The rebuild, recomputed here from the manifest's coefficients (Bruneton 2017,
  // GetExtrapolatedSingleMieScattering), over the texels the record counts.
  const json man = t::read_json(b / "manifest.json");
  const auto br = man["parameters"]["channels"]["rayleigh_scattering_per_m"].get<std::vector<double>>();
  const auto bm = man["parameters"]["channels"]["mie_scattering_per_m"].get<std::vector<double>>();
  double m_max = 0, worst = 0;
  for (float v : m) m_max = std::max(m_max, std::fabs(static_cast<double>(v)));
  for (std::size_t i = 0; i < s.size() / 3; ++i)
    for (int c = 1; c < 3; ++c) {
      if (std::fabs(m[3 * i + c]) < 1e-3 * m_max) continue;
      const double rebuilt =
          s[3 * i] > 0 ? double(s[3 * i + c]) * m[3 * i] / s[3 * i] * (br[0] / bm[0]) * (bm[c] / br[c]) : 0.0;
      worst = std::max(worst, std::fabs(rebuilt - m[3 * i + c]) / std::fabs(m[3 * i + c]));
    }
  const json* rec = specbake::find_accuracy(man["accuracy"], "rgba_combined:single_mie");
  ASSERT_NE(rec, nullptr);
  // Same formula on the same floats, in a different order: a few ulps of double apart.
  EXPECT_NEAR(rec->at("value").get<double>(), worst, 1e-12 + 1e-9 * worst);
  EXPECT_LE(rec->at("details").at("median_relative_error").get<double>(), rec->at("value").get<double>());
  EXPECT_LE(rec->at("details").at("median_relative_error").get<double>(),
            rec->at("details").at("p99_relative_error").get<double>());
}

TEST(AtmosphereKtx2, SettingsWithoutTheFormatAreRefused) {
  t::TempDir tmp;
  t::write_file(tmp / "bad.yaml",
                "specbake: 1\njobs:\n  - name: sky\n    kind: atmosphere\n    ktx2: {format: rgba16f}\n");
  const auto r = t::run_cli({"plan", (tmp / "bad.yaml").string()}, tmp.path());
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("bad.yaml:5:"), std::string::npos) << r.err;
}

}  // namespace

namespace {
// `diff` decodes KTX2 files: two bundles whose textures are equal but whose hashes differ (only the
// previews setting changed) hold KTX2 files that differ in their key/value data alone, which diff
// reports as the same values.
TEST(AtmosphereKtx2, DiffComparesTexelsNotKeyValueData) {
  t::TempDir tmp;
  for (const char* v : {"a", "b"}) {
    t::write_file(tmp / (std::string(v) + ".yaml"),
                  std::string("specbake: 1\noutput: out\njobs:\n  - name: sky-") + v +
                      "\n    kind: atmosphere\n    orders: 2\n    scene: none\n    previews: " +
                      (std::string(v) == "a" ? "none" : "{size: 32}") +
                      "\n    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, "
                      "nu: 3}}\n    formats: [bin, exr, ktx2]\n");
    const auto r = t::run_cli({"run", (tmp / (std::string(v) + ".yaml")).string()}, tmp.path());
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  const fs::path a = tmp / "out" / "sky-a" / "latest", b = tmp / "out" / "sky-b" / "latest";
  EXPECT_NE(read(a / "scattering.ktx2"), read(b / "scattering.ktx2"));  // the bundle hash differs
  const auto r = t::run_cli({"diff", a.string(), b.string()});
  EXPECT_NE(r.out.find("same-values  scattering.ktx2"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("same  scattering.bin"), std::string::npos) << r.out;
}
}  // namespace

namespace {

// `formats: [ktx2]` alone: the bundle holds the KTX2 textures (and the GLSL, previews, scene
// check) but no .bin or .exr, and the tools still read it: `inspect` checks it, `truth --bundle`
// reads its textures from the KTX2 copies — float32 ones give the .bin bundle's lookups exactly,
// half ones within their rounding; `formats: [exr]` likewise. rgba-combined needs bin or exr (the
// combined KTX2 holds single Mie's red alone), and an unknown format is an input error.
TEST(AtmosphereFormats, KtxOrExrAloneAndTheToolsReadThem) {
  t::TempDir tmp;
  auto bake_with = [&](const std::string& name, const std::string& formats) {
    t::write_file(tmp / (name + ".yaml"),
                  "specbake: 1\noutput: out\njobs:\n  - name: " + name + "\n    kind: atmosphere\n    orders: 2\n"
                  "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}\n"
                  "    scene: {points: 8}\n    previews: none\n" + formats);
    return t::run_cli({"run", (tmp / (name + ".yaml")).string()}, tmp.path());
  };
  ASSERT_EQ(bake_with("bin", "").exit_code, 0);
  const auto k32 = bake_with("k32", "    formats: [ktx2]\n    ktx2: {format: rgba32f}\n");
  ASSERT_EQ(k32.exit_code, 0) << k32.out << k32.err;
  ASSERT_EQ(bake_with("k16", "    formats: [ktx2]\n").exit_code, 0);
  ASSERT_EQ(bake_with("exr", "    formats: [exr]\n").exit_code, 0);
  for (const char* job : {"k32", "k16", "exr"}) {
    const fs::path b = tmp / "out" / job / "latest";
    const std::string ext = std::string(job) == "exr" ? ".exr" : ".ktx2";
    for (const char* tex : {"transmittance", "irradiance", "scattering", "single_mie_scattering"}) {
      EXPECT_FALSE(fs::exists(b / (std::string(tex) + ".bin"))) << job << " " << tex;
      EXPECT_EQ(fs::exists(b / (std::string(tex) + ".exr")), ext == ".exr") << job << " " << tex;
      EXPECT_TRUE(fs::exists(b / (std::string(tex) + ext))) << job << " " << tex;
    }
    EXPECT_TRUE(fs::exists(b / "sampling.glsl"));
    EXPECT_EQ(t::run_cli({"inspect", b.string()}).exit_code, 0) << job;
  }

  // the LUT's lookups at a few views, from each bundle's textures
  t::write_file(tmp / "points.csv",
                "altitude_km,view_zenith_deg,sun_zenith_deg,view_sun_azimuth_deg\n0.5,80,60,0\n2,45,85,90\n0,89,92,0\n");
  auto lut_of = [&](const char* job) {
    const auto r = t::run_cli({"truth", (tmp / (std::string(job) + ".yaml")).string(),
                               "--job", job, "--points", (tmp / "points.csv").string(), "--out",
                               (tmp / (std::string(job) + ".csv")).string(), "--paths", "64", "--bundle",
                               (tmp / "out" / job).string()},
                              tmp.path());
    EXPECT_EQ(r.exit_code, 0) << job << r.out << r.err;
    std::vector<double> lut;
    std::istringstream in(t::read_file(tmp / (std::string(job) + ".csv")));
    std::string line;
    std::getline(in, line);  // header: ..., lut_R, lut_G, lut_B last
    while (std::getline(in, line)) {
      std::vector<std::string> cells;
      std::stringstream ss(line);
      for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
      for (std::size_t c = cells.size() - 3; c < cells.size(); ++c) lut.push_back(std::stod(cells[c]));
    }
    return lut;
  };
  const auto want = lut_of("bin");
  ASSERT_EQ(want.size(), 9u);
  EXPECT_EQ(lut_of("k32"), want) << "float32 KTX2 texels are the .bin's: the same lookups";
  EXPECT_EQ(lut_of("exr"), want) << "float32 EXR texels are the .bin's: the same lookups";
  // half texels: each within 2^-11 relative, and a lookup blends at most 16 of them with positive
  // weights (and sums two such blends): within 2^-11 relative, plus the float rounding of the sums
  const auto half = lut_of("k16");
  for (std::size_t i = 0; i < want.size(); ++i)
    EXPECT_NEAR(half[i], want[i], std::ldexp(std::fabs(want[i]), -11) + 1e-6 * std::fabs(want[i]) + 1e-30) << i;

  const auto combined = bake_with("comb", "    formats: [ktx2]\n    ktx2: {scattering: rgba-combined}\n");
  EXPECT_EQ(combined.exit_code, 3) << combined.err;
  EXPECT_NE(combined.err.find("expected bin or exr in formats with rgba-combined"), std::string::npos) << combined.err;
  const auto bad = bake_with("bad", "    formats: [png]\n");
  EXPECT_EQ(bad.exit_code, 3) << bad.err;
  EXPECT_NE(bad.err.find("expected a format of this kind (bin, exr, ktx2), got 'png'"), std::string::npos) << bad.err;
}

}  // namespace
