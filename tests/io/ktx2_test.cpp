// KTX2 writer and reader: every header, index, DFD and key/value field checked byte by byte
// against the KTX 2.0 and Khronos Data Format specifications (the fields are read here with
// their own little-endian helpers, not through read_ktx2); round trips of 2D and 3D, half and
// float, plain and Zstandard; half rounding against its analytic bound; the half measurement
// flags "half" data that is really float data.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "core/errors.hpp"
#include "io/ktx2.hpp"

namespace specbake {
namespace {

std::uint32_t u32(const std::string& b, std::size_t at) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(b.at(at + i));
  return v;
}
std::uint64_t u64(const std::string& b, std::size_t at) {
  return u32(b, at) | (static_cast<std::uint64_t>(u32(b, at + 4)) << 32);
}

// Values over many decades, both signs, a few exact zeros: 0 or ±2^e·m, e in [-20, 15].
std::vector<float> test_values(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> mant(1.0f, 2.0f);
  std::uniform_int_distribution<int> expo(-20, 14), sign(0, 1), zero(0, 49);
  std::vector<float> v(n);
  for (auto& x : v) x = zero(rng) == 0 ? 0.0f : (sign(rng) ? -1.0f : 1.0f) * std::ldexp(mant(rng), expo(rng));
  return v;
}

struct Case {
  Ktx2Format format;
  std::uint32_t w, h, d;
  int channels;
  bool zstd;
};
std::string name_of(const Case& c) {
  return std::string(c.format == Ktx2Format::rgba16f ? "f16" : "f32") + "_" + std::to_string(c.w) + "x" +
         std::to_string(c.h) + "x" + std::to_string(c.d) + "_c" + std::to_string(c.channels) +
         (c.zstd ? "_zstd" : "_raw");
}

void PrintTo(const Case& c, std::ostream* os) { *os << name_of(c); }

class Ktx2Layout : public ::testing::TestWithParam<Case> {};

TEST_P(Ktx2Layout, FieldsFollowTheSpecification) {
  const Case c = GetParam();
  const std::uint64_t texels = std::uint64_t{c.w} * c.h * std::max<std::uint32_t>(c.d, 1);
  const std::vector<float> data = test_values(texels * c.channels, 7);
  Ktx2Options o;
  o.format = c.format;
  o.zstd = c.zstd;
  o.writer = "specbake 9.9.9";
  // Lengths chosen so the entries need 0, 1, 2 and 3 bytes of padding.
  o.metadata = {{"specbake.layout", "[z][y][x][rgba]"}, {"specbake.hash", "0123456789ab"}, {"a", "bc"}, {"Zz", ""}};
  const std::string f = write_ktx2(Ktx2Image{c.w, c.h, c.d, c.channels, data}, o);
  const bool half = c.format == Ktx2Format::rgba16f;
  const std::uint32_t tb = half ? 8 : 16;

  // Identifier and header.
  const unsigned char id[12] = {0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A};
  ASSERT_GE(f.size(), 104u);
  EXPECT_EQ(std::memcmp(f.data(), id, 12), 0);
  EXPECT_EQ(u32(f, 12), half ? 97u : 109u);  // vkFormat
  EXPECT_EQ(u32(f, 16), half ? 2u : 4u);     // typeSize: size of the component data type
  EXPECT_EQ(u32(f, 20), c.w);
  EXPECT_EQ(u32(f, 24), c.h);
  EXPECT_EQ(u32(f, 28), c.d);                // 0 for a 2D texture
  EXPECT_EQ(u32(f, 32), 0u);                 // layerCount
  EXPECT_EQ(u32(f, 36), 1u);                 // faceCount
  EXPECT_EQ(u32(f, 40), 1u);                 // levelCount
  EXPECT_EQ(u32(f, 44), c.zstd ? 2u : 0u);   // supercompressionScheme

  // Index: DFD right after the one-entry level index, KVD right after the DFD, no SGD.
  const std::uint32_t dfd_off = u32(f, 48), dfd_len = u32(f, 52), kvd_off = u32(f, 56), kvd_len = u32(f, 60);
  EXPECT_EQ(dfd_off, 80u + 24u);
  EXPECT_EQ(dfd_off % 4, 0u);
  EXPECT_EQ(kvd_off, dfd_off + dfd_len);
  EXPECT_EQ(kvd_off % 4, 0u);
  EXPECT_EQ(u64(f, 64), 0u);  // sgdByteOffset: 0 when there is no global data
  EXPECT_EQ(u64(f, 72), 0u);  // sgdByteLength
  ASSERT_LE(std::uint64_t{kvd_off} + kvd_len, f.size());

  // Level index.
  const std::uint64_t lo = u64(f, 80), ll = u64(f, 88), lu = u64(f, 96);
  EXPECT_EQ(lu, texels * tb);  // uncompressedByteLength = w*h*max(d,1)*texel bytes
  if (c.zstd) {
    EXPECT_EQ(lo, std::uint64_t{kvd_off} + kvd_len);  // alignment 1: no padding
  } else {
    EXPECT_EQ(ll, lu);
    EXPECT_EQ(lo % tb, 0u);                           // lcm(texel block size, 4) = 8 or 16
    EXPECT_GE(lo, std::uint64_t{kvd_off} + kvd_len);
    EXPECT_LT(lo, std::uint64_t{kvd_off} + kvd_len + tb);
    for (std::uint64_t i = kvd_off + kvd_len; i < lo; ++i) EXPECT_EQ(f[i], '\0');
  }
  EXPECT_EQ(lo + ll, f.size());  // the level ends the file

  // Data Format Descriptor: dfdTotalSize, basic block of 24 bytes + 4 samples x 16.
  ASSERT_EQ(dfd_len, 4u + 24u + 64u);
  std::vector<std::uint32_t> w;
  for (std::uint32_t i = 0; i < dfd_len; i += 4) w.push_back(u32(f, dfd_off + i));
  EXPECT_EQ(w[0], dfd_len);                  // dfdTotalSize
  EXPECT_EQ(w[1], 0u);                       // vendorId 0 (Khronos), descriptorType 0 (basic)
  EXPECT_EQ(w[2] & 0xFFFF, 2u);              // versionNumber: KHR_DF_VERSIONNUMBER_1_3
  EXPECT_EQ(w[2] >> 16, 88u);                // descriptorBlockSize
  EXPECT_EQ(w[3] & 0xFF, 1u);                // colorModel RGBSDA
  EXPECT_EQ((w[3] >> 8) & 0xFF, 1u);         // colorPrimaries BT709
  EXPECT_EQ((w[3] >> 16) & 0xFF, 1u);        // transferFunction LINEAR
  EXPECT_EQ(w[3] >> 24, 0u);                 // flags: straight alpha
  EXPECT_EQ(w[4], 0u);                       // texelBlockDimension0..3 = 1x1x1x1
  EXPECT_EQ(w[5], c.zstd ? 0u : tb);         // bytesPlane0 (0: supercompressed, unsized)
  EXPECT_EQ(w[6], 0u);                       // bytesPlane4..7
  const std::uint32_t bits = half ? 16 : 32, ids[4] = {0, 1, 2, 15};
  for (int s = 0; s < 4; ++s) {
    const std::uint32_t* sw = &w[7 + 4 * s];
    EXPECT_EQ(sw[0] & 0xFFFF, s * bits) << "bitOffset of sample " << s;
    EXPECT_EQ((sw[0] >> 16) & 0xFF, bits - 1) << "bitLength (minus 1) of sample " << s;
    EXPECT_EQ((sw[0] >> 24) & 0x0F, ids[s]) << "channelId of sample " << s;
    EXPECT_EQ(sw[0] >> 28, 0x8u | 0x4u) << "qualifiers FLOAT|SIGNED of sample " << s;
    EXPECT_EQ(sw[1], 0u);                    // samplePosition
    EXPECT_EQ(sw[2], std::bit_cast<std::uint32_t>(-1.0f));  // sampleLower
    EXPECT_EQ(sw[3], std::bit_cast<std::uint32_t>(1.0f));   // sampleUpper
  }

  // Key/value data: length-prefixed key\0value\0, zero padding to 4, keys in byte order.
  std::vector<std::string> keys;
  std::map<std::string, std::string> kv;
  std::uint64_t at = kvd_off;
  while (at < kvd_off + kvd_len) {
    const std::uint32_t n = u32(f, at);
    const std::string e = f.substr(at + 4, n);
    const std::size_t nul = e.find('\0');
    ASSERT_NE(nul, std::string::npos);
    ASSERT_EQ(e.back(), '\0') << "value not NUL-terminated";
    keys.push_back(e.substr(0, nul));
    kv[keys.back()] = e.substr(nul + 1, e.size() - nul - 2);
    const std::uint64_t padded = (n + 3) / 4 * 4;
    for (std::uint64_t i = at + 4 + n; i < at + 4 + padded; ++i) EXPECT_EQ(f[i], '\0') << "padding";
    at += 4 + padded;
  }
  EXPECT_EQ(at, std::uint64_t{kvd_off} + kvd_len);  // kvdByteLength counts the last padding
  for (std::size_t i = 1; i < keys.size(); ++i)
    EXPECT_LT(std::memcmp(keys[i - 1].data(), keys[i].data(), std::min(keys[i - 1].size(), keys[i].size()) + 1), 0)
        << keys[i - 1] << " before " << keys[i];
  EXPECT_EQ(keys, (std::vector<std::string>{"KTXorientation", "KTXwriter", "Zz", "a", "specbake.hash",
                                            "specbake.layout"}));
  EXPECT_EQ(kv["KTXwriter"], "specbake 9.9.9");
  EXPECT_EQ(kv["KTXorientation"], c.d ? "rdi" : "rd");
  EXPECT_EQ(kv["specbake.hash"], "0123456789ab");
  EXPECT_EQ(kv["Zz"], "");

  // The reader agrees with every field read here.
  const Ktx2File r = read_ktx2(f);
  EXPECT_EQ(r.dfd, w);
  EXPECT_EQ(r.level_offset, lo);
  EXPECT_EQ(r.level_length, ll);
  EXPECT_EQ(r.level.size(), lu);
  ASSERT_NE(r.value("specbake.layout"), nullptr);
  EXPECT_EQ(*r.value("specbake.layout"), "[z][y][x][rgba]");
}

TEST_P(Ktx2Layout, RoundTrip) {
  const Case c = GetParam();
  const std::uint64_t texels = std::uint64_t{c.w} * c.h * std::max<std::uint32_t>(c.d, 1);
  const std::vector<float> data = test_values(texels * c.channels, 11);
  Ktx2Options o;
  o.format = c.format;
  o.zstd = c.zstd;
  o.writer = "specbake test";
  const Ktx2File r = read_ktx2(write_ktx2(Ktx2Image{c.w, c.h, c.d, c.channels, data}, o));
  EXPECT_EQ(r.width, c.w);
  EXPECT_EQ(r.height, c.h);
  EXPECT_EQ(r.depth, c.d);
  ASSERT_EQ(r.rgba.size(), texels * 4);
  std::vector<float> src(data.size()), got(data.size());
  for (std::uint64_t t = 0; t < texels; ++t) {
    for (int ch = 0; ch < c.channels; ++ch) {
      src[t * c.channels + ch] = data[t * c.channels + ch];
      got[t * c.channels + ch] = r.rgba[t * 4 + ch];
    }
    if (c.channels == 3) EXPECT_EQ(r.rgba[t * 4 + 3], 1.0f) << "padded alpha at texel " << t;
  }
  if (c.format == Ktx2Format::rgba32f) {
    for (std::size_t i = 0; i < src.size(); ++i)
      ASSERT_EQ(std::bit_cast<std::uint32_t>(got[i]), std::bit_cast<std::uint32_t>(src[i])) << i;
    return;
  }
  for (std::size_t i = 0; i < src.size(); ++i) {
    const double x = src[i], err = std::fabs(got[i] - x);
    // Round to nearest: half an ulp. Normal halfs (|x| >= 2^-14) have 11 significant bits, so
    // err <= 2^-11 |x|; below 2^-14 the spacing is 2^-24, so err <= 2^-25.
    if (std::fabs(x) >= kHalfMinNormal) ASSERT_LE(err, std::ldexp(std::fabs(x), -11)) << "x=" << x;
    else ASSERT_LE(err, std::ldexp(1.0, -25)) << "x=" << x;
  }
  const HalfPrecision m = measure_half(src, got);
  EXPECT_LE(m.max_rel_error, std::ldexp(1.0, -11));
  // With a few hundred random significands some value lands in the top three quarters of the
  // bound (a single value does so with probability ~1/2); a 1x1x1 texture is too small to ask.
  if (src.size() >= 200) EXPECT_GT(m.max_rel_error, std::ldexp(1.0, -13));
  EXPECT_EQ(m.overflow_to_inf, 0u);
  EXPECT_EQ(m.not_half_values, 0u);
  EXPECT_FALSE(m.identical_to_float);
}

INSTANTIATE_TEST_SUITE_P(
    All, Ktx2Layout,
    ::testing::Values(Case{Ktx2Format::rgba16f, 17, 5, 0, 3, false}, Case{Ktx2Format::rgba16f, 17, 5, 0, 4, true},
                      Case{Ktx2Format::rgba32f, 17, 5, 0, 4, false}, Case{Ktx2Format::rgba32f, 17, 5, 0, 3, true},
                      Case{Ktx2Format::rgba16f, 9, 7, 6, 4, false}, Case{Ktx2Format::rgba16f, 9, 7, 6, 3, true},
                      Case{Ktx2Format::rgba32f, 9, 7, 6, 3, false}, Case{Ktx2Format::rgba32f, 9, 7, 6, 4, true},
                      Case{Ktx2Format::rgba16f, 1, 1, 1, 4, false}),
    [](const ::testing::TestParamInfo<Case>& i) { return name_of(i.param); });

TEST(Ktx2, KeyPaddingAlignsTheLevelForEveryKvdLength) {
  // Values of length 0..15 move the end of the key/value data through every residue mod 16.
  for (int len = 0; len < 16; ++len) {
    for (auto fmt : {Ktx2Format::rgba16f, Ktx2Format::rgba32f}) {
      const std::vector<float> d(2 * 2 * 4, 0.5f);
      Ktx2Options o;
      o.format = fmt;
      o.writer = "w";
      o.metadata["k"] = std::string(len, 'x');
      const std::string f = write_ktx2(Ktx2Image{2, 2, 0, 4, d}, o);
      EXPECT_EQ(u32(f, 60) % 4, 0u);
      EXPECT_EQ(u64(f, 80) % (fmt == Ktx2Format::rgba16f ? 8 : 16), 0u) << "value length " << len;
      EXPECT_EQ(read_ktx2(f).rgba, d);  // 0.5 is exact in both formats
    }
  }
}

TEST(Ktx2, ZstdShrinksSmoothDataAndIsDeterministic) {
  std::vector<float> d(64 * 64 * 4);
  for (std::size_t i = 0; i < d.size(); ++i) d[i] = std::sin(0.01f * static_cast<float>(i / 4));
  Ktx2Options o;
  o.format = Ktx2Format::rgba32f;
  o.writer = "w";
  o.zstd = true;
  const std::string a = write_ktx2(Ktx2Image{64, 64, 0, 4, d}, o), b = write_ktx2(Ktx2Image{64, 64, 0, 4, d}, o);
  EXPECT_EQ(a, b);
  EXPECT_LT(u64(a, 88), u64(a, 96));  // byteLength < uncompressedByteLength
}

TEST(Ktx2, HalfRoundsToNearestEven) {
  // Around 1 the half spacing is 2^-10; the midpoints go to the even significand.
  EXPECT_EQ(half_bits_to_float(float_to_half_bits(1.0f + std::ldexp(1.0f, -11))), 1.0f);
  EXPECT_EQ(half_bits_to_float(float_to_half_bits(1.0f + 3 * std::ldexp(1.0f, -11))), 1.0f + std::ldexp(1.0f, -9));
  EXPECT_EQ(half_bits_to_float(float_to_half_bits(1.0f + std::ldexp(1.1f, -11))), 1.0f + std::ldexp(1.0f, -10));
  // Largest half 65504 (spacing 32): 65519 rounds down, 65520 (the midpoint to 65536) to inf.
  EXPECT_EQ(half_bits_to_float(float_to_half_bits(65519.0f)), 65504.0f);
  EXPECT_TRUE(std::isinf(half_bits_to_float(float_to_half_bits(65520.0f))));
  // Smallest subnormal 2^-24: 2^-25 is the midpoint to 0 and goes to 0 (even).
  EXPECT_EQ(half_bits_to_float(float_to_half_bits(std::ldexp(1.0f, -24))), std::ldexp(1.0f, -24));
  EXPECT_EQ(half_bits_to_float(float_to_half_bits(std::ldexp(1.0f, -25))), 0.0f);
  EXPECT_EQ(half_bits_to_float(float_to_half_bits(std::ldexp(1.5f, -25))), std::ldexp(1.0f, -24));
}

TEST(Ktx2, HalfMeasurementCountsAndBounds) {
  std::vector<float> v = test_values(20000, 3);
  v.push_back(70000.0f);                // overflows to inf
  v.push_back(-1.0e-8f);                // flushes to -0 (below 2^-25)
  v.push_back(std::ldexp(1.0f, -20));   // subnormal half: exact, 2^-20 = 16·2^-24
  const HalfPrecision m = measure_half(v);
  EXPECT_EQ(m.count, v.size());
  EXPECT_EQ(m.overflow_to_inf, 1u);
  EXPECT_EQ(m.flush_to_zero, 1u);
  EXPECT_LE(m.max_rel_error, std::ldexp(1.0, -11));  // the analytic bound for |x| >= 2^-14
  EXPECT_GT(m.max_rel_error, std::ldexp(1.0, -12));  // 20000 random significands reach past half of it
  // Absolute error: half an ulp of the largest finite test value, < 2^14·2 → ulp 2^4, half 2^3.
  EXPECT_LE(m.max_abs_error, 8.0);
  EXPECT_EQ(m.not_half_values, 0u);
  EXPECT_FALSE(m.identical_to_float);
  const nlohmann::json j = m.to_json();
  EXPECT_EQ(j.at("overflow_to_inf"), 1);
  EXPECT_EQ(j.at("identical_to_float"), false);
}

TEST(Ktx2, HalfMeasurementCatchesFloatDataPassedOffAsHalf) {
  // A "half" path that stores the float values unrounded: zero error, which no genuine
  // rounding of 20000 random float significands gives, and values no binary16 number equals.
  const std::vector<float> v = test_values(20000, 5);
  const HalfPrecision fake = measure_half(v, v);
  EXPECT_TRUE(fake.identical_to_float);
  EXPECT_EQ(fake.max_abs_error, 0.0);
  EXPECT_GT(fake.not_half_values, 19000u);  // all but the zeros (1 in 50) and rare exact halfs
  // Data that already is half: identical too, but every value is a binary16 number.
  std::vector<float> exact(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) exact[i] = half_bits_to_float(float_to_half_bits(v[i]));
  const HalfPrecision same = measure_half(exact);
  EXPECT_TRUE(same.identical_to_float);
  EXPECT_EQ(same.not_half_values, 0u);
  // A file written as rgba16f and read back is genuine half data.
  Ktx2Options o;
  o.writer = "w";
  const Ktx2File r = read_ktx2(write_ktx2(Ktx2Image{100, 50, 0, 4, v}, o));
  const HalfPrecision real = measure_half(v, r.rgba);
  EXPECT_FALSE(real.identical_to_float);
  EXPECT_EQ(real.not_half_values, 0u);
  EXPECT_THROW(measure_half(v, std::span<const float>(r.rgba).first(10)), JobError);
}

// A 2D array texture (the diffraction table's terms): layerCount is the layer count, the level
// holds the layers one after the other, RG data gets blue 0 and alpha 1.
TEST(Ktx2, ArrayOfTwoChannelLayers) {
  const std::uint32_t w = 5, h = 3, layers = 4;
  const std::vector<float> data = test_values(std::size_t{w} * h * layers * 2, 3);
  Ktx2Options o;
  o.format = Ktx2Format::rgba32f;
  o.writer = "w";
  const std::string f = write_ktx2(Ktx2Image{w, h, 0, 2, data, layers}, o);
  EXPECT_EQ(u32(f, 28), 0u);      // pixelDepth
  EXPECT_EQ(u32(f, 32), layers);  // layerCount
  const Ktx2File r = read_ktx2(f);
  EXPECT_EQ(r.layer_count, layers);
  ASSERT_EQ(r.rgba.size(), std::size_t{w} * h * layers * 4);
  for (std::size_t t = 0; t < r.rgba.size() / 4; ++t) {
    EXPECT_EQ(r.rgba[4 * t], data[2 * t]);
    EXPECT_EQ(r.rgba[4 * t + 1], data[2 * t + 1]);
    EXPECT_EQ(r.rgba[4 * t + 2], 0.0f);
    EXPECT_EQ(r.rgba[4 * t + 3], 1.0f);
  }
}

TEST(Ktx2, RefusesBadInput) {
  const std::vector<float> d(12, 0.25f);
  Ktx2Options o;
  o.writer = "w";
  EXPECT_THROW(write_ktx2(Ktx2Image{0, 3, 0, 4, d}, o), JobError);
  EXPECT_THROW(write_ktx2(Ktx2Image{3, 0, 0, 4, d}, o), JobError);
  EXPECT_THROW(write_ktx2(Ktx2Image{4, 1, 0, 4, d}, o), JobError);   // 12 values for 4 texels x 4
  EXPECT_NO_THROW(write_ktx2(Ktx2Image{3, 1, 0, 4, d}, o));
  EXPECT_THROW(write_ktx2(Ktx2Image{12, 1, 0, 1, d}, o), JobError);  // 1 channel
  EXPECT_NO_THROW(write_ktx2(Ktx2Image{6, 1, 0, 2, d}, o));           // RG
  EXPECT_THROW(write_ktx2(Ktx2Image{1, 1, 3, 2, std::span<const float>(d).first(6), 1}, o), JobError);  // 3D array
  EXPECT_THROW(write_ktx2(Ktx2Image{2, 1, 0, 5, std::span<const float>(d).first(10)}, o), JobError);
  std::vector<float> bad = d;
  bad[7] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(write_ktx2(Ktx2Image{1, 1, 3, 4, bad}, o), JobError);
  bad[7] = std::numeric_limits<float>::infinity();
  EXPECT_THROW(write_ktx2(Ktx2Image{1, 1, 3, 4, bad}, o), JobError);
  bad[7] = 1.0e5f;  // finite, past the largest half
  EXPECT_THROW(write_ktx2(Ktx2Image{1, 1, 3, 4, bad}, o), JobError);
  o.format = Ktx2Format::rgba32f;
  EXPECT_NO_THROW(write_ktx2(Ktx2Image{1, 1, 3, 4, bad}, o));
  o.metadata["KTXwriter"] = "x";
  EXPECT_THROW(write_ktx2(Ktx2Image{1, 1, 3, 4, d}, o), JobError);   // reserved prefix
  o.metadata = {{"", "x"}};
  EXPECT_THROW(write_ktx2(Ktx2Image{1, 1, 3, 4, d}, o), JobError);
  o.metadata = {{"a", std::string("x\0y", 3)}};
  EXPECT_THROW(write_ktx2(Ktx2Image{1, 1, 3, 4, d}, o), JobError);
  o.metadata.clear();
  o.writer.clear();
  EXPECT_THROW(write_ktx2(Ktx2Image{1, 1, 3, 4, d}, o), JobError);
}

TEST(Ktx2, ReaderRefusesMalformedFiles) {
  const std::vector<float> d(4 * 4 * 4, 0.25f);
  Ktx2Options o;
  o.writer = "w";
  o.zstd = true;
  const std::string good = write_ktx2(Ktx2Image{4, 4, 0, 4, d}, o);
  ASSERT_NO_THROW(read_ktx2(good));
  EXPECT_THROW(read_ktx2(good.substr(0, 50)), InputError);
  EXPECT_THROW(read_ktx2(good.substr(0, good.size() - 1)), InputError);  // level runs past the end
  std::string s = good;
  s[1] = 'X';
  EXPECT_THROW(read_ktx2(s), InputError);
  s = good;
  s[12] = 37;  // vkFormat R8G8B8A8_UNORM
  EXPECT_THROW(read_ktx2(s), InputError);
  s = good;
  s[u64(good, 80)] ^= 0x5A;  // damage the Zstandard frame's magic number
  EXPECT_THROW(read_ktx2(s), InputError);
  s = good;
  s[96] ^= 0x01;  // uncompressedByteLength no longer w*h*8
  EXPECT_THROW(read_ktx2(s), InputError);
}

}  // namespace
}  // namespace specbake
