#include "kinds/atmosphere/render.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "core/text.hpp"
#include "io/png.hpp"
#include "kinds/atmosphere/reference.hpp"

namespace specbake::atmosphere {

struct Renderer::Impl {
  ref3::AtmosphereParameters a;
  const Luts* luts;
};

Renderer::Renderer(const Luts& luts) : impl_(std::make_unique<Impl>()) {
  impl_->a = ref3::make_parameters(luts.model, luts.rgb);
  impl_->luts = &luts;
}
Renderer::~Renderer() = default;

Vec3 Renderer::sky_radiance(const Vec3& camera, const Vec3& view, const Vec3& sun, Vec3* transmittance) const {
  Vec3 l{}, t{};
  ref3::sky_radiance(&impl_->a, impl_->luts->transmittance.data(), impl_->luts->scattering.data(),
                     impl_->luts->single_mie.data(), camera.data(), view.data(), 0.0, sun.data(), l.data(), t.data());
  if (transmittance) *transmittance = t;
  return l;
}
Vec3 Renderer::sky_radiance_to_point(const Vec3& camera, const Vec3& point, const Vec3& sun,
                                     Vec3* transmittance) const {
  Vec3 l{}, t{};
  ref3::sky_radiance_to_point(&impl_->a, impl_->luts->transmittance.data(), impl_->luts->scattering.data(),
                              impl_->luts->single_mie.data(), camera.data(), point.data(), 0.0, sun.data(), l.data(),
                              t.data());
  if (transmittance) *transmittance = t;
  return l;
}
Vec3 Renderer::sun_and_sky_irradiance(const Vec3& point, const Vec3& normal, const Vec3& sun, Vec3* sky) const {
  Vec3 e_sun{}, e_sky{};
  ref3::sun_and_sky_irradiance(&impl_->a, impl_->luts->transmittance.data(), impl_->luts->irradiance.data(),
                               point.data(), normal.data(), sun.data(), e_sun.data(), e_sky.data());
  if (sky) *sky = e_sky;
  return e_sun;
}
Vec3 Renderer::scattering_3d(double r, double mu, double mu_s, double nu, bool ground, bool mie) const {
  Vec3 v{};
  ref3::get_scattering(&impl_->a, mie ? impl_->luts->single_mie.data() : impl_->luts->scattering.data(),
                       r - impl_->a.bottom_radius, mu, mu_s,
                       nu, ground ? 1 : 0, v.data());
  return v;
}
Vec3 Renderer::transmittance_to_top(double r, double mu) const {
  Vec3 v{};
  ref3::transmittance_to_top(&impl_->a, impl_->luts->transmittance.data(), r - impl_->a.bottom_radius, mu, v.data());
  return v;
}
Vec3 Renderer::irradiance(double r, double mu_s) const {
  Vec3 v{};
  ref3::get_irradiance(&impl_->a, impl_->luts->irradiance.data(), r - impl_->a.bottom_radius, mu_s, v.data());
  return v;
}

std::vector<double> to_tiled2d(const std::vector<double>& tex3d, const Sizes& s) {
  const int wd = s.scattering_width();
  std::vector<double> out(tex3d.size());
  for (int k = 0; k < s.r; ++k)
    for (int j = 0; j < s.mu; ++j)
      for (int i = 0; i < wd; ++i)
        for (int c = 0; c < 3; ++c)
          out[((1LL * j * s.r + k) * wd + i) * 3 + c] = tex3d[((1LL * k * s.mu + j) * wd + i) * 3 + c];
  return out;
}

Vec3 sample_tiled2d(const Model& m, const std::vector<double>& tiled, double r, double mu, double mu_s, double nu,
                    bool ground) {
  const auto a = ref3::make_parameters(m, Channels{});
  const Sizes& s = m.sizes;
  double uvwz[4];
  ref3::scattering_uvwz(&a, r - a.bottom_radius, mu, mu_s, nu, ground ? 1 : 0, uvwz);
  // the lines below mirror GetScatteringTiled2D in sampling_glsl()
  const double x = std::clamp(uvwz[0], 0.0, 1.0) * (s.nu - 1);
  const double s0 = std::floor(x), f = x - s0;
  const double s1 = std::min(s0 + 1.0, double(s.nu - 1));
  const double z = uvwz[3] * s.r - 0.5;
  const double k0f = std::floor(z), g = z - k0f;
  const double k0 = std::clamp(k0f, 0.0, double(s.r - 1)), k1 = std::clamp(k0f + 1.0, 0.0, double(s.r - 1));
  const int width = s.r * s.nu * s.mu_s;
  auto fetch = [&](double k, double slice) {
    Vec3 v{};
    ref3::texture_2d(tiled.data(), width, s.mu, (k * s.nu + slice + uvwz[1]) / double(s.r * s.nu), uvwz[2], v.data());
    return v;
  };
  const Vec3 a00 = fetch(k0, s0), a01 = fetch(k0, s1), a10 = fetch(k1, s0), a11 = fetch(k1, s1);
  Vec3 out{};
  for (int c = 0; c < 3; ++c)
    out[c] = (a00[c] * (1.0 - f) + a01[c] * f) * (1.0 - g) + (a10[c] * (1.0 - f) + a11[c] * f) * g;
  return out;
}

std::string sampling_glsl(const Model& m, const Channels& rgb, bool layout_3d, bool layout_tiled2d,
                          const std::string& units_note) {
  const Sizes& s = m.sizes;
  std::ostringstream o;
  o << "// specbake atmosphere LUT sampling (Bruneton 2017 parameterisation). Lengths in km.\n"
    << "// " << units_note << "\n"
    << "// Textures: transmittance " << s.transmittance_w << "x" << s.transmittance_h << " (u: mu, v: r); irradiance "
    << s.irradiance_w << "x" << s.irradiance_h << " (u: mu_s, v: r), sky (indirect) only;\n"
    << "// scattering 3D: width NU*MU_S = " << s.scattering_width() << ", height MU = " << s.mu << ", depth R = " << s.r
    << " (x = nu_slice*MU_S + mu_s_index);\n"
    << "// scattering tiled 2D: width R*NU*MU_S = " << s.r * s.scattering_width() << ", height MU = " << s.mu
    << " (x = r_index*NU*MU_S + nu_slice*MU_S + mu_s_index).\n"
    << "// Filtering: linear, clamp to edge, no mipmaps; texel (i, j) at ((i+0.5)/W, (j+0.5)/H), row j = 0 at v ~ 0.\n"
    << "#ifndef SPECBAKE_ATMOSPHERE_GLSL\n#define SPECBAKE_ATMOSPHERE_GLSL\n"
    << "const float BOTTOM_RADIUS = " << glsl_float(m.bottom_radius_km) << ";\n"
    << "const float TOP_RADIUS = " << glsl_float(m.top_radius_km) << ";\n"
    << "const float MU_S_MIN = " << glsl_float(m.mu_s_min) << ";\n"
    << "const float SUN_ANGULAR_RADIUS = " << glsl_float(m.sun_angular_radius_rad) << ";\n"
    << "const float MIE_PHASE_G = " << glsl_float(m.mie_g) << ";\n"
    << "const vec3 SOLAR_IRRADIANCE = vec3(" << glsl_float(rgb.solar_irradiance[0]) << ", " << glsl_float(rgb.solar_irradiance[1])
    << ", " << glsl_float(rgb.solar_irradiance[2]) << ");\n"
    << "const int TRANSMITTANCE_TEXTURE_WIDTH = " << s.transmittance_w << ";\n"
    << "const int TRANSMITTANCE_TEXTURE_HEIGHT = " << s.transmittance_h << ";\n"
    << "const int IRRADIANCE_TEXTURE_WIDTH = " << s.irradiance_w << ";\n"
    << "const int IRRADIANCE_TEXTURE_HEIGHT = " << s.irradiance_h << ";\n"
    << "const int SCATTERING_TEXTURE_R_SIZE = " << s.r << ";\n"
    << "const int SCATTERING_TEXTURE_MU_SIZE = " << s.mu << ";\n"
    << "const int SCATTERING_TEXTURE_MU_S_SIZE = " << s.mu_s << ";\n"
    << "const int SCATTERING_TEXTURE_NU_SIZE = " << s.nu << ";\n";
  o << R"GLSL(
float SpecbakeCoord(float x, int n) { return 0.5 / float(n) + x * (1.0 - 1.0 / float(n)); }
float SpecbakeSafeSqrt(float a) { return sqrt(max(a, 0.0)); }
float SpecbakeDistanceToTop(float r, float mu) {
  float disc = (r * mu) * (r * mu) + (TOP_RADIUS - r) * (TOP_RADIUS + r);
  return max(-r * mu + SpecbakeSafeSqrt(disc), 0.0);
}
bool RayIntersectsGround(float r, float mu) {
  return mu < 0.0 && (r * mu) * (r * mu) - (r - BOTTOM_RADIUS) * (r + BOTTOM_RADIUS) >= 0.0;
}
float RayleighPhaseFunction(float nu) { return 3.0 / (16.0 * 3.14159265) * (1.0 + nu * nu); }
float MiePhaseFunction(float g, float nu) {
  float k = 3.0 / (8.0 * 3.14159265) * (1.0 - g * g) / (2.0 + g * g);
  float x = 1.0 + g * g - 2.0 * g * nu;
  return k * (1.0 + nu * nu) / (x * sqrt(x));
}
vec2 GetTransmittanceTextureUvFromRMu(float r, float mu) {
  float H = sqrt((TOP_RADIUS - BOTTOM_RADIUS) * (TOP_RADIUS + BOTTOM_RADIUS));
  float rho = SpecbakeSafeSqrt((r - BOTTOM_RADIUS) * (r + BOTTOM_RADIUS));
  float d = SpecbakeDistanceToTop(r, mu);
  float d_min = TOP_RADIUS - r, d_max = rho + H;
  return vec2(SpecbakeCoord((d - d_min) / (d_max - d_min), TRANSMITTANCE_TEXTURE_WIDTH),
              SpecbakeCoord(rho / H, TRANSMITTANCE_TEXTURE_HEIGHT));
}
vec2 GetIrradianceTextureUvFromRMuS(float r, float mu_s) {
  return vec2(SpecbakeCoord(mu_s * 0.5 + 0.5, IRRADIANCE_TEXTURE_WIDTH),
              SpecbakeCoord((r - BOTTOM_RADIUS) / (TOP_RADIUS - BOTTOM_RADIUS), IRRADIANCE_TEXTURE_HEIGHT));
}
// (u_nu, u_mu_s, u_mu, u_r); the ground flag picks the half of the mu axis.
vec4 GetScatteringTextureUvwzFromRMuMuSNu(float r, float mu, float mu_s, float nu, bool ray_r_mu_intersects_ground) {
  float H = sqrt((TOP_RADIUS - BOTTOM_RADIUS) * (TOP_RADIUS + BOTTOM_RADIUS));
  float rho = SpecbakeSafeSqrt((r - BOTTOM_RADIUS) * (r + BOTTOM_RADIUS));
  float u_r = SpecbakeCoord(rho / H, SCATTERING_TEXTURE_R_SIZE);
  float r_mu = r * mu;
  float disc = r_mu * r_mu - (r - BOTTOM_RADIUS) * (r + BOTTOM_RADIUS);
  float u_mu;
  if (ray_r_mu_intersects_ground) {
    float d = -r_mu - SpecbakeSafeSqrt(disc);
    float d_min = rho * rho / (r + BOTTOM_RADIUS), d_max = rho;
    u_mu = 0.5 - 0.5 * SpecbakeCoord(d_max == d_min ? 0.0 : (d - d_min) / (d_max - d_min),
                                     SCATTERING_TEXTURE_MU_SIZE / 2);
  } else {
    float d = -r_mu + SpecbakeSafeSqrt(disc + H * H);
    float d_min = TOP_RADIUS - r, d_max = rho + H;
    u_mu = 0.5 + 0.5 * SpecbakeCoord((d - d_min) / (d_max - d_min), SCATTERING_TEXTURE_MU_SIZE / 2);
  }
  float d_min = TOP_RADIUS - BOTTOM_RADIUS, d_max = H;
  float a = (SpecbakeDistanceToTop(BOTTOM_RADIUS, mu_s) - d_min) / (d_max - d_min);
  float A = (SpecbakeDistanceToTop(BOTTOM_RADIUS, MU_S_MIN) - d_min) / (d_max - d_min);
  float u_mu_s = SpecbakeCoord(max(1.0 - a / A, 0.0) / (1.0 + a), SCATTERING_TEXTURE_MU_S_SIZE);
  return vec4((nu + 1.0) / 2.0, u_mu_s, u_mu, u_r);
}
)GLSL";
  if (layout_3d)
    o << R"GLSL(
// Layout 3d: sampler3D of width NU*MU_S, height MU, depth R; two lookups around nu.
vec3 GetScattering3D(sampler3D tex, float r, float mu, float mu_s, float nu, bool ray_r_mu_intersects_ground) {
  vec4 uvwz = GetScatteringTextureUvwzFromRMuMuSNu(r, mu, mu_s, nu, ray_r_mu_intersects_ground);
  float x = clamp(uvwz.x, 0.0, 1.0) * float(SCATTERING_TEXTURE_NU_SIZE - 1);
  float s0 = floor(x);
  float f = x - s0;
  vec3 uvw0 = vec3((s0 + uvwz.y) / float(SCATTERING_TEXTURE_NU_SIZE), uvwz.z, uvwz.w);
  vec3 uvw1 = vec3((s0 + 1.0 + uvwz.y) / float(SCATTERING_TEXTURE_NU_SIZE), uvwz.z, uvwz.w);
  return texture(tex, uvw0).rgb * (1.0 - f) + texture(tex, uvw1).rgb * f;
}
)GLSL";
  if (layout_tiled2d)
    o << R"GLSL(
