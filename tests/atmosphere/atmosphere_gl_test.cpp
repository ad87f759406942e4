// The shipped atmosphere shader (sampling.glsl) run on a real GL implementation: Mesa's llvmpipe
// through EGL surfaceless (GLES 3.2). Bruneton's reference Earth textures are uploaded as an
// engine would (RGBA32F, LINEAR, CLAMP_TO_EDGE; the scattering textures both as 3D textures and
// in the tiled 2D layout), the preview views are drawn with GetSkyRadiance,
// GetSkyRadianceToPoint and GetSunAndSkyIrradiance, and every pixel is compared with the host's
// double evaluation of the same shared source (kernels/atmosphere/lookup.cl and render.glsl)
// from the same float32 texels and the same float32 inputs, within a per-pixel bound.
// Skipped, with the reason, only when no EGL device can be opened.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "atmosphere/gl_perturb.hpp"
#include "atmosphere/gl_pixel_bound.hpp"
#include "atmosphere/npy.hpp"
#include "atmosphere/sized.hpp"
#include "core/parallel.hpp"
#include "core/resources.hpp"
#include "kinds/atmosphere/bake/bake.hpp"
#include "kinds/atmosphere/model/model.hpp"
#include "kinds/atmosphere/shader/render.hpp"
#include "kinds/atmosphere/shader/shader_host.hpp"
#include "support/gl_context.hpp"
#include "support/testing.hpp"

using namespace specbake;
using namespace specbake::atmosphere;
using dvec3 = glm::dvec3;

namespace {

std::string ref(const std::string& name) { return (specbake::testing::refdata_dir() / "atmosphere" / name).string(); }

// Bruneton's demo Earth (the reference textures' atmosphere).
Luts reference_earth() {
  AtmosphereSpec spec;
  spec.rayleigh_density[1] = DensityLayer{0, 1, -1.0 / 8.0, 0, 0};
  spec.mie_density[1] = DensityLayer{0, 1, -1.0 / 1.2, 0, 0};
  spec.ozone_density[0] = DensityLayer{25.0, 0, 0, 1.0 / 15.0, -2.0 / 3.0};
  spec.ozone_density[1] = DensityLayer{0, 0, 0, -1.0 / 15.0, 8.0 / 3.0};
  Luts luts;
  luts.model = model_of(spec);
  luts.rgb = channels_at(spec, {kLambdaR, kLambdaG, kLambdaB});
  // Stored as float32 (as a bundle and the GL textures hold them): the host reads the same texels.
  const auto as_float = [](std::vector<double> v) {
    for (double& x : v) x = static_cast<float>(x);
    return v;
  };
  luts.transmittance = as_float(specbake::testing::read_npy(ref("textures/transmittance.npy")).data);
  luts.irradiance = as_float(specbake::testing::read_npy(ref("textures/irradiance.npy")).data);
  luts.scattering = as_float(specbake::testing::read_npy(ref("textures/scattering.npy")).data);
  luts.single_mie = as_float(specbake::testing::read_npy(ref("textures/single_mie_scattering.npy")).data);
  return luts;
}

using specbake::testing::f32;
using specbake::testing::turned;
using namespace specbake::testing::gl_bound;

struct View {
  std::string name;
  dvec3 up, sun;
  double h;
  int n;
  std::vector<Pixel> pixels;  // row 0 at the bottom, as glReadPixels returns them
};

// The preview views (render.hpp: kFisheyeViews, planet_view), the rays rounded to float32 as the
// GL side gets them.
std::vector<View> preview_views(const Model& m, int n) {
  const auto g = [](const Vec3& v) { return dvec3{v[0], v[1], v[2]}; };
  std::vector<View> views;
  for (const FisheyeView& fv : kFisheyeViews) {
    View v{"fisheye sun " + std::to_string(static_cast<int>(fv.sun_elevation_deg)) + " deg", {0, 0, 1},
           f32(g(fisheye_sun(fv))), f32(kFisheyeAltitudeKm), n, {}};
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        Pixel p;
        Vec3 dir{};
        if (fisheye_direction((2.0 * x + 1.0) / n - 1.0, (2.0 * y + 1.0) / n - 1.0, dir)) {
          p.dir = f32(g(dir));
          p.kind = 0;
        }
        v.pixels.push_back(p);
      }
    views.push_back(v);
  }
  const PlanetView pv = planet_view(m);
  const double rb = m.bottom_radius_km;
  const dvec3 camera = g(pv.camera);
  const double dist = glm::length(camera);
  View v{"planet from space", f32(camera / dist), f32(g(pv.sun)), f32(dist - rb), n, {}};
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const dvec3 view = g(pv.direction((2.0 * x + 1.0) / n - 1.0, (2.0 * y + 1.0) / n - 1.0));
      const double b = glm::dot(camera, view), disc = b * b - (dist * dist - rb * rb);
      Pixel p;
      p.kind = 0;
      p.dir = f32(view);
      if (disc >= 0.0 && -b - std::sqrt(disc) > 0.0) {
        const dvec3 point = camera + (-b - std::sqrt(disc)) * view;
        p.kind = 1;
        p.dir = f32(point - camera);
        p.p_up = f32(glm::normalize(point));
        p.p_h = f32(std::max(0.0, glm::length(point) - rb));
      }
      v.pixels.push_back(p);
    }
  views.push_back(v);
  return views;
}

