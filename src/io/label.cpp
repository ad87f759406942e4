#include "io/label.hpp"

#include <fontconfig/fontconfig.h>
#include <ft2build.h>
#include FT_FREETYPE_H
#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>
#include <mutex>

namespace specbake {

namespace {

constexpr int kInk = 235;  // the text's code: below 255, so a count of clipped pixels never counts a label
constexpr const char* kDebianFont = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

std::string find_font() {
  std::string file;
  if (FcConfig* config = FcInitLoadConfigAndFonts()) {
    if (FcPattern* pattern = FcNameParse(reinterpret_cast<const FcChar8*>("DejaVu Sans:style=Book"))) {
      FcConfigSubstitute(config, pattern, FcMatchPattern);
      FcDefaultSubstitute(pattern);
      FcResult result = FcResultNoMatch;
      if (FcPattern* match = FcFontMatch(config, pattern, &result)) {
        FcChar8* path = nullptr;
        if (FcPatternGetString(match, FC_FILE, 0, &path) == FcResultMatch && path)
          file = reinterpret_cast<const char*>(path);
        FcPatternDestroy(match);
      }
      FcPatternDestroy(pattern);
    }
    FcConfigDestroy(config);
  }
  std::error_code ec;
  if (!file.empty() && std::filesystem::is_regular_file(file, ec)) return file;
  return std::filesystem::is_regular_file(kDebianFont, ec) ? kDebianFont : "";
}

// The one FreeType face, used under a lock (a face is not thread-safe).
class Font {
 public:
  Font() : file_(find_font()) {
    if (file_.empty()) {
      spdlog::warn("previews: no font found (fontconfig, {}): their labels are left off; install fonts-dejavu-core",
                   kDebianFont);
      return;
    }
    if (FT_Init_FreeType(&lib_) != 0) {
      spdlog::warn("previews: FreeType did not start: their labels are left off");
      lib_ = nullptr;
      return;
    }
    if (FT_New_Face(lib_, file_.c_str(), 0, &face_) != 0) {
      spdlog::warn("previews: FreeType could not read the font {}: their labels are left off", file_);
      face_ = nullptr;
    }
  }
  ~Font() {
    if (face_) FT_Done_Face(face_);
    if (lib_) FT_Done_FreeType(lib_);
  }
  Font(const Font&) = delete;
  Font& operator=(const Font&) = delete;

  const std::string& file() const {
    static const std::string none;
    return face_ ? file_ : none;
  }
  FT_Face face() const { return face_; }
  std::mutex& lock() { return lock_; }

