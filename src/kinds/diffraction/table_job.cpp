// The diffraction job with a table (`table: {size, mapping, power, f_max_per_um, tolerance}`):
// the band/expansion plan of the full-bin job, the field weighted by the coherence window, the
// terms F_n at the N×N table texels by a non-uniform FFT, their error measured at texels and
// between them against direct sums, Parseval's energy ratio per κ, and the bundle size budget
// every diffraction job obeys (table.hpp and docs/diffraction-method.md, "Coherence and tables").
#include <Imath/half.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

#include "core/text.hpp"
#include "io/exr.hpp"
#include "io/label.hpp"
#include "io/png.hpp"
#include "kinds/diffraction/brdf.hpp"
#include "kinds/diffraction/shader.hpp"
#include "kinds/diffraction/diffraction_job.hpp"
#include "kinds/diffraction/planning.hpp"
#include "kinds/diffraction/table.hpp"
#include "kinds/diffraction/terms.hpp"

namespace specbake::diffraction {

using nlohmann::json;

namespace {

constexpr int kAutoRefinements = 3;
constexpr int kPhaseTexels = 1024;  // table columns per pass over the field (memory: table.cpp)
constexpr double kMB = 1e6;
constexpr double kPreviewIor = 1.5;  // the Fresnel term's dielectric index (shader and previews)
constexpr int kBrdfStepNm = 10;
constexpr int kFastWavelengths = 8;  // the shader's fast variant     // wavelength step of the previews' spectral sums
constexpr int kDefaultLobePanel = 256;     // pixels per side of each lobe panel (`previews: {size}` sets both)
constexpr int kDefaultSpherePixels = 512;  // the sphere preview's size
constexpr std::array<double, 3> kSphereLight = {2.0, 1.5, 3.0};

// Bytes of the data files: the float32 terms (.bin) and their EXR copies (float32 or half).
double term_bytes(const DiffractionSpec& spec, double terms, double texels) {
  const double ktx2 = spec.ktx2.enabled ? (spec.ktx2.half ? 8.0 : 16.0) : 0.0;  // RGBA per texel
  return terms * texels * (8.0 + (spec.storage == Storage::half ? 4.0 : 8.0) + ktx2);
}

// The table sizes a bake may use: the fixed size, or the ladder's sizes within the budget.
std::vector<int> candidate_sizes(const DiffractionSpec& spec, int terms) {
  if (spec.table->size) return {*spec.table->size};
  std::vector<int> out;
  for (int n : kTableLadder)
    if (term_bytes(spec, terms, static_cast<double>(n) * n) <= spec.max_bundle_mb * kMB) out.push_back(n);
  return out;
}

// Exposure that maps the 99.5th percentile of the lit pixels' luminance to 1.
float percentile_exposure(const std::vector<float>& rgb) {
  std::vector<double> lum;
  for (std::size_t i = 0; i + 2 < rgb.size(); i += 3) {
    const double y = 0.2126 * rgb[i] + 0.7152 * rgb[i + 1] + 0.0722 * rgb[i + 2];
    if (y > 0) lum.push_back(y);
  }
  if (lum.empty()) return 1.0f;
  std::sort(lum.begin(), lum.end());
  const double hi = lum[static_cast<std::size_t>(0.995 * static_cast<double>(lum.size() - 1))];
  return static_cast<float>(hi > 0 ? 1.0 / hi : 1.0);
}

// The BRDF previews (brdf.hpp): lobes for three light angles, and a lit sphere, over `wl`
// (every 10 nm); and the two fast shader variants' errors (the lobes over `fast`, and with the
// specular peak apart over `fast` and `wl`) against those, as fractions of the picture's peak
// (max and rms over the pixels and channels, and the max near the peak).
void add_brdf_previews(const BrdfPictures& pictures, const BrdfTable& t, const Wavelengths& wl, const Wavelengths& fast,
                       int size, BakeResult& r) {
  const int panel = size > 0 ? size : kDefaultLobePanel, sphere_px = size > 0 ? size : kDefaultSpherePixels;
  const std::vector<double> angles = {0.0, 30.0, 60.0};
  const auto lobes = pictures.lobes(wl, angles, panel);
  const float el = percentile_exposure(lobes);
  const int width = panel * static_cast<int>(angles.size());
  const std::string tone_label = "linear, white at 99.5th pct";
  Rgb8 lobe_img = srgb8_image(width, panel, lobes, el);
  for (std::size_t a = 0; a < angles.size(); ++a)
    draw_label(lobe_img, static_cast<int>(a) * panel, 0, {"light " + format_g(angles[a]) + "° from normal"},
               label_px(panel));
  draw_label(lobe_img, Corner::bottom_left, {tone_label}, label_px(panel));
  r.files.push_back({"preview/brdf_lobes.png", png_rgb8(width, panel, lobe_img.rgb), "",
                     {panel, width, 3}, "", "",
                     "Stam's diffraction BRDF from the table (Fresnel n = 1.5 and geometry factor, docs/diffraction.md) "
                     "times D65 over the outgoing hemisphere seen from above, light at 0, 30 and 60 degrees from the "
                     "normal in the x-z plane; exposure " + format_g(el) + " (99.5th percentile of the lit pixels); labelled"});
  const auto sphere = pictures.sphere(wl, kSphereLight, sphere_px);
  const float es = percentile_exposure(sphere);
  Rgb8 sphere_img = srgb8_image(sphere_px, sphere_px, sphere, es);
  draw_label(sphere_img, Corner::top_left, {"D65 point light at (2, 1.5, 3)"}, label_px(sphere_px));
  draw_label(sphere_img, Corner::bottom_left, {tone_label}, label_px(sphere_px));
  r.files.push_back({"preview/sphere.png", png_rgb8(sphere_px, sphere_px, sphere_img.rgb), "",
                     {sphere_px, sphere_px, 3}, "", "",
                     "a unit sphere covered by the surface (tangent x along circles about the vertical axis), seen along "
                     "-z, lit by a D65 point light at (2, 1.5, 3) radii; exposure " + format_g(es) +
                         " (99.5th percentile of the lit pixels); labelled"});
  double peak = 0;
  for (float v : lobes) peak = std::max(peak, static_cast<double>(std::fabs(v)));
  const double scale = peak > 0 ? 1.0 / peak : 0.0;
  // Pixels near the specular peak: where its shape G at 550 nm is ≥ 1e-2.
  const std::vector<float> peak_shape = brdf_lobes_specular_peak(t, angles, panel, 0.55);
  const auto record = [&](const std::string& name, const std::string& function, const std::vector<float>& quick,
                          const std::string& what) {
    double worst = 0, sq = 0, worst_near = 0;
    for (std::size_t i = 0; i < lobes.size(); ++i) {
      const double d = std::fabs(static_cast<double>(quick[i]) - lobes[i]);
      worst = std::max(worst, d);
      if (peak_shape[i] >= 1e-2f) worst_near = std::max(worst_near, d);
      sq += d * d;
    }
    r.accuracy.push_back(Accuracy::judged(
        name,
        "max |sRGB_fast - sRGB_full| / peak over the lobes picture (" + function + ", " + what +
            ", against diffraction_srgb every 10 nm)",
        worst * scale, std::nullopt, "the same BRDF every 10 nm",
        {{"wavelengths", fast.lambda_um.size()},
         {"rms_over_peak", std::sqrt(sq / lobes.size()) * scale},
         {"near_specular_max_over_peak", worst_near * scale},
         {"near_specular", "pixels where the specular peak's exp(-4 pi^2 sigma^2 |f|^2) at 550 nm is >= 1e-2"}}));
  };
  const std::string few = std::to_string(fast.lambda_um.size()) + " wavelengths";
  record("shader_fast_vs_full", "diffraction_srgb_fast", pictures.lobes(fast, angles, panel), few);
  record("shader_fast_specular_vs_full", "diffraction_srgb_fast_specular",
         pictures.lobes_fast_specular(fast, wl, angles, panel),
         few + " for the diffracted part, the specular peak every 10 nm");
}

json window_json(const DiffractionSpec& spec, const Window& w, double length_um) {
  json j = {{"type", "gaussian amplitude"},
            {"formula", "w(x,y) = exp(-(x^2 + y^2) / (2 sigma_um^2)), x, y from the patch centre; sigma = L/sqrt(2)"},
            {"sigma_um", w.sigma_um},
            {"coherence_length_um", length_um},
            {"sum", w.sum},
            {"sum_of_squares", w.sum_sq}};
  if (!spec.coherence.length_um) {
    j["source_angular_diameter_deg"] = spec.coherence.source_angular_diameter_deg;
    j["reference_wavelength_um"] = coherence_reference_lambda_um(spec);
    j["length_from"] = "van Cittert-Zernike, uniform disc: L = 2 lambda / (pi theta)";
  }
  return j;
}

json table_block(const DiffractionSpec& spec, const TableGeometry& g, const Window& w, double length_um) {
  return {{"size", g.size},
          {"mapping", spec.table->power_mapping ? "power" : "linear"},
          {"power", g.power},
          {"f_max_per_um", g.f_max},
          {"coherence_length_um", length_um},
          {"window", window_json(spec, w, length_um)},
          {"texel_to_frequency",
           "s = 2*(i + 0.5)/size - 1 per axis (i: column for f_u, row for f_v); f = sign(s)*|s|^power*f_max_per_um "
           "cycles/um; the shader looks up f = (u, v)/lambda_um"},
          {"origin", "x, y measured from the patch centre ((W-1)/2, (H-1)/2 samples): F_n differs from terms.bin's "
                     "corner-origin bins by a phase only"}};
}

}  // namespace

double check_bundle_budget(const DiffractionSpec& spec, const Field& f, const Plan& p) {
  const double terms = p.total_terms;
  const double budget = spec.max_bundle_mb * kMB;
  if (!spec.table) {
    const double bytes = term_bytes(spec, terms, static_cast<double>(p.bins.ku_count()) * p.bins.kv_count());
    if (bytes > budget)
      throw InputError(spec.budget_at,
                       "the planned bundle is " + format_g(bytes / kMB) + " MB, above max_bundle_mb = " +
                           format_g(spec.max_bundle_mb) + ": " + std::to_string(p.total_terms) + " terms (tolerance " +
                           format_g(spec.tolerance) + ", y_max " + format_g(p.y_max) + ") x " +
                           std::to_string(p.bins.ku_count()) + " x " + std::to_string(p.bins.kv_count()) +
                           " bins (field " + std::to_string(f.width) + " x " + std::to_string(f.height) + ", dx_um " +
                           format_g(f.dx_um) + ", range_nm lower end " + format_g(spec.range_nm.lo) +
                           ") x " + format_g(term_bytes(spec, 1.0, 1.0)) +
                           " bytes; use a table (table: {size: 256}) or raise max_bundle_mb");
    return bytes / kMB;
  }
  const int n = spec.table->size ? *spec.table->size : kTableLadder[0];
  const double bytes = term_bytes(spec, terms, static_cast<double>(n) * n);
  if (bytes > budget)
    throw InputError(spec.budget_at,
                     "the planned bundle is " + format_g(bytes / kMB) + " MB, above max_bundle_mb = " +
                         format_g(spec.max_bundle_mb) + ": " + std::to_string(p.total_terms) + " terms (tolerance " +
                         format_g(spec.tolerance) + ", y_max " + format_g(p.y_max) + ") x table " + std::to_string(n) + " x " +
                         std::to_string(n) + (spec.table->size ? "" : " (the smallest of size: auto)") +
                         " x 16 bytes; lower table.size, loosen tolerance or raise max_bundle_mb");
  return bytes / kMB;
}

json table_plan_json(const DiffractionSpec& spec, const Field& f, const Plan& p) {
  const double length = coherence_length_um(spec);
  const Window w = make_window(f, length / std::sqrt(2.0));
  const auto sizes = candidate_sizes(spec, p.total_terms);
  const TableGeometry g = table_geometry(spec, sizes.empty() ? 0 : sizes.front());
  json j = table_block(spec, g, w, length);
  j["size"] = spec.table->size ? json(*spec.table->size) : json("auto");
  j["candidate_sizes"] = sizes;
  return j;
}

BakeResult bake_table(const DiffractionSpec& spec, JobContext& ctx) {
  BakeResult r;
  Timings tm;
  tm.use(&ctx.device.profiler());
  ctx.enter(Stage::plan);
  ctx.progress("field", 0.0);
  const Field f = tm.time("field", [&] { return make_field(spec); });
  check_bundle_budget(spec, f, make_plan(spec, f, spec.tolerance));
  const double length = coherence_length_um(spec);
  const Window win = make_window(f, length / std::sqrt(2.0));

  ctx.enter(Stage::compute);
  const DeviceHeights heights = tm.time("field upload", [&] { return DeviceHeights(ctx.device, f); });
  Plan p;
  TableGeometry g;
  std::vector<float> values;
  TableError err;
  json attempts = json::array();
  double target = spec.tolerance;
  for (int refinement = 0;; ++refinement) {
    p = tm.time("plan", [&] { return make_plan(spec, f, target); });
    const auto sizes = candidate_sizes(spec, p.total_terms);
    if (sizes.empty())
      throw JobError("table: auto: " + std::to_string(p.total_terms) + " terms leave no table size of the ladder within " +
                     "max_bundle_mb = " + format_g(spec.max_bundle_mb));
    std::vector<TableGeometry> geoms;
    for (int n : sizes) geoms.push_back(table_geometry(spec, n));
    // The candidate sizes in phases of at most kPhaseTexels table columns: each phase's tables
    // come from one pass over the field; the between-texel error (its exact values shared by
    // all sizes) picks the first size that meets table.tolerance, and later phases run only if
    // none of an earlier phase did. The chosen table is then measured at texels and for energy.
    ctx.progress("error measurement", 0.1);
    const TableMeasurement meas =
        tm.time("error measurement", [&] { return TableMeasurement(&heights, f, win, geoms.front(), measurement_kappas(p)); });
    std::size_t chosen = 0;
    bool met = false;
    for (std::size_t first = 0; first < sizes.size() && !met;) {
      std::size_t last = first, columns = 0;
      while (last < sizes.size() && (last == first || columns + sizes[last] <= kPhaseTexels)) columns += sizes[last++];
      const std::vector<TableGeometry> phase(geoms.begin() + first, geoms.begin() + last);
      const double at = static_cast<double>(first) / sizes.size(), span = static_cast<double>(last - first) / sizes.size();
      const auto tables = tm.time("table terms", [&] {
        return table_terms_fft(heights, f, win, p.bands, phase,
                               [&](double done) { ctx.progress("table terms", 0.2 + 0.6 * (at + span * done)); });
      });
      for (std::size_t k = first; k < last && !met; ++k) {
        chosen = k;
        values = tables[k - first];
        const double between = tm.time("error measurement", [&] { return meas.between_max(p.bands, geoms[k], values); });
        attempts.push_back({{"target", target}, {"terms", p.total_terms}, {"size", sizes[k]}, {"between_texels_max", between}});
        spdlog::debug("table {}: {} terms, error between texels {:.3g}", sizes[k], p.total_terms, between);
        met = between <= spec.table->tolerance;
      }
      first = last;
    }
    g = geoms[chosen];
    err = tm.time("error measurement", [&] { return meas.measure(p.bands, g, values); });
    attempts.back()["at_texels_max"] = err.texel_max;
    if (spec.terms || err.texel_max <= spec.tolerance || refinement == kAutoRefinements) break;
    spdlog::info("table: measured {:.3g} at texels > tolerance {:.3g} with {} terms; tightening the target",
                 err.texel_max, spec.tolerance, p.total_terms);
    target *= 0.25;
  }
  if (!spec.table->size && err.between_max > spec.table->tolerance) {
    const bool capped = g.size < std::end(kTableLadder)[-1];  // larger sizes exceed max_bundle_mb
    throw JobError("table: size: auto: no size of the ladder up to " + std::to_string(g.size) +
                   " meets table.tolerance " + format_g(spec.table->tolerance) + " between texels (largest: " +
                   format_g(err.between_max) + " x the window's sum at kappa = " + format_g(err.between_at_kappa) +
                   (capped ? "; the larger sizes exceed max_bundle_mb = " + format_g(spec.max_bundle_mb) : std::string()) +
                   "); use " + (spec.table->power_mapping ? "" : "mapping: power, ") +
                   "a shorter coherence length (coherence)" + (capped ? ", a larger max_bundle_mb" : "") +
                   " or a looser table.tolerance");
  }
  if (err.texel_max > spec.tolerance)
    r.warnings.push_back("THE TABLE'S TEXELS DO NOT MEET THE TOLERANCE: measured " + format_g(err.texel_max) +
                         " x the window's sum at kappa = " + format_g(err.texel_at_kappa) + " rad/um, tolerance " +
                         format_g(spec.tolerance));
  if (spec.table->size && err.between_max > spec.table->tolerance)
    r.warnings.push_back("the fixed table size " + std::to_string(g.size) + " gives " + format_g(err.between_max) +
                         " x the window's sum between texels, above table.tolerance " + format_g(spec.table->tolerance));
  double min_energy = 1e300;
  for (double e : err.energy_ratio) min_energy = std::min(min_energy, e);

  ctx.enter(Stage::check);
  json error = err.json();
  error["tolerance_at_texels"] = spec.tolerance;
  error["tolerance_between_texels"] = spec.table->tolerance;
  error["normalisation"] = "|P - P_exact| / sum_j w_j (the window's sum: |P| at f = 0, kappa = 0)";
  error["attempts"] = attempts;
  r.accuracy.push_back(Accuracy::judged(
      "table_vs_exact_transform", "max |P - P_exact| / sum(w) at table texels over the kappas checked", err.texel_max,
      spec.tolerance, "direct double-precision sum of w * exp(i kappa h) (non-uniform DFT)", error));
  r.accuracy.push_back(Accuracy::judged(
      "table_between_texels", "max |P_bilinear - P_exact| / sum(w) between texels over the kappas checked",
      err.between_max, spec.table->tolerance, "direct double-precision sum of w * exp(i kappa h) (non-uniform DFT)",
      {{"p99", err.between_p99}, {"at_kappa", err.between_at_kappa}}));
  r.accuracy.push_back(Accuracy::judged(
      "table_energy", "min over kappa of sum |P|^2 * texel area / (sum w^2 / dx^2) (Parseval; 1 = all energy kept)",
      min_energy, std::nullopt, "the window's energy",
      {{"kappas", err.kappas}, {"energy_ratio", err.energy_ratio}}));

  ctx.enter(Stage::files);
  ctx.progress("files", 0.9);
  json block = {{"size", f.width == f.height ? json(f.width) : json({f.width, f.height})},
                {"dx_um", f.dx_um},
                {"center_um", f.c},
                {"scale_um", f.s},
                {"bands", bands_json(p.bands)},
                {"terms", p.total_terms},
                {"expansion", spec.expansion == Expansion::taylor ? "taylor" : "chebyshev"},
                {"kappa_range", {p.kappa_lo, p.kappa_hi}},
                {"y_max", p.y_max},
                {"formula",
                 "P(f;kappa) = M^2 * exp(i*kappa*center_um) * sum_{n<terms} coef_n * F[first_term+n][iv][iu] over the "
                 "band holding kappa; taylor: coef_n = ((kappa-kappa_expansion)*scale_um)^n/n!; chebyshev: coef_n = "
                 "T_n((kappa-kappa_expansion)/delta). kappa = 2*pi*w/lambda_um. M^2 = width*height."},
                {"dft_sign", "F(fu,fv) = sum w f[iy][ix] exp(-2 pi i (fu x + fv y)) / (W H), x = (ix-(W-1)/2) dx_um, "
                             "y = (iy-(H-1)/2) dx_um; fu pairs with x"},
                {"table", table_block(spec, g, win, length)},
                {"error", error}};
  r.parameters = {{"source", spec.source},
                  {"expansion", spec.expansion == Expansion::taylor ? "taylor" : "chebyshev"},
                  {"terms", p.total_terms},
                  {"kappa_range", {p.kappa_lo, p.kappa_hi}},
                  {"y_max", p.y_max},
                  {"bands", bands_json(p.bands)},
                  {"table_size", g.size},
                  {"coherence_length_um", length},
                  {"tolerance", spec.tolerance}};
  const int n = g.size;
  const std::string le = "little-endian float32, C order";
  if (spec.write_bin)
    r.files.push_back({"table_terms.bin", float32_le(values, "table terms"), "float32", {p.total_terms, n, n, 2},
                       le + "; [n][iv][iu][re,im], texel centres s = 2(i+0.5)/N - 1 mapped as the manifest's table block",
                       "1", "F_n of every band's terms at the table texels (see the manifest's diffraction block)"});
  const auto spectrum = add_spectrum_file(spec.range_nm, r);
  if (spec.write_exr)
    add_term_exrs(values, p.bands, n, n, spec.storage, "table", "table_terms.bin",
                  "rows iv (f_v), columns iu (f_u), table texels", tm, r);
  if (spec.ktx2.enabled)
    tm.time("table_terms.ktx2", [&] {
      add_ktx2_file(spec.ktx2,
                    {"table_terms.ktx2", static_cast<std::uint32_t>(n), static_cast<std::uint32_t>(n), 0,
                     static_cast<std::uint32_t>(p.total_terms), 2, values,
                     "2D array: layer n = F_n (the manifest's bands name each band's first layer), x = iu (f_u), "
                     "y = iv (f_v), table texels; R = Re, G = Im",
                     "1", "F_n at the table texels (KTX2 copy of table_terms.bin; sampler2DArray of the shader)", {}},
                    ctx, r);
    });
  const Wavelengths fast = bins(spectrum, kFastWavelengths);
  r.files.push_back({"shader/diffraction_brdf.glsl", diffraction_glsl(f, p.bands, g, win, kPreviewIor, fast), "", {},
                     "", "", "GLSL: the table's lookup and the BRDF the previews draw (Stam, relative form)"});
  ctx.progress("preview", 0.95);
  if (spec.previews) tm.time("preview", [&] {
    const BrdfTable table{f, p.bands, g, values, win.sum, kPreviewIor, win.sigma_um};
    // on a CPU device the host's threads (3.3 s against 2.3 s for the 8192² benchmark's previews)
    add_brdf_previews(BrdfPictures(table, unless_cpu(ctx.device)), table, every_nm(spectrum, kBrdfStepNm), fast,
                      spec.preview_size, r);
  });
  block["timings_s"] = tm.json();
  r.manifest_blocks["diffraction"] = block;
  ctx.progress("done", 1.0);
  return r;
}

}  // namespace specbake::diffraction
