// The shipped dispersion.glsl run on a real GL implementation (Mesa's llvmpipe through EGL
// surfaceless, GLES 3.2): specbake_dispersion_combine applies the bundle's K_n to per-sample
// colours held in a 2D array texture (random, out of gamut as real per-sample renders are; and a
// slit displaced per sample as a prism displaces it), and every pixel is compared with the host's
// double Σ_n K_n·rgb_n from matrices.bin (the same combine.glsl text compiled on the host).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/resources.hpp"
#include "kinds/dispersion/combine.hpp"
#include "support/gl_context.hpp"
#include "support/testing.hpp"

namespace t = specbake::testing;

TEST(DispersionGl, ShippedCombineMatchesTheHostSum) {
#ifndef SPECBAKE_HAVE_GL
  GTEST_SKIP() << "built without EGL/GLES headers (Debian: libegl-dev, libgles-dev)";
#else
  t::GlContext gl;
  if (!gl.why.empty()) GTEST_SKIP() << "no EGL device: " << gl.why;
  ASSERT_TRUE(t::gl_has_extension("GL_EXT_color_buffer_float")) << "float render targets";

  t::TempDir dir;
  t::write_file(dir / "c.yaml", "specbake: 1\noutput: out\njobs:\n"
                                "  - name: prism\n    kind: dispersion\n    samples: 12\n    material: {glass: N-SF11}\n");
  const auto r = t::run_cli({"run", (dir / "c.yaml").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string glsl = t::read_file(dir / "out/prism/latest/dispersion.glsl");
  const auto K = t::read_f32(dir / "out/prism/latest/matrices.bin");  // [n][3][3], row-major
  const int n = static_cast<int>(K.size() / 9);
  ASSERT_EQ(n, 12);
  // One source: the shader's sum is combine.glsl as written (its comment header and all).
  const std::string shared(specbake::resource("kernels/dispersion/combine.glsl"));
  EXPECT_NE(glsl.find(shared.substr(0, shared.size() - 1)), std::string::npos) << "combine.glsl is not verbatim";
  // The bundle's picture of the prism (top: the samples through that sum; bottom: the dense spectrum).
  const auto prism = t::read_png(dir / "out/prism/latest/preview/prism.png");
  EXPECT_GT(prism.width, 32);
  EXPECT_EQ(prism.height, 194);  // two 80-pixel strips, 4 apart, and a 30-pixel wavelength scale

  const std::string fs = "#version 320 es\nprecision highp float;\nprecision highp sampler2DArray;\n" + glsl +
                         "uniform sampler2DArray renders;\nout vec4 colour;\n"
                         "void main() { colour = vec4(specbake_dispersion_combine(renders, ivec2(gl_FragCoord.xy)), 1.0); }\n";
  std::string log;
  const GLuint prog = t::gl_program(t::kGlFullScreenVertex, fs, log);
  ASSERT_NE(prog, 0u) << log;
  glUseProgram(prog);
  glUniform1i(glGetUniformLocation(prog, "renders"), 0);

  // Per-sample renders (RGBA, [sample][y][x], row 0 at the bottom) through the shader: the
  // combined pixels, and the host's Σ_n K_n·rgb_n in double from the same float32 numbers (the
  // GLSL literals are the float32 values to 9 digits, exact). A float32 sum of m = 3n products
  // is within γ_m·Σ|K||rgb|, γ_m = m·u/(1 − m·u), u = 2^-24 (Higham, eq. 3.5); FMA only tightens it.
  const double u = std::ldexp(1.0, -24), gamma = 3 * n * u / (1 - 3 * n * u);
  const auto combine = [&](int w, int h, const std::vector<float>& renders, const char* figure) {
    GLuint tex = 0;
    glGenTextures(1, &tex);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D_ARRAY, tex);
    glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_RGBA32F, w, h, n, 0, GL_RGBA, GL_FLOAT, renders.data());
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    const t::GlTarget target(w, h);
    EXPECT_TRUE(target.complete);
    const std::vector<float> pixels = target.draw();
    EXPECT_EQ(glGetError(), static_cast<GLenum>(GL_NO_ERROR));
    std::vector<float> gl_rgb(3 * w * h), host_rgb(3 * w * h), over_bound(w * h, 0.0f);
    // The host's sum: combine.glsl compiled in double (the shader's text) over the same numbers.
    std::vector<double> rgb(3 * static_cast<std::size_t>(n) * w * h);
    for (std::size_t i = 0; i < rgb.size() / 3; ++i)
      for (int c = 0; c < 3; ++c) rgb[3 * i + c] = renders[4 * i + c];
    specbake::dispersion::Combiner host(std::vector<double>(K.begin(), K.end()));
    int checked = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int row = 0; row < 3; ++row) {
          const double sum = host.combine({rgb.data(), w, h}, x, y)[row];
          double mag = 0, direct = 0;  // direct: the row-major sum written out, independent of combine.glsl
          for (int s = 0; s < n; ++s)
            for (int c = 0; c < 3; ++c) {
              const double kv = double(K[9 * s + 3 * row + c]) * renders[4 * ((static_cast<std::size_t>(s) * h + y) * w + x) + c];
              mag += std::fabs(kv);
              direct += kv;
            }
          // the host's GLM evaluation of the shared text is that sum (double rounding only)
          EXPECT_NEAR(sum, direct, 1e-13 * mag + 1e-300) << figure << " host, pixel (" << x << ", " << y << ")";
          const std::size_t at = static_cast<std::size_t>(y) * w + x;
          const double got = pixels[4 * at + row], bound = gamma * mag + 1e-30;
          EXPECT_NEAR(got, sum, bound) << figure << " pixel (" << x << ", " << y << ") channel " << row;
          gl_rgb[3 * at + row] = static_cast<float>(got);
          host_rgb[3 * at + row] = static_cast<float>(sum);
          over_bound[at] = std::max(over_bound[at], static_cast<float>(std::fabs(got - sum) / bound));
          ++checked;
        }
    EXPECT_EQ(checked, 3 * w * h);
    t::write_gl_figure(figure, w, h, gl_rgb, host_rgb, over_bound,
                       {{"title", std::string(figure == std::string("dispersion-slit") ? "a slit through N-SF11" : "random colours") + ", 12 samples"},
                        {"gl", "llvmpipe, GLES 3.2"},
                        {"host", "sum of K_n rgb_n in double"},
                        {"bound", "|GL - host| / (gamma_3n sum |K rgb|), worst channel"}});
    glDeleteTextures(1, &tex);
    return pixels;
  };

  // Random colours, out of gamut as real per-sample renders are.
  constexpr int kSide = 16;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> value(-0.5f, 1.5f);
  std::vector<float> noise(static_cast<std::size_t>(4) * kSide * kSide * n);
  for (float& v : noise) v = value(rng);
  const std::vector<float> pixels = combine(kSide, kSide, noise, "dispersion-noise");
  // The sum is not the identity on these colours (the check can fail): K_n differ per sample.
  EXPECT_GT(std::fabs(pixels[0] - noise[0]), 1e-3);

  // A picture: a white slit seen through a prism, each sample's image displaced by 3 pixels more
  // than the previous one's (as a prism bends each wavelength by its own angle); the sum spreads
  // it into a spectrum.
  const int w = 96, h = 24;
  std::vector<float> slit(static_cast<std::size_t>(4) * w * h * n, 0.0f);
  for (int s = 0; s < n; ++s)
    for (int y = 0; y < h; ++y)
      for (int x = 14 + 3 * s; x < 20 + 3 * s; ++x)
        for (int c = 0; c < 4; ++c) slit[4 * ((static_cast<std::size_t>(s) * h + y) * w + x) + c] = 1.0f;
  combine(w, h, slit, "dispersion-slit");
#endif
}
