#include "io/heightfield.hpp"

#include <ImfChannelList.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfStdIO.h>
#include <png.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <csetjmp>
#include <cstdint>
#include <cstring>
#include <sstream>

#include "core/errors.hpp"
#include "io/exr.hpp"

namespace specbake {

namespace {

constexpr int kMaxSide = 16384;

[[noreturn]] void bad(const fs::path& file, const std::string& expected) { throw InputError({file, 0, 0, ""}, expected); }

void check_size(const fs::path& file, long long w, long long h) {
  if (w < 2 || h < 2 || w > kMaxSide || h > kMaxSide)
    bad(file, "expected a heightfield between 2 and " + std::to_string(kMaxSide) + " samples per side, got " +
                  std::to_string(w) + " x " + std::to_string(h));
}

// --- PNG via libpng ------------------------------------------------------------------------
struct PngSource {
  const std::string* bytes;
  std::size_t pos;
};

void png_read_bytes(png_structp png, png_bytep out, png_size_t n) {
  auto* src = static_cast<PngSource*>(png_get_io_ptr(png));
  if (src->pos + n > src->bytes->size()) png_error(png, "file is truncated");
  std::memcpy(out, src->bytes->data() + src->pos, n);
  src->pos += n;
}

struct PngMessage {
  char text[256] = {0};
};

void png_on_error(png_structp png, png_const_charp msg) {
  auto* m = static_cast<PngMessage*>(png_get_error_ptr(png));
  std::snprintf(m->text, sizeof m->text, "%s", msg);
  png_longjmp(png, 1);
}
void png_on_warning(png_structp, png_const_charp) {}

// Everything C++ lives outside the setjmp frame; the frame only touches PODs and the
// pre-sized buffers, so a longjmp leaves nothing half-destroyed.
bool png_decode_raw(const std::string& bytes, PngMessage& msg, png_uint_32& w, png_uint_32& h, int& bit_depth,
                    int& channels, std::vector<unsigned char>& pixels) {
  PngSource src{&bytes, 8};
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &msg, png_on_error, png_on_warning);
  if (!png) return false;
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_read_struct(&png, nullptr, nullptr);
    return false;
  }
  std::vector<png_bytep> rows;
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  png_set_read_fn(png, &src, png_read_bytes);
  png_set_sig_bytes(png, 8);
  png_read_info(png, info);
  int color_type = 0;
  png_get_IHDR(png, info, &w, &h, &bit_depth, &color_type, nullptr, nullptr, nullptr);
  if (w < 2 || h < 2 || w > kMaxSide || h > kMaxSide) {
    std::snprintf(msg.text, sizeof msg.text, "expected between 2 and %d pixels per side, got %u x %u", kMaxSide,
                  static_cast<unsigned>(w), static_cast<unsigned>(h));
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (color_type == PNG_COLOR_TYPE_GRAY && bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (color_type & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(png);
  if (png_get_valid(png, info, PNG_INFO_tRNS)) png_set_strip_alpha(png);
  png_read_update_info(png, info);
  bit_depth = png_get_bit_depth(png, info);
  channels = png_get_channels(png, info);
  const std::size_t stride = png_get_rowbytes(png, info);
  pixels.resize(stride * h);
  rows.resize(h);
  for (png_uint_32 y = 0; y < h; ++y) rows[y] = pixels.data() + y * stride;
  png_read_image(png, rows.data());
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  return true;
}

// --- BMP: 8-bit palette (grey) images, BI_RGB, bottom-up or top-down --------------------------
std::uint32_t le32(const std::string& b, std::size_t at) {
  return static_cast<std::uint32_t>(static_cast<unsigned char>(b[at])) |
         static_cast<std::uint32_t>(static_cast<unsigned char>(b[at + 1])) << 8 |
         static_cast<std::uint32_t>(static_cast<unsigned char>(b[at + 2])) << 16 |
         static_cast<std::uint32_t>(static_cast<unsigned char>(b[at + 3])) << 24;
}
std::uint16_t le16(const std::string& b, std::size_t at) {
  return static_cast<std::uint16_t>(static_cast<unsigned char>(b[at]) | static_cast<unsigned char>(b[at + 1]) << 8);
}

std::string lower_ext(const fs::path& file) {
  std::string e = file.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}

}  // namespace

HeightfieldFormat heightfield_format(const fs::path& file) {
  const std::string e = lower_ext(file);
  if (e == ".png") return HeightfieldFormat::png;
  if (e == ".bmp") return HeightfieldFormat::bmp;
  if (e == ".exr") return HeightfieldFormat::exr;
  if (e == ".raw" || e == ".f32") return HeightfieldFormat::raw;
  bad(file, "expected a heightfield file ending in .png, .bmp, .exr, .raw or .f32, got '" + e + "'");
}

const char* to_string(HeightfieldFormat f) {
  switch (f) {
    case HeightfieldFormat::png: return "png";
    case HeightfieldFormat::bmp: return "bmp";
    case HeightfieldFormat::exr: return "exr";
    case HeightfieldFormat::raw: return "raw-float32";
  }
  return "?";
}

GreyImage decode_png_grey(const std::string& bytes, const fs::path& file) {
  if (bytes.size() < 8 || png_sig_cmp(reinterpret_cast<png_const_bytep>(bytes.data()), 0, 8) != 0)
    bad(file, "expected a PNG image (the PNG signature is missing)");
  PngMessage msg;
  png_uint_32 w = 0, h = 0;
  int depth = 0, channels = 0;
  std::vector<unsigned char> px;
  if (!png_decode_raw(bytes, msg, w, h, depth, channels, px))
    bad(file, std::string("expected a readable PNG image: ") + (msg.text[0] ? msg.text : "libpng failed"));
  if (depth != 8 && depth != 16) bad(file, "expected an 8- or 16-bit PNG, got " + std::to_string(depth) + " bits");
  if (channels != 1 && channels != 3)
    bad(file, "expected a grey PNG (or RGB with R = G = B), got " + std::to_string(channels) + " channels");
  GreyImage g;
  g.width = static_cast<int>(w);
  g.height = static_cast<int>(h);
  g.max_level = depth == 16 ? 65535 : 255;
  g.levels.resize(static_cast<std::size_t>(w) * h);
  const std::size_t bps = depth / 8, stride = static_cast<std::size_t>(w) * channels * bps;
  for (std::size_t y = 0; y < h; ++y)
    for (std::size_t x = 0; x < w; ++x) {
      unsigned v[3] = {0, 0, 0};
      for (int c = 0; c < channels; ++c) {
        const unsigned char* p = px.data() + y * stride + (x * channels + c) * bps;
        v[c] = bps == 2 ? (static_cast<unsigned>(p[0]) << 8 | p[1]) : p[0];  // PNG samples are big-endian
      }
      if (channels == 3 && (v[0] != v[1] || v[1] != v[2]))
        bad(file, "expected a grey image; pixel (x " + std::to_string(x) + ", y " + std::to_string(y) +
                      ") has R, G, B = " + std::to_string(v[0]) + ", " + std::to_string(v[1]) + ", " +
                      std::to_string(v[2]));
      g.levels[y * w + x] = v[0];
    }
  return g;
}

GreyImage decode_bmp_grey(const std::string& b, const fs::path& file) {
  if (b.size() < 54 || b[0] != 'B' || b[1] != 'M') bad(file, "expected a BMP image (the 'BM' signature is missing)");
  const std::uint32_t data_offset = le32(b, 10), header_size = le32(b, 14);
  if (header_size < 40 || 14 + header_size > b.size()) bad(file, "expected a BMP with a BITMAPINFOHEADER or later");
  const auto width = static_cast<std::int32_t>(le32(b, 18)), height_signed = static_cast<std::int32_t>(le32(b, 22));
  const std::uint16_t bits = le16(b, 28);
  const std::uint32_t compression = le32(b, 30), colours_used = le32(b, 46);
  if (bits != 8) bad(file, "expected an 8-bit grey (palette) BMP, got " + std::to_string(bits) + " bits per pixel");
  if (compression != 0) bad(file, "expected an uncompressed BMP (BI_RGB), got compression " + std::to_string(compression));
  const long long height = height_signed < 0 ? -static_cast<long long>(height_signed) : height_signed;
  check_size(file, width, height);
  const std::uint32_t palette_count = colours_used ? colours_used : 256;
  const std::size_t palette_at = 14 + header_size;
  if (palette_count > 256 || palette_at + 4ull * palette_count > b.size())
    bad(file, "expected a palette of at most 256 entries inside the file");
  std::vector<int> grey(palette_count);
  for (std::uint32_t i = 0; i < palette_count; ++i) {
    const auto* e = reinterpret_cast<const unsigned char*>(b.data() + palette_at + 4 * i);  // B, G, R, 0
    if (e[0] != e[1] || e[1] != e[2])
      bad(file, "expected a grey palette; entry " + std::to_string(i) + " is not grey");
    grey[i] = e[0];
  }
  const std::size_t stride = (static_cast<std::size_t>(width) + 3) / 4 * 4;
  if (data_offset + stride * static_cast<std::size_t>(height) > b.size())
    bad(file, "expected " + std::to_string(stride * height) + " bytes of pixel data; the file is truncated");
  GreyImage g;
  g.width = width;
  g.height = static_cast<int>(height);
  g.max_level = 255;
  g.levels.resize(static_cast<std::size_t>(width) * height);
  for (long long row = 0; row < height; ++row) {
    const long long y = height_signed > 0 ? height - 1 - row : row;  // positive height: bottom-up rows
    for (int x = 0; x < width; ++x) {
      const auto idx = static_cast<unsigned char>(b[data_offset + row * stride + x]);
      if (idx >= palette_count)
        bad(file, "pixel (x " + std::to_string(x) + ", y " + std::to_string(y) + ") indexes past the palette");
      g.levels[static_cast<std::size_t>(y) * width + x] = grey[idx];
    }
  }
  return g;
}

namespace {

std::vector<double> exr_heights(const std::string& bytes, const fs::path& file, int& w, int& h) {
  std::vector<std::string> names;
  try {
    Imf::StdISStream in;
    in.str(bytes);
    Imf::InputFile f(in);
    for (auto it = f.header().channels().begin(); it != f.header().channels().end(); ++it) names.push_back(it.name());
  } catch (const std::exception& e) {
    bad(file, std::string("expected an OpenEXR image: ") + e.what());
  }
  std::string channel;
  if (names.size() == 1) channel = names[0];
  for (const char* preferred : {"H", "Z", "Y", "R"})
    if (channel.empty() && std::find(names.begin(), names.end(), preferred) != names.end()) channel = preferred;
  if (channel.empty()) {
    std::string list;
    for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
    bad(file, "expected one channel, or a channel named H, Z, Y or R holding heights in µm; found: " + list);
  }
  ExrImage img;
  try {
    img = exr_read(bytes, {channel});
  } catch (const InputError& e) {
    bad(file, e.what());
  }
  w = img.width;
  h = img.height;
  return std::vector<double>(img.pixels.begin(), img.pixels.end());
}

}  // namespace

Heightfield decode_heightfield(const std::string& bytes, const HeightfieldRead& how) {
  if (!(how.dx_um > 0.0) || !std::isfinite(how.dx_um)) bad(how.file, "expected a sample spacing dx_um > 0");
  Heightfield f;
  f.dx_um = how.dx_um;
  switch (how.format) {
    case HeightfieldFormat::png:
    case HeightfieldFormat::bmp: {
      if (!(how.height_um > 0.0) || !std::isfinite(how.height_um)) bad(how.file, "expected height_um > 0");
      const GreyImage g = how.format == HeightfieldFormat::png ? decode_png_grey(bytes, how.file)
                                                               : decode_bmp_grey(bytes, how.file);
      f.width = g.width;
      f.height = g.height;
      f.h_um.resize(g.levels.size());
      for (std::size_t i = 0; i < g.levels.size(); ++i) f.h_um[i] = g.levels[i] / g.max_level * how.height_um;
      break;
    }
    case HeightfieldFormat::exr:
      f.h_um = exr_heights(bytes, how.file, f.width, f.height);
      break;
    case HeightfieldFormat::raw: {
      if (!how.raw_size) bad(how.file, "expected size: [W, H] for a raw float32 heightfield");
      const auto [w, h] = *how.raw_size;
      check_size(how.file, w, h);
      const std::size_t want = 4ull * static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
      if (bytes.size() != want)
        bad(how.file, "expected " + std::to_string(want) + " bytes of little-endian float32 for size [" +
                          std::to_string(w) + ", " + std::to_string(h) + "], got " + std::to_string(bytes.size()) +
                          " bytes");
      f.width = w;
      f.height = h;
      f.h_um.resize(static_cast<std::size_t>(w) * h);
      for (std::size_t i = 0; i < f.h_um.size(); ++i) {
        const std::uint32_t u = le32(bytes, 4 * i);
        float v;
        std::memcpy(&v, &u, 4);
        f.h_um[i] = v;
      }
      break;
    }
  }
  check_size(how.file, f.width, f.height);
  for (std::size_t i = 0; i < f.h_um.size(); ++i)
    if (!std::isfinite(f.h_um[i]))
      bad(how.file, "expected finite heights; sample (x " + std::to_string(i % f.width) + ", y " +
                        std::to_string(i / f.width) + ") is " + (std::isnan(f.h_um[i]) ? "NaN" : "infinite"));
  return f;
}

}  // namespace specbake
