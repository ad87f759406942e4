#include "kinds/dispersion/dispersion_job.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <sstream>

#include "cl/buffers.hpp"
#include "core/glsl.hpp"
#include "core/text.hpp"
#include "core/colour_space.hpp"
#include "core/spectral_data.hpp"
#include "io/label.hpp"
#include "io/png.hpp"
#include "kinds/dispersion/combine.hpp"
#include "kinds/dispersion/reference.hpp"

namespace specbake::dispersion {

using cl_util::Device;
using nlohmann::json;

namespace {
constexpr double kFloat32Ulp = 5.9604644775390625e-08;  // 2^-24, unit roundoff of float32
// The thin-prism picture (samples: auto, the preview) depends on the sample positions and weights
// only, not on the glass's index: its tables are computed with this stand-in material.
const MaterialModel kPictureMaterial{1.5, 50.0, std::nullopt};

std::array<double, 3> white_xyz() {
  const Mat3 M = srgb_to_xyz();
  return {M[0] + M[1] + M[2], M[3] + M[4] + M[5], M[6] + M[7] + M[8]};
}

std::vector<double> sellmeier_bc(const std::optional<Sellmeier>& s) {
  std::vector<double> bc(8, 0.0);
  if (s)
    for (std::size_t i = 0; i < s->B.size(); ++i) {
      bc[i] = s->B[i];
      bc[4 + i] = s->C[i];
    }
  return bc;
}

double sellmeier_at(const Sellmeier& s, double nm) {
  return ref::sellmeier_ior(s.B.data(), s.C.data(), static_cast<int>(s.B.size()), nm);
}
}  // namespace

Lines lines_for(AbbeLines l) {
  if (l == AbbeLines::d) return {587.5618, 486.1327, 656.2725};
  return {589.3, 486.13, 656.27};
}

MaterialModel resolve_material(const Material& m, Lines lines) {
  MaterialModel out;
  out.sellmeier = m.sellmeier;
  if (m.sellmeier) {
    const double n_ref = sellmeier_at(*m.sellmeier, lines.ref_nm);
    const double n_F = sellmeier_at(*m.sellmeier, lines.F_nm), n_C = sellmeier_at(*m.sellmeier, lines.C_nm);
    out.n_ref = n_ref;
    out.v = (n_ref - 1.0) / (n_F - n_C);
  } else {
    out.n_ref = m.n_ref;
    out.v = m.v;
  }
  return out;
}

Tables compute_device(Device& dev, const DispersionSpec& spec, const Samples& s, const MaterialModel& m) {
  const int n = static_cast<int>(s.lambda_nm.size());
  const CmfTable& cmf = cmf_table(spec.cmf);
  const Lines lines = lines_for(spec.abbe_lines);
  cl::Program program = dev.build(kProgram, dev.real_options());
  Tables t;
  t.samples = s;
  return cl_util::checked("dispersion kernels", [&] {
    cl::Buffer lambda = cl_util::upload_real(dev, s.lambda_nm), weight = cl_util::upload_real(dev, s.weight_nm);
    cl::Buffer table = cl_util::upload_real(dev, cmf.xyz), bc = cl_util::upload_real(dev, sellmeier_bc(m.sellmeier));
    cl::Buffer w_raw = cl_util::device_real(dev, 3 * n), offset = cl_util::device_real(dev, n),
               ior = cl_util::device_real(dev, n);
    cl::Kernel k1(program, "dispersion_samples");
    k1.setArg(0, lambda);
    k1.setArg(1, weight);
    k1.setArg(2, n);
    k1.setArg(3, table);
    k1.setArg(4, cmf.count());
    cl_util::set_real_arg(dev, k1, 5, cmf.first_nm);
    cl_util::set_real_arg(dev, k1, 6, lines.ref_nm);
    cl_util::set_real_arg(dev, k1, 7, lines.F_nm);
    cl_util::set_real_arg(dev, k1, 8, lines.C_nm);
    k1.setArg(9, m.sellmeier ? 1 : 0);
    cl_util::set_real_arg(dev, k1, 10, m.n_ref);
    cl_util::set_real_arg(dev, k1, 11, m.v);
    k1.setArg(12, bc);
    k1.setArg(13, m.sellmeier ? static_cast<int>(m.sellmeier->B.size()) : 0);
    k1.setArg(14, w_raw);
    k1.setArg(15, offset);
    k1.setArg(16, ior);
    cl_util::run_1d(dev, k1, n);
    t.w_raw = cl_util::download_real(dev, w_raw, 3 * n);
    t.offset = cl_util::download_real(dev, offset, n);
    t.ior = cl_util::download_real(dev, ior, n);

    // The normalising sums are a reduction over N ≤ 4096 numbers: done on the host in double.
    for (int i = 0; i < n; ++i)
      for (int c = 0; c < 3; ++c) t.w_raw_sum[c] += t.w_raw[3 * i + c];
    for (int c = 0; c < 3; ++c)
      if (!(t.w_raw_sum[c] > 0.0))
        throw JobError("the colour-matching functions vanish at every sample (component " + std::to_string(c) +
                       "); widen range_nm");

    const Mat3 M = srgb_to_xyz(), Minv = xyz_to_srgb();
    std::vector<double> mm(M.begin(), M.end());
    mm.insert(mm.end(), Minv.begin(), Minv.end());
    cl::Buffer mats = cl_util::upload_real(dev, mm);
    cl::Buffer w_norm = cl_util::device_real(dev, 3 * n), K = cl_util::device_real(dev, 9 * n);
    cl::Kernel k2(program, "dispersion_matrices");
    k2.setArg(0, w_raw);
    k2.setArg(1, n);
    for (int c = 0; c < 3; ++c) cl_util::set_real_arg(dev, k2, 2 + c, 1.0 / t.w_raw_sum[c]);
    k2.setArg(5, mats);
    k2.setArg(6, w_norm);
    k2.setArg(7, K);
    cl_util::run_1d(dev, k2, n);
    t.w_norm = cl_util::download_real(dev, w_norm, 3 * n);
    t.K = cl_util::download_real(dev, K, 9 * n);
    return t;
  });
}

Tables compute_reference(const DispersionSpec& spec, const Samples& s, const MaterialModel& m) {
  const int n = static_cast<int>(s.lambda_nm.size());
  const CmfTable& cmf = cmf_table(spec.cmf);
  const Lines lines = lines_for(spec.abbe_lines);
  const auto bc = sellmeier_bc(m.sellmeier);
  const int terms = m.sellmeier ? static_cast<int>(m.sellmeier->B.size()) : 0;
  Tables t;
  t.samples = s;
  t.w_raw.resize(3 * n);
  t.offset.resize(n);
  t.ior.resize(n);
  for (int i = 0; i < n; ++i) {
    double xyz[3];
    ref::cmf_lerp(cmf.xyz.data(), cmf.count(), cmf.first_nm, s.lambda_nm[i], xyz);
    for (int c = 0; c < 3; ++c) {
      t.w_raw[3 * i + c] = xyz[c] * s.weight_nm[i];
      t.w_raw_sum[c] += t.w_raw[3 * i + c];
    }
    t.offset[i] = ref::abbe_offset(s.lambda_nm[i], lines.ref_nm, lines.F_nm, lines.C_nm);
    t.ior[i] = m.sellmeier ? ref::sellmeier_ior(bc.data(), bc.data() + 4, terms, s.lambda_nm[i])
                           : ref::cauchy_abbe_ior(m.n_ref, m.v, t.offset[i]);
  }
  const Mat3 M = srgb_to_xyz(), Minv = xyz_to_srgb();
  t.w_norm.resize(3 * n);
  t.K.resize(9 * n);
  for (int i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) t.w_norm[3 * i + c] = t.w_raw[3 * i + c] * (1.0 / t.w_raw_sum[c]);
    ref::k_matrix(M.data(), Minv.data(), &t.w_norm[3 * i], &t.K[9 * i]);
  }
  return t;
}

