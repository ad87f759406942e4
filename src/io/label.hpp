#pragma once
// Text drawn into 8-bit sRGB pictures (the previews' labels): FreeType rasterises DejaVu Sans
// (found through fontconfig, else at Debian's path of fonts-dejavu-core) in light grey, on a darkened
// box so that it reads over any picture. Only the PNGs carry labels; no linear data does.
#include <cstdint>
#include <string>
#include <vector>

#include "io/png.hpp"

namespace specbake {

// The font file the labels use; empty when none is installed (then labels are left off with one
// warning naming the package to install).
const std::string& label_font_file();

// The box `lines` take at a font `px` pixels tall (line height × line count, widest line), not
// counting the padding draw_label adds; {0, 0} without a font.
struct TextBox {
  int width = 0, height = 0;
};
TextBox text_box(const std::vector<std::string>& lines, int px);

// Where a label goes: a corner of the picture, or (x, y) as its box's top-left corner.
enum class Corner { top_left, top_right, bottom_left, bottom_right };

// Draws `lines` (UTF-8) in light grey (code 235: a label never reads as a clipped pixel) at a
// font `px` pixels tall, each line on its own, over a box that darkens the picture to 35 % with
// `px / 4` pixels of padding; the box's top-left corner at
// (x, y), clipped to the picture. False (nothing drawn) without a font.
bool draw_label(Rgb8& img, int x, int y, const std::vector<std::string>& lines, int px);
bool draw_label(Rgb8& img, Corner corner, const std::vector<std::string>& lines, int px);

// A font size for labels on a picture `width` pixels wide: width / 32, at least 10 and at most 18.
int label_px(int width);

}  // namespace specbake