 private:
  std::string file_;
  FT_Library lib_ = nullptr;
  FT_Face face_ = nullptr;
  std::mutex lock_;
};

Font& font() {
  static Font f;
  return f;
}

// The code points of UTF-8 text (a malformed byte reads as U+FFFD).
std::vector<char32_t> code_points(const std::string& s) {
  std::vector<char32_t> out;
  for (std::size_t i = 0; i < s.size();) {
    const auto b = static_cast<unsigned char>(s[i]);
    const int n = b < 0x80 ? 1 : (b >> 5) == 6 ? 2 : (b >> 4) == 14 ? 3 : (b >> 3) == 30 ? 4 : 0;
    if (n == 0 || i + n > s.size()) {
      out.push_back(0xFFFD);
      ++i;
      continue;
    }
    char32_t c = n == 1 ? b : b & (0x7F >> n);
    for (int k = 1; k < n; ++k) c = (c << 6) | (static_cast<unsigned char>(s[i + k]) & 0x3F);
    out.push_back(c);
    i += n;
  }
  return out;
}

struct Metrics {
  int ascender = 0, line = 0;
};

// Under the lock: the face at px pixels.
Metrics set_size(FT_Face face, int px) {
  FT_Set_Pixel_Sizes(face, 0, static_cast<FT_UInt>(px));
  return {static_cast<int>(face->size->metrics.ascender >> 6), static_cast<int>(face->size->metrics.height >> 6)};
}

int advance_of(FT_Face face, char32_t c) {
  if (FT_Load_Char(face, c, FT_LOAD_DEFAULT) != 0) return 0;
  return static_cast<int>(face->glyph->advance.x >> 6);
}

TextBox measure(FT_Face face, const std::vector<std::string>& lines, int px) {
  const Metrics m = set_size(face, px);
  TextBox box{0, m.line * static_cast<int>(lines.size())};
  for (const std::string& line : lines) {
    int w = 0;
    for (char32_t c : code_points(line)) w += advance_of(face, c);
    box.width = std::max(box.width, w);
  }
  return box;
}

}  // namespace

const std::string& label_font_file() { return font().file(); }

int label_px(int width) { return std::clamp(width / 32, 10, 18); }

TextBox text_box(const std::vector<std::string>& lines, int px) {
  Font& f = font();
  if (!f.face()) return {};
  std::lock_guard<std::mutex> hold(f.lock());
  return measure(f.face(), lines, px);
}

bool draw_label(Rgb8& img, int x, int y, const std::vector<std::string>& lines, int px) {
  Font& f = font();
  if (!f.face()) return false;
  std::lock_guard<std::mutex> hold(f.lock());
  FT_Face face = f.face();
  const TextBox box = measure(face, lines, px);
  const Metrics m = set_size(face, px);
  const int pad = std::max(1, px / 4);
  // the box: the picture darkened to 35 %
  const int x1 = std::min(img.width, x + box.width + 2 * pad), y1 = std::min(img.height, y + box.height + 2 * pad);
  for (int j = std::max(0, y); j < y1; ++j)
    for (int i = std::max(0, x); i < x1; ++i)
      for (int c = 0; c < 3; ++c) {
        std::uint8_t& v = img.rgb[(static_cast<std::size_t>(j) * img.width + i) * 3 + c];
        v = static_cast<std::uint8_t>((v * 35 + 50) / 100);
      }
  // the glyphs: light grey (code kInk) over the box by their coverage (FreeType's 8-bit
  // anti-aliased bitmaps, blended on the sRGB codes as text renderers do)
  for (std::size_t l = 0; l < lines.size(); ++l) {
    int pen = x + pad;
    const int baseline = y + pad + static_cast<int>(l) * m.line + m.ascender;
    for (char32_t c : code_points(lines[l])) {
      if (FT_Load_Char(face, c, FT_LOAD_RENDER) != 0) continue;
      const FT_GlyphSlot g = face->glyph;
      const FT_Bitmap& bm = g->bitmap;
      for (unsigned r = 0; r < bm.rows; ++r)
        for (unsigned q = 0; q < bm.width; ++q) {
          const int i = pen + g->bitmap_left + static_cast<int>(q), j = baseline - g->bitmap_top + static_cast<int>(r);
          if (i < 0 || j < 0 || i >= img.width || j >= img.height) continue;
          const int a = bm.buffer[static_cast<std::ptrdiff_t>(r) * bm.pitch + q];
          for (int ch = 0; ch < 3; ++ch) {
            std::uint8_t& v = img.rgb[(static_cast<std::size_t>(j) * img.width + i) * 3 + ch];
            v = static_cast<std::uint8_t>((v * (255 - a) + kInk * a + 127) / 255);
          }
        }
      pen += static_cast<int>(g->advance.x >> 6);
    }
  }
  return true;
}

bool draw_label(Rgb8& img, Corner corner, const std::vector<std::string>& lines, int px) {
  const TextBox box = text_box(lines, px);
  const int pad = std::max(1, px / 4), w = box.width + 2 * pad, h = box.height + 2 * pad;
  const bool right = corner == Corner::top_right || corner == Corner::bottom_right;
  const bool bottom = corner == Corner::bottom_left || corner == Corner::bottom_right;
  return draw_label(img, right ? img.width - w : 0, bottom ? img.height - h : 0, lines, px);
}

}  // namespace specbake