Samples dense_samples(const DispersionSpec& spec) {
  const int n = static_cast<int>(std::lround((spec.range_nm.hi - spec.range_nm.lo) / PrismGeometry::kDenseStepNm));
  return make_samples(Sampling::uniform, spec.range_nm, std::max(n, 1));
}

PrismGeometry prism_geometry(const DispersionSpec& spec) {
  const Lines l = lines_for(spec.abbe_lines);
  // Offset(λ) decreases with λ, so the extreme landing points are the range's ends.
  const double x_lo = spec.spread * ref::abbe_offset(spec.range_nm.hi, l.ref_nm, l.F_nm, l.C_nm) - 0.5;
  const double x_hi = spec.spread * ref::abbe_offset(spec.range_nm.lo, l.ref_nm, l.F_nm, l.C_nm) + 0.5;
  PrismGeometry g;
  g.dx = 1.0 / PrismGeometry::kPixelsPerBeam;
  g.pixels = static_cast<int>(std::ceil((x_hi - x_lo) / g.dx));
  g.x0 = x_lo;
  return g;
}

namespace {
std::vector<double> landing_x(const DispersionSpec& spec, const Tables& t) {
  std::vector<double> x(t.offset.size());
  for (std::size_t i = 0; i < x.size(); ++i) x[i] = spec.spread * t.offset[i];
  return x;
}

double mean_of_lit(const std::vector<double>& de) {
  double sum = 0.0;
  long lit = 0;
  for (double v : de)
    if (v >= 0.0) {
      sum += v;
      ++lit;
    }
  return lit ? sum / static_cast<double>(lit) : 0.0;
}
}  // namespace

