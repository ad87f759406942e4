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

namespace {

// `formats:` picks the terms' copies (any of bin, exr, ktx2) and `previews:` skips or sizes the
// pictures. A table bundle with [ktx2] alone holds table_terms.ktx2 and its shader, no
// table_terms.bin or per-term EXRs, and the report page's live lobes read the KTX2 copy;
// [exr] alone keeps the per-term EXRs. previews: none leaves out every picture (and the fast
// shader variants' records, measured on them); {size: N} makes every picture N pixels a side.
TEST(DiffractionFormats, CopiesAndPreviewsAsAsked) {
  t::TempDir tmp;
  auto bake_with = [&](const std::string& name, const std::string& extra) {
    t::write_file(tmp / (name + ".yaml"), std::string("specbake: 1\noutput: out\njobs:\n  - name: ") + name +
                                               "\n    kind: diffraction\n" + kGrating + "    tolerance_advisory: true\n" +
                                               extra);
    return t::run_cli({"run", (tmp / (name + ".yaml")).string()}, tmp.path());
  };
  const std::string table = "    table: {size: 16}\n    coherence: {length_um: 3}\n";
  ASSERT_EQ(bake_with("k", table + "    formats: [ktx2]\n    ktx2: {format: rgba32f}\n    previews: {size: 64}\n").exit_code, 0);
  const fs::path k = tmp / "out" / "k" / "latest";
  EXPECT_TRUE(fs::exists(k / "table_terms.ktx2"));
  EXPECT_FALSE(fs::exists(k / "table_terms.bin"));
  EXPECT_FALSE(fs::exists(k / "table"));
  EXPECT_TRUE(fs::exists(k / "shader" / "diffraction_brdf.glsl"));
  const json m = t::read_json(k / "manifest.json");
  for (const auto& f : m["files"]) {
    const std::string path = f["path"];
    if (path == "preview/brdf_lobes.png") EXPECT_EQ(f["shape"], json({64, 192, 3}));
    if (path == "preview/sphere.png") EXPECT_EQ(f["shape"], json({64, 64, 3}));
  }
  EXPECT_NE(specbake::find_accuracy(m["accuracy"], "shader_fast_vs_full"), nullptr);
  EXPECT_EQ(t::run_cli({"inspect", k.string()}).exit_code, 0);
  // the page's live lobes from the KTX2 copy
  const auto page = t::run_cli({"report", (tmp / "out").string(), "--out", (tmp / "page.html").string()}, tmp.path());
  ASSERT_EQ(page.exit_code, 0) << page.out << page.err;
  EXPECT_NE(t::read_file(tmp / "page.html").find("\"file\":\"table_terms.ktx2\""), std::string::npos);

  ASSERT_EQ(bake_with("e", "    formats: [exr]\n    previews: none\n").exit_code, 0);
  const fs::path e = tmp / "out" / "e" / "latest";
  EXPECT_FALSE(fs::exists(e / "terms.bin"));
  EXPECT_TRUE(fs::exists(e / "terms" / "F_000.exr"));
  EXPECT_FALSE(fs::exists(e / "preview"));
  ASSERT_EQ(bake_with("n", table + "    previews: none\n").exit_code, 0);
  const json mn = t::read_json(tmp / "out" / "n" / "latest" / "manifest.json");
  EXPECT_FALSE(fs::exists(tmp / "out" / "n" / "latest" / "preview"));
  EXPECT_EQ(specbake::find_accuracy(mn["accuracy"], "shader_fast_vs_full"), nullptr);
  ASSERT_EQ(bake_with("s", "    previews: {size: 96}\n").exit_code, 0);
  for (const auto& f : t::read_json(tmp / "out" / "s" / "latest" / "manifest.json")["files"])
    if (f["path"] == "preview/white_normal.png") EXPECT_EQ(f["shape"], json({96, 96, 3}));

  for (const auto& [extra, says] : std::vector<std::pair<std::string, std::string>>{
           {"    previews: {size: 33}\n", "expected an even number of pixels in [32, 2048], got '33'"},
           {"    previews: all\n", "previews: none, or {size: N}"},
           {"    formats: [bin, bin]\n", "format 'bin' is listed twice"},
           {"    formats: [json]\n", "expected a format of this kind (bin, exr, ktx2), got 'json'"}}) {
    const auto r = bake_with("bad", extra);
    EXPECT_EQ(r.exit_code, 3) << extra << r.err;
    EXPECT_NE(r.err.find(says), std::string::npos) << extra << r.err;
  }
}

}  // namespace
