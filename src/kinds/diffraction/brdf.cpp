#include "kinds/diffraction/brdf.hpp"

#include <algorithm>
#include <cmath>

#include "core/colour_space.hpp"
#include "core/parallel.hpp"
#include "kinds/diffraction/reference.hpp"

namespace specbake::diffraction {

namespace {
constexpr double kPi = 3.141592653589793238462643;

using Vec3 = std::array<double, 3>;
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 normalize(const Vec3& a) {
  const double l = std::sqrt(dot(a, a));
  return {a[0] / l, a[1] / l, a[2] / l};
}
Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// Σ_λ ρ·weight_λ (CIE XYZ), for one pair of directions.
std::array<double, 3> xyz_sum(const BrdfTable& t, const Vec3& wi, const Vec3& wo, const Wavelengths& wl) {
  std::array<double, 3> xyz{0, 0, 0};
  for (std::size_t k = 0; k < wl.lambda_um.size(); ++k) {
    const double rho = brdf(t, wi, wo, wl.lambda_um[k]);
    for (int c = 0; c < 3; ++c) xyz[c] += rho * wl.xyz[k][c];
  }
  return xyz;
}
std::array<float, 3> to_srgb(const std::array<double, 3>& xyz, const Mat3& m) {
  std::array<float, 3> rgb{};
  for (int r = 0; r < 3; ++r)
    rgb[r] = static_cast<float>(m[3 * r] * xyz[0] + m[3 * r + 1] * xyz[1] + m[3 * r + 2] * xyz[2]);
  return rgb;
}

// The lobes picture (brdf_lobes) of pixel(wi, wo), three floats per pixel.
template <class Pixel>
std::vector<float> lobes(const std::vector<double>& light_deg, int panel, Pixel pixel) {
  const int width = panel * static_cast<int>(light_deg.size());
  std::vector<float> rgb(3 * static_cast<std::size_t>(width) * panel, 0.0f);
  parallel_for(panel, [&](long long py) {
    const double y = 1.0 - (static_cast<double>(py) + 0.5) * 2.0 / panel;
    for (std::size_t k = 0; k < light_deg.size(); ++k) {
      const double a = light_deg[k] * kPi / 180.0;
      const Vec3 wi = {std::sin(a), 0.0, std::cos(a)};
      for (int px = 0; px < panel; ++px) {
        const double x = -1.0 + (px + 0.5) * 2.0 / panel, r2 = x * x + y * y;
        if (r2 >= 1.0) continue;
        const std::array<float, 3> c = pixel(wi, Vec3{x, y, std::sqrt(1.0 - r2)});
        float* dst = rgb.data() + 3 * (static_cast<std::size_t>(py) * width + k * panel + px);
        for (int i = 0; i < 3; ++i) dst[i] = c[i];
      }
    }
  });
  return rgb;
}
}  // namespace

std::array<double, 3> xyz_fast_specular(const BrdfTable& t, const Vec3& wi, const Vec3& wo, const Wavelengths& few,
                                        const Wavelengths& all) {
  std::array<double, 3> xyz{0, 0, 0};
  const double ci = wi[2], co = wo[2];
  if (ci <= 0.0 || co <= 0.0) return xyz;
  const Vec3 h = normalize({wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]});
  const double gain = ref::stam_gain(ci, co, dot(wi, wo), dot(wi, h), t.ior);
  const double du = -(wi[0] + wo[0]), dv = -(wi[1] + wo[1]);
  const auto peak = [&](double lambda_um) {  // G(f), 0 beyond the table's reach (as P)
    if (std::fabs(du / lambda_um) > t.g.f_max || std::fabs(dv / lambda_um) > t.g.f_max) return 0.0;
    return ref::specular_peak(du * du + dv * dv, lambda_um, t.sigma_um);
  };
  const double t0 = t.g.texel_of(0.0);
  std::vector<double> chi2(few.lambda_um.size());
  for (std::size_t k = 0; k < few.lambda_um.size(); ++k) {
    const double lambda = few.lambda_um[k], kappa = 2.0 * kPi * (ci + co) / lambda;
    const Band& band = band_for(t.bands, kappa);
    chi2[k] = std::norm(table_bilinear(t.terms, t.g, t.f, band, kappa, t0, t0) / t.window_sum);
    const double rest = brdf(t, wi, wo, lambda) - gain * chi2[k] * peak(lambda);
    for (int c = 0; c < 3; ++c) xyz[c] += rest * few.xyz[k][c];
  }
  for (std::size_t i = 0; i < all.lambda_um.size(); ++i) {
    const double lambda = all.lambda_um[i];
    // |χ|² at λ: linear between the few wavelengths (ascending), clamped
    std::size_t k = 0;
    while (k + 2 < few.lambda_um.size() && lambda > few.lambda_um[k + 1]) ++k;
    const double w = ref::lerp_weight(lambda, few.lambda_um[k], few.lambda_um[k + 1]);
    const double spec = gain * (chi2[k] * (1.0 - w) + chi2[k + 1] * w) * peak(lambda);
    for (int c = 0; c < 3; ++c) xyz[c] += spec * all.xyz[i][c];
  }
  return xyz;
}