cl::Buffer PrismJudge::render(const Tables& t) {
  cl::Program program = dev_.build(kProgram, dev_.real_options());
  const auto white = white_xyz();
  return cl_util::checked("prism picture", [&] {
    cl::Buffer x = cl_util::upload_real(dev_, landing_x(spec_, t)), w = cl_util::upload_real(dev_, t.w_norm);
    cl::Buffer xyz = cl_util::device_real(dev_, 3 * geo_.pixels);
    cl::Kernel k(program, "prism_image");
    k.setArg(0, x);
    k.setArg(1, w);
    k.setArg(2, static_cast<int>(t.offset.size()));
    cl_util::set_real_arg(dev_, k, 3, geo_.x0);
    cl_util::set_real_arg(dev_, k, 4, geo_.dx);
    k.setArg(5, geo_.pixels);
    for (int c = 0; c < 3; ++c) cl_util::set_real_arg(dev_, k, 6 + c, white[c]);
    k.setArg(9, xyz);
    cl_util::run_1d(dev_, k, geo_.pixels);
    return xyz;
  });
}

PrismJudge::PrismJudge(Device& dev, const DispersionSpec& spec) : dev_(dev), spec_(spec), geo_(prism_geometry(spec)) {
  ref_xyz_ = render(compute_device(dev, spec, dense_samples(spec), kPictureMaterial));
}

double PrismJudge::mean_delta_e(const Tables& t) {
  const cl::Buffer xyz = render(t);
  cl::Program program = dev_.build(kProgram, dev_.real_options());
  const auto white = white_xyz();
  return cl_util::checked("prism colour error", [&] {
    cl::Buffer de = cl_util::device_real(dev_, geo_.pixels);
    cl::Kernel cmp(program, "prism_delta_e");
    cmp.setArg(0, xyz);
    cmp.setArg(1, ref_xyz_);
    cmp.setArg(2, geo_.pixels);
    for (int c = 0; c < 3; ++c) cl_util::set_real_arg(dev_, cmp, 3 + c, white[c]);
    cl_util::set_real_arg(dev_, cmp, 6, geo_.lit_y);
    cmp.setArg(7, de);
    cl_util::run_1d(dev_, cmp, geo_.pixels);
    return mean_of_lit(cl_util::download_real(dev_, de, geo_.pixels));
  });
}

double prism_mean_delta_e_reference(const DispersionSpec& spec, const Tables& t) {
  const PrismGeometry g = prism_geometry(spec);
  const Tables dense = compute_reference(spec, dense_samples(spec), kPictureMaterial);
  const auto white = white_xyz();
  const auto xt = landing_x(spec, t), xr = landing_x(spec, dense);
  std::vector<double> de(g.pixels);
  for (int p = 0; p < g.pixels; ++p) {
    double a[3], b[3], L1, a1, b1, L2, a2, b2;
    const double px = g.x0 + g.dx * p;
    ref::prism_pixel(xt.data(), t.w_norm.data(), static_cast<int>(xt.size()), px, g.dx, white.data(), a);
    ref::prism_pixel(xr.data(), dense.w_norm.data(), static_cast<int>(xr.size()), px, g.dx, white.data(), b);
    if (!(b[1] > g.lit_y)) {
      de[p] = -1.0;
      continue;
    }
    ref::xyz_to_lab(a[0], a[1], a[2], white[0], white[1], white[2], &L1, &a1, &b1);
    ref::xyz_to_lab(b[0], b[1], b[2], white[0], white[1], white[2], &L2, &a2, &b2);
    de[p] = ref::ciede2000(L1, a1, b1, L2, a2, b2);
  }
  return mean_of_lit(de);
}

