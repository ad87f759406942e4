// `specbake diff` compares what the files hold: EXR pixels decoded (float or half), float32
// .bin elements; NaN in both bundles at the same place is no change.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>

#include "core/hash.hpp"
#include "io/bundle_diff.hpp"
#include "io/exr.hpp"
#include "support/testing.hpp"

namespace specbake {
namespace {

namespace t = testing;
using nlohmann::json;

const float kNaN = std::numeric_limits<float>::quiet_NaN();

std::string bin_bytes(const std::vector<float>& v) {
  std::string s(v.size() * 4, '\0');
  std::memcpy(s.data(), v.data(), s.size());
  return s;
}

// A bundle folder with one EXR (3 x 2 pixels, R G B) and one float32 .bin of 6 values.
void write_bundle(const fs::path& dir, const std::vector<float>& pixels, const std::vector<float>& bin, bool half) {
  fs::create_directories(dir);
  ExrImage img;
  img.width = 3;
  img.height = 2;
  img.channels = {"R", "G", "B"};
  img.pixels = pixels;
  img.half = half;
  const std::string exr = exr_bytes(img), b = bin_bytes(bin);
  t::write_file(dir / "t.exr", exr);
  t::write_file(dir / "v.bin", b);
  const json m = {{"files",
                   {{{"path", "t.exr"}, {"sha256", sha256_hex(exr)}, {"bytes", exr.size()}, {"dtype", half ? "half" : "float32"},
                     {"shape", {2, 3, 3}}},
                    {{"path", "v.bin"}, {"sha256", sha256_hex(b)}, {"bytes", b.size()}, {"dtype", "float32"},
                     {"shape", {6}}}}}};
  t::write_file(dir / "manifest.json", m.dump());
}

std::vector<float> ramp() {
  std::vector<float> v(18);
  for (int i = 0; i < 18; ++i) v[i] = 0.25f + 0.5f * i;
  return v;
}

const FileDiff& file(const BundleDiff& d, const std::string& path) {
  for (const auto& f : d.files)
    if (f.path == path) return f;
  throw std::runtime_error("no " + path);
}

TEST(BundleDiff, ExrPixelsAreDecodedNotReadAsRawFloats) {
  t::TempDir tmp;
  auto a = ramp(), b = ramp();
  b[3 * (1 * 3 + 2) + 1] += 1e-3f;  // row 1, column 2, channel G
  write_bundle(tmp / "a", a, {1, 2, 3, 4, 5, 6}, false);
  write_bundle(tmp / "b", b, {1, 2, 3, 4, 5, 6}, false);
  const BundleDiff d = diff_bundles(tmp / "a", tmp / "b", 0.0, 0.0);
  const FileDiff& f = file(d, "t.exr");
  EXPECT_EQ(f.status, "differs");
  ASSERT_TRUE(f.numeric);
  // The change as stored in float32: |(x + 1e-3) - x| within one ulp of x (x = 8.75).
  EXPECT_NEAR(f.max_abs, 1e-3, 8.75 * 1.2e-7);
  EXPECT_EQ(f.at_abs, (std::vector<std::int64_t>{1, 2, 1}));
  EXPECT_EQ(f.channels.at(f.at_abs[2]), "G");
  EXPECT_FALSE(diff_passes(d));
  EXPECT_TRUE(diff_passes(diff_bundles(tmp / "a", tmp / "b", 2e-3, 0.0)));
}

TEST(BundleDiff, OneFlippedLowBitIsATinyDifference) {
  t::TempDir tmp;
  auto a = ramp(), b = ramp();
  std::uint32_t bits;
  std::memcpy(&bits, &b[7], 4);
  bits ^= 1u;  // the lowest mantissa bit
  std::memcpy(&b[7], &bits, 4);
  write_bundle(tmp / "a", a, {1, 2, 3, 4, 5, 6}, false);
  write_bundle(tmp / "b", b, {1, 2, 3, 4, 5, 6}, false);
  const BundleDiff d = diff_bundles(tmp / "a", tmp / "b", 0.0, 0.0);
  const FileDiff& f = file(d, "t.exr");
  EXPECT_EQ(f.status, "differs");
  // One ulp of 3.75: 2^-22.
  EXPECT_EQ(f.max_abs, std::ldexp(1.0, -22));
  EXPECT_LT(f.max_rel, 2.0 * std::ldexp(1.0, -23));
}

TEST(BundleDiff, HalfExrComparedAsValues) {
  t::TempDir tmp;
  auto b = ramp();
  b[0] = 0.3f;  // 0.25 -> 0.3: in half 0.25 and 0.2998 (11-bit mantissa)
  write_bundle(tmp / "a", ramp(), {1, 2, 3, 4, 5, 6}, true);
  write_bundle(tmp / "b", b, {1, 2, 3, 4, 5, 6}, true);
  const BundleDiff d = diff_bundles(tmp / "a", tmp / "b", 0.0, 0.0);
  const FileDiff& f = file(d, "t.exr");
  EXPECT_NEAR(f.max_abs, 0.05, std::ldexp(1.0, -12));  // half rounding of 0.3: |err| <= 2^-12 (0.3 < 0.5)
  // Pixel (0, 0), channel R: the EXR's channels are in the header's order B, G, R.
  EXPECT_EQ(f.at_abs, (std::vector<std::int64_t>{0, 0, 2}));
  EXPECT_EQ(f.channels.at(2), "R");
}

TEST(BundleDiff, NanInBothIsNoChangeNanInOneIs) {
  t::TempDir tmp;
  auto a = ramp();
  a[4] = kNaN;
  write_bundle(tmp / "a", a, {1, kNaN, 3, 4, 5, 6}, false);
  write_bundle(tmp / "b", a, {1, kNaN, 3, 4, 5, 6}, false);
  // Identical files: same. Now re-encode b's EXR with a different NaN payload and a bin whose
  // NaN has another bit pattern: values are the same, bytes are not.
  std::vector<float> bin = {1, -kNaN, 3, 4, 5, 6};
  write_bundle(tmp / "c", a, bin, false);
  BundleDiff d = diff_bundles(tmp / "a", tmp / "c", 0.0, 0.0);
  EXPECT_TRUE(diff_passes(d));
  EXPECT_EQ(file(d, "v.bin").nan_mismatches, 0u);
  // NaN against a number is a change.
  write_bundle(tmp / "e", ramp(), {1, 2, 3, 4, 5, 6}, false);
  d = diff_bundles(tmp / "a", tmp / "e", 1.0, 1.0);
  EXPECT_FALSE(diff_passes(d));
  EXPECT_EQ(file(d, "t.exr").nan_mismatches, 1u);
  EXPECT_EQ(file(d, "v.bin").nan_mismatches, 1u);
}

}  // namespace
}  // namespace specbake
