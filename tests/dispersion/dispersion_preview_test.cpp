// preview/prism.png: the two strips at a readable size, each labelled, with a wavelength scale.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>

#include "support/testing.hpp"

namespace t = specbake::testing;

namespace {

// Pixels of [x0, x1) × [y0, y1) whose three channels are all at least 180: grey-white label ink.
// The spectrum's colours are saturated (at the red end, where the labels sit, blue and green stay
// below 100), so only a label puts such pixels there.
int ink(const t::Image& img, int x0, int x1, int y0, int y1) {
  int n = 0;
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) {
      const unsigned char* p = &img.rgba[4 * (static_cast<std::size_t>(y) * img.width + x)];
      n += std::min({p[0], p[1], p[2]}) >= 180;
    }
  return n;
}

}  // namespace

// Strips 80 pixels tall (4 apart) and a 30-pixel scale under them: 194 rows; each pixel of the
// judged picture (32 per beam width) drawn as wide as makes the strip at least 512 pixels.
TEST(DispersionPreview, PrismIsReadableAndLabelled) {
  t::TempDir dir;
  t::write_file(dir / "c.yaml", "specbake: 1\noutput: out\njobs:\n"
                                "  - name: prism\n    kind: dispersion\n    samples: 12\n    material: {glass: N-SF11}\n");
  const auto r = t::run_cli({"run", (dir / "c.yaml").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto img = t::read_png(dir / "out/prism/latest/preview/prism.png");
  EXPECT_EQ(img.height, 194);
  EXPECT_GE(img.width, 512);
  EXPECT_GT(ink(img, 0, 150, 0, 14), 20) << "the sampled strip's label";
  EXPECT_GT(ink(img, 0, 150, 84, 98), 20) << "the reference strip's label";
  EXPECT_GT(ink(img, 0, img.width, 164, 194), 20) << "the wavelength scale";
  EXPECT_EQ(ink(img, 0, img.width, 80, 84), 0) << "the gap between the strips";
}