double brdf(const BrdfTable& t, const Vec3& wi, const Vec3& wo, double lambda_um) {
  const double ci = wi[2], co = wo[2];
  if (ci <= 0.0 || co <= 0.0) return 0.0;
  const double fu = -(wi[0] + wo[0]) / lambda_um, fv = -(wi[1] + wo[1]) / lambda_um;
  if (std::fabs(fu) > t.g.f_max || std::fabs(fv) > t.g.f_max) return 0.0;
  const double kappa = 2.0 * kPi * (ci + co) / lambda_um;
  const Band& band = band_for(t.bands, kappa);
  const cplx p = table_bilinear(t.terms, t.g, t.f, band, kappa, t.g.texel_of(fu), t.g.texel_of(fv)) / t.window_sum;
  const Vec3 h = normalize({wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]});
  return ref::stam_gain(ci, co, dot(wi, wo), dot(wi, h), t.ior) * std::norm(p);
}

Wavelengths every_nm(const std::vector<double>& spectrum, int step_nm) {
  Wavelengths wl;
  for (std::size_t row = 0; row < spectrum.size(); row += 4 * static_cast<std::size_t>(step_nm)) {
    wl.lambda_um.push_back(spectrum[row] * 1e-3);
    wl.xyz.push_back({spectrum[row + 1] * step_nm, spectrum[row + 2] * step_nm, spectrum[row + 3] * step_nm});
  }
  return wl;
}

Wavelengths bins(const std::vector<double>& spectrum, int count) {
  Wavelengths wl;
  const std::size_t rows = spectrum.size() / 4;
  for (int k = 0; k < count; ++k) {
    std::array<double, 3> sum{0, 0, 0};
    double centre = 0;
    for (std::size_t r = rows * k / count; r < rows * (k + 1) / count; ++r) {
      for (int c = 0; c < 3; ++c) sum[c] += spectrum[4 * r + 1 + c];
      centre += spectrum[4 * r] * spectrum[4 * r + 2];
    }
    wl.lambda_um.push_back(sum[1] > 0 ? centre / sum[1] * 1e-3 : spectrum[4 * (rows * (2 * k + 1) / (2 * count))] * 1e-3);
    wl.xyz.push_back(sum);
  }
  return wl;
}

std::vector<float> brdf_lobes(const BrdfTable& t, const Wavelengths& wl, const std::vector<double>& light_deg, int panel) {
  const Mat3 m = xyz_to_srgb();
  return lobes(light_deg, panel, [&](const Vec3& wi, const Vec3& wo) { return to_srgb(xyz_sum(t, wi, wo, wl), m); });
}

std::vector<float> brdf_lobes_fast_specular(const BrdfTable& t, const Wavelengths& few, const Wavelengths& all,
                                            const std::vector<double>& light_deg, int panel) {
  const Mat3 m = xyz_to_srgb();
  return lobes(light_deg, panel,
               [&](const Vec3& wi, const Vec3& wo) { return to_srgb(xyz_fast_specular(t, wi, wo, few, all), m); });
}

std::vector<float> brdf_lobes_specular_peak(const BrdfTable& t, const std::vector<double>& light_deg, int panel,
                                            double lambda_um) {
  return lobes(light_deg, panel, [&](const Vec3& wi, const Vec3& wo) {
    const double du = wi[0] + wo[0], dv = wi[1] + wo[1];
    const auto g = static_cast<float>(ref::specular_peak(du * du + dv * dv, lambda_um, t.sigma_um));
    return std::array<float, 3>{g, g, g};
  });
}

std::vector<float> brdf_sphere(const BrdfTable& t, const Wavelengths& wl, const Vec3& light, int size) {
  std::vector<float> rgb(3 * static_cast<std::size_t>(size) * size, 0.0f);
  const Mat3 m = xyz_to_srgb();
  const Vec3 view = {0.0, 0.0, 1.0};
  parallel_for(size, [&](long long py) {
    const double y = 1.0 - (static_cast<double>(py) + 0.5) * 2.0 / size;
    for (int px = 0; px < size; ++px) {
      const double x = -1.0 + (px + 0.5) * 2.0 / size, r2 = x * x + y * y;
      if (r2 >= 1.0) continue;
      const Vec3 n = {x, y, std::sqrt(1.0 - r2)};
      // Tangent along the latitude circle about the view axis (any direction at the pole).
      const Vec3 tx = r2 > 1e-12 ? normalize({-y, x, 0.0}) : Vec3{1.0, 0.0, 0.0};
      const Vec3 ty = cross(n, tx);
      const Vec3 l = normalize({light[0] - n[0], light[1] - n[1], light[2] - n[2]});
      const Vec3 wi = {dot(l, tx), dot(l, ty), dot(l, n)}, wo = {dot(view, tx), dot(view, ty), dot(view, n)};
      const auto c = to_srgb(xyz_sum(t, wi, wo, wl), m);
      float* dst = rgb.data() + 3 * (static_cast<std::size_t>(py) * size + px);
      for (int i = 0; i < 3; ++i) dst[i] = c[i];
    }
  });
  return rgb;
}

}  // namespace specbake::diffraction
