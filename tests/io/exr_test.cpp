// EXR encoding and decoding of bundle images, and the decoder's refusal of untrusted headers.
#include <gtest/gtest.h>

#include <cstring>

#include "core/errors.hpp"
#include "io/exr.hpp"

namespace specbake {
namespace {

ExrImage ramp(bool half) {
  ExrImage img;
  img.width = 7;
  img.height = 3;
  img.channels = {"R", "G", "B"};
  img.half = half;
  img.attributes["specbake.layout"] = "[row][column][R,G,B]";
  for (int i = 0; i < 7 * 3 * 3; ++i) img.pixels.push_back(0.125f * i - 2.0f);
  return img;
}

TEST(Exr, FloatRoundTripIsExactAndKeepsAttributes) {
  const ExrImage a = ramp(false);
  const std::string bytes = exr_bytes(a);
  EXPECT_EQ(bytes, exr_bytes(a));  // deterministic encoding
  const ExrImage b = exr_read(bytes, {"R", "G", "B"});
  EXPECT_EQ(b.width, 7);
  EXPECT_EQ(b.height, 3);
  EXPECT_EQ(b.pixels, a.pixels);  // float32 is stored as it is
  EXPECT_EQ(b.attributes.at("specbake.layout"), "[row][column][R,G,B]");
}

TEST(Exr, HalfRoundTripWithinHalfPrecision) {
  const ExrImage a = ramp(true);
  const ExrImage b = exr_read(exr_bytes(a), {"R", "G", "B"});
  ASSERT_EQ(b.pixels.size(), a.pixels.size());
  // Multiples of 1/8 up to 8 in magnitude are exactly representable in half (11-bit significand).
  for (std::size_t i = 0; i < a.pixels.size(); ++i) EXPECT_EQ(b.pixels[i], a.pixels[i]) << i;
}

// The header's compression attribute ("compression\0compression\0", a 4-byte size, one byte:
// 0 = none, 3 = ZIP): float32 goes uncompressed (ZIP hardly shrinks its noise-like low bytes,
// at several times the encoding time), half goes ZIP.
int compression_of(const std::string& bytes) {
  const std::string key = std::string("compression") + '\0' + "compression" + '\0';
  const auto pos = bytes.find(key);
  return pos == std::string::npos ? -1 : static_cast<unsigned char>(bytes[pos + key.size() + 4]);
}

TEST(Exr, Float32IsUncompressedAndHalfIsZip) {
  EXPECT_EQ(compression_of(exr_bytes(ramp(false))), 0);
  EXPECT_EQ(compression_of(exr_bytes(ramp(true))), 3);
}

TEST(Exr, HugeDataWindowInHeaderIsRefusedBeforeAllocation) {
  std::string bytes = exr_bytes(ramp(false));
  // dataWindow is a box2i (xMin, yMin, xMax, yMax) after "dataWindow\0box2i\0" and a 4-byte size.
  const std::string key = std::string("dataWindow") + '\0' + "box2i" + '\0';
  const auto pos = bytes.find(key);
  ASSERT_NE(pos, std::string::npos);
  const std::int32_t huge = 1 << 30;
  std::memcpy(bytes.data() + pos + key.size() + 4 + 8, &huge, 4);  // xMax
  try {
    exr_read(bytes, {"R"});
    FAIL() << "a 2^30-wide header must be refused";
  } catch (const InputError& e) {
    // OpenEXR's own header checks or ours (kMaxExrSide) refuse it; either way before allocating.
    EXPECT_NE(std::string(e.what()).find("EXR"), std::string::npos) << e.what();
  }
}

// A flattened table is long and narrow: the default ground scene's sky-view table is 32 pixels
// wide and 33 suns × 9 altitudes × 64 views = 19008 high. It writes and reads back bit for bit;
// past the limits the writer refuses (a file its own readers would refuse is never written).
TEST(Exr, LongNarrowTablesRoundTripAndOversizeOnesAreNotWritten) {
  ExrImage img;
  img.width = 32;
  img.height = 19008;
  img.channels = {"R", "G", "B"};
  img.pixels.resize(static_cast<std::size_t>(img.width) * img.height * 3);
  for (std::size_t i = 0; i < img.pixels.size(); ++i) img.pixels[i] = static_cast<float>(i % 1000) * 0.25f;
  const ExrImage back = exr_read(exr_bytes(img), {"R", "G", "B"});
  EXPECT_EQ(back.width, 32);
  EXPECT_EQ(back.height, 19008);
  EXPECT_EQ(back.pixels, img.pixels);
  ExrImage tall;
  tall.width = 1;
  tall.height = kMaxExrSide + 1;
  tall.channels = {"R"};
  tall.pixels.assign(static_cast<std::size_t>(tall.height), 0.0f);
  EXPECT_THROW((void)exr_bytes(tall), JobError);
}

TEST(Exr, GarbageIsAnInputError) {
  EXPECT_THROW(exr_read("not an exr file at all", {"R"}), InputError);
}

}  // namespace
}  // namespace specbake