AutoChoice choose_samples(Device& dev, const DispersionSpec& spec, const Progress& progress) {
  PrismJudge judge(dev, spec);
  AutoChoice choice;
  auto error_at = [&](int n) {
    const double e = judge.mean_delta_e(compute_device(dev, spec, make_samples(spec.sampling, spec.range_nm, n), kPictureMaterial));
    choice.tried.emplace_back(n, e);
    spdlog::debug("samples: auto: N = {} gives mean CIEDE2000 {:.4f}", n, e);
    return e;
  };
  int hi = 1;
  double e_hi = error_at(hi);
  while (e_hi > spec.tolerance_de2000) {
    if (hi >= kMaxSamples)
      throw JobError("samples: auto cannot meet tolerance_de2000 " + format_g(spec.tolerance_de2000) +
                     " with at most " + std::to_string(kMaxSamples) + " samples (mean CIEDE2000 " +
                     format_g(e_hi) + " at N = " + std::to_string(hi) + ")");
    hi = std::min(2 * hi, kMaxSamples);
    e_hi = error_at(hi);
    progress("samples: auto (doubling)", 0.3 * std::log2(hi) / std::log2(kMaxSamples));
  }
  choice.samples = hi;
  choice.delta_e = e_hi;
  for (int n = hi / 2 + 1; n < hi; ++n) {
    const double e = error_at(n);
    progress("samples: auto (scan)", 0.3 + 0.3 * (n - hi / 2) / std::max(1, hi / 2));
    if (e <= spec.tolerance_de2000) {
      choice.samples = n;
      choice.delta_e = e;
      break;
    }
  }
  return choice;
}

namespace {

json material_json(const DispersionSpec& spec, const MaterialModel& m, Lines lines) {
  json j = {{"kind", spec.material.kind == Material::Kind::abbe    ? "abbe"
                     : spec.material.kind == Material::Kind::glass ? "glass"
                                                                   : "sellmeier"},
            {"n_ref", m.n_ref},
            {"abbe_number", m.v},
            {"reference_line_nm", lines.ref_nm},
            {"ior_model", m.sellmeier ? "sellmeier" : "cauchy-abbe"}};
  if (!spec.material.glass.empty()) j["glass"] = spec.material.glass;
  if (spec.material.valid_nm) j["sellmeier_valid_nm"] = {spec.material.valid_nm->lo, spec.material.valid_nm->hi};
  return j;
}

// A GLSL literal of v's float32 value (the value the bundle's .bin files hold).
std::string f32_literal(double v) { return glsl_float(static_cast<float>(v)); }

std::vector<double> as_float(const std::vector<double>& v) {
  std::vector<double> out(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) out[i] = static_cast<float>(v[i]);
  return out;
}

std::string glsl_include(const Tables& t, const json& params) {
  const std::size_t n = t.offset.size();
  std::ostringstream o;
  o << "// specbake dispersion tables: " << n << " samples, " << params["sampling"].get<std::string>() << " over "
    << params["range_nm"][0].get<double>() << "-" << params["range_nm"][1].get<double>() << " nm, "
    << params["cmf"].get<std::string>() << ".\n"
    << "// Final colour = sum_n SPECBAKE_K[n] * rgb_n (linear sRGB); SPECBAKE_K sums to the identity.\n"
    << "// Per-sample colours are out of gamut (negative components): do not clamp per sample.\n"
    << "// IOR in the shader: n = n_ref + (n_ref - 1) / V * SPECBAKE_IOR_OFFSET[n].\n"
    << "#ifndef SPECBAKE_DISPERSION_GLSL\n#define SPECBAKE_DISPERSION_GLSL\n"
    << "const int SPECBAKE_SAMPLES = " << n << ";\n";
  auto scalars = [&](const char* name, const std::vector<double>& v) {
    o << "const float " << name << "[" << n << "] = float[" << n << "](";
    for (std::size_t i = 0; i < n; ++i) o << (i ? ", " : "") << f32_literal(v[i]);
    o << ");\n";
  };
  scalars("SPECBAKE_WAVELENGTH_NM", t.samples.lambda_nm);
  o << "const vec3 SPECBAKE_WEIGHT[" << n << "] = vec3[" << n << "](";
  for (std::size_t i = 0; i < n; ++i)
    o << (i ? ",\n    " : "\n    ") << "vec3(" << f32_literal(t.w_norm[3 * i]) << ", " << f32_literal(t.w_norm[3 * i + 1]) << ", "
      << f32_literal(t.w_norm[3 * i + 2]) << ")";
  o << ");\n";
  o << "// mat3 takes columns: column c = (K[0][c], K[1][c], K[2][c]), so K * rgb is the row-major product.\n";
  o << "const mat3 SPECBAKE_K[" << n << "] = mat3[" << n << "](";
  for (std::size_t i = 0; i < n; ++i) {
    o << (i ? ",\n    " : "\n    ") << "mat3(";
    for (int c = 0; c < 3; ++c)
      for (int r = 0; r < 3; ++r) o << f32_literal(t.K[9 * i + 3 * r + c]) << (c == 2 && r == 2 ? "" : ", ");
    o << ")";
  }
  o << ");\n";
  scalars("SPECBAKE_IOR_OFFSET", t.offset);
  scalars("SPECBAKE_IOR", t.ior);
  o << "// specbake_dispersion_combine(renders, texel): the final linear sRGB colour from the per-sample\n"
    << "// colours rgb_n, layer n of `renders` (an RGBA 2D array texture, one layer per sample, unclamped\n"
    << "// float, NEAREST): sum_n SPECBAKE_K[n] * rgb_n.\n"
    << "#define TEXEL_RGB(renders, texel, n) texelFetch(renders, ivec3(texel, n), 0).rgb\n"
    << glsl_shared_source("kernels/dispersion/combine.glsl") << "#undef TEXEL_RGB\n";
  o << "#endif\n";
  return o.str();
}

int resolved_samples(const DispersionSpec& spec, Device& dev, const Progress& progress, json& parameters) {
  if (spec.samples) return *spec.samples;
  const AutoChoice c = choose_samples(dev, spec, progress);
  json tried = json::array();
  for (auto& [n, e] : c.tried) tried.push_back({n, e});
  parameters["samples_auto"] = {{"tolerance_de2000", spec.tolerance_de2000}, {"spread", spec.spread},
                                {"chosen", c.samples}, {"mean_de2000", c.delta_e}, {"tried", tried}};
  return c.samples;
}

}  // namespace

