#pragma once
// OpenEXR encoding of float images into bytes, for bundle files: float32 uncompressed, half ZIP.
#include <map>
#include <string>
#include <vector>

namespace specbake {

struct ExrImage {
  int width = 0, height = 0;
  std::vector<std::string> channels;  // e.g. {"R", "G", "B"}; stored in this order per pixel
  std::vector<float> pixels;          // [height][width][channels.size()], row 0 at the top
  bool half = false;                  // store as 16-bit half instead of 32-bit float (read: stored so)
  std::map<std::string, std::string> attributes;  // extra string header attributes
};

std::string exr_bytes(const ExrImage& image);
// What exr_read accepts of an untrusted header, and exr_bytes writes: bundle files are flattened
// arrays (a sky-view table is AZIMUTH wide and SUN·ALTITUDE·VIEW high: 32 × 19008 for the default
// ground scene), not pictures, so a side may be long; the pixel count bounds the allocation.
inline constexpr int kMaxExrSide = 1 << 20;
inline constexpr long long kMaxExrPixels = 1LL << 28;
inline bool exr_size_allowed(long long width, long long height) {
  return width >= 1 && height >= 1 && width <= kMaxExrSide && height <= kMaxExrSide && width * height <= kMaxExrPixels;
}

// Decodes an EXR (any pixel type) into float, channels in the given order (tests, readers).
ExrImage exr_read(const std::string& bytes, const std::vector<std::string>& channels);
// The channel names an EXR holds, in the header's order (alphabetical: B, G, R).
std::vector<std::string> exr_channels(const std::string& bytes);

}  // namespace specbake