#ifdef SPECBAKE_HAVE_GL
GLuint texture_2d(int w, int h, const std::vector<double>& rgb, GLenum filter) {
  std::vector<float> rgba(4 * static_cast<std::size_t>(w) * h, 0.0f);
  for (std::size_t i = 0; i < rgba.size() / 4; ++i)
    for (int c = 0; c < 3; ++c) rgba[4 * i + c] = static_cast<float>(rgb[3 * i + c]);
  GLuint t;
  glGenTextures(1, &t);
  glBindTexture(GL_TEXTURE_2D, t);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA32F, w, h, 0, GL_RGBA, GL_FLOAT, rgba.data());
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, filter);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, filter);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  return t;
}
GLuint texture_3d(int w, int h, int d, const std::vector<double>& values, int channels = 3) {
  std::vector<float> rgba(4 * static_cast<std::size_t>(w) * h * d, 1.0f);
  for (std::size_t i = 0; i < rgba.size() / 4; ++i)
    for (int c = 0; c < channels; ++c) rgba[4 * i + c] = static_cast<float>(values[channels * i + c]);
  GLuint t;
  glGenTextures(1, &t);
  glBindTexture(GL_TEXTURE_3D, t);
  glTexImage3D(GL_TEXTURE_3D, 0, GL_RGBA32F, w, h, d, 0, GL_RGBA, GL_FLOAT, rgba.data());
  glTexParameteri(GL_TEXTURE_3D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_3D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  for (GLenum wrap : {GL_TEXTURE_WRAP_S, GL_TEXTURE_WRAP_T, GL_TEXTURE_WRAP_R})
    glTexParameteri(GL_TEXTURE_3D, wrap, GL_CLAMP_TO_EDGE);
  return t;
}
#endif

}  // namespace

// The shader carries the shared source as written: the host's evaluation is the shader's code.
TEST(AtmosphereGl, SamplingGlslCarriesTheSharedSourceVerbatim) {
  const Luts luts = reference_earth();
  const std::string glsl = sampling_glsl(luts.model, luts.rgb, true, true, "test");
  for (const char* path : {"kernels/atmosphere/lookup.cl", "kernels/atmosphere/render.glsl"}) {
    std::string text(specbake::resource(path)), body;
    std::size_t at = 0;
    while (at < text.size()) {  // its lines but the #include ones
      const std::size_t end = text.find('\n', at);
      const std::string line = text.substr(at, end - at + 1);
      if (line.rfind("#include ", 0) != 0) body += line;
      at = end == std::string::npos ? text.size() : end + 1;
    }
    EXPECT_NE(glsl.find(body), std::string::npos) << path << " is not in sampling.glsl verbatim";
  }
}

