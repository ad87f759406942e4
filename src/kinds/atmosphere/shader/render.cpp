#include "kinds/atmosphere/shader/render.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "core/glsl.hpp"
#include "core/parallel.hpp"
#include "core/text.hpp"
#include "io/label.hpp"
#include "io/png.hpp"
#include "kinds/atmosphere/shader/shader_host.hpp"

namespace specbake::atmosphere {

struct Renderer::Impl {
  glsl::SpecbakeAtmosphere atm;
  glsl::sampler2D transmittance, irradiance;
  glsl::sampler3D scattering, single_mie;
  glsl::SkyViewSamplers sky_view;  // the sky-view table, where the bake has one
};

Renderer::Renderer(const Luts& luts) : impl_(std::make_unique<Impl>()) {
  const Sizes& s = luts.model.sizes;
  impl_->atm = glsl::atmosphere_of(luts.model, luts.rgb);
  impl_->transmittance = {luts.transmittance.data(), s.transmittance_w, s.transmittance_h};
  impl_->irradiance = {luts.irradiance.data(), s.irradiance_w, s.irradiance_h};
  impl_->scattering = {luts.scattering.data(), s.scattering_width(), s.mu, s.r};
  impl_->single_mie = {luts.single_mie.data(), s.scattering_width(), s.mu, s.r};
  impl_->sky_view = glsl::sky_view_samplers(luts);
}
Renderer::~Renderer() = default;

namespace {
glsl::vec3 to_glm(const Vec3& v) { return {v[0], v[1], v[2]}; }
Vec3 to_array(const glsl::vec3& v) { return {v.x, v.y, v.z}; }
// A planet-centred position (km) as the shared code takes it: the unit vertical and the altitude.
void up_and_altitude(const Vec3& x, double rb, glsl::vec3& up, double& h) {
  const glsl::vec3 v = to_glm(x);
  const double r = glm::length(v);
  up = v / r;
  h = r - rb;
}
}  // namespace

Vec3 Renderer::sky_radiance(const Vec3& camera, const Vec3& view, const Vec3& sun, Vec3* transmittance) const {
  const Impl& i = *impl_;
  glsl::vec3 up, t;
  double h;
  up_and_altitude(camera, i.atm.bottom_radius, up, h);
  const glsl::vec3 l =
      i.sky_view.on
          ? glsl::GetSkyRadianceWithSkyView(i.atm, i.sky_view.grid, i.transmittance, i.scattering, i.single_mie,
                                            i.sky_view.radiance, i.sky_view.single_mie, up, h, to_glm(view),
                                            to_glm(sun), t)
          : glsl::GetSkyRadiance(i.atm, i.transmittance, i.scattering, i.single_mie, up, h, to_glm(view), 0.0,
                                 to_glm(sun), t);
  if (transmittance) *transmittance = to_array(t);
  return to_array(l);
}
Vec3 Renderer::sky_radiance_to_point(const Vec3& camera, const Vec3& point, const Vec3& sun,
                                     Vec3* transmittance) const {
  const Impl& i = *impl_;
  glsl::vec3 up, t;
  double h;
  up_and_altitude(camera, i.atm.bottom_radius, up, h);
  const glsl::vec3 l =
      glsl::GetSkyRadianceToPoint(i.atm, i.transmittance, i.scattering, i.single_mie, up, h,
                                  to_glm(point) - to_glm(camera), 0.0, to_glm(sun), t);
  if (transmittance) *transmittance = to_array(t);
  return to_array(l);
}
Vec3 Renderer::sun_and_sky_irradiance(const Vec3& point, const Vec3& normal, const Vec3& sun, Vec3* sky) const {
  const Impl& i = *impl_;
  glsl::vec3 up, e_sky;
  double h;
  up_and_altitude(point, i.atm.bottom_radius, up, h);
  const glsl::vec3 e_sun = glsl::GetSunAndSkyIrradiance(i.atm, i.transmittance, i.irradiance, up, h,
                                                        to_glm(normal), to_glm(sun), e_sky);
  if (sky) *sky = to_array(e_sky);
  return to_array(e_sun);
}
Vec3 Renderer::scattering_3d(double r, double mu, double mu_s, double nu, bool ground, bool mie) const {
  const Impl& i = *impl_;
  return to_array(glsl::GetScattering3D(i.atm, mie ? i.single_mie : i.scattering, r - i.atm.bottom_radius, mu,
                                              mu_s, nu, ground ? 1 : 0));
}
Vec3 Renderer::transmittance_to_top(double r, double mu) const {
  const Impl& i = *impl_;
  return to_array(
      glsl::GetTransmittanceToTopAtmosphereBoundary(i.atm, i.transmittance, r - i.atm.bottom_radius, mu));
}
Vec3 Renderer::irradiance(double r, double mu_s) const {
  const Impl& i = *impl_;
  return to_array(glsl::GetIrradiance(i.atm, i.irradiance, r - i.atm.bottom_radius, mu_s));
}

struct SpectralRenderer::Impl {
  glsl::spectral::SpecbakeAtmosphere atm;
  glsl::sampler2DArray transmittance, irradiance, scattering, single_mie;
};

SpectralRenderer::SpectralRenderer(const Model& m, const SpectralLuts& l) : impl_(std::make_unique<Impl>()) {
  const Sizes& s = m.sizes;
  const int sets = l.sets();
  impl_->atm = glsl::spectral::atmosphere_of(m, l);
  impl_->transmittance = {l.transmittance.data(), s.transmittance_w, s.transmittance_h, sets};
  impl_->irradiance = {l.irradiance.data(), s.irradiance_w, s.irradiance_h, sets};
  impl_->scattering = {l.scattering.data(), s.r * s.scattering_width(), s.mu, sets};
  impl_->single_mie = {l.single_mie.data(), s.r * s.scattering_width(), s.mu, sets};
}
SpectralRenderer::~SpectralRenderer() = default;

double SpectralRenderer::sky_radiance(const Vec3& camera, const Vec3& view, const Vec3& sun, double lambda_nm,
                                      double* transmittance) const {
  const Impl& i = *impl_;
  glsl::vec3 up;
  double h, t;
  up_and_altitude(camera, i.atm.bottom_radius, up, h);
  const double l = glsl::spectral::GetSkyRadianceAtWavelength(i.atm, i.transmittance, i.scattering, i.single_mie, up,
                                                               h, to_glm(view), 0.0, to_glm(sun), lambda_nm, t);
  if (transmittance) *transmittance = t;
  return l;
}
double SpectralRenderer::sky_radiance_stored(const Vec3& camera, const Vec3& view, const Vec3& sun, int k,
                                             double* transmittance) const {
  const Impl& i = *impl_;
  glsl::vec3 up;
  glsl::vec4 t;
  double h;
  up_and_altitude(camera, i.atm.bottom_radius, up, h);
  const glsl::vec4 l = glsl::spectral::GetSkyRadiance(glsl::spectral::SpecbakeAtmosphereOfWavelength(i.atm, k),
                                                      i.transmittance, i.scattering, i.single_mie, up, h,
                                                      to_glm(view), 0.0, to_glm(sun), t);
  if (transmittance) *transmittance = t[k % 4];
  return l[k % 4];
}
double SpectralRenderer::sun_and_sky_irradiance(const Vec3& point, const Vec3& normal, const Vec3& sun,
                                                double lambda_nm, double* sky) const {
  const Impl& i = *impl_;
  glsl::vec3 up;
  double h, e_sky;
  up_and_altitude(point, i.atm.bottom_radius, up, h);
  const double e_sun = glsl::spectral::GetSunAndSkyIrradianceAtWavelength(
      i.atm, i.transmittance, i.irradiance, up, h, to_glm(normal), to_glm(sun), lambda_nm, e_sky);
  if (sky) *sky = e_sky;
  return e_sun;
}
double SpectralRenderer::sun_and_sky_irradiance_stored(const Vec3& point, const Vec3& normal, const Vec3& sun, int k,
                                                       double* sky) const {
  const Impl& i = *impl_;
  glsl::vec3 up;
  glsl::vec4 e_sky;
  double h;
  up_and_altitude(point, i.atm.bottom_radius, up, h);
  const glsl::vec4 e_sun = glsl::spectral::GetSunAndSkyIrradiance(
      glsl::spectral::SpecbakeAtmosphereOfWavelength(i.atm, k), i.transmittance, i.irradiance, up, h, to_glm(normal),
      to_glm(sun), e_sky);
  if (sky) *sky = e_sky[k % 4];
  return e_sun[k % 4];
}

std::vector<double> to_tiled2d(const std::vector<double>& tex3d, const Sizes& s) {
  std::vector<double> out(tex3d.size());
  for (std::size_t t = 0; t < tex3d.size() / 3; ++t)
    for (int c = 0; c < 3; ++c) out[3 * tiled2d_index(t, s) + c] = tex3d[3 * t + c];
  return out;
}

Vec3 sample_tiled2d(const Model& m, const std::vector<double>& tiled, double r, double mu, double mu_s, double nu,
                    bool ground) {
  const Sizes& s = m.sizes;
  const glsl::SpecbakeAtmosphere atm = glsl::atmosphere_of(m, Channels{});
  const glsl::sampler2D tex{tiled.data(), s.r * s.scattering_width(), s.mu};
  return to_array(glsl::GetScatteringTiled2D(atm, tex, r - m.bottom_radius_km, mu, mu_s, nu, ground ? 1 : 0));
}

std::string sampling_glsl(const Model& m, const Channels& rgb, bool layout_3d, bool layout_tiled2d,
                          const std::string& units_note) {
  const Sizes& s = m.sizes;
  const auto f = [](double v) { return glsl_float(v); };
  std::ostringstream o;
  o << "// specbake atmosphere: sampling the baked textures (Bruneton 2017's GetSkyRadiance & co., in\n"
    << "// the altitude-based form that stays accurate in float32 near the ground). Lengths in km.\n"
    << "// " << units_note << "\n"
    << "// GLSL 4.50 core or ES 3.20, without #version: include it after yours (ES: precision highp float,\n"
    << "// sampler2D and sampler3D). The functions take the atmosphere as SPECBAKE_ATMOSPHERE below.\n"
    << "// Textures (filtering LINEAR, wrap CLAMP_TO_EDGE, no mipmaps; texel (i, j) at ((i+0.5)/W, (j+0.5)/H),\n"
    << "// row j = 0 at v ~ 0):\n"
    << "//   transmittance " << s.transmittance_w << "x" << s.transmittance_h << " (u: mu, v: altitude); irradiance "
    << s.irradiance_w << "x" << s.irradiance_h << " (u: mu_s, v: altitude), sky (indirect) only;\n";
  if (layout_3d)
    o << "//   scattering, single_mie_scattering 3D: width NU*MU_S = " << s.scattering_width() << ", height MU = "
      << s.mu << ", depth R = " << s.r << " (x = nu_slice*MU_S + mu_s_index);\n";
  if (layout_tiled2d)
    o << "//   scattering, single_mie_scattering tiled 2D: width R*NU*MU_S = " << s.r * s.scattering_width()
      << ", height MU = " << s.mu << " (x = r_index*NU*MU_S + nu_slice*MU_S + mu_s_index);\n";
  o << "// GetSkyRadiance, GetSkyRadianceToPoint and GetSunAndSkyIrradiance take GetScattering's layout:\n"
    << "// 3D, or tiled 2D where SPECBAKE_SCATTERING_TILED2D is defined before this file"
    << (layout_3d ? "" : " (this bundle has no 3D layout, so it is defined here)") << ".\n"
    << "#ifndef SPECBAKE_ATMOSPHERE_GLSL\n#define SPECBAKE_ATMOSPHERE_GLSL\n";
  if (!layout_3d) o << "#ifndef SPECBAKE_SCATTERING_TILED2D\n#define SPECBAKE_SCATTERING_TILED2D\n#endif\n";
  o << "\n" << glsl_subset_prelude()
    << "#define TEXTURE_RGB(s, uv) texture(s, uv).rgb\n#define TEXTURE_RGBA(s, uv) texture(s, uv)\n"
    << "#define OUT(T) out T\n#define INOUT(T) inout T\n\n"
    << glsl_shared_source("kernels/atmosphere/lookup.cl") << "\n"
    << glsl_shared_source("kernels/atmosphere/render.glsl") << "\n"
    << "const SpecbakeAtmosphere SPECBAKE_ATMOSPHERE = SpecbakeAtmosphere(\n"
    << "    " << f(m.bottom_radius_km) << ", " << f(m.top_radius_km) << ",  // bottom_radius, top_radius (km)\n"
    << "    " << f(m.mu_s_min) << ", " << f(m.sun_angular_radius_rad) << ", " << f(m.mie_g)
    << ",  // mu_s_min, sun_angular_radius (rad), mie_g\n"
    << "    vec3(" << f(rgb.solar_irradiance[0]) << ", " << f(rgb.solar_irradiance[1]) << ", "
    << f(rgb.solar_irradiance[2]) << "),  // solar_irradiance\n"
    << "    vec3(" << f(rgb.rayleigh_scattering[0]) << ", " << f(rgb.rayleigh_scattering[1]) << ", "
    << f(rgb.rayleigh_scattering[2]) << "),  // rayleigh_scattering (km^-1)\n"
    << "    vec3(" << f(rgb.mie_scattering[0]) << ", " << f(rgb.mie_scattering[1]) << ", "
    << f(rgb.mie_scattering[2]) << "),  // mie_scattering (km^-1)\n"
    << "    " << f(s.transmittance_w) << ", " << f(s.transmittance_h) << ", " << f(s.irradiance_w) << ", "
    << f(s.irradiance_h) << ",  // transmittance_w, _h, irradiance_w, _h\n"
    << "    " << f(s.r) << ", " << f(s.mu) << ", " << f(s.mu_s) << ", " << f(s.nu) << ",  // R, MU, MU_S, NU\n"
    << "    " << f(m.mu_s_geometric ? 1.0 : 0.0) << ");  // mu_s_geometric: mu_s texels blended geometrically\n";
  if (const SkyView& v = m.sky_view; v.on())
    o << "// The sky-view table (sky_view, sky_view_single_mie: 3D, width AZIMUTH = " << v.azimuth << ", height VIEW = "
      << v.view << ", depth SUN*ALTITUDE = " << v.sun << "*" << v.altitude
      << "): the sky of cameras at\n// " << f(v.altitude_min_km) << ".." << f(v.altitude_max_km)
      << " km under suns at " << f(v.sun_min_deg) << ".." << f(v.sun_max_deg)
      << " degrees elevation; GetSkyRadianceWithSkyView(SPECBAKE_ATMOSPHERE, SPECBAKE_SKY_VIEW, ...)\n"
      << "// reads it there and the 4D textures elsewhere.\n"
      << "const SpecbakeSkyView SPECBAKE_SKY_VIEW = SpecbakeSkyView(\n"
      << "    " << f(v.altitude_min_km) << ", " << f(v.altitude_max_km) << ", " << f(v.sun_min_deg * M_PI / 180.0)
      << ", " << f(v.sun_max_deg * M_PI / 180.0) << ",  // altitude_min, _max (km), sun_min, _max (rad)\n"
      << "    " << f(v.altitude) << ", " << f(v.sun) << ", " << f(v.view) << ", " << f(v.azimuth)
      << ");  // altitude_size, sun_size, view_size, azimuth_size\n";
  o << glsl_subset_epilogue() << "#undef TEXTURE_RGB\n#undef TEXTURE_RGBA\n#undef OUT\n#undef INOUT\n"
    << "#endif\n";
  return o.str();
}

std::string sampling_spectral_glsl(const Model& m, const SpectralLuts& l, const std::string& units_note) {
  const Sizes& s = m.sizes;
  const auto f = [](double v) { return glsl_float(v); };
  const int sets = l.sets();
  const double step = l.step_nm();
  std::ostringstream o;
  o << "// specbake atmosphere, spectral radiance: sampling.glsl's lookups at " << l.lambda_nm.size()
    << " stored wavelengths,\n"
    << "// " << f(l.lambda_nm.front()) << " + i * " << f(step)
    << " nm, four per RGBA texel: wavelength set k (wavelengths 4k..4k+3 in R, G, B, A) is layer k of\n"
    << "// 2D array textures (" << sets << " layers). Lengths in km. " << units_note << "\n"
    << "// GLSL 4.50 core or ES 3.20, without #version: include it after yours (ES: precision highp float and\n"
    << "// sampler2DArray). Textures (filtering LINEAR, wrap CLAMP_TO_EDGE, no mipmaps):\n"
    << "//   spectral_transmittance " << s.transmittance_w << "x" << s.transmittance_h << " (u: mu, v: altitude); "
    << "spectral_irradiance " << s.irradiance_w << "x" << s.irradiance_h << " (u: mu_s, v: altitude), sky only;\n"
    << "//   spectral_scattering_tiled2d, spectral_single_mie_scattering_tiled2d: width R*NU*MU_S = "
    << s.r * s.scattering_width() << ", height MU = " << s.mu
    << " (x = r_index*NU*MU_S + nu_slice*MU_S + mu_s_index).\n"
    << "// GetSkyRadianceAtWavelength, GetSkyRadianceToPointAtWavelength, GetSunAndSkyIrradianceAtWavelength and\n"
    << "// GetSolarIrradianceAtWavelength take any wavelength (nm) and interpolate linearly between the stored\n"
    << "// ones; GetSkyRadiance & co. return the four wavelengths of set atm.layer.\n"
    << "#ifndef SPECBAKE_ATMOSPHERE_SPECTRAL_GLSL\n#define SPECBAKE_ATMOSPHERE_SPECTRAL_GLSL\n"
    << "#define SPECBAKE_SPECTRAL\n#define SPECBAKE_WAVELENGTH_SETS " << sets << "\n\n"
    << glsl_subset_prelude() << "#define TEXTURE_LAYER(s, uv, layer) texture(s, vec3(uv, layer))\n"
    << "#define OUT(T) out T\n#define INOUT(T) inout T\n\n"
    << glsl_shared_source("kernels/atmosphere/lookup.cl") << "\n"
    << glsl_shared_source("kernels/atmosphere/render.glsl") << "\n"
    << "const SpecbakeAtmosphere SPECBAKE_ATMOSPHERE = SpecbakeAtmosphere(\n"
    << "    " << f(m.bottom_radius_km) << ", " << f(m.top_radius_km) << ",  // bottom_radius, top_radius (km)\n"
    << "    " << f(m.mu_s_min) << ", " << f(m.sun_angular_radius_rad) << ", " << f(m.mie_g)
    << ",  // mu_s_min, sun_angular_radius (rad), mie_g\n"
    << "    0.0, " << f(l.lambda_nm.front()) << ", " << f(step) << ", "
    << f(static_cast<double>(l.lambda_nm.size())) << ",  // layer, lambda_first, lambda_step (nm), lambda_count\n"
    << "    SpecbakeRadiance[" << sets << "](";
  for (int k = 0; k < sets; ++k) {
    o << (k ? ",\n        " : "") << "vec4(";
    for (int c = 0; c < 4; ++c) {
      const std::size_t i = 4 * static_cast<std::size_t>(k) + c;
      o << (c ? ", " : "") << f(i < l.solar_irradiance.size() ? l.solar_irradiance[i] : 0.0);
    }
    o << ")";
  }
  o << "),  // solar_irradiance per set\n"
    << "    " << f(s.transmittance_w) << ", " << f(s.transmittance_h) << ", " << f(s.irradiance_w) << ", "
    << f(s.irradiance_h) << ",  // transmittance_w, _h, irradiance_w, _h\n"
    << "    " << f(s.r) << ", " << f(s.mu) << ", " << f(s.mu_s) << ", " << f(s.nu) << ",  // R, MU, MU_S, NU\n"
    << "    " << f(m.mu_s_geometric ? 1.0 : 0.0) << ");  // mu_s_geometric: mu_s texels blended geometrically\n"
    << glsl_subset_epilogue() << "#undef TEXTURE_LAYER\n#undef OUT\n#undef INOUT\n"
    << "#endif\n";
  return o.str();
}

namespace {

Vec3 normalize(Vec3 v) {
  const double l = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  return {v[0] / l, v[1] / l, v[2] / l};
}

// An n × n view: shade(x, y), linear sRGB luminance in cd/m², at every pixel centre, x right and
// y up, both in (−1, 1); RGB innermost, row 0 at the top; pixels on the hardware threads.
// symmetric_in_y: shade(x, −y) = shade(x, y) (a view symmetric about the plane through the zenith
// and the sun), so the lower half is the upper one mirrored (n is even).
template <class Shade>
std::vector<float> render_view(int n, Shade shade, bool symmetric_in_y = false) {
  std::vector<float> px(3 * static_cast<std::size_t>(n) * n, 0.0f);
  const std::size_t rows = symmetric_in_y ? static_cast<std::size_t>(n / 2) : static_cast<std::size_t>(n);
  // rows of pixels on the host's threads (each thread writes whole rows: no cache line shared
  // between threads, as interleaved pixels would)
  parallel_chunks(rows * n, static_cast<std::size_t>(n), [&](std::size_t first, std::size_t last, std::size_t) {
    for (std::size_t p = first; p < last; ++p) {
      const Vec3 v = shade((2.0 * (p % n) + 1.0) / n - 1.0, 1.0 - (2.0 * (p / n) + 1.0) / n);
      for (int c = 0; c < 3; ++c) px[3 * p + c] = v[c] > 0.0 ? static_cast<float>(v[c]) : 0.0f;
    }
  });
  const std::size_t row = 3 * static_cast<std::size_t>(n);
  for (std::size_t j = rows; j < static_cast<std::size_t>(n); ++j)
    std::copy_n(px.begin() + (n - 1 - j) * row, row, px.begin() + j * row);
  return px;
}

// A view and its exposure (docs/atmosphere.md, "Previews").
struct PreviewView {
  std::string file, what;
  std::string title;        // what the picture shows, its label
  double fixed_ev100 = 0;   // the view's fixed exposure
  double ev100 = 0;         // the exposure it got: fixed_ev100, or raised to keep the highlights
  std::vector<float> shown;  // display values in [0, 1] (exposed, through the tone curve), linear
};

// The exposure rule: the view's fixed EV100, raised (to a tenth of a stop) where the brightest
// channel of the lit pixels' 99.5th percentile would land above kHighlight of white after the
// tone curve; then x = L / (1.2 · 2^EV100) through the curve, per channel.
constexpr double kHighlightPercentile = 0.995, kHighlight = 0.975;
void expose(PreviewView& v, const std::vector<float>& lum, ToneCurve curve) {
  std::vector<float> brightest;
  brightest.reserve(lum.size() / 3);
  for (std::size_t i = 0; i < lum.size(); i += 3) {
    const float b = std::max({lum[i], lum[i + 1], lum[i + 2]});
    if (b > 0.0f) brightest.push_back(b);
  }
  v.ev100 = v.fixed_ev100;
  if (!brightest.empty()) {
    const auto at = brightest.begin() + static_cast<std::ptrdiff_t>(kHighlightPercentile * (brightest.size() - 1));
    std::nth_element(brightest.begin(), at, brightest.end());
    const double needed = std::log2(*at / (1.2 * tone_inverse(kHighlight, curve)));
    if (needed > v.fixed_ev100) v.ev100 = std::ceil(needed * 10.0 - 1e-9) / 10.0;
  }
  const float k = static_cast<float>(1.0 / (1.2 * std::exp2(v.ev100)));
  v.shown.resize(lum.size());
  for (std::size_t i = 0; i < lum.size(); ++i) v.shown[i] = tone(lum[i] * k, curve);
}

std::string ev_text(const PreviewView& v) {
  return "EV100 " + format_g(v.ev100) + (v.ev100 > v.fixed_ev100 ? " (raised from " + format_g(v.fixed_ev100) + ")" : "");
}

}  // namespace

Vec3 fisheye_sun(const FisheyeView& v) {
  const double e = v.sun_elevation_deg * M_PI / 180.0;
  return {std::cos(e), 0.0, std::sin(e)};
}

bool fisheye_direction(double x, double y, Vec3& view) {
  const double rho = std::sqrt(x * x + y * y);
  if (rho > 1.0) return false;
  const double theta = rho * M_PI / 2.0, phi = std::atan2(y, x);
  view = {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
  return true;
}

PlanetView planet_view(const Model& m) {
  PlanetView v;
  const double rb = m.bottom_radius_km;
  v.camera = {0.0, -3.2 * rb, 0.6 * rb};
  v.sun = normalize({1.0, -0.15, 0.3});  // from the right, a little in front: the terminator in view
  v.fwd = normalize({-v.camera[0], -v.camera[1], -v.camera[2]});
  v.right = normalize({v.fwd[1], -v.fwd[0], 0.0});
  v.up = {v.right[1] * v.fwd[2] - v.right[2] * v.fwd[1], v.right[2] * v.fwd[0] - v.right[0] * v.fwd[2],
          v.right[0] * v.fwd[1] - v.right[1] * v.fwd[0]};
  const double dist = std::sqrt(v.camera[0] * v.camera[0] + v.camera[1] * v.camera[1] + v.camera[2] * v.camera[2]);
  v.half = std::tan(std::asin(m.top_radius_km / dist)) * 1.15;
  return v;
}

Vec3 PlanetView::direction(double x, double y) const {
  const double sx = x * half, sy = y * half;
  return normalize({fwd[0] + sx * right[0] + sy * up[0], fwd[1] + sx * right[1] + sy * up[1],
                    fwd[2] + sx * right[2] + sy * up[2]});
}

namespace {

// The fisheye skies (kFisheyeViews) with the sun's disc, rendered and exposed.
std::vector<PreviewView> fisheye_previews(const Renderer& render, const Luts& luts, const std::array<double, 3>& k_sky,
                                          const std::array<double, 3>& k_sun, int n, ToneCurve curve) {
  const Model& m = luts.model;
  const double alpha = m.sun_angular_radius_rad;
  // The sun's disc: radiance E_sun/(π α²) through the atmosphere, drawn at least one pixel wide.
  Vec3 sun_radiance{};
  for (int c = 0; c < 3; ++c)
    sun_radiance[c] = (luts.rgb.solar_irradiance.size() == 3 ? luts.rgb.solar_irradiance[c] : 0.0) /
                      (M_PI * alpha * alpha) * k_sun[c];
  std::vector<PreviewView> views;
  for (const FisheyeView& fv : kFisheyeViews) {
    const Vec3 sun = fisheye_sun(fv);
    const Vec3 camera{0.0, 0.0, m.bottom_radius_km + kFisheyeAltitudeKm};
    const double disc = std::cos(std::max(alpha, M_PI / n));  // a pixel spans π/n of zenith angle
    const std::vector<float> scene = render_view(n, [&](double dx, double dy) {
      Vec3 lum{}, view{};
      if (!fisheye_direction(dx, dy, view)) return lum;
      Vec3 t{};
      const Vec3 l = render.sky_radiance(camera, view, sun, &t);
      const bool on_sun = view[0] * sun[0] + view[1] * sun[1] + view[2] * sun[2] > disc;
      for (int c = 0; c < 3; ++c) lum[c] = l[c] * k_sky[c] + (on_sun ? t[c] * sun_radiance[c] : 0.0);
      return lum;
    }, /*symmetric_in_y=*/true);  // the sun at azimuth 0: the sky mirrors across the picture's x axis
    char file[64], title[32];
    std::snprintf(file, sizeof file, "preview/sky_fisheye_sun_%+03.0fdeg.png", fv.sun_elevation_deg);
    std::snprintf(title, sizeof title, "sun %s%g°", fv.sun_elevation_deg < 0 ? "−" : "+",
                  std::fabs(fv.sun_elevation_deg));
    PreviewView v;
    v.file = file;
    v.title = title;
    v.fixed_ev100 = fv.ev100;
    expose(v, scene, curve);
    v.what = "sky and sun seen from 1 m above the ground (equidistant fisheye, zenith at the centre, sun at the right, "
             "elevation " + std::to_string(static_cast<int>(fv.sun_elevation_deg)) + " deg), " + ev_text(v) +
             ", tone curve " + name(curve) + ", from the baked LUTs through sampling.glsl's functions";
    views.push_back(std::move(v));
  }
  return views;
}

// The planet from space: Lambertian ground of the bake's albedo lit by sun and sky, seen through
// the atmosphere; the limb from GetSkyRadiance. The whole planet and its atmosphere in frame.
PreviewView planet_preview(const Renderer& render, const Luts& luts, const std::array<double, 3>& k_sky,
                           const std::array<double, 3>& k_sun, int n, ToneCurve curve) {
  const Model& m = luts.model;
  const double rb = m.bottom_radius_km;
  const PlanetView pv = planet_view(m);
  const Vec3& camera = pv.camera;
  const Vec3& sun = pv.sun;
  const double dist = std::sqrt(camera[0] * camera[0] + camera[1] * camera[1] + camera[2] * camera[2]);
  const double albedo = luts.rgb.ground_albedo.empty() ? 0.1 : luts.rgb.ground_albedo[0];
  const std::vector<float> scene = render_view(n, [&](double x, double y) {
    const Vec3 view = pv.direction(x, y);
    const double b = camera[0] * view[0] + camera[1] * view[1] + camera[2] * view[2];
    const double disc = b * b - (dist * dist - rb * rb);
    Vec3 lum{};
    if (disc >= 0.0 && -b - std::sqrt(disc) > 0.0) {
      const double t = -b - std::sqrt(disc);
      const Vec3 point{camera[0] + t * view[0], camera[1] + t * view[1], camera[2] + t * view[2]};
      const Vec3 normal = normalize(point);
      Vec3 sky{}, trans{};
      const Vec3 sun_e = render.sun_and_sky_irradiance(point, normal, sun, &sky);
      const Vec3 in = render.sky_radiance_to_point(camera, point, sun, &trans);
      for (int c = 0; c < 3; ++c)
        lum[c] = (albedo / M_PI * (sun_e[c] * k_sun[c] + sky[c] * k_sky[c])) * trans[c] + in[c] * k_sky[c];
    } else {
      const Vec3 l = render.sky_radiance(camera, view, sun, nullptr);
      for (int c = 0; c < 3; ++c) lum[c] = l[c] * k_sky[c];
    }
    return lum;
  });
  PreviewView v;
  v.file = "preview/planet_from_space.png";
  v.title = "planet from 3.2 radii";
  v.fixed_ev100 = pv.ev100;
  expose(v, scene, curve);
  v.what = "the planet seen from 3.2 radii away: ground (albedo " + format_g(albedo) +
           ") lit by sun and sky through the atmosphere, and the limb, " + ev_text(v) + ", tone curve " +
           name(curve) + ", from the baked LUTs through sampling.glsl's functions";
  return v;
}

// The contact sheet: every view at half size (2 × 2 box filter of the display values), three
// to a row in the order given; `order` lists the views' files in that order.
std::vector<float> contact_sheet(const std::vector<PreviewView>& views, int n, std::string& order) {
  const int tile = n / 2, cols = 3, rows = static_cast<int>((views.size() + cols - 1) / cols);
  std::vector<float> sheet(3 * static_cast<std::size_t>(cols * tile) * rows * tile, 0.0f);
  for (std::size_t v = 0; v < views.size(); ++v) {
    const std::vector<float>& px = views[v].shown;
    const int x0 = static_cast<int>(v % cols) * tile, y0 = static_cast<int>(v / cols) * tile;
    for (int y = 0; y < tile; ++y)
      for (int x = 0; x < tile; ++x)
        for (int c = 0; c < 3; ++c) {
          const auto at = [&](int i, int j) { return px[(static_cast<std::size_t>(j) * n + i) * 3 + c]; };
          sheet[(static_cast<std::size_t>(y0 + y) * cols * tile + x0 + x) * 3 + c] =
              0.25f * (at(2 * x, 2 * y) + at(2 * x + 1, 2 * y) + at(2 * x, 2 * y + 1) + at(2 * x + 1, 2 * y + 1));
        }
    order += (v ? ", " : "") + views[v].file.substr(8);
  }
  return sheet;
}

}  // namespace

std::vector<OutputFile> preview_files(const Luts& luts, const std::array<double, 3>& k_sky,
                                      const std::array<double, 3>& k_sun, int n, ToneCurve curve) {
  const auto t_render = std::chrono::steady_clock::now();
  const Renderer render(luts);
  std::vector<PreviewView> views = fisheye_previews(render, luts, k_sky, k_sun, n, curve);
  views.push_back(planet_preview(render, luts, k_sky, k_sun, n, curve));
  const auto t_encode = std::chrono::steady_clock::now();
  std::vector<OutputFile> files;
  const int tile = n / 2, cols = 3, rows = static_cast<int>((views.size() + cols - 1) / cols);
  std::string order;
  const std::vector<float> sheet = contact_sheet(views, n, order);
  // Labels: what the view shows (top left), its exposure (top right) and the tone curve (bottom
  // left); the sheet's tiles the first two. Then every PNG encoding (zlib, one thread per file) on
  // the hardware threads.
  const std::string tone_label = std::string("tone ") + (curve == ToneCurve::aces ? "ACES filmic" : "linear");
  std::vector<std::string> pngs(views.size() + 1);
  parallel_for(static_cast<long long>(pngs.size()), [&](long long v) {
    if (v < static_cast<long long>(views.size())) {
      Rgb8 img = srgb8_image(n, n, views[v].shown);
      const int px = label_px(n);
      draw_label(img, Corner::top_left, {views[v].title}, px);
      std::vector<std::string> ev{"EV100 " + format_g(views[v].ev100)};
      if (views[v].ev100 > views[v].fixed_ev100) ev.push_back("raised from " + format_g(views[v].fixed_ev100));
      draw_label(img, Corner::top_right, ev, px);
      draw_label(img, Corner::bottom_left, {tone_label}, px);
      pngs[v] = png_rgb8(n, n, img.rgb);
    } else {
      Rgb8 img = srgb8_image(cols * tile, rows * tile, sheet);
      const int px = label_px(tile);
      for (std::size_t t = 0; t < views.size(); ++t) {
        const int x0 = static_cast<int>(t % cols) * tile, y0 = static_cast<int>(t / cols) * tile;
        draw_label(img, x0, y0, {views[t].title, "EV100 " + format_g(views[t].ev100)}, px);
      }
      draw_label(img, Corner::bottom_right, {"EV100 fixed per view, raised where highlights would clip", tone_label}, px);
      pngs[v] = png_rgb8(cols * tile, rows * tile, img.rgb);
    }
  });
  for (std::size_t v = 0; v < views.size(); ++v)
    files.push_back({views[v].file, std::move(pngs[v]), "", {n, n, 3}, "8-bit sRGB", "", views[v].what});
  files.push_back({"preview/contact_sheet.png", std::move(pngs.back()), "", {rows * tile, cols * tile, 3}, "8-bit sRGB",
                   "", "every preview at half size, labelled with its view and EV100, left to right and top to bottom: " +
                           order + "; tone curve " + name(curve)});
  const auto seconds = [](auto a, auto b) { return std::chrono::duration<double>(b - a).count(); };
  spdlog::debug("atmosphere: previews: {} views of {} x {} rendered and exposed in {:.3f} s, encoded in {:.3f} s",
                views.size(), n, n, seconds(t_render, t_encode), seconds(t_encode, std::chrono::steady_clock::now()));
  return files;
}

}  // namespace specbake::atmosphere