// Layout tiled2d: sampler2D of width R*NU*MU_S, height MU. Bilinear filtering covers mu_s
// and mu (u_mu_s keeps half a texel from each slice edge, so no two slices or r layers are
// blended); r and nu are interpolated here: 4 fetches.
vec3 GetScatteringTiled2D(sampler2D tex, float r, float mu, float mu_s, float nu, bool ray_r_mu_intersects_ground) {
  vec4 uvwz = GetScatteringTextureUvwzFromRMuMuSNu(r, mu, mu_s, nu, ray_r_mu_intersects_ground);
  float x = clamp(uvwz.x, 0.0, 1.0) * float(SCATTERING_TEXTURE_NU_SIZE - 1);
  float s0 = floor(x);
  float f = x - s0;
  float s1 = min(s0 + 1.0, float(SCATTERING_TEXTURE_NU_SIZE - 1));
  float z = uvwz.w * float(SCATTERING_TEXTURE_R_SIZE) - 0.5;
  float k0f = floor(z);
  float g = z - k0f;
  float k0 = clamp(k0f, 0.0, float(SCATTERING_TEXTURE_R_SIZE - 1));
  float k1 = clamp(k0f + 1.0, 0.0, float(SCATTERING_TEXTURE_R_SIZE - 1));
  float tiles = float(SCATTERING_TEXTURE_R_SIZE * SCATTERING_TEXTURE_NU_SIZE);
  float n = float(SCATTERING_TEXTURE_NU_SIZE);
  vec3 a00 = texture(tex, vec2((k0 * n + s0 + uvwz.y) / tiles, uvwz.z)).rgb;
  vec3 a01 = texture(tex, vec2((k0 * n + s1 + uvwz.y) / tiles, uvwz.z)).rgb;
  vec3 a10 = texture(tex, vec2((k1 * n + s0 + uvwz.y) / tiles, uvwz.z)).rgb;
  vec3 a11 = texture(tex, vec2((k1 * n + s1 + uvwz.y) / tiles, uvwz.z)).rgb;
  return mix(mix(a00, a01, f), mix(a10, a11, f), g);
}
)GLSL";
  o << "#endif\n";
  return o.str();
}