// The light-shaft parameter (shadow_length: the first km of the ray left out), on the host's
// evaluation of the shared text: continuous with the no-shadow branch, more shadow means less
// light, and a shadow over the whole segment leaves none.
TEST(AtmosphereGl, ShadowLengthLeavesOutTheNearestScattering) {
  const Luts luts = reference_earth();
  const Model& m = luts.model;
  const Sizes& s = m.sizes;
  const auto atm = glsl::atmosphere_of(m, luts.rgb);
  const glsl::sampler2D T{luts.transmittance.data(), s.transmittance_w, s.transmittance_h};
  const glsl::sampler3D S{luts.scattering.data(), s.scattering_width(), s.mu, s.r};
  const glsl::sampler3D M{luts.single_mie.data(), s.scattering_width(), s.mu, s.r};
  const dvec3 up{0, 0, 1}, sun = glm::normalize(dvec3{1, 0, 0.5});
  for (const dvec3 view : {glm::normalize(dvec3{0.2, 0.1, 1.0}), glm::normalize(dvec3{1.0, 0.3, 0.05})}) {
    dvec3 t;
    const dvec3 l0 = glsl::GetSkyRadiance(atm, T, S, M, up, 0.5, view, 0.0, sun, t);
    // 1 mm of shadow: the shadowed branch (a lookup a distance along the ray, times T) agrees with
    // the plain one to the light scattered in that millimetre and the lookups' rounding
    const dvec3 l_eps = glsl::GetSkyRadiance(atm, T, S, M, up, 0.5, view, 1e-6, sun, t);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(l_eps[c], l0[c], 1e-6 * l0[c]) << c;
    dvec3 previous = l0;
    for (double shadow : {1.0, 5.0, 20.0}) {
      const dvec3 l = glsl::GetSkyRadiance(atm, T, S, M, up, 0.5, view, shadow, sun, t);
      for (int c = 0; c < 3; ++c) EXPECT_LT(l[c], previous[c]) << "shadow " << shadow << " km, channel " << c;
      previous = l;
    }
    // to a point 10 km away with all 10 km in shadow: S − T·S at the camera itself, nothing left
    const dvec3 to_point = 10.0 * view;
    const dvec3 lp0 = glsl::GetSkyRadianceToPoint(atm, T, S, M, up, 0.5, to_point, 0.0, sun, t);
    const dvec3 lp = glsl::GetSkyRadianceToPoint(atm, T, S, M, up, 0.5, to_point, 10.0, sun, t);
    for (int c = 0; c < 3; ++c) {
      EXPECT_GT(lp0[c], 0.0);
      EXPECT_LE(std::fabs(lp[c]), 1e-12 * l0[c]) << c;
    }
  }
}