json plan(const DispersionSpec& spec, JobContext& ctx) {
  json p;
  const int n = resolved_samples(spec, ctx.device, ctx.progress, p);
  const Lines lines = lines_for(spec.abbe_lines);
  p["samples"] = n;
  p["sampling"] = to_string(spec.sampling);
  p["range_nm"] = {spec.range_nm.lo, spec.range_nm.hi};
  p["cmf"] = to_string(spec.cmf);
  p["abbe_lines_nm"] = {{"ref", lines.ref_nm}, {"F", lines.F_nm}, {"C", lines.C_nm}};
  p["material"] = material_json(spec, resolve_material(spec.material, lines), lines);
  return p;
}

namespace {

// What the steps of a bake pass on.
struct Planned {
  int n = 0;
  Lines lines{};
  MaterialModel material;
  Samples samples;
};

Planned plan_step(const DispersionSpec& spec, JobContext& ctx, BakeResult& r) {
  ctx.enter(Stage::plan);
  ctx.progress("planning", 0.0);
  r.parameters = plan(spec, ctx);
  Planned p;
  p.n = r.parameters["samples"].get<int>();
  p.lines = lines_for(spec.abbe_lines);
  p.material = resolve_material(spec.material, p.lines);
  p.samples = make_samples(spec.sampling, spec.range_nm, p.n);
  r.parameters["precision"] = ctx.device.info().fp64 ? "float64" : "float32";
  r.parameters["quadrature_weights_nm"] = p.samples.weight_nm;
  return p;
}

Tables compute_step(const DispersionSpec& spec, const Planned& p, JobContext& ctx, BakeResult& r) {
  ctx.enter(Stage::compute);
  ctx.progress("matrices", 0.6);
  Tables t = compute_device(ctx.device, spec, p.samples, p.material);
  const std::pair<const char*, const std::vector<double>*> outputs[] = {
      {"weights", &t.w_norm}, {"matrices", &t.K}, {"ior offsets", &t.offset}, {"ior", &t.ior}};
  for (const auto& [what, v] : outputs)
    for (std::size_t i = 0; i < v->size(); ++i)
      if (!std::isfinite((*v)[i])) {
        const std::size_t sample = i * static_cast<std::size_t>(p.n) / v->size();
        throw JobError(std::string(what) + ": non-finite value at sample " + std::to_string(sample) + " (" +
                       format_g(p.samples.lambda_nm[sample]) + " nm); check the material");
      }
  r.parameters["w_raw_sum"] = t.w_raw_sum;
  return t;
}

void check_step(const DispersionSpec& spec, const Planned& p, const Tables& t, JobContext& ctx, BakeResult& r) {
  ctx.enter(Stage::check);
  Device& dev = ctx.device;
  const int n = p.n;
  // --- self-check: device path against the double reference path ---------------------
  ctx.progress("self-check", 0.8);
  const Tables ref_t = compute_reference(spec, p.samples, p.material);
  auto max_diff = [](const std::vector<double>& a, const std::vector<double>& b) {
    double m = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i) {
      const double d = std::fabs(a[i] - b[i]);
      if (!(d <= m)) m = d;  // a NaN difference wins and fails the check below
    }
    return m;
  };
  // Device arithmetic differs from the reference by a few units of the device's roundoff
  // per operation (≤ ~10 operations per value, values ≤ ~4): allow 64 roundoffs.
  const double device_eps = dev.info().fp64 ? 1.1102230246251565e-16 : kFloat32Ulp;
  const double agree_tol = 64.0 * device_eps * 4.0;
  json check = {{"K_max_abs", max_diff(t.K, ref_t.K)},
                {"weights_max_abs", max_diff(t.w_norm, ref_t.w_norm)},
                {"ior_offsets_max_abs", max_diff(t.offset, ref_t.offset)},
                {"ior_max_abs", max_diff(t.ior, ref_t.ior)}};
  double worst = 0.0;
  for (const char* k : {"K_max_abs", "weights_max_abs", "ior_offsets_max_abs", "ior_max_abs"}) {
    const double v = check[k].get<double>();
    if (!(v <= worst)) worst = v;
    if (!(v <= agree_tol))
      throw JobError(std::string("self-check failed: device and reference disagree in ") + k + " by " +
                     std::to_string(v) + " > " + std::to_string(agree_tol));
  }
  const Accuracy self = Accuracy::judged("self_check", "max abs difference (K, weights, IOR offsets, IOR)", worst,
                                         agree_tol, "double-precision host path of the same maths", check);

