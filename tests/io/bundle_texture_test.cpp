// A bundle texture read back from whichever copy the bundle holds: the .bin, the EXR or the KTX2
// give the same float32 values (half copies within their rounding), the first present wins, and
// a bundle without any copy or with the wrong count is an input error naming it.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "core/errors.hpp"
#include "io/bundle_texture.hpp"
#include "io/exr.hpp"
#include "io/ktx2.hpp"
#include "support/testing.hpp"

namespace specbake {
namespace {

namespace t = testing;

// A 3D texture of 2 slices × 3 rows × 4 columns, RGB: the values .bin holds, in its order.
std::vector<float> texels() {
  std::vector<float> v(2 * 3 * 4 * 3);
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = std::ldexp(1.0f + 0.37f * static_cast<float>(i), -int(i % 7)) + 1e-3f;
  return v;
}

std::string bin_of(const std::vector<float>& v) {
  std::string s(v.size() * 4, '\0');
  std::memcpy(s.data(), v.data(), s.size());  // little-endian hosts only, as the bundle format
  return s;
}

std::string exr_of(const std::vector<float>& v, bool half) {
  ExrImage img;
  img.width = 4;
  img.height = 6;  // the slices stacked as rows, as the bundle's EXR copies of 3D textures
  img.channels = {"R", "G", "B"};
  img.pixels = v;
  img.half = half;
  return exr_bytes(img);
}

std::string ktx2_of(const std::vector<float>& v, bool half) {
  Ktx2Image img;
  img.width = 4;
  img.height = 3;
  img.depth = 2;
  img.channels = 3;
  img.texels = v;
  Ktx2Options o;
  o.format = half ? Ktx2Format::rgba16f : Ktx2Format::rgba32f;
  o.writer = "test";
  return write_ktx2(img, o);
}

TEST(BundleTexture, EveryCopyReadsAsTheBin) {
  const auto v = texels();
  for (const char* only : {".bin", ".exr", ".ktx2"}) {
    t::TempDir dir;
    const std::string ext = only;
    t::write_file(dir / ("s" + ext), ext == ".bin" ? bin_of(v) : ext == ".exr" ? exr_of(v, false) : ktx2_of(v, false));
    ASSERT_TRUE(has_bundle_texture(dir.path(), "s"));
    const BundleTexture r = read_bundle_texture(dir.path(), "s", 3, 24);
    EXPECT_EQ(r.file, "s" + ext);
    EXPECT_FALSE(r.half);
    EXPECT_EQ(r.values, v) << ext;
  }
  // half copies: within round-to-nearest-even's 2^-11 relative (the values are normal halfs)
  for (const char* only : {".exr", ".ktx2"}) {
    t::TempDir dir;
    const std::string ext = only;
    t::write_file(dir / ("s" + ext), ext == ".exr" ? exr_of(v, true) : ktx2_of(v, true));
    const BundleTexture r = read_bundle_texture(dir.path(), "s", 3, 24);
    EXPECT_TRUE(r.half) << ext;
    ASSERT_EQ(r.values.size(), v.size());
    for (std::size_t i = 0; i < v.size(); ++i) EXPECT_LE(std::fabs(r.values[i] - v[i]), std::ldexp(std::fabs(v[i]), -11)) << i;
  }
}

TEST(BundleTexture, TheBinFirstAndClearErrors) {
  const auto v = texels();
  t::TempDir dir;
  std::vector<float> other = v;
  other[0] = 42.0f;
  t::write_file(dir / "s.ktx2", ktx2_of(other, false));
  t::write_file(dir / "s.bin", bin_of(v));
  EXPECT_EQ(read_bundle_texture(dir.path(), "s", 3, 24).values, v) << "the exact .bin before any other copy";
  EXPECT_FALSE(has_bundle_texture(dir.path(), "missing"));
  try {
    read_bundle_texture(dir.path(), "missing", 3, 24);
    ADD_FAILURE() << "no copy: an error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.bin, missing.exr or missing.ktx2"), std::string::npos) << e.what();
  }
  try {
    read_bundle_texture(dir.path(), "s", 3, 25);
    ADD_FAILURE() << "a count the manifest does not give: an error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("s.bin with 75 values"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace specbake
