// The shipped diffraction shader (shader/diffraction_brdf.glsl) run on a real GL implementation:
// Mesa's llvmpipe through EGL surfaceless (GLES 3.2), the table and spectrum uploaded as a shader
// would, the outgoing hemisphere drawn for one light direction and every pixel compared with the
// host's double evaluation of the same BRDF from the same float32 table (BrdfPictures::lobes, what the
// bundle's preview draws). Skipped, with the reason, only when no EGL device can be opened.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "core/colour_space.hpp"
#include "kinds/diffraction/brdf.hpp"
#include "kinds/diffraction/diffraction_job.hpp"
#include "kinds/diffraction/planning.hpp"
#include "kinds/diffraction/reference.hpp"
#include "kinds/diffraction/shader.hpp"
#include "kinds/diffraction/table.hpp"
#include "kinds/diffraction/terms.hpp"

#include "support/gl_context.hpp"
#include "support/testing.hpp"

using namespace specbake;
using namespace specbake::diffraction;

TEST(DiffractionGl, ShippedShaderMatchesTheHostBrdfOnLlvmpipe) {
#ifndef SPECBAKE_HAVE_GL
  GTEST_SKIP() << "built without EGL/GLES headers (Debian: libegl-dev, libgles-dev)";
#else
  SPECBAKE_GL_CONTEXT_OR_SKIP(gl);

  // A sawtooth (asymmetric, so a mirrored lookup would show) 48² field, window L = 3 µm, a 32²
  // power-mapped table, the terms in double then stored as float32 as the bundle stores them.
  DiffractionSpec spec;
  spec.procedural = ProceduralField{ProceduralField::Type::blazed_grating, 48, 0.1, 1.2, 0.25};
  TableSpec ts;
  ts.size = 32;
  ts.power = 3.0;
  ts.power_mapping = true;
  spec.table = ts;
  spec.coherence.length_um = 3.0;
  const Field f = make_field(spec);
  const Plan p = make_plan(spec, f, spec.tolerance);
  const Window w = make_window(f, coherence_length_um(spec) / std::sqrt(2.0));
  const TableGeometry g = table_geometry(spec, 32);
  std::vector<float> values;
  for (const cplx& v : table_terms(f, w, p.bands, g)) {
    values.push_back(static_cast<float>(v.real()));
    values.push_back(static_cast<float>(v.imag()));
  }
  double y_norm = 0;
  const auto spectrum = spectrum_rows(spec.range_nm, y_norm);
  const int layers = p.total_terms, n = g.size, rows = static_cast<int>(spectrum.size() / 4);

  // Textures as docs/diffraction.md ("Use it in an engine") tells an engine to upload them.
  GLuint tex[2];
  glGenTextures(2, tex);
  glBindTexture(GL_TEXTURE_2D_ARRAY, tex[0]);
  glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_RG32F, n, n, layers, 0, GL_RG, GL_FLOAT, values.data());
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  const std::vector<float> spec_rgba(spectrum.begin(), spectrum.end());
  glBindTexture(GL_TEXTURE_2D, tex[1]);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA32F, rows, 1, 0, GL_RGBA, GL_FLOAT, spec_rgba.data());
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  constexpr int kPanel = 64;
  const specbake::testing::GlTarget target(kPanel, kPanel);
  ASSERT_TRUE(target.complete);

  // The light 30° from the normal in the x–z plane; pixel (x, y) ↦ ω_o = (x, y, √(1 − x² − y²)).
  const double light_deg = 30.0;
  const Wavelengths full = every_nm(spectrum, 10), fast = bins(spectrum, 8);
  const std::string glsl = diffraction_glsl(f, p.bands, g, w, 1.5, fast);
  const std::string fs = "#version 320 es\nprecision highp float;\nprecision highp sampler2DArray;\n" + glsl +
                         "uniform sampler2DArray terms;\nuniform sampler2D spectrum;\nuniform int fast;\nout vec4 colour;\n"
                         "void main() {\n"
                         "  vec2 xy = -1.0 + gl_FragCoord.xy * (2.0 / " + std::to_string(kPanel) + ".0);\n"
                         "  float r2 = dot(xy, xy);\n"
                         "  if (r2 >= 1.0) { colour = vec4(0.0); return; }\n"
                         "  float a = radians(" + std::to_string(light_deg) + ");\n"
                         "  vec3 wi = vec3(sin(a), 0.0, cos(a)), wo = vec3(xy, sqrt(1.0 - r2));\n"
                         "  colour = vec4(fast == 2 ? diffraction_srgb_fast_specular(terms, spectrum, wi, wo, 10)\n"
                         "               : fast == 1 ? diffraction_srgb_fast(terms, wi, wo) : diffraction_srgb(terms, spectrum, wi, wo, 10), 1.0);\n"
                         "}\n";
  std::string log;
  const GLuint prog = specbake::testing::gl_program(specbake::testing::kGlFullScreenVertex, fs, log);
  ASSERT_NE(prog, 0u) << log;
  glUseProgram(prog);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D_ARRAY, tex[0]);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D, tex[1]);
  glUniform1i(glGetUniformLocation(prog, "terms"), 0);
  glUniform1i(glGetUniformLocation(prog, "spectrum"), 1);
  const auto draw = [&](int which) {
    glUniform1i(glGetUniformLocation(prog, "fast"), which);
    return target.draw();
  };
  const std::vector<float> pixels_full = draw(0), pixels_fast = draw(1), pixels_specular = draw(2);
  ASSERT_EQ(glGetError(), static_cast<GLenum>(GL_NO_ERROR));

  // The host's evaluation: BrdfPictures::lobes' pixel centres match gl_FragCoord's, its row 0 at the top.
  const BrdfTable t{f, p.bands, g, values, w.sum, 1.5, w.sigma_um};
  // The variant drawn: 0 diffraction_srgb (every 10 nm), 1 diffraction_srgb_fast, 2
  // diffraction_srgb_fast_specular.
  const auto compare = [&](const std::vector<float>& pixels, int variant, const char* what) {
  const Wavelengths& wl = variant == 0 ? full : fast;
  const BrdfPictures pictures(t);
  const auto host = variant == 2 ? pictures.lobes_fast_specular(fast, full, {light_deg}, kPanel)
                                 : pictures.lobes(wl, {light_deg}, kPanel);

  // The bound, per pixel and channel, from the host's own lookups. Per wavelength, with P_i/Σw at
  // the four texels the fetch blends: the filter's weights carry 8 fractional bits (D3D11's
  // minimum, which GL implementations follow; the weight error is at most 2^-9 per axis), so the
  // blend moves by at most δ_f = 2^-8·max|P_i − P_j|; float32 arithmetic (coefficient recurrence,
  // the sum over T terms, the phase) adds at most δ_a = 16·T·u·Σ_n|coef_n·F_n|·W·H/Σw. Then
  // |ρ_gl − ρ| ≤ C·(2A·δ + δ²) + 16u·C·A², A = max|P_i|/Σw, δ = δ_f + δ_a, and through the spectral
  // sum and |XYZ → sRGB| to each channel, plus float32 accumulation over the 41 wavelengths.
  const double u = std::ldexp(1.0, -24), kPi = 3.141592653589793;
  double peak = 0;
  for (float v : host) peak = std::max(peak, static_cast<double>(v));
  ASSERT_GT(peak, 0.0);
  const Mat3 m = xyz_to_srgb();
  const double a = light_deg * kPi / 180.0;
  const double wi[3] = {std::sin(a), 0.0, std::cos(a)};
  double worst = 0, worst_ratio = 0;
  int lit = 0;
  std::vector<float> gl_rgb(3 * kPanel * kPanel), host_rgb(3 * kPanel * kPanel), over_bound(kPanel * kPanel, 0.0f);
  for (int row = 0; row < kPanel; ++row)
    for (int x = 0; x < kPanel; ++x) {
      const double px = -1.0 + (x + 0.5) * 2.0 / kPanel, py = -1.0 + (row + 0.5) * 2.0 / kPanel, r2 = px * px + py * py;
      double dxyz[3] = {0, 0, 0};
      if (r2 < 1.0) {
        const double wo[3] = {px, py, std::sqrt(1.0 - r2)};
        double h[3] = {wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]};
        const double hl = std::sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
        for (double& c : h) c /= hl;
        const double gain = ref::stam_gain(wi[2], wo[2], wi[0] * wo[0] + wi[1] * wo[1] + wi[2] * wo[2],
                                           wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2], 1.5);
        // |P/Σw|² at (fu, fv; κ) and the bound on its GL value's error (gain 1)
        const auto p2_bound = [&](double fu, double fv, double kappa, double& p2) {
          const Band& band = band_for(p.bands, kappa);
          const double tu = std::clamp(g.texel_of(fu), 0.0, n - 1.0), tv = std::clamp(g.texel_of(fv), 0.0, n - 1.0);
          const int u0 = std::min(static_cast<int>(tu), n - 2), v0 = std::min(static_cast<int>(tv), n - 2);
          cplx c[4];
          double amp = 0, spread = 0, mass = 0;
          std::vector<double> coef(band.terms);
          ref::expansion_coefficients(band.expansion == Expansion::taylor ? 0 : 1, kappa, band.kappa0, band.delta, f.s,
                                      band.terms, coef.data());
          for (int k = 0; k < 4; ++k) {
            const int iu = u0 + (k & 1), iv = v0 + (k >> 1);
            c[k] = table_value(values, g, f, band, kappa, iu, iv) / w.sum;
            amp = std::max(amp, std::abs(c[k]));
            double sm = 0;
            for (int n2 = 0; n2 < band.terms; ++n2) {
              const std::size_t at = 2 * ((static_cast<std::size_t>(band.first_term + n2) * n + iv) * n + iu);
              sm += std::fabs(coef[n2]) * std::hypot(values[at], values[at + 1]);
            }
            mass = std::max(mass, sm * static_cast<double>(f.count()) / w.sum);
          }
          for (int k = 0; k < 4; ++k)
            for (int l = 0; l < 4; ++l) spread = std::max(spread, std::abs(c[k] - c[l]));
          const double delta = std::ldexp(spread, -8) + 16.0 * band.terms * u * mass;
          p2 = std::norm(table_bilinear(values, g, f, band, kappa, g.texel_of(fu), g.texel_of(fv)) / w.sum);
          return 2.0 * amp * delta + delta * delta + 16.0 * u * amp * amp;
        };
        const double du = -(wi[0] + wo[0]), dv = -(wi[1] + wo[1]);
        const auto peak_arg = [&](double lambda) {  // G = exp(−arg)
          const double a = 2.0 * kPi * w.sigma_um / lambda;
          return a * a * (du * du + dv * dv);
        };
        const auto reach = [&](double lambda) { return std::fabs(du / lambda) <= g.f_max && std::fabs(dv / lambda) <= g.f_max; };
        const auto add = [&](const std::array<double, 3>& weight, double d) {
          for (int k = 0; k < 3; ++k) dxyz[k] += std::fabs(weight[k]) * d;
        };
        std::vector<double> chi2(wl.lambda_um.size()), dchi2(wl.lambda_um.size());
        for (std::size_t i = 0; i < wl.lambda_um.size(); ++i) {
          const double lambda = wl.lambda_um[i], kappa = 2.0 * kPi * (wi[2] + wo[2]) / lambda;
          double p2 = 0;
          if (reach(lambda)) add(wl.xyz[i], gain * p2_bound(du / lambda, dv / lambda, kappa, p2));
          if (variant != 2) continue;
          // the specular split: |χ|² = |P(0; κ)/Σw|² (its fetch bounded alike) times the peak
          // G = exp(−arg): float32 forms arg within 16 ulps of it (σ/λ, its square, |d|² from the
          // float inputs) and GLSL ES's exp is within (3 + 2|arg|) ulps, so |ΔG| ≤ G·(3 + 18 arg)·u
          dchi2[i] = p2_bound(0.0, 0.0, kappa, chi2[i]);
          const double arg = peak_arg(lambda), peak = reach(lambda) ? ref::specular_peak(du * du + dv * dv, lambda, w.sigma_um) : 0.0;
          add(wl.xyz[i], gain * (dchi2[i] * peak + chi2[i] * peak * (3.0 + 18.0 * arg) * u + 16.0 * u * chi2[i] * peak));
        }
        if (variant == 2) {  // the peak every 10 nm, |χ|² interpolated between the fast wavelengths
          std::size_t k = 0;
          for (std::size_t i = 0; i < full.lambda_um.size(); ++i) {
            const double lambda = full.lambda_um[i];
            while (k + 2 < fast.lambda_um.size() && lambda > fast.lambda_um[k + 1]) ++k;
            if (!reach(lambda)) continue;
            const double peak = ref::specular_peak(du * du + dv * dv, lambda, w.sigma_um), arg = peak_arg(lambda);
            const double c2 = std::max(chi2[k], chi2[k + 1]), dc2 = std::max(dchi2[k], dchi2[k + 1]);
            // the interpolation weight in float32: within 4 ulps, moving the blend by 4u·|χ²_k − χ²_k+1|
            add(full.xyz[i], gain * (dc2 * peak + c2 * peak * (3.0 + 18.0 * arg) * u + 16.0 * u * c2 * peak +
                                     4.0 * u * std::fabs(chi2[k] - chi2[k + 1]) * peak));
          }
        }
      }
      for (int c = 0; c < 3; ++c) {
        const double hv = host[3 * ((kPanel - 1 - row) * kPanel + x) + c], gv = pixels[4 * (row * kPanel + x) + c];
        const double bound = std::fabs(m[3 * c]) * dxyz[0] + std::fabs(m[3 * c + 1]) * dxyz[1] +
                             std::fabs(m[3 * c + 2]) * dxyz[2] + 64.0 * u * peak;
        const double err = std::fabs(gv - hv);
        worst = std::max(worst, err);
        worst_ratio = std::max(worst_ratio, err / bound);
        const std::size_t at = static_cast<std::size_t>(row) * kPanel + x;
        gl_rgb[3 * at + c] = static_cast<float>(gv);
        host_rgb[3 * at + c] = static_cast<float>(hv);
        over_bound[at] = std::max(over_bound[at], static_cast<float>(err / bound));
        lit += hv > 1e-3 * peak;
        EXPECT_LE(err, bound) << what << " pixel (" << x << ", " << row << ") channel " << c << ": GL " << gv << ", host " << hv;
      }
    }
  EXPECT_GT(lit, 50) << what << ": the view must show the pattern";
  specbake::testing::write_gl_figure(
      std::string("diffraction-") + (variant == 0 ? "full" : variant == 1 ? "fast" : "fast-specular"), kPanel, kPanel, gl_rgb,
      host_rgb, over_bound,
      {{"title", std::string(what) + ", light at 30 deg"},
       {"gl", "llvmpipe, GLES 3.2"},
       {"host", "BrdfPictures::lobes in double"},
       {"bound", "|GL - host| / bound, worst channel"}});
  RecordProperty(std::string(what) + "_worst_over_peak", std::to_string(worst / peak));
  RecordProperty(std::string(what) + "_worst_over_bound", std::to_string(worst_ratio));
  };
  compare(pixels_full, 0, "diffraction_srgb");
  compare(pixels_fast, 1, "diffraction_srgb_fast");
  compare(pixels_specular, 2, "diffraction_srgb_fast_specular");
#endif
}