TEST(AtmosphereGl, ShippedSamplingMatchesTheHostOnLlvmpipe) {
#ifndef SPECBAKE_HAVE_GL
  GTEST_SKIP() << "built without EGL/GLES headers (Debian: libegl-dev, libgles-dev)";
#else
  SPECBAKE_GL_CONTEXT_OR_SKIP(gl);

  const Luts luts = reference_earth();
  const Model& m = luts.model;
  const Sizes& s = m.sizes;
  GLint max_2d = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_2d);
  ASSERT_GE(max_2d, s.r * s.scattering_width()) << "the tiled 2D layout's width";

  constexpr int kN = 48;
  const std::vector<View> views = preview_views(m, kN);
  const std::vector<double> combined = combined_texture(luts);
  const Host host = host_of(luts, combined);

  // Textures: units 0 transmittance, 1 irradiance, 2/3 scattering and single Mie 3D, 4/5 the same
  // tiled 2D, 6 the pixels' inputs (dir, kind), 7 the ground points (p_up, p_h), 8 the combined 3D.
  const GLuint t_tex = texture_2d(s.transmittance_w, s.transmittance_h, luts.transmittance, GL_LINEAR);
  const GLuint e_tex = texture_2d(s.irradiance_w, s.irradiance_h, luts.irradiance, GL_LINEAR);
  const GLuint s_tex = texture_3d(s.scattering_width(), s.mu, s.r, luts.scattering);
  const GLuint m_tex = texture_3d(s.scattering_width(), s.mu, s.r, luts.single_mie);
  const GLuint s_tiled =
      texture_2d(s.r * s.scattering_width(), s.mu, to_tiled2d(luts.scattering, s), GL_LINEAR);
  const GLuint m_tiled =
      texture_2d(s.r * s.scattering_width(), s.mu, to_tiled2d(luts.single_mie, s), GL_LINEAR);
  const GLuint units[] = {t_tex, e_tex};
  for (int u = 0; u < 2; ++u) {
    glActiveTexture(GL_TEXTURE0 + u);
    glBindTexture(GL_TEXTURE_2D, units[u]);
  }
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_3D, s_tex);
  glActiveTexture(GL_TEXTURE3);
  glBindTexture(GL_TEXTURE_3D, m_tex);
  glActiveTexture(GL_TEXTURE4);
  glBindTexture(GL_TEXTURE_2D, s_tiled);
  glActiveTexture(GL_TEXTURE5);
  glBindTexture(GL_TEXTURE_2D, m_tiled);
  const GLuint c_tex = texture_3d(s.scattering_width(), s.mu, s.r, combined, 4);
  glActiveTexture(GL_TEXTURE8);
  glBindTexture(GL_TEXTURE_3D, c_tex);

  const std::string glsl = sampling_glsl(m, luts.rgb, true, true, "test");
  const auto program = [&](bool tiled) {
    const std::string fs =
        std::string("#version 320 es\nprecision highp float;\nprecision highp sampler2D;\nprecision highp sampler3D;\n") +
        (tiled ? "#define SPECBAKE_SCATTERING_TILED2D\n" : "") + glsl +
        "uniform sampler2D transmittance_texture, irradiance_texture, inputs, points;\n"
        "uniform SpecbakeScatteringSampler scattering_texture, single_mie_texture;\n"
        "uniform sampler3D combined_texture;\n"
        "uniform vec3 camera_up, sun;\nuniform float camera_h;\nuniform int part;\nout vec4 colour;\n"
        "void main() {\n"
        "  ivec2 p = ivec2(gl_FragCoord.xy);\n"
        "  vec4 d = texelFetch(inputs, p, 0);\n"
        "  vec3 v[6] = vec3[6](vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0));\n"
        "  if (d.w == 0.0) {\n"
        "    v[0] = GetSkyRadiance(SPECBAKE_ATMOSPHERE, transmittance_texture, scattering_texture, single_mie_texture,\n"
        "                          camera_up, camera_h, d.xyz, 0.0, sun, v[1]);\n"
        "    if (camera_h < SPECBAKE_ATMOSPHERE.top_radius - SPECBAKE_ATMOSPHERE.bottom_radius) {\n"
        "      float mu = clamp(dot(camera_up, d.xyz), -1.0, 1.0);\n"
        "      v[4] = GetCombinedScattering3D(SPECBAKE_ATMOSPHERE, combined_texture, camera_h, mu,\n"
        "                                     clamp(dot(camera_up, sun), -1.0, 1.0), clamp(dot(d.xyz, sun), -1.0, 1.0),\n"
        "                                     ray_meets_ground(SPECBAKE_ATMOSPHERE.bottom_radius, camera_h, mu), v[5]);\n"
        "    }\n"
        "  } else if (d.w == 1.0) {\n"
        "    v[0] = GetSkyRadianceToPoint(SPECBAKE_ATMOSPHERE, transmittance_texture, scattering_texture,\n"
        "                                 single_mie_texture, camera_up, camera_h, d.xyz, 0.0, sun, v[1]);\n"
        "    vec4 q = texelFetch(points, p, 0);\n"
        "    v[2] = GetSunAndSkyIrradiance(SPECBAKE_ATMOSPHERE, transmittance_texture, irradiance_texture, q.xyz, q.w,\n"
        "                                  q.xyz, sun, v[3]);\n"
        "  }\n"
        "  colour = vec4(v[part], 1.0);\n"
        "}\n";
    std::string log;
    const GLuint prog = specbake::testing::gl_program(specbake::testing::kGlFullScreenVertex, fs, log);
    EXPECT_NE(prog, 0u) << log;
    glUseProgram(prog);
    const std::pair<const char*, int> samplers[] = {{"transmittance_texture", 0}, {"irradiance_texture", 1},
                                                    {"scattering_texture", tiled ? 4 : 2},
                                                    {"single_mie_texture", tiled ? 5 : 3}, {"inputs", 6}, {"points", 7},
                                                    {"combined_texture", 8}};
    for (const auto& [name, unit] : samplers) glUniform1i(glGetUniformLocation(prog, name), unit);
    return prog;
  };
  const GLuint progs[2] = {program(false), program(true)};
  ASSERT_NE(progs[0], 0u);
  ASSERT_NE(progs[1], 0u);
  const specbake::testing::GlTarget target(kN, kN);
  ASSERT_TRUE(target.complete);

  const char* part_names[kParts] = {"radiance",       "transmittance",       "sun irradiance",
                                   "sky irradiance", "combined scattering", "combined single Mie"};
  double worst_ratio[2] = {0, 0};
  std::vector<Out> previous_host;  // the previous view's host values: a wrong reference must fail
  double wrong_view_ratio = 0;
  for (const View& view : views) {
    std::vector<double> in(4 * view.pixels.size()), pts(4 * view.pixels.size());
    for (std::size_t i = 0; i < view.pixels.size(); ++i) {
      const Pixel& p = view.pixels[i];
      for (int c = 0; c < 3; ++c) {
        in[4 * i + c] = p.dir[c];
        pts[4 * i + c] = p.p_up[c];
      }
      in[4 * i + 3] = p.kind;
      pts[4 * i + 3] = p.p_h;
    }
    const auto rgba_texture = [&](const std::vector<double>& v, int unit) {
      std::vector<float> f(v.begin(), v.end());
      GLuint t;
      glGenTextures(1, &t);
      glActiveTexture(GL_TEXTURE0 + unit);
      glBindTexture(GL_TEXTURE_2D, t);
      glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA32F, kN, kN, 0, GL_RGBA, GL_FLOAT, f.data());
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
      return t;
    };
    const GLuint in_tex = rgba_texture(in, 6), pts_tex = rgba_texture(pts, 7);

    // The host: value and bound per pixel.
    std::vector<Out> value(view.pixels.size()), bound(view.pixels.size());
    parallel_for(static_cast<long long>(view.pixels.size()), [&](long long i) {
      value[i] = host.eval(view.up, view.h, view.sun, view.pixels[i]);
      bound[i] = bound_of(host, view.up, view.h, view.sun, view.pixels[i], value[i]);
    });

    std::vector<float> gl_parts[kParts];  // the 3D program's outputs, for the docs' figure
    std::vector<float> over_bound(view.pixels.size(), 0.0f);
    for (int tiled = 0; tiled < 2; ++tiled) {
      glUseProgram(progs[tiled]);
      glUniform3f(glGetUniformLocation(progs[tiled], "camera_up"), view.up.x, view.up.y, view.up.z);
      glUniform3f(glGetUniformLocation(progs[tiled], "sun"), view.sun.x, view.sun.y, view.sun.z);
      glUniform1f(glGetUniformLocation(progs[tiled], "camera_h"), view.h);
      for (int part = 0; part < kParts; ++part) {
        glUniform1i(glGetUniformLocation(progs[tiled], "part"), part);
        const std::vector<float> px = target.draw();
        ASSERT_EQ(glGetError(), static_cast<GLenum>(GL_NO_ERROR));
        if (!tiled) gl_parts[part] = px;
        int failures = 0;
        for (std::size_t i = 0; i < view.pixels.size(); ++i)
          for (int c = 0; c < 3; ++c) {
            const double got = px[4 * i + c], want = value[i].v[part][c], b = bound[i].v[part][c];
            ASSERT_TRUE(std::isfinite(got)) << view.name << " pixel " << i;
            const double ratio = std::fabs(got - want) / std::max(b, 1e-30);
            if (got != want) worst_ratio[tiled] = std::max(worst_ratio[tiled], ratio);
            if (!tiled && got != want) over_bound[i] = std::max(over_bound[i], static_cast<float>(ratio));
            if (std::fabs(got - want) > b && failures++ < 5)
              ADD_FAILURE() << view.name << (tiled ? " (tiled 2D)" : " (3D)") << ", " << part_names[part] << ", pixel ("
                            << i % kN << ", " << i / kN << ") channel " << c << ": GL " << got << ", host " << want
                            << ", bound " << b;
            if (!tiled && part == 0 && !previous_host.empty() && want > 0)
              wrong_view_ratio =
                  std::max(wrong_view_ratio, std::fabs(got - previous_host[i].v[0][c]) / std::max(b, 1e-30));
          }
      }
    }
    if (view.name == "fisheye sun 20 deg" || view.name == "planet from space") {
      // What the preview shows: sky radiance, and at ground points the Lambertian ground
      // (albedo 0.1) lit by sun and sky seen through the atmosphere plus the light scattered in.
      std::vector<float> gl_rgb(3 * view.pixels.size()), host_rgb(3 * view.pixels.size());
      for (std::size_t i = 0; i < view.pixels.size(); ++i)
        for (int c = 0; c < 3; ++c) {
          const auto shade = [&](double l, double t, double e_sun, double e_sky) {
            return view.pixels[i].kind == 1 ? 0.1 / M_PI * (e_sun + e_sky) * t + l : l;
          };
          gl_rgb[3 * i + c] = static_cast<float>(shade(gl_parts[0][4 * i + c], gl_parts[1][4 * i + c],
                                                       gl_parts[2][4 * i + c], gl_parts[3][4 * i + c]));
          host_rgb[3 * i + c] = static_cast<float>(
              shade(value[i].v[0][c], value[i].v[1][c], value[i].v[2][c], value[i].v[3][c]));
        }
      specbake::testing::write_gl_figure(
          view.name == "planet from space" ? "atmosphere-planet" : "atmosphere-fisheye-20",
          kN, kN, gl_rgb, host_rgb, over_bound,
          {{"title", view.name},
           {"gl", "llvmpipe, GLES 3.2, 3D textures"},
           {"host", "render.glsl in double"},
           {"bound", "|GL - host| / bound, worst of every output checked, worst channel"}});
    }
    previous_host = value;
    glDeleteTextures(1, &in_tex);
    glDeleteTextures(1, &pts_tex);
  }
  std::printf("worst |GL - host| / bound: 3D %.3g, tiled 2D %.3g; against the previous view's host values %.3g\n",
              worst_ratio[0], worst_ratio[1], wrong_view_ratio);
  // The comparison can fail: the host values of another view (another sun) are far outside it.
  EXPECT_GT(wrong_view_ratio, 100.0);
