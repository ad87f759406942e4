#include "kinds/diffraction/brdf.hpp"

#include <algorithm>
#include <cmath>

#include "cl/buffers.hpp"
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

// Wavelength rows as table.cl takes them: λ µm, then the X, Y, Z weights.
std::vector<double> packed_rows(const Wavelengths& wl) {
  std::vector<double> r;
  for (std::size_t k = 0; k < wl.lambda_um.size(); ++k)
    r.insert(r.end(), {wl.lambda_um[k], wl.xyz[k][0], wl.xyz[k][1], wl.xyz[k][2]});
  return r;
}

// The table as table.cl's functions take it, and their double evaluations on the host; `d` holds
// ω_i then ω_o, wavelength rows as packed_rows.
struct PackedTable {
  const BrdfTable& t;
  std::vector<double> bands = packed_bands(t.bands);
  int expansion = expansion_id(t.bands.front().expansion);
  double p_scale = static_cast<double>(t.f.count()) / t.window_sum;  // W·H/Σw
  int n_bands() const { return static_cast<int>(t.bands.size()); }
  double brdf(const double* d, double lambda_um) const {
    return ref::table_brdf(t.terms.data(), t.g.size, t.g.f_max, t.g.power, n_bands(), bands.data(), expansion, t.f.s,
                           p_scale, t.ior, d[0], d[1], d[2], d[3], d[4], d[5], lambda_um);
  }
  void xyz(const double* d, const std::vector<double>& rows, double* out) const {
    ref::table_xyz(t.terms.data(), t.g.size, t.g.f_max, t.g.power, n_bands(), bands.data(), expansion, t.f.s, p_scale,
                   t.ior, d[0], d[1], d[2], d[3], d[4], d[5], static_cast<int>(rows.size() / 4), rows.data(), out);
  }
  void xyz_fast_specular(const double* d, const std::vector<double>& few, const std::vector<double>& all,
                         double* out) const {
    ref::table_xyz_fast_specular(t.terms.data(), t.g.size, t.g.f_max, t.g.power, n_bands(), bands.data(), expansion,
                                 t.f.s, p_scale, t.ior, t.sigma_um, d[0], d[1], d[2], d[3], d[4], d[5],
                                 static_cast<int>(few.size() / 4), few.data(), static_cast<int>(all.size() / 4),
                                 all.data(), out);
  }
};

// The lit pixels of a picture: each one's directions (ω_i, ω_o: six reals) and its index.
struct Pairs {
  int width = 0, height = 0;
  std::vector<double> dirs;
  std::vector<std::size_t> pixel;
  void add(std::size_t at, const Vec3& wi, const Vec3& wo) {
    dirs.insert(dirs.end(), {wi[0], wi[1], wi[2], wo[0], wo[1], wo[2]});
    pixel.push_back(at);
  }
};

// The lobes picture (BrdfPictures::lobes): for each light angle a panel, the outgoing hemisphere
// seen from above, pixel (x, y) ↦ ω_o = (x, y, √(1 − x² − y²)).
Pairs lobe_pairs(const std::vector<double>& light_deg, int panel) {
  Pairs p;
  p.width = panel * static_cast<int>(light_deg.size());
  p.height = panel;
  for (int py = 0; py < panel; ++py) {
    const double y = 1.0 - (static_cast<double>(py) + 0.5) * 2.0 / panel;
    for (std::size_t k = 0; k < light_deg.size(); ++k) {
      const double a = light_deg[k] * kPi / 180.0;
      const Vec3 wi = {std::sin(a), 0.0, std::cos(a)};
      for (int px = 0; px < panel; ++px) {
        const double x = -1.0 + (px + 0.5) * 2.0 / panel, r2 = x * x + y * y;
        if (r2 >= 1.0) continue;
        p.add(static_cast<std::size_t>(py) * p.width + k * panel + px, wi, {x, y, std::sqrt(1.0 - r2)});
      }
    }
  }
  return p;
}

