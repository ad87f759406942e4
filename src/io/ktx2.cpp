// KTX 2.0 writer and reader (see ktx2.hpp). Layout of the file this writer produces:
//
//   offset  size  what
//   0       12    identifier «KTX 20» (AB 4B 54 58 20 32 30 BB 0D 0A 1A 0A)
//   12      36    vkFormat, typeSize, pixelWidth, pixelHeight, pixelDepth, layerCount,
//                 faceCount, levelCount, supercompressionScheme (UInt32 each)
//   48      32    index: dfdByteOffset, dfdByteLength, kvdByteOffset, kvdByteLength (UInt32),
//                 sgdByteOffset, sgdByteLength (UInt64; both 0: no global data)
//   80      24    level index: byteOffset, byteLength, uncompressedByteLength (UInt64)
//   104     92    DFD: dfdTotalSize (92) + basic descriptor block (24 bytes + 4 samples x 16)
//   196     ...   key/value data: per entry UInt32 keyAndValueByteLength, key\0value\0,
//                 zero padding to a multiple of 4 (counted in kvdByteLength)
//   ...     ...   zero padding to lcm(texel size, 4) = texel size (8 or 16) without
//                 supercompression, none with Zstandard; then the level's bytes.
// Everything is little-endian.
#include "io/ktx2.hpp"

#include <Imath/half.h>
#include <zstd.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <sstream>

#include <spdlog/spdlog.h>

#include "core/errors.hpp"

