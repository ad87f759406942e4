#pragma once
// The atmosphere GL tests' per-pixel comparison: one pixel's float32 inputs, the outputs checked,
// the host's double evaluation of the shipped shader's functions (kinds/atmosphere/shader/shader_host.hpp)
// and the bound on |GL − host| (bound_of). Used by the llvmpipe GL test and by the report page's
// WebGL check (tests/report/sky_host.cpp).
#include <cmath>
#include <vector>

#include <glm/glm.hpp>

#include "atmosphere/gl_perturb.hpp"
#include "kinds/atmosphere/shader/shader_host.hpp"

namespace specbake::testing::gl_bound {
// Internal linkage, as the shader functions' host copies it holds (shader_host.hpp): each
// includer (one test binary) gets its own.
namespace {

using dvec3 = glm::dvec3;
namespace glsl = specbake::atmosphere::glsl;
using specbake::testing::f32;
using specbake::testing::turned;

// One pixel's inputs, as the GL side gets them (float32): kind 0 a sky ray along `dir`, kind 1 a
// ground point `dir` km from the camera with its local vertical p_up at altitude p_h, kind −1
// nothing (outside a fisheye's circle).
struct Pixel {
  dvec3 dir{0.0};
  double kind = -1;
  dvec3 p_up{0.0};
  double p_h = 0;
};
// The outputs a pixel is checked on: radiance, transmittance, at ground points the sun and sky
// irradiance (what the planet preview shades the ground with), and for sky rays the combined
// texture's lookup (`rgba-combined`): its scattering and the rebuilt single Mie.
constexpr int kParts = 6;
struct Out {
  dvec3 v[kParts] = {dvec3(0.0), dvec3(0.0), dvec3(0.0), dvec3(0.0), dvec3(0.0), dvec3(0.0)};
};
struct Host {
  glsl::SpecbakeAtmosphere atm;
  glsl::sampler2D transmittance, irradiance;
  glsl::sampler3D scattering, single_mie, combined;
  // with a sky-view table (sky_view.on), a sky ray's radiance comes from GetSkyRadianceWithSkyView
  glsl::SkyViewSamplers sky_view;
  Out eval(const dvec3& up, double h, const dvec3& sun, const Pixel& p) const {
    Out o;
    if (p.kind == 0) {
      o.v[0] = sky_view.on ? glsl::GetSkyRadianceWithSkyView(atm, sky_view.grid, transmittance, scattering, single_mie,
                                                             sky_view.radiance, sky_view.single_mie, up, h, p.dir,
                                                             sun, o.v[1])
                            : glsl::GetSkyRadiance(atm, transmittance, scattering, single_mie, up, h, p.dir, 0.0, sun,
                                                   o.v[1]);
      if (h < atm.top_radius - atm.bottom_radius) {  // the ray as GetSkyRadiance sees it from inside
        const double mu = glsl::clamp_cosine(glm::dot(up, p.dir));
        o.v[4] = glsl::GetCombinedScattering3D(atm, combined, h, mu, glsl::clamp_cosine(glm::dot(up, sun)),
                                               glsl::clamp_cosine(glm::dot(p.dir, sun)),
                                               glsl::ray_meets_ground(atm.bottom_radius, h, mu), o.v[5]);
      }
    } else if (p.kind == 1) {
      o.v[0] = glsl::GetSkyRadianceToPoint(atm, transmittance, scattering, single_mie, up, h, p.dir, 0.0, sun, o.v[1]);
      o.v[2] = glsl::GetSunAndSkyIrradiance(atm, transmittance, irradiance, p.p_up, p.p_h, p.p_up, sun, o.v[3]);
    }
    return o;
  }
  Host with(glsl::FilterProbe* probe) const {
    Host h = *this;
    h.transmittance.probe = h.irradiance.probe = h.scattering.probe = h.single_mie.probe = h.combined.probe = probe;
    h.sky_view.radiance.probe = h.sky_view.single_mie.probe = probe;
    return h;
  }
};

// The combined texture (RGB scattering, alpha single Mie red), as scattering.ktx2 holds it.
std::vector<double> combined_texture(const atmosphere::Luts& luts) {
  std::vector<double> combined(luts.scattering.size() / 3 * 4);
  for (std::size_t i = 0; i < luts.scattering.size() / 3; ++i) {
    for (int c = 0; c < 3; ++c) combined[4 * i + c] = luts.scattering[3 * i + c];
    combined[4 * i + 3] = luts.single_mie[3 * i];
  }
  return combined;
}
// The host evaluation of a bundle's textures (`combined`: combined_texture(luts), kept alive).
Host host_of(const atmosphere::Luts& luts, const std::vector<double>& combined) {
  const auto& s = luts.model.sizes;
  return Host{glsl::atmosphere_of(luts.model, luts.rgb),
              {luts.transmittance.data(), s.transmittance_w, s.transmittance_h},
              {luts.irradiance.data(), s.irradiance_w, s.irradiance_h},
              {luts.scattering.data(), s.scattering_width(), s.mu, s.r},
              {luts.single_mie.data(), s.scattering_width(), s.mu, s.r},
              {combined.data(), s.scattering_width(), s.mu, s.r, nullptr, 4}};
}

// The per-pixel bound on |GL − host|, per output and channel, as three terms:
//  - filtering: GL implementations resolve texel coordinates to 8 fractional bits (D3D11's
//    minimum, which GL implementations follow), so each fetch may blend as if its coordinate were
//    off by up to 2^-9 texel along each axis. The host moves each coordinate of each fetch by
//    ±2^-9 texel, one at a time, and adds the larger change of each (first order: each fetch is
//    piecewise linear in its coordinate). Where a fetch sits on a texel centre at the edge of a
//    nu slice or r layer, this includes the neighbouring slice's texel, which may be far brighter.
//  - float32 arithmetic on the geometry: every mu, mu_s, nu, altitude and texture coordinate the
//    shader derives comes from dot products, square roots, divisions and the altitude-based
//    forms of lookup.cl (no cancelling differences: its header), a chain of ≤ 5 operations per
//    quantity from the inputs, each within 3 ulps (GLSL ES 3.20's highp bounds for sqrt and
//    division; the others are correctly rounded), so within 15 ulps of its double value. The host
//    turns each input direction by 16 ulps (2^-20 rad) both ways about two axes, scales each
//    altitude and distance by 1 ± 2^-20, and adds the largest change per input: the first-order
//    effect of an error of that size on each. This also covers rays the float32 ground test may
//    classify either way (the change is then the jump between the two halves of the texture).
//  - float32 arithmetic on the values: ~20 operations from texel to result, each within 3 ulps:
//    60 ulps, taken as 64·2^-24 relative.
// The tiled 2D program is held to the same bound: it fetches the same texels with the same x and
// y coordinates (2D bilinear, whose coordinate rounding the 3D probe's x and y shifts cover) and
// interpolates r and nu in shader arithmetic (the 64-ulp term) instead of the filter; the two
// layouts' values agree to 1e-12 of the texture's scale in double (AtmosphereDevice.Tiled2dSamplesEqual3d).
Out bound_of(const Host& host, const dvec3& up, double h, const dvec3& sun, const Pixel& p, const Out& value) {
  Out b;
  // adds the largest change among `outs` (one input moved each way) to the bound
  const auto add_max = [&](const std::vector<Out>& outs) {
    Out m;
    for (const Out& o : outs)
      for (int k = 0; k < kParts; ++k) m.v[k] = glm::max(m.v[k], glm::abs(o.v[k] - value.v[k]));
    for (int k = 0; k < kParts; ++k) b.v[k] += m.v[k];
  };
  // filtering
  glsl::FilterProbe count;
  host.with(&count).eval(up, h, sun, p);
  for (int fetch = 0; fetch < count.fetches; ++fetch)
    for (int axis = 0; axis < 3; ++axis) {
      std::vector<Out> moved;
      for (double shift : {std::ldexp(1.0, -9), -std::ldexp(1.0, -9)}) {
        glsl::FilterProbe probe{0, fetch, axis, shift};
        moved.push_back(host.with(&probe).eval(up, h, sun, p));
      }
      add_max(moved);
    }
  // geometry
  const double e = std::ldexp(1.0, -20);
  std::vector<Out> outs;
  for (const dvec3& u2 : turned(up, e)) outs.push_back(host.eval(u2, h, sun, p));
  add_max(outs);
  outs.clear();
  for (double s : {1.0 + e, 1.0 - e}) outs.push_back(host.eval(up, h * s, sun, p));
  add_max(outs);
  outs.clear();
  for (const dvec3& s2 : turned(sun, e)) outs.push_back(host.eval(up, h, s2, p));
  add_max(outs);
  outs.clear();
  const double len = glm::length(p.dir);
  for (const dvec3& d2 : turned(p.dir / len, e)) {
    Pixel q = p;
    q.dir = d2 * len;
    outs.push_back(host.eval(up, h, sun, q));
  }
  for (double s : {1.0 + e, 1.0 - e}) {
    Pixel q = p;
    q.dir = p.dir * s;
    outs.push_back(host.eval(up, h, sun, q));
  }
  add_max(outs);
  if (p.kind == 1) {
    outs.clear();
    for (const dvec3& u2 : turned(p.p_up, e)) {
      Pixel q = p;
      q.p_up = u2;
      outs.push_back(host.eval(up, h, sun, q));
    }
    for (double s : {1.0 + e, 1.0 - e}) {
      Pixel q = p;
      q.p_h = p.p_h * s;
      outs.push_back(host.eval(up, h, sun, q));
    }
    add_max(outs);
  }
  // values
  for (int k = 0; k < kParts; ++k) b.v[k] += 64.0 * std::ldexp(1.0, -24) * glm::abs(value.v[k]);
  return b;
}

}  // namespace
}  // namespace specbake::testing::gl_bound