namespace {

Vec3 normalize(Vec3 v) {
  const double l = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  return {v[0] / l, v[1] / l, v[2] / l};
}

// Tone map (1 − exp(−x)) after an exposure that puts the image's mean luminance at 0.6.
std::string tone_mapped_png(int w, int h, std::vector<double> lum_rgb) {
  double mean_y = 0.0;
  long n = 0;
  for (std::size_t i = 0; i < lum_rgb.size(); i += 3) {
    const double y = 0.2126 * lum_rgb[i] + 0.7152 * lum_rgb[i + 1] + 0.0722 * lum_rgb[i + 2];
    if (y > 0.0 && std::isfinite(y)) {
      mean_y += y;
      ++n;
    }
  }
  mean_y = n ? mean_y / n : 1.0;
  const double exposure = mean_y > 0.0 ? 0.6 / mean_y : 1.0;
  std::vector<float> rgb(lum_rgb.size());
  for (std::size_t i = 0; i < rgb.size(); ++i)
    rgb[i] = static_cast<float>(1.0 - std::exp(-std::max(0.0, lum_rgb[i]) * exposure));
  return png_from_linear(w, h, rgb, 1.0f);
}

// An n × n image, RGB innermost: shade(x, y) at every pixel centre, x right and y up, both in
// (−1, 1); rows on the hardware threads.
template <class Shade>
std::vector<double> render_image(int n, Shade shade) {
  std::vector<double> img(3 * n * n, 0.0);
  parallel_for(1LL * n * n, [&](long long p) {
    const Vec3 v = shade((2.0 * (p % n) + 1.0) / n - 1.0, 1.0 - (2.0 * (p / n) + 1.0) / n);
    for (int c = 0; c < 3; ++c) img[3 * p + c] = v[c];
  });
  return img;
}

}  // namespace

