// The previews' labels: a font is found, text measures and draws where it is asked to, and the
// ACES tone curve the previews use by default.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "io/label.hpp"
#include "io/png.hpp"

namespace specbake {
namespace {

// scripts/setup.sh installs fonts-dejavu-core: without a font every preview goes unlabelled.
TEST(Label, FindsAFont) { ASSERT_FALSE(label_font_file().empty()) << "no font: install fonts-dejavu-core"; }

// A line of text at px pixels: its height is the font's line spacing (DejaVu Sans: 1.164 em, so
// between px and 1.5 px), its width that of 10 characters of a proportional sans (DejaVu's
// digits and capitals are 0.6–0.8 em wide, the space 0.32: between 0.4 and 0.8 px a character).
TEST(Label, MeasuresTextAtItsSize) {
  ASSERT_FALSE(label_font_file().empty());
  const int px = 16;
  const TextBox one = text_box({"EV100 14.5"}, px);
  EXPECT_GE(one.height, px);
  EXPECT_LE(one.height, 3 * px / 2);
  EXPECT_GE(one.width, 10 * px * 4 / 10);
  EXPECT_LE(one.width, 10 * px * 8 / 10);
  const TextBox two = text_box({"EV100 14.5", "sun +20°"}, px);
  EXPECT_EQ(two.height, 2 * one.height);
  EXPECT_EQ(two.width, one.width);  // "sun +20°" is the narrower line
  const TextBox big = text_box({"EV100 14.5"}, 2 * px);
  EXPECT_NEAR(big.width, 2 * one.width, 0.1 * one.width);  // hinting moves each advance by < 1 px
}

// On a black picture the label changes pixels only inside its box (text box plus px/4 padding,
// at the asked place), draws ink there, and never a full-white code (labels never read as
// clipped pixels); without text only the box shows, which on black is black.
TEST(Label, DrawsInsideItsBoxOnly) {
  ASSERT_FALSE(label_font_file().empty());
  const int px = 14, x0 = 20, y0 = 30;
  Rgb8 img(200, 100);
  ASSERT_TRUE(draw_label(img, x0, y0, {"sun −4°"}, px));
  const TextBox box = text_box({"sun −4°"}, px);
  const int pad = px / 4;
  int ink = 0, outside = 0, white = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const int v = img.rgb[(static_cast<std::size_t>(y) * img.width + x) * 3 + c];
        const bool in = x >= x0 && x < x0 + box.width + 2 * pad && y >= y0 && y < y0 + box.height + 2 * pad;
        outside += !in && v != 0;
        ink += in && v > 128;
        white += v == 255;
      }
  EXPECT_EQ(outside, 0);
  EXPECT_GT(ink, 3 * 30);  // seven glyphs of 14 px strokes: many more than 30 fully inked pixels
  EXPECT_EQ(white, 0);
  // a corner places the box against the picture's edges
  Rgb8 corner(200, 100);
  ASSERT_TRUE(draw_label(corner, Corner::bottom_right, {"EV100 7.5"}, px));
  const TextBox cb = text_box({"EV100 7.5"}, px);
  int first_x = corner.width, first_y = corner.height;
  for (int y = 0; y < corner.height; ++y)
    for (int x = 0; x < corner.width; ++x)
      if (corner.rgb[(static_cast<std::size_t>(y) * corner.width + x) * 3] != 0) {
        first_x = std::min(first_x, x);
        first_y = std::min(first_y, y);
      }
  EXPECT_GE(first_x, corner.width - cb.width - 2 * pad);
  EXPECT_GE(first_y, corner.height - cb.height - 2 * pad);
}

// The box darkens what is under it to 35 %, so a label reads over a white sky.
TEST(Label, DarkensTheBoxUnderIt) {
  ASSERT_FALSE(label_font_file().empty());
  Rgb8 img(100, 40);
  std::fill(img.rgb.begin(), img.rgb.end(), 200);
  ASSERT_TRUE(draw_label(img, 0, 0, {"i"}, 20));
  EXPECT_EQ(img.rgb[(39 * 100 + 99) * 3], 200);                // outside the box: untouched
  EXPECT_EQ(img.rgb[(1 * 100 + 1) * 3], (200 * 35 + 50) / 100);  // the box's corner (padding, no ink)
}

// Narkowicz's ACES fit: 0 at 0, rising, the values its formula gives, white from x ≈ 7.24 (the
// root of 0.08 x² − 0.56 x − 0.14), and tone_inverse inverting it; linear clips at 1.
TEST(ToneCurve, AcesFitAndItsInverse) {
  EXPECT_EQ(tone(0.0f, ToneCurve::aces), 0.0f);
  EXPECT_EQ(tone(-1.0f, ToneCurve::aces), 0.0f);
  EXPECT_NEAR(tone(1.0f, ToneCurve::aces), 2.54 / 3.16, 1e-6);
  float last = 0.0f;
  for (float x = 0.01f; x < 8.0f; x += 0.01f) {
    const float d = tone(x, ToneCurve::aces);
    EXPECT_GE(d, last) << x;
    last = d;
  }
  EXPECT_LT(tone(7.2f, ToneCurve::aces), 1.0f);
  EXPECT_EQ(tone(7.3f, ToneCurve::aces), 1.0f);
  EXPECT_NEAR(tone_inverse(0.975, ToneCurve::aces), (0.545 + std::sqrt(0.545 * 0.545 + 4 * 0.141 * 0.1365)) / 0.282,
              1e-2);  // 0.975 · (2.43 x² + 0.59 x + 0.14) = 2.51 x² + 0.03 x, coefficients to 3 digits
  EXPECT_NEAR(tone(static_cast<float>(tone_inverse(0.5, ToneCurve::aces)), ToneCurve::aces), 0.5, 1e-6);
  EXPECT_EQ(tone(3.0f, ToneCurve::linear), 1.0f);
  EXPECT_EQ(tone(0.25f, ToneCurve::linear), 0.25f);
  EXPECT_NEAR(tone_inverse(0.975, ToneCurve::linear), 0.975, 1e-7);  // the curve is in float32: an ulp of 6e-8
}

}  // namespace
}  // namespace specbake