#endif
}

// The sky-view table through sampling.glsl's GetSkyRadianceWithSkyView on llvmpipe against the
// host's double evaluation of the same text, within the per-pixel bound of the test above
// (gl_pixel_bound.hpp: the filter's 8-bit subtexel coordinates for every fetch, float32 geometry
// and values). A small bake of a twilight scene (double reference, stored as float32), its table
// uploaded as an engine would (RGBA32F 3D, LINEAR, CLAMP_TO_EDGE), fisheyes from the ground with
// the sun 3° and 7° below the horizon (in the table) and 20° above it (the 4D textures).
TEST(AtmosphereGl, SkyViewTableMatchesTheHostOnLlvmpipe) {
#ifndef SPECBAKE_HAVE_GL
  GTEST_SKIP() << "built without EGL/GLES headers (Debian: libegl-dev, libgles-dev)";
#else
  SPECBAKE_GL_CONTEXT_OR_SKIP(gl);
  AtmosphereSpec spec;
  set_earth_profiles(spec);
  spec.scene.sun_elevation_min_deg = -9.0;
  spec.sky_view = AtmosphereSpec::SkyViewMode::sized;
  spec.sky_view_altitude = 3;
  spec.sky_view_sun = 9;
  spec.sky_view_view = 32;
  spec.sky_view_azimuth = 9;
  spec.orders = 3;
  spec = specbake::testing::sized(spec, {64, 16}, {32, 8}, {8, 32, 16, 4});
  Luts luts = bake_luts_reference(spec).luts;
  for (auto* v : {&luts.transmittance, &luts.irradiance, &luts.scattering, &luts.single_mie, &luts.sky_view,
                  &luts.sky_view_mie})
    for (double& x : *v) x = static_cast<float>(x);
  const Model& m = luts.model;
  const Sizes& s = m.sizes;
  const SkyView& sv = m.sky_view;
  ASSERT_TRUE(sv.on());
  const std::vector<double> combined = combined_texture(luts);
  Host host = host_of(luts, combined);
  host.sky_view = glsl::sky_view_samplers(luts);
  ASSERT_TRUE(host.sky_view.on);

  const GLuint textures[] = {texture_2d(s.transmittance_w, s.transmittance_h, luts.transmittance, GL_LINEAR),
                             texture_3d(s.scattering_width(), s.mu, s.r, luts.scattering),
                             texture_3d(s.scattering_width(), s.mu, s.r, luts.single_mie),
                             texture_3d(sv.azimuth, sv.view, sv.sun * sv.altitude, luts.sky_view),
                             texture_3d(sv.azimuth, sv.view, sv.sun * sv.altitude, luts.sky_view_mie)};
  for (int u = 0; u < 5; ++u) {
    glActiveTexture(GL_TEXTURE0 + u);
    glBindTexture(u == 0 ? GL_TEXTURE_2D : GL_TEXTURE_3D, textures[u]);
  }
  const std::string fs =
      std::string("#version 320 es\nprecision highp float;\nprecision highp sampler2D;\nprecision highp sampler3D;\n") +
      sampling_glsl(m, luts.rgb, true, false, "test") +
      "uniform sampler2D transmittance_texture, inputs;\n"
      "uniform sampler3D scattering_texture, single_mie_texture, sky_view_texture, sky_view_mie_texture;\n"
      "uniform vec3 camera_up, sun;\nuniform float camera_h;\nuniform int part;\nout vec4 colour;\n"
      "void main() {\n"
      "  vec4 d = texelFetch(inputs, ivec2(gl_FragCoord.xy), 0);\n"
      "  vec3 v[2] = vec3[2](vec3(0.0), vec3(0.0));\n"
      "  if (d.w == 0.0)\n"
      "    v[0] = GetSkyRadianceWithSkyView(SPECBAKE_ATMOSPHERE, SPECBAKE_SKY_VIEW, transmittance_texture,\n"
      "                                     scattering_texture, single_mie_texture, sky_view_texture,\n"
      "                                     sky_view_mie_texture, camera_up, camera_h, d.xyz, sun, v[1]);\n"
      "  colour = vec4(v[part], 1.0);\n"
      "}\n";
  std::string log;
  const GLuint prog = specbake::testing::gl_program(specbake::testing::kGlFullScreenVertex, fs, log);
  ASSERT_NE(prog, 0u) << log;
  glUseProgram(prog);
  const std::pair<const char*, int> samplers[] = {{"transmittance_texture", 0}, {"scattering_texture", 1},
                                                  {"single_mie_texture", 2},    {"sky_view_texture", 3},
                                                  {"sky_view_mie_texture", 4},  {"inputs", 6}};
  for (const auto& [name, unit] : samplers) glUniform1i(glGetUniformLocation(prog, name), unit);
  constexpr int kN = 32;
  const specbake::testing::GlTarget target(kN, kN);
  ASSERT_TRUE(target.complete);

  double worst = 0.0, table_vs_4d = 0.0;
  for (double sun_elevation : {-3.0, -7.0, 20.0}) {
    const double e = sun_elevation * M_PI / 180.0;
    const dvec3 up{0, 0, 1}, sun = f32(dvec3{std::cos(e), 0.0, std::sin(e)});
    const double h = f32(kFisheyeAltitudeKm);
    std::vector<Pixel> pixels(kN * kN);
    std::vector<double> in(4 * pixels.size(), 0.0);
    for (int y = 0; y < kN; ++y)
      for (int x = 0; x < kN; ++x) {
        Vec3 dir{};
        Pixel& p = pixels[y * kN + x];
        if (fisheye_direction((2.0 * x + 1.0) / kN - 1.0, (2.0 * y + 1.0) / kN - 1.0, dir)) {
          p.dir = f32(dvec3{dir[0], dir[1], dir[2]});
          p.kind = 0;
        }
        for (int c = 0; c < 3; ++c) in[4 * (y * kN + x) + c] = p.dir[c];
        in[4 * (y * kN + x) + 3] = p.kind;
      }
    const std::vector<float> f(in.begin(), in.end());
    GLuint in_tex;
    glGenTextures(1, &in_tex);
    glActiveTexture(GL_TEXTURE6);
    glBindTexture(GL_TEXTURE_2D, in_tex);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA32F, kN, kN, 0, GL_RGBA, GL_FLOAT, f.data());
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glUniform3f(glGetUniformLocation(prog, "camera_up"), up.x, up.y, up.z);
    glUniform3f(glGetUniformLocation(prog, "sun"), sun.x, sun.y, sun.z);
    glUniform1f(glGetUniformLocation(prog, "camera_h"), h);
    std::vector<Out> value(pixels.size()), bound(pixels.size());
    parallel_for(static_cast<long long>(pixels.size()), [&](long long i) {
      value[i] = host.eval(up, h, sun, pixels[i]);
      bound[i] = bound_of(host, up, h, sun, pixels[i], value[i]);
      if (pixels[i].kind == 0 && sun_elevation < 0.0) {  // the table is read: it differs from the 4D textures
        Host plain = host;
        plain.sky_view.on = false;
        const Out v4 = plain.eval(up, h, sun, pixels[i]);
        for (int c = 0; c < 3; ++c)
          if (value[i].v[0][c] > 0.0)
            table_vs_4d = std::max(table_vs_4d, std::fabs(v4.v[0][c] - value[i].v[0][c]) / std::max(bound[i].v[0][c], 1e-30));
      }
    });
    for (int part = 0; part < 2; ++part) {
      glUniform1i(glGetUniformLocation(prog, "part"), part);
      const std::vector<float> px = target.draw();
      ASSERT_EQ(glGetError(), static_cast<GLenum>(GL_NO_ERROR));
      int failures = 0;
      for (std::size_t i = 0; i < pixels.size(); ++i)
        for (int c = 0; c < 3; ++c) {
          const double got = px[4 * i + c], want = value[i].v[part][c], b = bound[i].v[part][c];
          ASSERT_TRUE(std::isfinite(got));
          if (got != want) worst = std::max(worst, std::fabs(got - want) / std::max(b, 1e-30));
          if (std::fabs(got - want) > b && failures++ < 5)
            ADD_FAILURE() << "sun " << sun_elevation << " deg, part " << part << ", pixel (" << i % kN << ", "
                          << i / kN << ") channel " << c << ": GL " << got << ", host " << want << ", bound " << b;
        }
    }
    glDeleteTextures(1, &in_tex);
  }
  std::printf("sky view: worst |GL - host| / bound %.3g; the 4D textures' values against the bound %.3g\n", worst,
              table_vs_4d);
  // The comparison can fail: below the horizon the 4D textures' values lie far outside the bound.
  EXPECT_GT(table_vs_4d, 100.0);
  glDeleteTextures(5, textures);
#endif
}