std::vector<OutputFile> preview_files(const Luts& luts, const std::array<double, 3>& k_sky,
                                      const std::array<double, 3>& k_sun) {
  const Renderer render(luts);
  const Model& m = luts.model;
  std::vector<OutputFile> files;
  const int n = 160;
  // Fisheye (equidistant, zenith at the centre) from 1 m above the ground, sun at azimuth 0.
  for (double elevation_deg : {60.0, 20.0, 5.0, 0.0, -4.0}) {
    const double e = elevation_deg * M_PI / 180.0;
    const Vec3 sun{std::cos(e), 0.0, std::sin(e)};
    const Vec3 camera{0.0, 0.0, m.bottom_radius_km + 0.001};
    const auto img = render_image(n, [&](double dx, double dy) {
      Vec3 lum{};
      const double rho = std::sqrt(dx * dx + dy * dy);
      if (rho > 1.0) return lum;
      const double theta = rho * M_PI / 2.0, phi = std::atan2(dy, dx);
      const Vec3 view{std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
      const Vec3 l = render.sky_radiance(camera, view, sun, nullptr);
      for (int c = 0; c < 3; ++c) lum[c] = l[c] * k_sky[c];
      return lum;
    });
    char name[64];
    std::snprintf(name, sizeof name, "preview/sky_fisheye_sun_%+03.0fdeg.png", elevation_deg);
    files.push_back({name, tone_mapped_png(n, n, img), "", {n, n, 3}, "8-bit sRGB", "",
                     "sky seen from the ground (equidistant fisheye, zenith at the centre, sun at the right, "
                     "elevation " + std::to_string(static_cast<int>(elevation_deg)) + " deg), from the baked LUTs"});
  }
  // The planet from space: Lambertian ground of the bake's albedo lit by sun and sky, seen
  // through the atmosphere; the limb from sky_radiance.
  {
    const int w = 192;
    const double rb = m.bottom_radius_km;
    const Vec3 camera{0.0, -3.2 * rb, 0.6 * rb};
    const Vec3 sun = normalize({1.0, -0.6, 0.45});
    const Vec3 fwd = normalize({-camera[0], -camera[1], -camera[2]});
    const Vec3 right = normalize({fwd[1], -fwd[0], 0.0});
    const Vec3 up{right[1] * fwd[2] - right[2] * fwd[1], right[2] * fwd[0] - right[0] * fwd[2],
                  right[0] * fwd[1] - right[1] * fwd[0]};
    const double dist = std::sqrt(camera[0] * camera[0] + camera[1] * camera[1] + camera[2] * camera[2]);
    const double half = std::tan(std::asin(m.top_radius_km / dist)) * 1.08;
    const double albedo = luts.rgb.ground_albedo.empty() ? 0.1 : luts.rgb.ground_albedo[0];
    const auto img = render_image(w, [&](double x, double y) {
      const double sx = x * half, sy = y * half;
      const Vec3 view = normalize({fwd[0] + sx * right[0] + sy * up[0], fwd[1] + sx * right[1] + sy * up[1],
                                   fwd[2] + sx * right[2] + sy * up[2]});
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
    files.push_back({"preview/planet_from_space.png", tone_mapped_png(w, w, img), "", {w, w, 3}, "8-bit sRGB", "",
                     "the planet seen from 3.2 radii away: ground (albedo " + std::to_string(albedo) +
                         ") lit by sun and sky through the atmosphere, and the limb, from the baked LUTs"});
  }
  return files;
}

}  // namespace specbake::atmosphere