// The sphere picture: a unit sphere seen along −z (orthographic), the tangent x along the latitude
// circle about the vertical (y) axis, lit by a point light at `light`. A tangent field on a sphere
// has a pole somewhere (hairy ball); about y its two poles sit at the top and bottom of the
// outline, seen edge-on, instead of pinching the picture at its centre as circles about the view
// axis would.
Pairs sphere_pairs(const Vec3& light, int size) {
  Pairs p;
  p.width = p.height = size;
  const Vec3 view = {0.0, 0.0, 1.0};
  for (int py = 0; py < size; ++py) {
    const double y = 1.0 - (static_cast<double>(py) + 0.5) * 2.0 / size;
    for (int px = 0; px < size; ++px) {
      const double x = -1.0 + (px + 0.5) * 2.0 / size, r2 = x * x + y * y;
      if (r2 >= 1.0) continue;
      const Vec3 n = {x, y, std::sqrt(1.0 - r2)};
      const double rho2 = n[0] * n[0] + n[2] * n[2];  // 0 only at the poles (0, ±1, 0), outside the disc's pixels
      const Vec3 tx = rho2 > 1e-12 ? normalize({n[2], 0.0, -n[0]}) : Vec3{1.0, 0.0, 0.0};
      const Vec3 ty = cross(n, tx);
      const Vec3 l = normalize({light[0] - n[0], light[1] - n[1], light[2] - n[2]});
      p.add(static_cast<std::size_t>(py) * size + px, {dot(l, tx), dot(l, ty), dot(l, n)},
            {dot(view, tx), dot(view, ty), dot(view, n)});
    }
  }
  return p;
}

// Linear sRGB pixels (3 floats each, 0 where no pair) from each pair's CIE XYZ.
std::vector<float> to_picture(const Pairs& p, const std::vector<double>& xyz) {
  const Mat3 m = xyz_to_srgb();
  std::vector<float> rgb(3 * static_cast<std::size_t>(p.width) * p.height, 0.0f);
  for (std::size_t i = 0; i < p.pixel.size(); ++i) {
    const auto c = apply(m, xyz.data() + 3 * i);
    for (int r = 0; r < 3; ++r) rgb[3 * p.pixel[i] + r] = static_cast<float>(c[r]);
  }
  return rgb;
}
}  // namespace

struct BrdfPictures::OnDevice {
  cl_util::Device& dev;
  cl::Kernel kernel;
  cl::Buffer terms, bands;
};

BrdfPictures::BrdfPictures(const BrdfTable& t, cl_util::Device* dev) : t_(t) {
  if (!dev) return;
  cl_util::checked("BRDF previews: device set-up", [&] {
    const cl::Program program = dev->build(kProgram, dev->real_options());
    device_ = std::make_shared<OnDevice>(OnDevice{
        *dev, cl::Kernel(program, "diffraction_brdf_xyz"),
        cl::Buffer(dev->context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, t.terms.size() * sizeof(float),
                   const_cast<float*>(t.terms.data())),
        cl_util::upload_real(*dev, packed_bands(t.bands))});
    return 0;
  });
}

bool BrdfPictures::on_device() const { return device_ != nullptr; }

