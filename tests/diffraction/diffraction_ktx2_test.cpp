// Diffraction bundles with `formats: [bin, exr, ktx2]`: the terms as a KTX2 2D array texture
// (layer n = F_n, R = Re, G = Im, blue 0, alpha 1), the same texels as table_terms.bin / terms.bin
// (float32: bit for bit; half: within the recorded, measured rounding).
#include <gtest/gtest.h>

#include <cmath>

#include "io/ktx2.hpp"
#include "job/kind.hpp"
#include "support/testing.hpp"

namespace {

namespace t = specbake::testing;
namespace fs = std::filesystem;
using nlohmann::json;

const char* kGrating =
    "    procedural: {type: sine-grating, size: 32, dx_um: 0.125, period_um: 1.0, amplitude_um: 0.2}\n";

fs::path bake(const t::TempDir& tmp, const std::string& extra) {
  t::write_file(tmp / "g.yaml", std::string("specbake: 1\noutput: out\njobs:\n  - name: grating\n    kind: diffraction\n") +
                                    kGrating + "    formats: [bin, exr, ktx2]\n" +
                                    // small tables miss their tolerance between texels: not what is tested here
                                    "    tolerance_advisory: true\n" + extra);
  const auto r = t::run_cli({"run", (tmp / "g.yaml").string()}, tmp.path());
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  return fs::canonical(tmp / "out" / "grating" / "latest");
}

// The KTX2 texels' RG against the .bin's [n][y][x][re, im]; blue 0 and alpha 1 everywhere.
std::vector<float> rg_of(const specbake::Ktx2File& k) {
  std::vector<float> rg;
  for (std::size_t i = 0; i < k.rgba.size(); i += 4) {
    rg.push_back(k.rgba[i]);
    rg.push_back(k.rgba[i + 1]);
    EXPECT_EQ(k.rgba[i + 2], 0.0f);
    EXPECT_EQ(k.rgba[i + 3], 1.0f);
  }
  return rg;
}

TEST(DiffractionKtx2, TableTermsAsAHalfArrayWithTheirMeasuredRounding) {
  t::TempDir tmp;
  const fs::path b = bake(tmp, "    table: {size: 16}\n    coherence: {length_um: 3}\n    ktx2: {format: rgba16f}\n");
  const json m = t::read_json(b / "manifest.json");
  const auto k = specbake::read_ktx2(t::read_file(b / "table_terms.ktx2"), "table_terms.ktx2");
  const auto bin = t::read_f32(b / "table_terms.bin");  // [n][16][16][2]
  EXPECT_EQ(k.vk_format, specbake::kVkFormatR16G16B16A16Sfloat);
  EXPECT_EQ(k.width, 16u);
  EXPECT_EQ(k.height, 16u);
  EXPECT_EQ(k.depth, 0u);
  EXPECT_EQ(k.layer_count, bin.size() / (16 * 16 * 2));  // one layer per term
  EXPECT_GT(k.layer_count, 1u);
  ASSERT_NE(k.value("specbake.layout"), nullptr);
  const std::vector<float> rg = rg_of(k);
  ASSERT_EQ(rg.size(), bin.size());
  const specbake::HalfPrecision h = specbake::measure_half(bin, rg);
  EXPECT_FALSE(h.identical_to_float);  // genuinely rounded to half
  // Round to nearest even: relative error <= 2^-11 for normal halfs.
  EXPECT_LE(h.max_rel_error, std::ldexp(1.0, -11));
  const json* rec = specbake::find_accuracy(m["accuracy"], "half:table_terms.ktx2");
  ASSERT_NE(rec, nullptr);
  EXPECT_EQ(rec->at("value").get<double>(), h.max_rel_error);  // the manifest records what the file holds
}

TEST(DiffractionKtx2, FullTermsAsAFloatArrayBitForBit) {
  t::TempDir tmp;
  const fs::path b = bake(tmp, "    ktx2: {format: rgba32f, zstd: true}\n");
  const auto k = specbake::read_ktx2(t::read_file(b / "terms.ktx2"), "terms.ktx2");
  EXPECT_EQ(k.vk_format, specbake::kVkFormatR32G32B32A32Sfloat);
  EXPECT_EQ(k.supercompression, specbake::kKtx2SupercompressionZstd);
  const auto bin = t::read_f32(b / "terms.bin");
  EXPECT_EQ(std::size_t{k.width} * k.height * k.layer_count * 2, bin.size());
  EXPECT_EQ(rg_of(k), bin);
  EXPECT_EQ(specbake::find_accuracy(t::read_json(b / "manifest.json")["accuracy"], "half:terms.ktx2"), nullptr);
}

TEST(DiffractionKtx2, SettingsWithoutTheFormatAreRefused) {
  t::TempDir tmp;
  t::write_file(tmp / "bad.yaml", std::string("specbake: 1\njobs:\n  - name: g\n    kind: diffraction\n") + kGrating +
                                      "    ktx2: {zstd: true}\n");
  const auto r = t::run_cli({"plan", (tmp / "bad.yaml").string()}, tmp.path());
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("bad.yaml:6:"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("ktx2 settings only with ktx2 in formats"), std::string::npos) << r.err;
}

}  // namespace