  // Σ K_n − I of what is stored (float32), summed in double. Bound: each stored entry is
  // within 2^-24 relative of the exact one, so |Σ K̃ − I| ≤ 2^-24·Σ|K_n| + the device error.
  const auto Kf = as_float(t.K);
  double sum_err = 0.0, bound = 0.0;
  for (int e = 0; e < 9; ++e) {
    double sum = 0.0, a = 0.0;
    for (int i = 0; i < n; ++i) {
      sum += Kf[9 * i + e];
      a += std::fabs(t.K[9 * i + e]);
    }
    sum_err = std::max(sum_err, std::fabs(sum - ((e % 4 == 0) ? 1.0 : 0.0)));
    bound = std::max(bound, kFloat32Ulp * a + n * agree_tol);
  }
  if (!(sum_err <= bound))
    throw JobError("self-check failed: |sum K_n - I| = " + format_g(sum_err) + " exceeds its bound " +
                   format_g(bound));
  const Accuracy sum_k = Accuracy::judged("sum_K_minus_I", "max abs entry of sum_n K_n - I (stored float32)", sum_err,
                                          bound, "the identity (white stays white)",
                                          {{"bound", "2^-24 * sum |K_n| + N * self-check tolerance"}});

  ctx.progress("prism colour error", 0.85);
  PrismJudge judge(dev, spec);
  r.accuracy.push_back(Accuracy::judged(
      "prism_de2000", "mean CIEDE2000 over lit pixels", judge.mean_delta_e(t),
      spec.judge_de2000 ? std::optional<double>(spec.tolerance_de2000) : std::nullopt,
      "the same prism picture from a 0.1 nm spectrum",
      {{"spread", spec.spread},
       {"note", "white box beam through a thin prism; falls slowly with N (about N^-1.3) and not monotonically"},
       {"tolerance_de2000", spec.tolerance_de2000}}));
  r.accuracy.push_back(self);
  r.accuracy.push_back(sum_k);

  // Cauchy/Abbe (the shader's model) against the Sellmeier fit, 1 nm steps over the range.
  const MaterialModel& material = p.material;
  const Lines& lines = p.lines;
  if (material.sellmeier) {
    double worst_ior = 0.0, at = spec.range_nm.lo;
    for (double l = spec.range_nm.lo; l <= spec.range_nm.hi + 1e-9; l += 1.0) {
      const double nc = ref::cauchy_abbe_ior(material.n_ref, material.v,
                                             ref::abbe_offset(l, lines.ref_nm, lines.F_nm, lines.C_nm));
      const double d = std::fabs(nc - sellmeier_at(*material.sellmeier, l));
      if (d > worst_ior) worst_ior = d, at = l;
    }
    const double spread = sellmeier_at(*material.sellmeier, spec.range_nm.lo) -
                          sellmeier_at(*material.sellmeier, spec.range_nm.hi);
    r.accuracy.push_back(Accuracy::judged("cauchy_vs_sellmeier", "max abs index difference, 1 nm steps", worst_ior,
                                          std::nullopt, "the glass's Sellmeier fit",
                                          {{"at_nm", at}, {"relative_to_index_spread", worst_ior / spread}}));
    if (worst_ior / spread > 0.02)
      r.warnings.push_back("the Cauchy/Abbe model the shader uses is off the Sellmeier index by up to " +
                           format_g(worst_ior, 3) + " (" + format_g(100.0 * worst_ior / spread, 3) +
                           " % of the index spread over range_nm) at " + format_g(at) + " nm; ior.bin holds the "
                           "Sellmeier index");
    if (spec.material.valid_nm &&
        (spec.range_nm.lo < spec.material.valid_nm->lo || spec.range_nm.hi > spec.material.valid_nm->hi))
      r.warnings.push_back("range_nm extrapolates the Sellmeier fit of " + spec.material.glass + " (valid " +
                           format_g(spec.material.valid_nm->lo) + "-" + format_g(spec.material.valid_nm->hi) +
                           " nm)");
  }
}