std::vector<double> BrdfPictures::shade(const std::vector<double>& dirs, const Wavelengths& wl,
                                        const Wavelengths* few) const {
  const std::size_t n = dirs.size() / 6;
  const PackedTable pt{t_};
  const auto rows = packed_rows(wl), few_rows = few ? packed_rows(*few) : std::vector<double>{};
  if (!device_) {
    std::vector<double> xyz(3 * n);
    parallel_for(static_cast<long long>(n), [&](long long i) {
      if (few)
        pt.xyz_fast_specular(dirs.data() + 6 * i, few_rows, rows, xyz.data() + 3 * i);
      else
        pt.xyz(dirs.data() + 6 * i, rows, xyz.data() + 3 * i);
    });
    return xyz;
  }
  cl_util::Device& dev = device_->dev;
  return cl_util::checked("BRDF previews", [&] {
    const cl::Buffer pairs = cl_util::upload_real(dev, dirs), wl_dev = cl_util::upload_real(dev, rows),
                     few_dev = cl_util::upload_real(dev, few_rows), out = cl_util::device_real(dev, 3 * n);
    cl::Kernel& k = device_->kernel;
    int arg = 0;
    k.setArg(arg++, device_->terms);
    k.setArg(arg++, t_.g.size);
    cl_util::set_real_arg(dev, k, arg++, t_.g.f_max);
    cl_util::set_real_arg(dev, k, arg++, t_.g.power);
    k.setArg(arg++, pt.n_bands());
    k.setArg(arg++, device_->bands);
    k.setArg(arg++, pt.expansion);
    cl_util::set_real_arg(dev, k, arg++, t_.f.s);
    cl_util::set_real_arg(dev, k, arg++, pt.p_scale);
    cl_util::set_real_arg(dev, k, arg++, t_.ior);
    cl_util::set_real_arg(dev, k, arg++, t_.sigma_um);
    k.setArg(arg++, few ? 1 : 0);
    k.setArg(arg++, static_cast<int>(n));
    k.setArg(arg++, pairs);
    k.setArg(arg++, static_cast<int>(rows.size() / 4));
    k.setArg(arg++, wl_dev);
    k.setArg(arg++, static_cast<int>(few_rows.size() / 4));
    k.setArg(arg++, few_dev);
    k.setArg(arg++, out);
    cl_util::run_1d(dev, k, n);
    return cl_util::download_real(dev, out, 3 * n);
  });
}

std::vector<float> BrdfPictures::lobes(const Wavelengths& wl, const std::vector<double>& light_deg, int panel) const {
  const Pairs p = lobe_pairs(light_deg, panel);
  return to_picture(p, shade(p.dirs, wl, nullptr));
}

std::vector<float> BrdfPictures::lobes_fast_specular(const Wavelengths& few, const Wavelengths& all,
                                                     const std::vector<double>& light_deg, int panel) const {
  const Pairs p = lobe_pairs(light_deg, panel);
  return to_picture(p, shade(p.dirs, all, &few));
}

std::vector<float> BrdfPictures::sphere(const Wavelengths& wl, const Vec3& light, int size) const {
  const Pairs p = sphere_pairs(light, size);
  return to_picture(p, shade(p.dirs, wl, nullptr));
}

std::array<double, 3> xyz_fast_specular(const BrdfTable& t, const Vec3& wi, const Vec3& wo, const Wavelengths& few,
                                        const Wavelengths& all) {
  const double d[6] = {wi[0], wi[1], wi[2], wo[0], wo[1], wo[2]};
  std::array<double, 3> xyz{};
  PackedTable{t}.xyz_fast_specular(d, packed_rows(few), packed_rows(all), xyz.data());
  return xyz;
}

double brdf(const BrdfTable& t, const Vec3& wi, const Vec3& wo, double lambda_um) {
  const double d[6] = {wi[0], wi[1], wi[2], wo[0], wo[1], wo[2]};
  return PackedTable{t}.brdf(d, lambda_um);
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

std::vector<float> brdf_lobes_specular_peak(const BrdfTable& t, const std::vector<double>& light_deg, int panel,
                                            double lambda_um) {
  const Pairs p = lobe_pairs(light_deg, panel);
  std::vector<float> g(3 * static_cast<std::size_t>(p.width) * p.height, 0.0f);
  for (std::size_t i = 0; i < p.pixel.size(); ++i) {
    const double* d = p.dirs.data() + 6 * i;
    const double du = d[0] + d[3], dv = d[1] + d[4];
    const auto v = static_cast<float>(ref::specular_peak(du * du + dv * dv, lambda_um, t.sigma_um));
    for (int c = 0; c < 3; ++c) g[3 * p.pixel[i] + c] = v;
  }
  return g;
}

}  // namespace specbake::diffraction
