#pragma once
// The host side of the shipped atmosphere shader: kernels/atmosphere/lookup.cl and render.glsl,
// the text sampling.glsl carries, compiled in double with GLM's vector types over textures
// filtered as a GPU filters them (texel centres at (i + 0.5)/n, clamp to edge, bilinear and
// trilinear). Renderer (render.hpp) is built on it; the GL test uses it directly, with a
// FilterProbe to measure how the result depends on each fetch's texel coordinates.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <glm/glm.hpp>

#include "kinds/atmosphere/model/model.hpp"
#include "kinds/atmosphere/shader/render.hpp"

namespace specbake::atmosphere::glsl {

using real = double;
using vec2 = glm::dvec2;
using vec3 = glm::dvec3;
using vec4 = glm::dvec4;
using glm::dot, glm::length, glm::normalize;
using std::exp, std::fabs, std::floor, std::fmax, std::fmin, std::pow, std::sqrt;

// Counts a shader evaluation's filtered fetches in call order and moves the texel coordinate of
// one of them: fetch `target`, axis `axis` (0 x, 1 y, 2 z), by `delta` texels. A GPU resolves
// texel coordinates to its subtexel precision; this shows what that can do to a result.
struct FilterProbe {
  int fetches = 0;
  int target = -1, axis = 0;
  double delta = 0.0;
};

struct sampler2D {  // [h][w][channels]
  const double* texels;
  int w, h;
  FilterProbe* probe = nullptr;
  int channels = 3;  // 3 (a fetch's alpha reads 1) or 4
};
struct sampler2DArray {  // [layers][h][w][4]: a spectral bundle's wavelength sets
  const float* texels;
  int w, h, layers;
  FilterProbe* probe = nullptr;
};
struct sampler3D {  // [d][h][w][channels]
  const double* texels;
  int w, h, d;
  FilterProbe* probe = nullptr;
  int channels = 3;
};

namespace detail {
// The two texels around coordinate u on n texels (moved by `shift` texels) and the weight of the
// second.
struct Taps {
  int i0, i1;
  double f;
};
inline Taps taps(double u, int n, double shift = 0.0) {
  const double x = u * n - 0.5 + shift, x0 = std::floor(x);
  const int i = static_cast<int>(x0);
  return {std::clamp(i, 0, n - 1), std::clamp(i + 1, 0, n - 1), x - x0};
}
inline vec4 texel(const double* t, int channels, long long index) {
  const double* v = t + channels * index;
  return {v[0], v[1], v[2], channels == 4 ? v[3] : 1.0};
}
// The probe's shift (if any) for this fetch along `axis`.
inline double shift(FilterProbe* p, int fetch, int axis) {
  return p && fetch == p->target && axis == p->axis ? p->delta : 0.0;
}
// The bilinear blend of at(i, j) around uv on w × h texels, with fetch n's probe shifts (if any).
template <class At>
vec4 bilinear(FilterProbe* p, int n, vec2 uv, int w, int h, At at) {
  const Taps a[2] = {taps(uv.x, w, shift(p, n, 0)), taps(uv.y, h, shift(p, n, 1))};
  return (1.0 - a[1].f) * ((1.0 - a[0].f) * at(a[0].i0, a[1].i0) + a[0].f * at(a[0].i1, a[1].i0)) +
         a[1].f * ((1.0 - a[0].f) * at(a[0].i0, a[1].i1) + a[0].f * at(a[0].i1, a[1].i1));
}
}  // namespace detail

inline vec4 texture_rgba(const sampler2D& s, vec2 uv) {
  const int n = s.probe ? s.probe->fetches++ : 0;
  return detail::bilinear(s.probe, n, uv, s.w, s.h,
                          [&](int i, int j) { return detail::texel(s.texels, s.channels, 1LL * j * s.w + i); });
}
inline vec4 texture_rgba(const sampler3D& s, vec3 uvw) {
  const int n = s.probe ? s.probe->fetches++ : 0;
  const detail::Taps z = detail::taps(uvw.z, s.d, detail::shift(s.probe, n, 2));
  const auto plane = [&](int k) {
    return detail::bilinear(s.probe, n, vec2(uvw.x, uvw.y), s.w, s.h, [&](int i, int j) {
      return detail::texel(s.texels, s.channels, (1LL * k * s.h + j) * s.w + i);
    });
  };
  return (1.0 - z.f) * plane(z.i0) + z.f * plane(z.i1);
}
// A layer of a 2D array texture, bilinear: the GPU's layer index is round(layer), clamped.
inline vec4 texture_layer(const sampler2DArray& s, vec2 uv, double layer) {
  const int n = s.probe ? s.probe->fetches++ : 0;
  const int l = std::clamp(static_cast<int>(std::floor(layer + 0.5)), 0, s.layers - 1);
  return detail::bilinear(s.probe, n, uv, s.w, s.h, [&](int i, int j) {
    const float* v = s.texels + 4 * ((1LL * l * s.h + j) * s.w + i);
    return vec4(v[0], v[1], v[2], v[3]);
  });
}
template <class Sampler, class Uv>
vec3 texture_rgb(const Sampler& s, Uv uv) {
  const vec4 v = texture_rgba(s, uv);
  return {v.x, v.y, v.z};
}

// The shared text. Internal linkage: each includer gets its own copy of these inline-sized
// functions (render.glsl's are not marked inline, as GLSL has no such word).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
namespace {
#define TEXTURE_RGB(s, uv) texture_rgb(s, uv)
#define TEXTURE_RGBA(s, uv) texture_rgba(s, uv)
#define OUT(T) T&
#define INOUT(T) T&
#include "atmosphere/lookup.cl"
#include "atmosphere/render.glsl"
#undef GetScattering
#undef SpecbakeScatteringSampler
#undef SpecbakeRadiance
#undef SpecbakeSampler2D
#undef SPECBAKE_CHANNELS
#undef SPECBAKE_FETCH
#undef SPECBAKE_SOLAR_IRRADIANCE

// What both builds' SpecbakeAtmosphere hold alike: radii, sun, Mie g and the texture sizes.
template <class Atmosphere>
Atmosphere shared_atmosphere_of(const Model& m) {
  const Sizes& s = m.sizes;
  Atmosphere a{};
  a.bottom_radius = m.bottom_radius_km;
  a.top_radius = m.top_radius_km;
  a.mu_s_min = m.mu_s_min;
  a.sun_angular_radius = m.sun_angular_radius_rad;
  a.mie_g = m.mie_g;
  a.transmittance_w = s.transmittance_w;
  a.transmittance_h = s.transmittance_h;
  a.irradiance_w = s.irradiance_w;
  a.irradiance_h = s.irradiance_h;
  a.r_size = s.r;
  a.mu_size = s.mu;
  a.mu_s_size = s.mu_s;
  a.nu_size = s.nu;
  a.mu_s_geometric = m.mu_s_geometric ? 1.0 : 0.0;
  return a;
}

inline SpecbakeAtmosphere atmosphere_of(const Model& m, const Channels& rgb) {
  SpecbakeAtmosphere a = shared_atmosphere_of<SpecbakeAtmosphere>(m);
  const auto v3 = [](const std::vector<double>& v) { return v.size() == 3 ? vec3(v[0], v[1], v[2]) : vec3(0.0); };
  a.solar_irradiance = v3(rgb.solar_irradiance);
  a.rayleigh_scattering = v3(rgb.rayleigh_scattering);
  a.mie_scattering = v3(rgb.mie_scattering);
  return a;
}

// The sky-view table's range and node counts (Model::sky_view) as the shader takes them.
inline SpecbakeSkyView sky_view_of(const Model& m) {
  const SkyView& v = m.sky_view;
  constexpr double kRad = 3.14159265358979323846 / 180.0;
  return SpecbakeSkyView{v.altitude_min_km, v.altitude_max_km, v.sun_min_deg * kRad, v.sun_max_deg * kRad,
                         double(v.altitude), double(v.sun), double(v.view), double(v.azimuth)};
}

// The sky-view table as GetSkyRadianceWithSkyView samples it: its grid and its two 3D textures
// (azimuth × view × sun·altitude; R,G,B and single Mie). `on` is false where the bake has none
// (or its textures are not the model's size), and the samplers are then empty.
struct SkyViewSamplers {
  bool on = false;
  SpecbakeSkyView grid{};
  sampler3D radiance{}, single_mie{};
};
inline SkyViewSamplers sky_view_samplers(const Luts& luts) {
  const SkyView& v = luts.model.sky_view;
  if (!v.on() || luts.sky_view.size() != 3ULL * v.texels() || luts.sky_view_mie.size() != luts.sky_view.size())
    return {};
  return {true, sky_view_of(luts.model), {luts.sky_view.data(), v.azimuth, v.view, v.sun * v.altitude},
          {luts.sky_view_mie.data(), v.azimuth, v.view, v.sun * v.altitude}};
}

// The spectral build (`spectrum: {store: radiance}`, sampling_spectral.glsl): four stored
// wavelengths per texel, wavelength sets as layers of 2D array textures, scattering tiled 2D.
namespace spectral {
#define SPECBAKE_SPECTRAL
#define SPECBAKE_WAVELENGTH_SETS 64
#define TEXTURE_LAYER(s, uv, layer) texture_layer(s, uv, layer)
#include "atmosphere/render.glsl"
#undef SPECBAKE_SPECTRAL
#undef SPECBAKE_SCATTERING_TILED2D
#undef TEXTURE_LAYER
#undef GetScattering
#undef SpecbakeScatteringSampler
#undef SpecbakeRadiance
#undef SpecbakeSampler2D
#undef SPECBAKE_CHANNELS
#undef SPECBAKE_FETCH
#undef SPECBAKE_SOLAR_IRRADIANCE

// The atmosphere of a spectral bundle's stored wavelengths (equally spaced, four per set); layer 0.
inline SpecbakeAtmosphere atmosphere_of(const Model& m, const SpectralLuts& l) {
  if (l.lambda_nm.size() > 4 * SPECBAKE_WAVELENGTH_SETS || l.solar_irradiance.size() != l.lambda_nm.size())
    throw std::invalid_argument("spectral atmosphere: too many wavelengths or mismatched solar irradiance");
  SpecbakeAtmosphere a = shared_atmosphere_of<SpecbakeAtmosphere>(m);
  a.layer = 0.0;
  a.lambda_first = l.lambda_nm.empty() ? 0.0 : l.lambda_nm.front();
  a.lambda_step = l.step_nm();
  a.lambda_count = static_cast<double>(l.lambda_nm.size());
  for (std::size_t i = 0; i < l.lambda_nm.size(); ++i)
    a.solar_irradiance[i / 4][static_cast<int>(i % 4)] = l.solar_irradiance[i];
  return a;
}
}  // namespace spectral
#undef TEXTURE_RGB
#undef TEXTURE_RGBA
#undef OUT
#undef INOUT
}  // namespace
#pragma GCC diagnostic pop

}  // namespace specbake::atmosphere::glsl
