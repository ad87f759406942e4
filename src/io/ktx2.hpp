#pragma once
// KTX 2.0 textures (Khronos KTX File Format Specification 2.0) that engines load directly:
// three.js KTX2Loader (DataTexture / Data3DTexture, HalfFloatType / FloatType, RGBA, optional
// Zstandard), Bevy, Vulkan and WebGPU loaders.
//
// What the writer emits, and nothing else:
//   - one 2D (depth 0) or 3D texture, or a 2D array texture (layerCount >= 1, depth 0), one mip
//     level (levelCount 1), faceCount 1;
//   - vkFormat VK_FORMAT_R16G16B16A16_SFLOAT (97, typeSize 2) or VK_FORMAT_R32G32B32A32_SFLOAT
//     (109, typeSize 4); three-channel data is padded to RGBA with alpha 1, two-channel data
//     with blue 0 and alpha 1;
//   - a Khronos basic Data Format Descriptor (model RGBSDA, primaries BT.709, transfer linear,
//     1x1x1 texel block, four samples R, G, B, A with the FLOAT and SIGNED qualifiers,
//     sampleLower -1.0f and sampleUpper 1.0f as the Khronos Data Format Specification gives for
//     signed float channels). bytesPlane0 is the texel size (8 or 16) for plain data and 0 for
//     supercompressed data, which the KTX 2.0 specification calls "unsized";
//   - key/value data sorted by key bytes: KTXwriter, KTXorientation and the caller's own keys;
//   - optionally Zstandard supercompression (supercompressionScheme 2) of the level.
// Texels are stored x fastest, then y, then z (or the layer), channels interleaved, row 0 first:
// the same order as the bundle's .bin files.
//
// Every function works on bytes in memory: a job hands the returned string to an OutputFile.
#include <cstddef>
#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace specbake {

enum class Ktx2Format {
  rgba16f,  // VK_FORMAT_R16G16B16A16_SFLOAT: half floats, round to nearest even
  rgba32f,  // VK_FORMAT_R32G32B32A32_SFLOAT: the float values bit for bit
};

inline constexpr std::uint32_t kVkFormatR16G16B16A16Sfloat = 97;
inline constexpr std::uint32_t kVkFormatR32G32B32A32Sfloat = 109;
inline constexpr std::uint32_t kKtx2SupercompressionNone = 0;
inline constexpr std::uint32_t kKtx2SupercompressionZstd = 2;

// The texture to write. `texels` holds width*height*max(depth,1)*max(layers,1)*channels floats.
struct Ktx2Image {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::uint32_t depth = 0;  // 0: a 2D texture; >= 1: a 3D texture of that many slices
  int channels = 4;         // 2 (blue 0, alpha 1), 3 (alpha 1) or 4
  std::span<const float> texels;
  std::uint32_t layers = 0;  // 0: not an array; >= 1: a 2D array texture of that many layers (depth 0)
};

struct Ktx2Options {
  Ktx2Format format = Ktx2Format::rgba16f;
  bool zstd = false;
  int zstd_level = 9;  // 1..22; the output is deterministic for a given level and libzstd
  // Value of the KTXwriter key, e.g. "specbake 0.1.0" (required, non-empty).
  std::string writer;
  // Further keys, e.g. {"specbake.hash", ...}, {"specbake.layout", ...}. Keys must be non-empty
  // UTF-8 without NUL and must not begin with "KTX"/"ktx" (reserved by the specification).
  std::map<std::string, std::string> metadata;
};

// Encodes a KTX2 file. Throws JobError (naming what is wrong) when: a size is 0 or the texel
// count does not match; channels is not 2, 3 or 4; an array has depth; a value is NaN or infinite (first index
// named); in rgba16f, a finite value overflows half precision (|x| > 65504 rounds to inf);
// the writer string is empty; a key is empty, reserved, contains NUL or repeats KTXwriter.
std::string write_ktx2(const Ktx2Image& image, const Ktx2Options& options);

// A KTX2 file as read back, for tests and tools.
struct Ktx2File {
  std::uint32_t vk_format = 0, type_size = 0;
  std::uint32_t width = 0, height = 0, depth = 0;
  std::uint32_t layer_count = 0, face_count = 0, level_count = 0;
  std::uint32_t supercompression = 0;
  std::uint32_t dfd_offset = 0, dfd_length = 0, kvd_offset = 0, kvd_length = 0;
  std::uint64_t sgd_offset = 0, sgd_length = 0;
  std::uint64_t level_offset = 0, level_length = 0, level_uncompressed_length = 0;
  std::vector<std::uint32_t> dfd;                          // dfdTotalSize first, then the block
  std::vector<std::pair<std::string, std::string>> kv;     // in file order; value without its NUL
  std::string level;                                       // the level bytes, decompressed
  std::vector<float> rgba;                                 // the level as floats, 4 per texel

  const std::string* value(const std::string& key) const;  // nullptr if absent
};

// Parses a KTX2 file that holds one of the two formats above (one level, one face, a 2D, 3D or
// 2D array texture, no supercompression or Zstandard), checks the index against the file size, decompresses and
// widens the level to floats. Throws InputError naming `name` on anything malformed or
// unsupported.
Ktx2File read_ktx2(std::string_view bytes, const std::string& name = "<ktx2>");

// --- Half precision, measured -----------------------------------------------------------
// IEEE 754 binary16: 11 significant bits, so rounding to nearest even gives a relative error
// of at most 2^-11 for values in the normal range [2^-14, 65504]; below 2^-14 the spacing is
// fixed at 2^-24 and the absolute error is at most 2^-25.
inline constexpr double kHalfMax = 65504.0;
inline constexpr double kHalfMinNormal = 6.103515625e-05;  // 2^-14

// Round to nearest even (Imath::half) and back.
std::uint16_t float_to_half_bits(float value);
float half_bits_to_float(std::uint16_t bits);

struct HalfPrecision {
  std::size_t count = 0;
  double max_abs_error = 0.0;       // max |h - x|
  std::size_t max_abs_index = 0;
  double rel_floor = kHalfMinNormal;  // the relative error only counts values with |x| >= floor
  double max_rel_error = 0.0;       // max |h - x| / |x| over |x| >= rel_floor
  std::size_t max_rel_index = 0;
  std::size_t overflow_to_inf = 0;  // finite x whose half is infinite (|x| >= 65520)
  std::size_t flush_to_zero = 0;    // x != 0 whose half is ±0 (|x| <= 2^-25)
  std::size_t not_half_values = 0;  // "half" values that no binary16 number equals
  // Every widened half equals its float bit for bit. For measured data this says the "half"
  // holds no rounding at all: either every value was already a binary16 number, or the half
  // path stored the float data unrounded.
  bool identical_to_float = false;

  nlohmann::json to_json() const;
};

// Compares float data with its half rounding as a reader sees it (the halfs widened to float,
// e.g. Ktx2File::rgba of an rgba16f file). The spans must be the same length (JobError if not).
HalfPrecision measure_half(std::span<const float> source, std::span<const float> widened_half,
                           double rel_floor = kHalfMinNormal);
// The same, rounding `source` itself with float_to_half_bits.
HalfPrecision measure_half(std::span<const float> source, double rel_floor = kHalfMinNormal);

}  // namespace specbake
