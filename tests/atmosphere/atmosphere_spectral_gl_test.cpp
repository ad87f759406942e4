// The spectral shader (sampling_spectral.glsl, `store: radiance`) run on Mesa's llvmpipe through
// EGL surfaceless (GLES 3.2): a small spectral bake's radiance textures are uploaded as an engine
// would (2D array textures, RGBA32F, LINEAR, CLAMP_TO_EDGE, one layer per wavelength set), a
// fisheye is drawn with GetSkyRadianceAtWavelength at wavelengths inside a set, across two sets
// and past the stored range, and every pixel's radiance and transmittance is compared with the
// host's double evaluation of the same render.glsl (glsl::spectral) over the same float32 texels
// and float32 inputs, within a per-pixel bound (as atmosphere_gl_test.cpp's): each fetch's
// texel coordinates moved ±2⁻⁹ texel per axis, each input direction turned and each altitude and
// wavelength scaled by 2⁻²⁰ (~16 ulps), 64 ulps on the value. Skipped only without an EGL device.
#include <gtest/gtest.h>

#include <cmath>

#include "core/parallel.hpp"
#include "kinds/atmosphere/atmosphere_job.hpp"
#include "kinds/atmosphere/shader/shader_host.hpp"
#include "atmosphere/radiance_earth.hpp"
#include "atmosphere/gl_perturb.hpp"
#include "support/gl_context.hpp"

namespace {

using namespace specbake;
using namespace specbake::atmosphere;
using glm::dvec3;

using specbake::testing::f32;
using specbake::testing::turned;

struct Host {
  glsl::spectral::SpecbakeAtmosphere atm;
  glsl::sampler2DArray transmittance, scattering, single_mie;
  // radiance and transmittance at lambda along view from altitude h (camera up = z)
  std::array<double, 2> eval(const dvec3& view, double h, const dvec3& sun, double lambda,
                             glsl::FilterProbe* probe = nullptr) const {
    glsl::sampler2DArray t = transmittance, s = scattering, m = single_mie;
    t.probe = s.probe = m.probe = probe;
    double tr = 0.0;
    const double l = glsl::spectral::GetSkyRadianceAtWavelength(atm, t, s, m, dvec3(0, 0, 1), h, view, 0.0, sun,
                                                                lambda, tr);
    return {l, tr};
  }
  std::array<double, 2> bound(const dvec3& view, double h, const dvec3& sun, double lambda) const {
    const auto value = eval(view, h, sun, lambda);
    std::array<double, 2> b{0.0, 0.0};
    const auto add_max = [&](const std::vector<std::array<double, 2>>& outs) {
      for (int k = 0; k < 2; ++k) {
        double m = 0.0;
        for (const auto& o : outs) m = std::max(m, std::fabs(o[k] - value[k]));
        b[k] += m;
      }
    };
    glsl::FilterProbe count;
    eval(view, h, sun, lambda, &count);
    for (int fetch = 0; fetch < count.fetches; ++fetch)
      for (int axis = 0; axis < 2; ++axis) {
        std::vector<std::array<double, 2>> moved;
        for (double shift : {std::ldexp(1.0, -9), -std::ldexp(1.0, -9)}) {
          glsl::FilterProbe probe{0, fetch, axis, shift};
          moved.push_back(eval(view, h, sun, lambda, &probe));
        }
        add_max(moved);
      }
    const double e = std::ldexp(1.0, -20);
    std::vector<std::array<double, 2>> outs;
    for (const dvec3& v2 : turned(view, e)) outs.push_back(eval(v2, h, sun, lambda));
    add_max(outs);
    outs.clear();
    for (const dvec3& s2 : turned(sun, e)) outs.push_back(eval(view, h, s2, lambda));
    add_max(outs);
    outs.clear();
    for (double s : {1.0 + e, 1.0 - e}) outs.push_back(eval(view, h * s, sun, lambda));
    add_max(outs);
    outs.clear();
    for (double s : {1.0 + e, 1.0 - e}) outs.push_back(eval(view, h, sun, lambda * s));
    add_max(outs);
    for (int k = 0; k < 2; ++k) b[k] += 64.0 * std::ldexp(1.0, -24) * std::fabs(value[k]);
    return b;
  }
};

TEST(AtmosphereSpectralGl, ShippedSpectralSamplingMatchesTheHostOnLlvmpipe) {
#ifndef SPECBAKE_HAVE_GL
  GTEST_SKIP() << "built without EGL/GLES headers (Debian: libegl-dev, libgles-dev)";
#else
  SPECBAKE_GL_CONTEXT_OR_SKIP(gl);

  // A small spectral bake of Bruneton's Earth, 8 wavelengths (2 sets), in double on the host.
  const Baked baked = bake_luts_reference(specbake::testing::radiance_earth({64, 16}, {16, 4}, {8, 32, 8, 4}));
  const SpectralLuts& L = baked.radiance;
  const Model& m = baked.luts.model;
  const Sizes& s = m.sizes;
  const int tiled_w = s.r * s.scattering_width();
  const Host host{glsl::spectral::atmosphere_of(m, L),
                  {L.transmittance.data(), s.transmittance_w, s.transmittance_h, L.sets()},
                  {L.scattering.data(), tiled_w, s.mu, L.sets()},
                  {L.single_mie.data(), tiled_w, s.mu, L.sets()}};

  const auto array_texture = [&](int unit, int w, int h, const std::vector<float>& texels) {
    GLuint t;
    glGenTextures(1, &t);
    glActiveTexture(GL_TEXTURE0 + unit);
    glBindTexture(GL_TEXTURE_2D_ARRAY, t);
    glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_RGBA32F, w, h, L.sets(), 0, GL_RGBA, GL_FLOAT, texels.data());
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  };
  array_texture(0, s.transmittance_w, s.transmittance_h, L.transmittance);
  array_texture(1, tiled_w, s.mu, L.scattering);
  array_texture(2, tiled_w, s.mu, L.single_mie);