// preview/prism.png: the thin-prism picture `samples: auto` judges (a white beam one unit wide,
// sample n landing at spread·Offset(λ_n), 32 pixels per beam width), each of its pixels drawn
// `scale` pixels wide (the smallest whole number making the strip at least 512 wide): the top
// strip through the shipped shader's sum (combine.glsl, on the host), the bottom one from the dense
// 0.1 nm spectrum, each labelled, and a wavelength scale under them.
OutputFile prism_preview(const DispersionSpec& spec, const Tables& t) {
  const PrismGeometry g = prism_geometry(spec);
  const int w = g.pixels, scale = std::max(1, (512 + w - 1) / w), W = w * scale;
  const int band = 80, gap = 4, axis = 30, h = 2 * band + gap + axis;
  // Per-sample renders, [n][1][w][3]: the beam's coverage of each pixel, white.
  const auto x = landing_x(spec, t);
  const int n = static_cast<int>(x.size());
  std::vector<double> renders(3 * static_cast<std::size_t>(n) * w);
  for (int s = 0; s < n; ++s)
    for (int px = 0; px < w; ++px) {
      const double x0 = g.x0 + g.dx * px, cover = ref::overlap(x[s] - 0.5, x[s] + 0.5, x0, x0 + g.dx) / g.dx;
      for (int c = 0; c < 3; ++c) renders[3 * (static_cast<std::size_t>(s) * w + px) + c] = cover;
    }
  Combiner combiner(t.K);
  const Tables dense = compute_reference(spec, dense_samples(spec), kPictureMaterial);
  const auto xd = landing_x(spec, dense);
  const auto white = white_xyz();
  const Mat3 m = xyz_to_srgb();
  std::vector<float> rgb(3 * static_cast<std::size_t>(W) * h, 0.0f);
  for (int px = 0; px < w; ++px) {
    const auto sampled = combiner.combine({renders.data(), w, 1}, px, 0);
    double xyz[3];
    ref::prism_pixel(xd.data(), dense.w_norm.data(), static_cast<int>(xd.size()), g.x0 + g.dx * px, g.dx, white.data(),
                     xyz);
    for (int c = 0; c < 3; ++c) {
      const float truth = static_cast<float>(m[3 * c] * xyz[0] + m[3 * c + 1] * xyz[1] + m[3 * c + 2] * xyz[2]);
      for (int y = 0; y < band; ++y)
        for (int k = 0; k < scale; ++k) {
          const std::size_t X = static_cast<std::size_t>(px) * scale + k;
          rgb[3 * (static_cast<std::size_t>(y) * W + X) + c] = static_cast<float>(sampled[c]);
          rgb[3 * (static_cast<std::size_t>(band + gap + y) * W + X) + c] = truth;
        }
    }
  }
  Rgb8 img = srgb8_image(W, h, rgb);
  const int px = 12;
  draw_label(img, 0, 0, {"sampled: " + std::to_string(n) + " samples summed by dispersion.glsl"}, px);
  draw_label(img, 0, band + gap, {"reference: dense 0.1 nm spectrum"}, px);
  // The wavelength scale: a tick every 50 nm in the range (landing at spread·Offset(λ), the
  // beam's centre), numbered every 100 nm.
  const Lines l = lines_for(spec.abbe_lines);
  const int y0 = 2 * band + gap;
  for (int nm = 50 * static_cast<int>(std::ceil(spec.range_nm.lo / 50.0)); nm <= spec.range_nm.hi; nm += 50) {
    const double at = (spec.spread * ref::abbe_offset(nm, l.ref_nm, l.F_nm, l.C_nm) - g.x0) / g.dx * scale;
    const int X = static_cast<int>(std::lround(at));
    if (X < 0 || X >= W) continue;
    for (int y = y0; y < y0 + (nm % 100 ? 4 : 7); ++y)
      for (int c = 0; c < 3; ++c) img.rgb[3 * (static_cast<std::size_t>(y) * W + X) + c] = 220;
    if (nm % 100 == 0) {
      const std::string label = std::to_string(nm) + " nm";
      const int half = text_box({label}, px - 2).width / 2;
      draw_label(img, std::clamp(X - half, 0, std::max(0, W - 2 * half - 4)), y0 + 8, {label}, px - 2);
    }
  }
  return {"preview/prism.png", png_rgb8(W, h, img.rgb), "", {h, W, 3}, "8-bit sRGB", "",
          "a white beam through a thin prism of this glass (spread " + format_g(spec.spread) +
              " beam widths between the range's ends), " + std::to_string(scale) +
              " pixels per pixel of the judged picture: top, the " + std::to_string(n) +
              " samples summed with K_n as dispersion.glsl sums them; bottom, the dense 0.1 nm spectrum; "
              "linear sRGB clamped to [0, 1]; labelled, with a wavelength scale"};
}

