// The shipped dispersion.glsl run on a real GL implementation (Mesa's llvmpipe through EGL
// surfaceless, GLES 3.2): specbake_dispersion_combine applies the bundle's K_n to per-sample
// colours held in a 2D array texture (random, out of gamut as real per-sample renders are), and
// every pixel is compared with the host's double Σ_n K_n·rgb_n from matrices.bin.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

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

  constexpr int kSide = 16;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> value(-0.5f, 1.5f);
  std::vector<float> renders(static_cast<std::size_t>(4) * kSide * kSide * n);
  for (float& v : renders) v = value(rng);
  GLuint tex = 0;
  glGenTextures(1, &tex);
  glBindTexture(GL_TEXTURE_2D_ARRAY, tex);
  glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_RGBA32F, kSide, kSide, n, 0, GL_RGBA, GL_FLOAT, renders.data());
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  const t::GlTarget target(kSide, kSide);
  ASSERT_TRUE(target.complete);
  const std::string fs = "#version 320 es\nprecision highp float;\nprecision highp sampler2DArray;\n" + glsl +
                         "uniform sampler2DArray renders;\nout vec4 colour;\n"
                         "void main() { colour = vec4(specbake_dispersion_combine(renders, ivec2(gl_FragCoord.xy)), 1.0); }\n";
  std::string log;
  const GLuint prog = t::gl_program(t::kGlFullScreenVertex, fs, log);
  ASSERT_NE(prog, 0u) << log;
  glUseProgram(prog);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D_ARRAY, tex);
  glUniform1i(glGetUniformLocation(prog, "renders"), 0);
  const std::vector<float> pixels = target.draw();
  ASSERT_EQ(glGetError(), static_cast<GLenum>(GL_NO_ERROR));

  // Host: Σ_n K_n·rgb_n in double from the same float32 numbers (the GLSL literals are the
  // float32 values to 9 digits, exact). A float32 sum of m = 3n products is within
  // γ_m·Σ|K||rgb|, γ_m = m·u/(1 − m·u), u = 2^-24 (Higham, eq. 3.5); FMA only tightens it.
  const double u = std::ldexp(1.0, -24), gamma = 3 * n * u / (1 - 3 * n * u);
  int checked = 0;
  for (int y = 0; y < kSide; ++y)
    for (int x = 0; x < kSide; ++x)
      for (int row = 0; row < 3; ++row) {
        double sum = 0, mag = 0;
        for (int s = 0; s < n; ++s)
          for (int c = 0; c < 3; ++c) {
            const double k = K[9 * s + 3 * row + c], v = renders[4 * ((static_cast<std::size_t>(s) * kSide + y) * kSide + x) + c];
            sum += k * v;
            mag += std::fabs(k * v);
          }
        EXPECT_NEAR(pixels[4 * (y * kSide + x) + row], sum, gamma * mag + 1e-30) << "pixel (" << x << ", " << y << ") channel " << row;
        ++checked;
      }
  EXPECT_EQ(checked, 3 * kSide * kSide);
  // The sum is not the identity on these colours (the check can fail): K_n differ per sample.
  EXPECT_GT(std::fabs(pixels[0] - renders[0]), 1e-3);
#endif
}