  // The fisheye's view directions (float32, as the GL side gets them) in an RGBA32F texture.
  constexpr int kN = 32;
  std::vector<float> dirs(4 * kN * kN, 0.0f);
  for (int p = 0; p < kN * kN; ++p) {
    Vec3 v;
    // row 0 at the bottom, as gl_FragCoord counts
    if (!fisheye_direction((2.0 * (p % kN) + 1.0) / kN - 1.0, (2.0 * (p / kN) + 1.0) / kN - 1.0, v)) continue;
    for (int c = 0; c < 3; ++c) dirs[4 * p + c] = static_cast<float>(v[c]);
    dirs[4 * p + 3] = 1.0f;
  }
  GLuint in_tex;
  glGenTextures(1, &in_tex);
  glActiveTexture(GL_TEXTURE3);
  glBindTexture(GL_TEXTURE_2D, in_tex);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA32F, kN, kN, 0, GL_RGBA, GL_FLOAT, dirs.data());
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);

  const std::string fs =
      std::string("#version 320 es\nprecision highp float;\nprecision highp sampler2D;\n"
                  "precision highp sampler2DArray;\n") +
      sampling_spectral_glsl(m, L, "test") +
      "uniform sampler2DArray transmittance_texture, scattering_texture, single_mie_texture;\n"
      "uniform sampler2D inputs;\nuniform vec3 sun;\nuniform float camera_h, lambda;\nout vec4 colour;\n"
      "void main() {\n"
      "  vec4 d = texelFetch(inputs, ivec2(gl_FragCoord.xy), 0);\n"
      "  float t = 0.0;\n"
      "  float l = d.w == 0.0 ? 0.0 : GetSkyRadianceAtWavelength(SPECBAKE_ATMOSPHERE, transmittance_texture,\n"
      "      scattering_texture, single_mie_texture, vec3(0.0, 0.0, 1.0), camera_h, d.xyz, 0.0, sun, lambda, t);\n"
      "  colour = vec4(l, t, 0.0, 1.0);\n"
      "}\n";
  std::string log;
  const GLuint prog = specbake::testing::gl_program(specbake::testing::kGlFullScreenVertex, fs, log);
  ASSERT_NE(prog, 0u) << log;
  glUseProgram(prog);
  const std::pair<const char*, int> samplers[] = {
      {"transmittance_texture", 0}, {"scattering_texture", 1}, {"single_mie_texture", 2}, {"inputs", 3}};
  for (const auto& [name, unit] : samplers) glUniform1i(glGetUniformLocation(prog, name), unit);
  const specbake::testing::GlTarget target(kN, kN);
  ASSERT_TRUE(target.complete);

  const double h = f32(0.5);
  const dvec3 sun = f32(glm::normalize(dvec3(std::cos(0.35), 0.0, std::sin(0.35))));
  glUniform3f(glGetUniformLocation(prog, "sun"), float(sun.x), float(sun.y), float(sun.z));
  glUniform1f(glGetUniformLocation(prog, "camera_h"), float(h));
  const auto& lam = L.lambda_nm;
  // inside set 0, across sets 0 → 1, past the stored range (clamped to the last)
  const double lambdas[] = {f32(0.7 * lam[1] + 0.3 * lam[2]), f32(0.5 * (lam[3] + lam[4])), 720.0};
  double worst = 0.0, wrong_worst = 0.0;
  int compared = 0;
  for (double lambda : lambdas) {
    SCOPED_TRACE(lambda);
    glUniform1f(glGetUniformLocation(prog, "lambda"), float(lambda));
    const std::vector<float> px = target.draw();
    std::vector<double> ratio(kN * kN, 0.0), wrong(kN * kN, 0.0);
    parallel_for(kN * kN, [&](long long p) {
      if (dirs[4 * p + 3] == 0.0f) return;
      const dvec3 view(dirs[4 * p], dirs[4 * p + 1], dirs[4 * p + 2]);
      const auto v = host.eval(view, h, sun, lambda);
      const auto b = host.bound(view, h, sun, lambda);
      // a wrong reference must fail: the host at a wavelength a quarter step away
      const auto w = host.eval(view, h, sun, lambda - 0.25 * (lam[1] - lam[0]));
      for (int k = 0; k < 2; ++k) {
        ratio[p] = std::max(ratio[p], std::fabs(px[4 * p + k] - v[k]) / (b[k] + 1e-37));
        wrong[p] = std::max(wrong[p], std::fabs(px[4 * p + k] - w[k]) / (b[k] + 1e-37));
      }
    });
    for (int p = 0; p < kN * kN; ++p) {
      if (dirs[4 * p + 3] == 0.0f) continue;
      ++compared;
      worst = std::max(worst, ratio[p]);
      if (lambda < lam.back()) wrong_worst = std::max(wrong_worst, wrong[p]);
    }
  }
  EXPECT_GT(compared, 3 * 700);
  EXPECT_LE(worst, 1.0) << "|GL - host| / bound";
  EXPECT_GT(wrong_worst, 10.0) << "the host at another wavelength must be told apart";
  std::printf("spectral GL vs host: worst |GL - host| / bound = %.3g over %d pixels; another wavelength: %.3g\n",
              worst, compared, wrong_worst);
#endif
}

}  // namespace