void files_step(const DispersionSpec& spec, const Planned& p, const Tables& t, JobContext& ctx, BakeResult& r) {
  ctx.enter(Stage::files);
  const int n = p.n;
  const auto Kf = as_float(t.K);
  ctx.progress("files", 0.95);
  const std::string le = "little-endian float32, C order";
  if (spec.write_bin) {
    r.files.push_back({"wavelengths.bin", float32_le(t.samples.lambda_nm, "wavelengths"), "float32", {n}, le, "nm",
                       "sample wavelengths lambda_n, ascending"});
    r.files.push_back({"weights.bin", float32_le(t.w_norm, "weights"), "float32", {n, 3}, le + "; [n][x,y,z]", "1",
                       "normalised CMF weights W_n, sum over n = (1,1,1)"});
    r.files.push_back({"matrices.bin", float32_le(t.K, "matrices"), "float32", {n, 3, 3},
                       le + "; [n][row][col], applied as K_n * rgb (column vector)", "1",
                       "spectral integration matrices K_n in linear sRGB, sum over n = I"});
    r.files.push_back({"ior_offsets.bin", float32_le(t.offset, "ior offsets"), "float32", {n}, le, "1",
                       "Offset(lambda_n) = (1/l^2 - 1/l_ref^2)/(1/l_F^2 - 1/l_C^2)"});
    r.files.push_back({"ior.bin", float32_le(t.ior, "ior"), "float32", {n}, le, "1",
                       std::string("refractive index n(lambda_n) from the ") +
                           (p.material.sellmeier ? "Sellmeier fit" : "Cauchy/Abbe model")});
  }
  json tables = {{"samples", n},
                 {"wavelengths_nm", as_float(t.samples.lambda_nm)},
                 {"weights", json::array()},
                 {"matrices", json::array()},
                 {"ior_offsets", as_float(t.offset)},
                 {"ior", as_float(t.ior)},
                 {"quadrature_weights_nm", p.samples.weight_nm},
                 {"material", r.parameters["material"]},
                 {"conventions", "K_n row-major, applied as K_n * rgb; final = sum_n K_n * rgb_n"}};
  const auto wf = as_float(t.w_norm);
  for (int i = 0; i < n; ++i) {
    tables["weights"].push_back({wf[3 * i], wf[3 * i + 1], wf[3 * i + 2]});
    json m = json::array();
    for (int row = 0; row < 3; ++row) m.push_back({Kf[9 * i + 3 * row], Kf[9 * i + 3 * row + 1], Kf[9 * i + 3 * row + 2]});
    tables["matrices"].push_back(m);
  }
  if (spec.write_json) r.files.push_back({"dispersion.json", tables.dump(1) + "\n", "", {}, "", "", "the same tables as JSON"});
  r.files.push_back({"dispersion.glsl", glsl_include(t, r.parameters), "", {}, "", "",
                     "GLSL: the tables as const arrays and specbake_dispersion_combine"});
  r.files.push_back(prism_preview(spec, t));
}

}  // namespace

BakeResult bake(const DispersionSpec& spec, JobContext& ctx) {
  BakeResult r;
  const Planned p = plan_step(spec, ctx, r);
  const Tables t = compute_step(spec, p, ctx, r);
  check_step(spec, p, t, ctx, r);
  files_step(spec, p, t, ctx, r);
  ctx.progress("done", 1.0);
  return r;
}

}  // namespace specbake::dispersion