namespace specbake {
namespace {

constexpr unsigned char kIdentifier[12] = {0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32,
                                           0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A};
constexpr std::size_t kHeaderBytes = 80;
constexpr std::size_t kLevelIndexBytes = 24;
constexpr std::size_t kDfdOffset = kHeaderBytes + kLevelIndexBytes;  // 104

// Khronos Data Format Specification 1.3, basic descriptor block.
constexpr std::uint32_t kDfVersion13 = 2;
constexpr std::uint32_t kDfModelRgbsda = 1;
constexpr std::uint32_t kDfPrimariesBt709 = 1;
constexpr std::uint32_t kDfTransferLinear = 1;
constexpr std::uint32_t kDfChannelAlpha = 15;         // R 0, G 1, B 2, A 15
constexpr std::uint32_t kDfQualifierSigned = 0x40;    // in the channelType byte
constexpr std::uint32_t kDfQualifierFloat = 0x80;
constexpr std::uint32_t kFloatMinusOne = 0xBF800000;  // -1.0f: sampleLower of a signed float
constexpr std::uint32_t kFloatPlusOne = 0x3F800000;   // 1.0f: sampleUpper
constexpr std::uint32_t kDfBlockBytes = 24 + 4 * 16;  // 88
constexpr std::uint32_t kDfdTotalBytes = 4 + kDfBlockBytes;

void put32(std::string& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
void put64(std::string& out, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
void set64(std::string& out, std::size_t at, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) out[at + i] = static_cast<char>((v >> (8 * i)) & 0xFF);
}
std::uint32_t get32(std::string_view b, std::size_t at) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(b[at + i]);
  return v;
}
std::uint64_t get64(std::string_view b, std::size_t at) {
  return get32(b, at) | (static_cast<std::uint64_t>(get32(b, at + 4)) << 32);
}
void pad_to(std::string& out, std::size_t alignment) {
  while (out.size() % alignment) out.push_back('\0');
}

std::uint32_t texel_bytes(Ktx2Format f) { return f == Ktx2Format::rgba16f ? 8 : 16; }

std::vector<std::uint32_t> make_dfd(Ktx2Format format, bool supercompressed) {
  const std::uint32_t channel_bits = format == Ktx2Format::rgba16f ? 16 : 32;
  std::vector<std::uint32_t> d;
  d.push_back(kDfdTotalBytes);
  d.push_back(0);                                       // vendorId Khronos 0, descriptorType basic 0
  d.push_back(kDfVersion13 | (kDfBlockBytes << 16));    // versionNumber, descriptorBlockSize
  d.push_back(kDfModelRgbsda | (kDfPrimariesBt709 << 8) | (kDfTransferLinear << 16));  // flags 0: straight alpha
  d.push_back(0);                                       // texelBlockDimension0..3 = 1x1x1x1 (stored minus 1)
  d.push_back(supercompressed ? 0 : texel_bytes(format));  // bytesPlane0..3
  d.push_back(0);                                       // bytesPlane4..7
  const std::uint32_t channels[4] = {0, 1, 2, kDfChannelAlpha};
  for (std::uint32_t s = 0; s < 4; ++s) {
    const std::uint32_t type = channels[s] | kDfQualifierFloat | kDfQualifierSigned;
    d.push_back((s * channel_bits) | ((channel_bits - 1) << 16) | (type << 24));
    d.push_back(0);  // samplePosition0..3
    d.push_back(kFloatMinusOne);
    d.push_back(kFloatPlusOne);
  }
  return d;
}

bool reserved_key(const std::string& k) {
  return k.size() >= 3 && (k.compare(0, 3, "KTX") == 0 || k.compare(0, 3, "ktx") == 0);
}

[[noreturn]] void bad_file(const std::string& name, const std::string& what) {
  throw InputError(Location{name, 0, 0, ""}, "a KTX2 file: " + what);
}

}  // namespace

std::uint16_t float_to_half_bits(float value) { return Imath::half(value).bits(); }

float half_bits_to_float(std::uint16_t bits) {
  Imath::half h;
  h.setBits(bits);
  return static_cast<float>(h);
}

std::string write_ktx2(const Ktx2Image& image, const Ktx2Options& options) {
  if (image.width == 0 || image.height == 0)
    throw JobError("KTX2: texture size " + std::to_string(image.width) + "x" + std::to_string(image.height) +
                   ": width and height must be at least 1");
  if (image.channels < 2 || image.channels > 4)
    throw JobError("KTX2: " + std::to_string(image.channels) +
                   " channels; expected 2 (RG, blue 0, alpha 1), 3 (RGB, alpha 1) or 4 (RGBA)");
  if (image.layers > 0 && image.depth > 0)
    throw JobError("KTX2: an array of 3D textures (layers " + std::to_string(image.layers) + ", depth " +
                   std::to_string(image.depth) + ") is not written");
  const std::uint64_t texels = std::uint64_t{image.width} * image.height * std::max<std::uint32_t>(image.depth, 1) *
                               std::max<std::uint32_t>(image.layers, 1);
  if (image.texels.size() != texels * static_cast<std::uint64_t>(image.channels))
    throw JobError("KTX2: " + std::to_string(image.texels.size()) + " values for " + std::to_string(texels) +
                   " texels of " + std::to_string(image.channels) + " channels");
  if (options.writer.empty()) throw JobError("KTX2: the KTXwriter value is empty");
  if (options.zstd && (options.zstd_level < 1 || options.zstd_level > ZSTD_maxCLevel()))
    throw JobError("KTX2: Zstandard level " + std::to_string(options.zstd_level) + " outside 1.." +
                   std::to_string(ZSTD_maxCLevel()));
  for (const auto& [k, v] : options.metadata) {
    if (k.empty() || k.find('\0') != std::string::npos || v.find('\0') != std::string::npos)
      throw JobError("KTX2: key/value keys must be non-empty and keys and values free of NUL bytes (key '" + k + "')");
    if (reserved_key(k)) throw JobError("KTX2: key '" + k + "' begins with KTX/ktx, which the specification reserves");
  }

  // Level bytes, RGBA.
  const bool half = options.format == Ktx2Format::rgba16f;
  const std::uint32_t tb = texel_bytes(options.format);
  std::string level(texels * tb, '\0');
  char* out = level.data();
  for (std::uint64_t t = 0; t < texels; ++t) {
    for (int c = 0; c < 4; ++c) {
      const std::uint64_t i = t * image.channels + c;
      const float x = c < image.channels ? image.texels[i] : c == 3 ? 1.0f : 0.0f;
      if (!std::isfinite(x))
        throw JobError("KTX2: value " + std::to_string(x) + " at index " + std::to_string(i) + " is not finite");
      if (half) {
        const std::uint16_t h = float_to_half_bits(x);
        if ((h & 0x7FFF) == 0x7C00)
          throw JobError("KTX2: value " + std::to_string(x) + " at index " + std::to_string(i) +
                         " overflows half precision (largest half 65504); write rgba32f instead");
        out[0] = static_cast<char>(h & 0xFF);
        out[1] = static_cast<char>(h >> 8);
        out += 2;
      } else {
        const std::uint32_t b = std::bit_cast<std::uint32_t>(x);
        for (int k = 0; k < 4; ++k) out[k] = static_cast<char>((b >> (8 * k)) & 0xFF);
        out += 4;
      }
    }
  }
  const std::uint64_t uncompressed = level.size();
  if (options.zstd) {
    std::string packed(ZSTD_compressBound(level.size()), '\0');
    const std::size_t n = ZSTD_compress(packed.data(), packed.size(), level.data(), level.size(), options.zstd_level);
    if (ZSTD_isError(n)) throw JobError(std::string("KTX2: Zstandard compression failed: ") + ZSTD_getErrorName(n));
    packed.resize(n);
    level = std::move(packed);
  }

  // Key/value data, sorted by key bytes (std::map<std::string> orders by unsigned char).
  std::map<std::string, std::string> kv = options.metadata;
  kv["KTXwriter"] = options.writer;
  kv["KTXorientation"] = image.depth == 0 ? "rd" : "rdi";
  std::string kvd;
  for (const auto& [k, v] : kv) {
    put32(kvd, static_cast<std::uint32_t>(k.size() + 1 + v.size() + 1));
    kvd += k;
    kvd.push_back('\0');
    kvd += v;
    kvd.push_back('\0');
    pad_to(kvd, 4);
  }

  const std::vector<std::uint32_t> dfd = make_dfd(options.format, options.zstd);
  const std::size_t kvd_offset = kDfdOffset + dfd.size() * 4;

  std::string f;
  f.reserve(kvd_offset + kvd.size() + 16 + level.size());
  f.append(reinterpret_cast<const char*>(kIdentifier), sizeof kIdentifier);
  put32(f, half ? kVkFormatR16G16B16A16Sfloat : kVkFormatR32G32B32A32Sfloat);
  put32(f, half ? 2 : 4);  // typeSize
  put32(f, image.width);
  put32(f, image.height);
  put32(f, image.depth);
  put32(f, image.layers);  // layerCount: 0 unless an array
  put32(f, 1);  // faceCount
  put32(f, 1);  // levelCount
  put32(f, options.zstd ? kKtx2SupercompressionZstd : kKtx2SupercompressionNone);
  put32(f, static_cast<std::uint32_t>(kDfdOffset));
  put32(f, static_cast<std::uint32_t>(dfd.size() * 4));
  put32(f, static_cast<std::uint32_t>(kvd_offset));
  put32(f, static_cast<std::uint32_t>(kvd.size()));
  put64(f, 0);  // sgdByteOffset
  put64(f, 0);  // sgdByteLength
  const std::size_t level_index_at = f.size();
  put64(f, 0);  // byteOffset, filled in below
  put64(f, level.size());
  put64(f, uncompressed);
  for (std::uint32_t w : dfd) put32(f, w);
  f += kvd;
  pad_to(f, options.zstd ? 1 : tb);  // lcm(texel block size, 4) = texel size; 1 when supercompressed
  set64(f, level_index_at, f.size());
  f += level;
  spdlog::debug("KTX2: {}x{}x{} {} {}: {} bytes", image.width, image.height, image.depth, half ? "rgba16f" : "rgba32f",
                options.zstd ? "zstd" : "raw", f.size());
  return f;
}

const std::string* Ktx2File::value(const std::string& key) const {
  for (const auto& [k, v] : kv)
    if (k == key) return &v;
  return nullptr;
}

Ktx2File read_ktx2(std::string_view b, const std::string& name) {
  if (b.size() < kDfdOffset) bad_file(name, std::to_string(b.size()) + " bytes, shorter than the header");
  if (std::memcmp(b.data(), kIdentifier, sizeof kIdentifier) != 0) bad_file(name, "no KTX 2.0 identifier");
  Ktx2File k;
  k.vk_format = get32(b, 12);
  k.type_size = get32(b, 16);
  k.width = get32(b, 20);
  k.height = get32(b, 24);
  k.depth = get32(b, 28);
  k.layer_count = get32(b, 32);
  k.face_count = get32(b, 36);
  k.level_count = get32(b, 40);
  k.supercompression = get32(b, 44);
  k.dfd_offset = get32(b, 48);
  k.dfd_length = get32(b, 52);
  k.kvd_offset = get32(b, 56);
  k.kvd_length = get32(b, 60);
  k.sgd_offset = get64(b, 64);
  k.sgd_length = get64(b, 72);
  k.level_offset = get64(b, 80);
  k.level_length = get64(b, 88);
  k.level_uncompressed_length = get64(b, 96);

  std::uint32_t tb = 0;
  if (k.vk_format == kVkFormatR16G16B16A16Sfloat && k.type_size == 2) tb = 8;
  else if (k.vk_format == kVkFormatR32G32B32A32Sfloat && k.type_size == 4) tb = 16;
  else
    bad_file(name, "vkFormat " + std::to_string(k.vk_format) + " with typeSize " + std::to_string(k.type_size) +
                       "; expected 97 (R16G16B16A16_SFLOAT, 2) or 109 (R32G32B32A32_SFLOAT, 4)");
  if (k.width == 0 || k.height == 0) bad_file(name, "pixelWidth and pixelHeight must be at least 1");
  if (k.face_count != 1 || k.level_count != 1) bad_file(name, "expected faceCount 1, levelCount 1");
  if (k.layer_count != 0 && k.depth != 0) bad_file(name, "an array of 3D textures is not expected");
  if (k.supercompression != kKtx2SupercompressionNone && k.supercompression != kKtx2SupercompressionZstd)
    bad_file(name, "supercompressionScheme " + std::to_string(k.supercompression) + "; expected 0 or 2 (Zstandard)");
  if (k.sgd_length != 0) bad_file(name, "supercompression global data is not expected");

  auto in_bounds = [&](std::uint64_t off, std::uint64_t len) { return off <= b.size() && len <= b.size() - off; };
  if (k.dfd_offset != kDfdOffset || k.dfd_length < 4 || !in_bounds(k.dfd_offset, k.dfd_length))
    bad_file(name, "DFD index out of place or out of bounds");
  if (k.kvd_length && (k.kvd_offset != k.dfd_offset + k.dfd_length || !in_bounds(k.kvd_offset, k.kvd_length)))
    bad_file(name, "key/value index out of place or out of bounds");
  if (!in_bounds(k.level_offset, k.level_length)) bad_file(name, "level index out of bounds");

  for (std::uint32_t at = 0; at + 4 <= k.dfd_length; at += 4) k.dfd.push_back(get32(b, k.dfd_offset + at));
  if (k.dfd[0] != k.dfd_length) bad_file(name, "dfdTotalSize differs from dfdByteLength");

  for (std::uint64_t at = k.kvd_offset, end = k.kvd_offset + k.kvd_length; k.kvd_length && at < end;) {
    if (end - at < 4) bad_file(name, "key/value entry truncated");
    const std::uint32_t n = get32(b, at);
    if (n > end - at - 4) bad_file(name, "key/value entry runs past kvdByteLength");
    const std::string_view kv = b.substr(at + 4, n);
    const std::size_t nul = kv.find('\0');
    if (nul == std::string_view::npos || nul == 0) bad_file(name, "key/value entry without a NUL-terminated key");
    std::string_view v = kv.substr(nul + 1);
    if (!v.empty() && v.back() == '\0') v.remove_suffix(1);
    k.kv.emplace_back(std::string(kv.substr(0, nul)), std::string(v));
    at += 4 + ((n + 3) / 4) * 4;
  }

  // At most 2^36 bytes (64 GiB) of texels; keeps the products below from overflowing.
  const long double claimed = static_cast<long double>(k.width) * k.height * std::max<std::uint32_t>(k.depth, 1) *
                              std::max<std::uint32_t>(k.layer_count, 1) * tb;
  if (claimed > 68719476736.0L) bad_file(name, "texture size past 64 GiB");
  const std::uint64_t texels = std::uint64_t{k.width} * k.height * std::max<std::uint32_t>(k.depth, 1) *
                               std::max<std::uint32_t>(k.layer_count, 1);
  const std::uint64_t want = texels * tb;
  if (k.level_uncompressed_length != want)
    bad_file(name, "uncompressedByteLength " + std::to_string(k.level_uncompressed_length) + ", expected " +
                       std::to_string(want));
  const std::string_view raw = b.substr(k.level_offset, k.level_length);
  if (k.supercompression == kKtx2SupercompressionNone) {
    if (k.level_length != want) bad_file(name, "byteLength differs from the texel data size");
    k.level.assign(raw);
  } else {
    // The frame must declare the size the header claims before anything that large is allocated.
    if (ZSTD_getFrameContentSize(raw.data(), raw.size()) != want)
      bad_file(name, "the Zstandard frame does not declare uncompressedByteLength");
    k.level.assign(want, '\0');
    const std::size_t n = ZSTD_decompress(k.level.data(), k.level.size(), raw.data(), raw.size());
    if (ZSTD_isError(n)) bad_file(name, std::string("Zstandard level data: ") + ZSTD_getErrorName(n));
    if (n != want) bad_file(name, "Zstandard level decompresses to " + std::to_string(n) + " bytes, expected " +
                                      std::to_string(want));
  }

  k.rgba.resize(texels * 4);
  for (std::uint64_t i = 0; i < texels * 4; ++i) {
    if (tb == 8) {
      const auto lo = static_cast<unsigned char>(k.level[2 * i]), hi = static_cast<unsigned char>(k.level[2 * i + 1]);
      k.rgba[i] = half_bits_to_float(static_cast<std::uint16_t>(lo | (hi << 8)));
    } else {
      k.rgba[i] = std::bit_cast<float>(get32(k.level, 4 * i));
    }
  }
  return k;
}

HalfPrecision measure_half(std::span<const float> source, std::span<const float> widened, double rel_floor) {
  if (source.size() != widened.size())
    throw JobError("half precision: " + std::to_string(source.size()) + " values against " +
                   std::to_string(widened.size()) + " half values");
  HalfPrecision m;
  m.count = source.size();
  m.rel_floor = rel_floor;
  m.identical_to_float = true;
  for (std::size_t i = 0; i < source.size(); ++i) {
    const float x = source[i], h = widened[i];
    if (std::bit_cast<std::uint32_t>(x) != std::bit_cast<std::uint32_t>(h)) m.identical_to_float = false;
    // A binary16 number widens to a float that survives the round trip unchanged.
    if (!std::isnan(h) && half_bits_to_float(float_to_half_bits(h)) != h) ++m.not_half_values;
    if (!std::isfinite(x)) continue;
    if (std::isinf(h)) {
      ++m.overflow_to_inf;
      continue;
    }
    if (x != 0.0f && h == 0.0f) ++m.flush_to_zero;
    const double err = std::fabs(static_cast<double>(h) - static_cast<double>(x));
    if (err > m.max_abs_error) {
      m.max_abs_error = err;
      m.max_abs_index = i;
    }
    if (std::fabs(static_cast<double>(x)) >= rel_floor) {
      const double rel = err / std::fabs(static_cast<double>(x));
      if (rel > m.max_rel_error) {
        m.max_rel_error = rel;
        m.max_rel_index = i;
      }
    }
  }
  if (source.empty()) m.identical_to_float = false;
  return m;
}

HalfPrecision measure_half(std::span<const float> source, double rel_floor) {
  std::vector<float> widened(source.size());
  for (std::size_t i = 0; i < source.size(); ++i) widened[i] = half_bits_to_float(float_to_half_bits(source[i]));
  return measure_half(source, widened, rel_floor);
}

nlohmann::json HalfPrecision::to_json() const {
  return {{"count", count},
          {"max_abs_error", max_abs_error},
          {"max_abs_index", max_abs_index},
          {"rel_floor", rel_floor},
          {"max_rel_error", max_rel_error},
          {"max_rel_index", max_rel_index},
          {"overflow_to_inf", overflow_to_inf},
          {"flush_to_zero", flush_to_zero},
          {"not_half_values", not_half_values},
          {"identical_to_float", identical_to_float}};
}

}  // namespace specbake
