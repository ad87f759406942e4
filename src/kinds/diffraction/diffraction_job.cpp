// The diffraction job: Taylor / Chebyshev FFT terms of a heightfield for a
// real-time diffraction shader, with term counts and bands from a proven bound, the real
// error measured against double-precision DFTs, a spectrum table for the λ integral, EXR
// copies of the terms and previews. The maths is in kernels/diffraction/diffraction.cl.
#include "kinds/diffraction/diffraction_job.hpp"

#include <Imath/half.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <memory>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "core/colour_space.hpp"
#include "core/resources.hpp"
#include "core/spectral_data.hpp"
#include "core/text.hpp"
#include "io/exr.hpp"
#include "cl/buffers.hpp"
#include "io/label.hpp"
#include "io/png.hpp"
#include "kinds/diffraction/planning.hpp"
#include "kinds/diffraction/reference.hpp"
#include "kinds/diffraction/terms.hpp"

namespace specbake::diffraction {

using nlohmann::json;

namespace {

constexpr double kTwoPi = 6.283185307179586476925287;
constexpr double kPreviewStepNm = 5.0;
constexpr int kAutoRefinements = 3;

const char* name(Expansion e) { return e == Expansion::taylor ? "taylor" : "chebyshev"; }

}  // namespace

// Spectrum rows (λ nm, D65·x̄, D65·ȳ, D65·z̄) at 1 nm steps over range_nm, normalised so that
// Σ D65·ȳ·1 nm = 1 (a perfect mirror under D65 has Y = 1).
std::vector<double> spectrum_rows(const RangeNm& r, double& y_norm) {
  const CmfTable& cmf = cmf_table(CmfSet::cie1931_2deg);
  std::vector<double> rows;
  double ysum = 0.0;
  for (double nm = std::ceil(r.lo); nm <= std::floor(r.hi) + 1e-9; nm += 1.0) {
    const double s = d65_table().at_whole_nm(nm);
    const auto xyz = cmf.at(nm);
    rows.insert(rows.end(), {nm, s * xyz[0], s * xyz[1], s * xyz[2]});
    ysum += s * xyz[1];
  }
  if (!(ysum > 0)) throw JobError("the D65 x CIE 1931 spectrum vanishes over range_nm");
  for (std::size_t i = 0; i < rows.size(); i += 4)
    for (int c = 1; c < 4; ++c) rows[i + c] /= ysum;
  y_norm = ysum;
  return rows;
}

std::vector<double> add_spectrum_file(const RangeNm& range, BakeResult& r) {
  double y_norm = 0.0;
  const auto spectrum = spectrum_rows(range, y_norm);
  r.files.push_back({"spectrum.bin", float32_le(spectrum, "spectrum"), "float32",
                     {static_cast<std::int64_t>(spectrum.size() / 4), 4},
                     "little-endian float32, C order; [l][lambda_nm, X, Y, Z]", "nm, 1/nm",
                     "lambda and D65 * CIE 1931 xbar, ybar, zbar at 1 nm steps, normalised so sum(Y) * 1 nm = 1"});
  r.parameters["spectrum_normalisation"] = y_norm;
  return spectrum;
}

void add_term_exrs(const std::vector<float>& values, const std::vector<Band>& bands, int width, int height,
                   Storage storage, const std::string& folder, const std::string& source_file,
                   const std::string& rows_columns, Timings& tm, BakeResult& r) {
  const std::size_t per = static_cast<std::size_t>(width) * height;
  for (const auto& band : bands)
    for (int n = 0; n < band.terms; ++n) {
      const int term = band.first_term + n;
      ExrImage img;
      img.width = width;
      img.height = height;
      img.channels = {"R", "G"};
      img.half = storage == Storage::half;
      img.pixels.assign(values.begin() + 2 * term * per, values.begin() + 2 * (term + 1) * per);
      img.attributes = {{"specbake.term", std::to_string(term)},
                        {"specbake.expansion", name(band.expansion)},
                        {"specbake.band_order", std::to_string(n)},
                        {"specbake.kappa_expansion", format_g(band.kappa0)},
                        {"specbake.channels", "R = Re F_n, G = Im F_n; " + rows_columns}};
      char path[64];
      std::snprintf(path, sizeof path, "%s/F_%03d.exr", folder.c_str(), term);
      r.files.push_back({path, tm.time("EXR", [&] { return exr_bytes(img); }), img.half ? "half" : "float32",
                         {height, width, 2}, "EXR, R = Re, G = Im", "1",
                         "term " + std::to_string(term) + " of " + source_file});
    }
}

// κ values where the error is measured: κ_lo, κ_hi, every band's edges and middle (the
// Taylor bound peaks at band edges), at most ~16.
std::vector<double> measurement_kappas(const Plan& p) {
  std::vector<double> k = {p.kappa_lo};
  const std::size_t stride = std::max<std::size_t>(1, (p.bands.size() + 6) / 7);
  for (std::size_t b = 0; b < p.bands.size(); b += stride) {
    k.push_back(0.5 * (p.bands[b].kappa_lo + p.bands[b].kappa_hi));
    k.push_back(p.bands[b].kappa_hi);
  }
  k.push_back(p.kappa_hi);
  std::sort(k.begin(), k.end());
  k.erase(std::unique(k.begin(), k.end()), k.end());
  return k;
}

std::vector<double> preview_xyz(cl_util::Device* dev, const Field& f, const Plan& p, const Terms& t,
                                const std::vector<double>& spectrum, double w_max, int n) {
  const int step = static_cast<int>(kPreviewStepNm);
  std::vector<double> rows;  // every step-th spectrum row
  for (std::size_t row = 0; row < spectrum.size(); row += 4 * static_cast<std::size_t>(step))
    rows.insert(rows.end(), spectrum.begin() + row, spectrum.begin() + row + 4);
  const int n_rows = static_cast<int>(rows.size() / 4);
  const auto bands = packed_bands(p.bands);
  const int expansion = expansion_id(p.bands.front().expansion);
  const Bins& b = t.bins;
  if (dev)
    return cl_util::checked("preview", [&] {
      const cl::Program program = dev->build(kProgram, dev->real_options());
      cl::Kernel k(program, "diffraction_bins_preview");
      const cl::Buffer terms(dev->context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, t.values.size() * sizeof(float),
                             const_cast<float*>(t.values.data()));
      const cl::Buffer bands_dev = cl_util::upload_real(*dev, bands), rows_dev = cl_util::upload_real(*dev, rows),
                       out = cl_util::device_real(*dev, 3 * static_cast<std::size_t>(n) * n);
      int arg = 0;
      k.setArg(arg++, terms);
      k.setArg(arg++, b.ku_min);
      k.setArg(arg++, b.kv_min);
      k.setArg(arg++, b.ku_count());
      k.setArg(arg++, b.kv_count());
      k.setArg(arg++, static_cast<int>(p.bands.size()));
      k.setArg(arg++, bands_dev);
      k.setArg(arg++, expansion);
      cl_util::set_real_arg(*dev, k, arg++, f.s);
      k.setArg(arg++, f.width);
      k.setArg(arg++, f.height);
      cl_util::set_real_arg(*dev, k, arg++, f.dx_um);
      cl_util::set_real_arg(*dev, k, arg++, w_max);
      k.setArg(arg++, n_rows);
      k.setArg(arg++, rows_dev);
      cl_util::set_real_arg(*dev, k, arg++, static_cast<double>(step));
      k.setArg(arg++, n);
      k.setArg(arg++, out);
      cl::Event ev;
      dev->queue().enqueueNDRangeKernel(k, cl::NullRange, cl::NDRange(n, n), cl::NullRange, nullptr, &ev);
      dev->profiler().record(ev);
      return cl_util::download_real(*dev, out, 3 * static_cast<std::size_t>(n) * n);
    });
  // The terms regrouped per bin ([kv][ku][n][re,im]) so that a bin's sum reads one run.
  const std::size_t per = t.per_term(), stride = 2 * static_cast<std::size_t>(t.count);
  std::vector<float> by_bin(t.values.size());
  constexpr std::size_t kRun = 4096;  // bins per task
  parallel_for(static_cast<long long>((per + kRun - 1) / kRun), [&](long long run) {
    const std::size_t lo = static_cast<std::size_t>(run) * kRun, hi = std::min(per, lo + kRun);
    for (int k = 0; k < t.count; ++k)
      for (std::size_t i = lo; i < hi; ++i) {
        by_bin[i * stride + 2 * k] = t.values[2 * (k * per + i)];
        by_bin[i * stride + 2 * k + 1] = t.values[2 * (k * per + i) + 1];
      }
  });
  std::vector<double> xyz(3 * static_cast<std::size_t>(n) * n);
  parallel_for(n, [&](long long py) {
    const double v = 1.0 - (static_cast<double>(py) + 0.5) * 2.0 / n;
    for (int px = 0; px < n; ++px) {
      const double u = -1.0 + (px + 0.5) * 2.0 / n;
      ref::bins_preview_xyz(by_bin.data(), 2, static_cast<long>(stride), b.ku_min, b.kv_min, b.ku_count(), b.kv_count(),
                            static_cast<int>(p.bands.size()), bands.data(), expansion, f.s, f.width, f.height, f.dx_um,
                            u, v, w_max, n_rows, rows.data(), static_cast<double>(step),
                            xyz.data() + 3 * (static_cast<std::size_t>(py) * n + px));
    }
  });
  return xyz;
}

namespace {

struct Measured {
  double max_over_m2 = 0.0, at_kappa = 0.0;
  std::vector<double> kappas, per_kappa;
};

// Max |P_rec − P_exact|/M² over the bins at each κ, for every band holding κ, P_rec from `terms`.
// On a GPU the device reduces; on a CPU device the host's threads are faster (ExactDft::prepare).
Measured measure(const Plan& p, const Field& f, ExactDft& exact, const Terms& terms, cl_util::Device& dev,
                 const Progress& progress, Timings& tm) {
  Measured m;
  m.kappas = measurement_kappas(p);
  const double inv = 1.0 / static_cast<double>(f.count());
  exact.prepare(terms, unless_cpu(dev) != nullptr);
  for (std::size_t i = 0; i < m.kappas.size(); ++i) {
    const double kappa = m.kappas[i];
    tm.time("error: exact DFT", [&] { exact.transform(kappa); });
    double worst = 0.0;
    for (const auto& band : p.bands) {
      if (kappa < band.kappa_lo || kappa > band.kappa_hi) continue;
      worst = std::max(worst, tm.time("error: reconstruction", [&] { return exact.max_error(band); }) * inv);
    }
    m.per_kappa.push_back(worst);
    if (worst >= m.max_over_m2) {
      m.max_over_m2 = worst;
      m.at_kappa = kappa;
    }
    progress("measuring error", 0.75 + 0.1 * (i + 1) / m.kappas.size());
  }
  return m;
}

// Device terms against the double reference at a few bins, every term (or the first and last
// of each band on large fields). Bound per term, over M²: input rounding and storage (2u), a
// float32 FFT (≤ 6u·log2(4·W·H) relative to max|q_n|, Bluestein included) and the float
// evaluation of the inputs on devices without fp64 (u·(n + 2 + κ_0·s)).
json self_check(cl_util::Device& dev, const Field& f, const Plan& p, const Terms& t) {
  std::vector<std::pair<int, int>> bins;
  const Bins& b = p.bins;
  for (auto [u, v] : std::vector<std::pair<int, int>>{{0, 0}, {1, 0}, {0, 1}, {-2, 3}, {b.ku_max, b.kv_min},
                                                      {b.ku_min, b.kv_max}, {b.ku_max / 2, -b.kv_max / 3}})
    if (u >= b.ku_min && u <= b.ku_max && v >= b.kv_min && v <= b.kv_max) bins.emplace_back(u, v);
  const double work = static_cast<double>(f.count()) * p.total_terms * bins.size();
  std::vector<Band> bands = p.bands;
  if (work > 4e8) {
    for (auto& band : bands) band.terms = std::min(band.terms, 2);
  }
  const auto ref_vals = reference_terms_at(f, bands, bins);
  const double u = kUnitRoundoffF32, log_n = std::log2(4.0 * static_cast<double>(f.count()));
  double worst_ratio = 0.0, worst_abs = 0.0;
  int checked = 0;
  for (const auto& band : bands)
    for (int n = 0; n < band.terms; ++n) {
      const double a = band.expansion == Expansion::taylor ? 1.0 : (n == 0 ? 1.0 : 2.0);
      const double tol = a * u * (2.0 + 6.0 * log_n + (dev.info().fp64 ? 0.0 : n + 2.0 + band.kappa0 * f.s));
      for (std::size_t j = 0; j < bins.size(); ++j) {
        const cplx got = t.at(band.first_term + n, bins[j].first, bins[j].second);
        const double d = std::abs(got - ref_vals[(band.first_term + n) * bins.size() + j]);
        worst_abs = std::max(worst_abs, d);
        worst_ratio = std::max(worst_ratio, d / tol);
        ++checked;
      }
    }
  if (!(worst_ratio <= 1.0))
    throw JobError("self-check failed: device FFT terms differ from the double reference by " + format_g(worst_abs) +
                   " (" + format_g(worst_ratio) + " x the float32 FFT bound)");
  return {{"values_checked", checked}, {"max_abs_over_M2", worst_abs}, {"max_fraction_of_bound", worst_ratio}};
}

Terms rounded_to_half(const Terms& t) {
  Terms h = t;
  for (auto& v : h.values) v = static_cast<float>(Imath::half(v));
  return h;
}

// Linear sRGB of preview_xyz's picture, and each pixel's Y.
std::vector<float> preview_rgb(const std::vector<double>& xyz, int n, std::vector<double>& luminance) {
  luminance.assign(n * n, 0.0);
  const Mat3 M = xyz_to_srgb();
  std::vector<float> rgb(3 * n * n);
  for (int i = 0; i < n * n; ++i) {
    luminance[i] = xyz[3 * i + 1];
    const auto c = apply(M, xyz.data() + 3 * i);
    for (int r = 0; r < 3; ++r) rgb[3 * i + r] = static_cast<float>(c[r]);
  }
  return rgb;
}

json field_json(const Field& f) {
  return {{"width", f.width},   {"height", f.height}, {"dx_um", f.dx_um},  {"h_min_um", f.h_min},
          {"h_max_um", f.h_max}, {"h_mean_um", f.h_mean}, {"center_um", f.c}, {"scale_um", f.s}};
}

json plan_json(const DiffractionSpec& spec, const Field& f, const Plan& p) {
  json j;
  j["source"] = spec.source;
  j["field"] = field_json(f);
  j["expansion"] = name(spec.expansion);
  j["terms"] = p.total_terms;
  j["terms_requested"] = spec.terms ? json(*spec.terms) : json("auto");
  j["kappa_range"] = {p.kappa_lo, p.kappa_hi};
  j["y_max"] = p.y_max;
  j["bands"] = bands_json(p.bands);
  j["bins"] = {{"ku", {p.bins.ku_min, p.bins.ku_max}}, {"kv", {p.bins.kv_min, p.bins.kv_max}}};
  j["estimated_error_over_M2"] = std::isfinite(p.estimated_error) ? json(p.estimated_error) : json("infinite");
  j["tolerance"] = spec.tolerance;
  return j;
}

}  // namespace

json plan(const DiffractionSpec& spec, JobContext&) {
  const Field f = make_field(spec);
  const Plan p = make_plan(spec, f, spec.tolerance);
  json j = plan_json(spec, f, p);
  j["planned_bundle_mb"] = check_bundle_budget(spec, f, p);
  if (spec.table) {
    j["table"] = table_plan_json(spec, f, p);
    j["table_size"] = j["table"]["size"];
    j.erase("bins");  // a table job keeps no bins
  }
  return j;
}

namespace {

// What the steps of a bake pass on.
struct Work {
  Timings tm;
  Field f;
  std::unique_ptr<DeviceHeights> heights;  // uploaded once for the terms and the exact transforms
  std::unique_ptr<ExactDft> exact;
  Plan p;
  Terms terms;
  Measured m;
  json attempts = json::array();
  json error;
};

void plan_step(const DiffractionSpec& spec, JobContext& ctx, Work& w) {
  ctx.enter(Stage::plan);
  ctx.progress("field", 0.0);
  w.f = w.tm.time("field", [&] { return make_field(spec); });
  check_bundle_budget(spec, w.f, make_plan(spec, w.f, spec.tolerance));
  w.exact = w.tm.time("exact DFT plan", [&] {
    w.heights = std::make_unique<DeviceHeights>(ctx.device, w.f);
    return std::make_unique<ExactDft>(w.heights.get(), w.f, crop_bins(spec, w.f.width, w.f.height, w.f.dx_um));
  });
}

void compute_step(const DiffractionSpec& spec, JobContext& ctx, Work& w, BakeResult& r) {
  ctx.enter(Stage::compute);
  // --- plan, bake, measure; under `terms: auto` tighten the target if the measured error
  // exceeds the tolerance (the roundoff part of the bound is an estimate) ------------------
  Plan& p = w.p;
  Terms& terms = w.terms;
  Measured& m = w.m;
  json& attempts = w.attempts;
  const Field& f = w.f;
  ExactDft& exact = *w.exact;
  Timings& tm = w.tm;
  cl_util::Device& dev = ctx.device;
  double target = spec.tolerance;
  for (int attempt = 0;; ++attempt) {
    p = tm.time("plan", [&] { return make_plan(spec, f, target); });
    ctx.progress("FFT terms", 0.1);
    terms = device_terms(*w.heights, f, p, ctx.progress, &tm);
    m = measure(p, f, exact, terms, dev, ctx.progress, tm);
    attempts.push_back({{"target", target}, {"terms", p.total_terms}, {"bands", p.bands.size()},
                        {"measured_max_over_M2", m.max_over_m2}});
    if (spec.terms || m.max_over_m2 <= spec.tolerance) break;
    if (attempt == kAutoRefinements)
      throw JobError("terms: auto measured an error of " + format_g(m.max_over_m2) + " x M^2 at kappa = " +
                     format_g(m.at_kappa) + " rad/um, above the tolerance " + format_g(spec.tolerance) + " after " +
                     std::to_string(kAutoRefinements) + " refinements (" + std::to_string(p.total_terms) +
                     " terms); raise the tolerance");
    spdlog::info("terms: auto: measured {:.3g} > tolerance {:.3g} with {} terms; tightening the target",
                 m.max_over_m2, spec.tolerance, p.total_terms);
    target *= 0.25;
  }
  if (m.max_over_m2 > spec.tolerance)
    r.warnings.push_back("FIXED TERMS DO NOT MEET THE TOLERANCE: terms = " + std::to_string(*spec.terms) + " (" +
                         name(spec.expansion) + ") gives a measured error of " + format_g(m.max_over_m2) +
                         " x M^2 at kappa = " + format_g(m.at_kappa) + " rad/um (y_max = " + format_g(p.y_max) +
                         "), above the tolerance " + format_g(spec.tolerance) + "; use terms: auto");

}

void check_step(const DiffractionSpec& spec, JobContext& ctx, Work& w, BakeResult& r) {
  ctx.enter(Stage::check);
  const Plan& p = w.p;
  const Terms& terms = w.terms;
  const Measured& m = w.m;
  const Field& f = w.f;
  ExactDft& exact = *w.exact;
  Timings& tm = w.tm;
  cl_util::Device& dev = ctx.device;
  const bool meets = m.max_over_m2 <= spec.tolerance;
  ctx.progress("self-check", 0.85);
  const json device_check = tm.time("self-check", [&] { return self_check(dev, f, p, terms); });

  json error = {{"max_over_M2", m.max_over_m2},
                {"at_kappa", m.at_kappa},
                {"tolerance", spec.tolerance},
                {"meets_tolerance", meets},
                {"bound_estimate_over_M2", std::isfinite(p.estimated_error) ? json(p.estimated_error) : json("infinite")},
                {"kappas", m.kappas},
                {"per_kappa_over_M2", m.per_kappa},
                {"reference", exact.on_device() ? "double-precision VkFFT DFT of exp(i kappa h) on the device"
                                                : "double-precision host DFT of exp(i kappa h)"},
                {"reconstruction", "float32 terms.bin summed in double over the bins kept"}};
  if (spec.storage == Storage::half) {
    const Terms h = rounded_to_half(terms);
    const Measured mh = measure(p, f, exact, h, dev, ctx.progress, tm);
    error["exr_half_max_over_M2"] = mh.max_over_m2;
    error["exr_half_meets_tolerance"] = mh.max_over_m2 <= spec.tolerance;
    if (mh.max_over_m2 > spec.tolerance)
      r.warnings.push_back("the half-precision EXR copies reach an error of " + format_g(mh.max_over_m2) +
                           " x M^2, above the tolerance " + format_g(spec.tolerance) +
                           " (half has 11 bits); terms.bin (float32) meets " + format_g(m.max_over_m2));
  }
  if (!spec.terms) error["auto_attempts"] = w.attempts;

  r.accuracy.push_back(Accuracy::judged(
      "vs_exact_transform", "max |P - P_exact| / M^2 over the bins kept and the kappas checked", m.max_over_m2,
      spec.tolerance,
      exact.on_device() ? "double-precision DFT of exp(i kappa h) on the device" : "double-precision host DFT of exp(i kappa h)",
      error));
  r.accuracy.push_back(Accuracy::judged("self_check", "max |F_n device - F_n reference| / bound", 
                                        device_check["max_fraction_of_bound"].get<double>(), 1.0,
                                        "double-precision terms at a few bins", device_check));
  w.error = error;
}

void files_step(const DiffractionSpec& spec, JobContext& ctx, Work& w, BakeResult& r) {
  ctx.enter(Stage::files);
  const Plan& p = w.p;
  const Field& f = w.f;
  cl_util::Device& dev = ctx.device;
  // --- manifest block ----------------------------------------------------------------------
  const bool square = f.width == f.height;
  const bool same_bins = p.bins.ku_min == p.bins.kv_min && p.bins.ku_max == p.bins.kv_max;
  json block = {{"size", square ? json(f.width) : json({f.width, f.height})},
                {"dx_um", f.dx_um},
                {"center_um", f.c},
                {"scale_um", f.s},
                {"bins", same_bins ? json({p.bins.ku_min, p.bins.ku_max})
                                   : json({{"ku", {p.bins.ku_min, p.bins.ku_max}}, {"kv", {p.bins.kv_min, p.bins.kv_max}}})},
                {"bands", bands_json(p.bands)},
                {"terms", p.total_terms},
                {"expansion", name(spec.expansion)},
                {"kappa_range", {p.kappa_lo, p.kappa_hi}},
                {"y_max", p.y_max},
                {"window_sigma_bins", kWindowSigmaBins},
                {"formula",
                 "P(k;kappa) = M^2 * exp(i*kappa*center_um) * sum_{n<terms} coef_n * F[first_term+n][kv][ku] over the "
                 "band holding kappa; taylor: coef_n = ((kappa-kappa_expansion)*scale_um)^n/n!; chebyshev: coef_n = "
                 "T_n((kappa-kappa_expansion)/delta). kappa = 2*pi*w/lambda_um. M^2 = width*height."},
                {"dft_sign", "F[kv][ku] = sum f[iy][ix] exp(-2 pi i (ku ix/W + kv iy/H)) / (W H); ku pairs with x"},
                {"error", w.error}};
  r.parameters = plan_json(spec, f, p);
  r.manifest_blocks["diffraction"] = block;
  r.parameters["fft"] = "VkFFT float32 (OpenCL backend)";
  r.parameters["term_inputs_precision"] = dev.info().fp64 ? "float64" : "float32";

  const Terms& terms = w.terms;
  Timings& tm = w.tm;
  // --- files -----------------------------------------------------------------------------------
  ctx.progress("files", 0.9);
  const int ku = p.bins.ku_count(), kv = p.bins.kv_count();
  const std::string le = "little-endian float32, C order";
  if (spec.write_bin)
    tm.time("terms.bin", [&] {
      r.files.push_back({"terms.bin", float32_le(terms.values, "FFT terms"), "float32", {p.total_terms, kv, ku, 2},
                         le + "; [n][kv][ku][re,im], kv and ku ascending from the bins' lower ends (fftshifted)", "1",
                         "F_n = DFT(q_n)/M^2 of every band's terms (see the manifest's diffraction block)"});
    });
  const auto spectrum = add_spectrum_file(spec.range_nm, r);
  if (spec.write_exr)
    add_term_exrs(terms.values, p.bands, ku, kv, spec.storage, "terms", "terms.bin", "rows kv, columns ku (fftshifted)",
                  tm, r);
  if (spec.ktx2.enabled)
    tm.time("terms.ktx2", [&] {
      add_ktx2_file(spec.ktx2,
                    {"terms.ktx2", static_cast<std::uint32_t>(ku), static_cast<std::uint32_t>(kv), 0,
                     static_cast<std::uint32_t>(p.total_terms), 2, terms.values,
                     "2D array: layer n = F_n (the manifest's bands name each band's first layer), x = ku, y = kv "
                     "(fftshifted); R = Re, G = Im",
                     "1", "F_n on the FFT grid (KTX2 copy of terms.bin)", {}},
                    ctx, r);
    });

  ctx.progress("preview", 0.95);
  const int size = spec.preview_size > 0 ? spec.preview_size : kPreviewSize;
  if (!spec.previews) {
    // `previews: none`
  } else if (spec.w_max >= 1.0) {
    std::vector<double> lum;
    const auto rgb = tm.time("preview", [&] {
      return preview_rgb(preview_xyz(unless_cpu(dev), f, p, terms, spectrum, spec.w_max, size), size, lum);
    });
    std::vector<double> lit;
    for (double y : lum)
      if (y > 0) lit.push_back(y);
    std::sort(lit.begin(), lit.end());
    const double hi = lit.empty() ? 1.0 : lit[static_cast<std::size_t>(0.995 * (lit.size() - 1))];
    const int px = label_px(size);
    const auto labelled = [&](const std::vector<float>& shown, float exposure, const std::string& scale) {
      Rgb8 img = srgb8_image(size, size, shown, exposure);
      draw_label(img, Corner::top_left, {"D65, normal incidence"}, px);
      draw_label(img, Corner::bottom_left, {scale}, px);
      return png_rgb8(size, size, img.rgb);
    };
    r.files.push_back({"preview/white_normal.png",
                       labelled(rgb, static_cast<float>(hi > 0 ? 1.0 / hi : 1.0), "linear, white at 99.5th pct"), "",
                       {size, size, 3}, "", "",
                       "diffracted colour over the (u,v) disk, D65 at normal incidence, exposure at the 99.5th "
                       "percentile; labelled"});
    // Log scale: brightness log10(Y / Y_max) / D + 1 over the D decades below the brightest pixel that
    // hold 99 % of the lit pixels (D rounded up to half a decade, at least 1 and at most 8), black
    // below; the colour the pixel's linear sRGB scaled so that its largest channel is that
    // brightness (chromaticity kept, nothing above white).
    const double y_max = lit.empty() ? 1.0 : lit.back();
    const double y_low = lit.empty() ? 1.0 : lit[static_cast<std::size_t>(0.01 * (lit.size() - 1))];
    const double decades = std::clamp(std::ceil(2.0 * std::log10(y_max / y_low)) / 2.0, 1.0, 8.0);
    std::vector<float> logrgb(rgb.size(), 0.0f);
    for (std::size_t i = 0; i < lum.size(); ++i) {
      const float top = std::max({rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]});
      if (!(lum[i] > 0) || !(top > 0)) continue;
      const double level = std::max(0.0, std::log10(lum[i] / y_max) / decades + 1.0);
      for (int c = 0; c < 3; ++c) logrgb[3 * i + c] = static_cast<float>(rgb[3 * i + c] / top * level);
    }
    r.files.push_back({"preview/white_normal_log.png", labelled(logrgb, 1.0f, "log10 Y, " + format_g(decades) +
                                                                                    " decades below max"),
                       "", {size, size, 3}, "", "",
                       "the same on a log10 brightness scale over the " + format_g(decades) +
                           " decades below the brightest pixel (those holding 99 % of the lit pixels; black below), "
                           "each pixel's colour scaled to its largest channel; labelled"});
  } else {
    r.warnings.push_back("no preview: w_max < 1 does not reach normal incidence");
  }
  r.manifest_blocks["diffraction"]["timings_s"] = tm.json();
}

}  // namespace

BakeResult bake(const DiffractionSpec& spec, JobContext& ctx) {
  if (spec.table) return bake_table(spec, ctx);
  BakeResult r;
  Work w;
  w.tm.use(&ctx.device.profiler());
  plan_step(spec, ctx, w);
  compute_step(spec, ctx, w, r);
  check_step(spec, ctx, w, r);
  files_step(spec, ctx, w, r);
  ctx.progress("done", 1.0);
  return r;
}

}  // namespace specbake::diffraction
