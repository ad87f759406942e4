#pragma once
// Heightfield readers for the diffraction job. Integer images (8/16-bit grey PNG, 8-bit grey
// BMP) map grey levels to heights as h = gray / max_gray · height_um; float EXR and raw
// little-endian float32 files already hold heights in µm. Every reader checks what it reads
// and throws InputError naming the file and what was expected: non-finite heights, a raw
// file whose byte count does not match its size, a colour image, an unsupported encoding.
#include <filesystem>
#include <optional>
#include <string>
#include <utility>

#include <vector>

namespace specbake {

namespace fs = std::filesystem;

// A heightfield in µm, row-major [iy][ix] (x = ix·dx along columns, y = iy·dx along rows).
struct Heightfield {
  int width = 0, height = 0;
  double dx_um = 0.0;
  std::vector<double> h_um;
};


enum class HeightfieldFormat { png, bmp, exr, raw };

// From the file's extension (.png, .bmp, .exr, .raw/.f32); InputError for anything else.
HeightfieldFormat heightfield_format(const fs::path& file);
// PNG and BMP hold integer grey levels; EXR and raw hold heights in µm.
inline bool holds_grey_levels(HeightfieldFormat f) { return f == HeightfieldFormat::png || f == HeightfieldFormat::bmp; }
const char* to_string(HeightfieldFormat f);

struct HeightfieldRead {
  fs::path file;                                // named in every message
  HeightfieldFormat format = HeightfieldFormat::png;
  double dx_um = 0.0;                           // > 0
  double height_um = 1.0;                       // integer images only: height of the largest grey level
  std::optional<std::pair<int, int>> raw_size;  // raw float32 only: [W, H]
};

struct GreyImage {
  int width = 0, height = 0;
  int max_level = 0;            // 255 or 65535
  std::vector<double> levels;   // [iy][ix], row 0 at the top
};

// Decoders of the file's bytes (exposed for tests). InputError naming `file` on bad input.
GreyImage decode_png_grey(const std::string& bytes, const fs::path& file);
GreyImage decode_bmp_grey(const std::string& bytes, const fs::path& file);

// Decodes a heightfield from the file's bytes.
Heightfield decode_heightfield(const std::string& bytes, const HeightfieldRead& how);

}  // namespace specbake
