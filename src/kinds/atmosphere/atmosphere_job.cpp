#include "kinds/atmosphere/atmosphere_job.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <mutex>
#include <optional>

#include "core/parallel.hpp"
#include "core/text.hpp"
#include "core/version.hpp"
#include "io/exr.hpp"
#include "kinds/atmosphere/bake/reference.hpp"
#include "kinds/atmosphere/search/auto_settings.hpp"

namespace specbake::atmosphere {

using nlohmann::json;

namespace {

std::string exr_of(int width, int height, const std::vector<double>& rgb,
                   const std::map<std::string, std::string>& attributes) {
  ExrImage img;
  img.width = width;
  img.height = height;
  img.channels = {"R", "G", "B"};
  img.pixels.assign(rgb.begin(), rgb.end());
  img.attributes = attributes;
  return exr_bytes(img);
}

}  // namespace

double estimated_seconds(const AtmosphereSpec& spec) {
  if (spec.auto_sizes || spec.auto_spectrum) {
    const AtmosphereSpec start = search_start(spec);
    AtmosphereSpec bare = start;  // what each try costs; the interpolation pass runs once
    bare.store_radiance = false;
    // the truth is traced once and kept for every try, and once more at the held-out points;
    // the chosen bake's twilight strip once
    return kTypicalTries * bake_seconds(bare) + (bake_seconds(start) - bake_seconds(bare)) + 2.0 * check_seconds(start) +
           twilight_strip_seconds(start);
  }
  return bake_seconds(spec) + check_seconds(spec) + twilight_strip_seconds(spec);
}

std::optional<KeptCost> kept_estimated_seconds(const AtmosphereSpec& spec, JobContext& ctx) {
  if (!ctx.memo) return std::nullopt;
  if (!(spec.auto_sizes || spec.auto_spectrum)) {
    if (!scene_truth_kept(spec, spec.orders, ctx.device, *ctx.memo)) return std::nullopt;
    return KeptCost{bake_seconds(spec), "2-core CPU model, the scene's truth kept"};
  }
  const std::optional<KeptSearch> k = find_kept_search(spec, ctx.device, *ctx.memo);
  if (!k) return std::nullopt;
  // the choice's bake; its scene check reads kept truths
  return KeptCost{bake_seconds(with_settings(spec, k->chosen)), "2-core CPU model of the kept search's choice"};
}

std::vector<double> interpolation_test_wavelengths(const std::vector<double>& stored) {
  std::vector<double> out;
  const int gaps = static_cast<int>(stored.size()) - 1;
  if (gaps < 1) return out;
  const int n = std::min(gaps, kInterpolationTests);
  for (int k = 0; k < n; ++k) {
    const int i = n == 1 ? 0 : static_cast<int>(std::lround(double(k) * (gaps - 1) / (n - 1)));
    out.push_back(0.5 * (stored[i] + stored[i + 1]));
  }
  return out;
}

InterpolationError interpolation_error(const Model& m, const SpectralLuts& stored, const SpectralLuts& exact) {
  const SpectralRenderer at(m, stored), ref(m, exact);
  const Vec3 camera{0.0, 0.0, m.bottom_radius_km + kFisheyeAltitudeKm}, ground{0.0, 0.0, m.bottom_radius_km},
      up{0.0, 0.0, 1.0};
  // one wavelength's values, interpolated and exact, then their relative errors (floor: 1e-3 of
  // the largest exact value at that wavelength)
  struct Pairs {
    std::vector<double> test, truth;
    void errors_into(std::vector<double>& out) const {
      double top = 0.0;
      for (double v : truth) top = std::max(top, std::fabs(v));
      for (std::size_t i = 0; i < truth.size(); ++i)
        out.push_back(std::fabs(test[i] - truth[i]) / std::max(std::fabs(truth[i]), 1e-3 * top));
    }
  };
  std::vector<double> radiance, transmittance, irradiance;
  for (std::size_t w = 0; w < exact.lambda_nm.size(); ++w) {
    const double lambda = exact.lambda_nm[w];
    Pairs l, t, e;
    for (const FisheyeView& v : kFisheyeViews) {
      const Vec3 sun = fisheye_sun(v);
      for (int p = 0; p < kInterpolationGrid * kInterpolationGrid; ++p) {
        Vec3 view;
        if (!fisheye_direction((2.0 * (p % kInterpolationGrid) + 1.0) / kInterpolationGrid - 1.0, (2.0 * (p / kInterpolationGrid) + 1.0) / kInterpolationGrid - 1.0, view))
          continue;
        double t_test = 0.0, t_truth = 0.0;
        l.test.push_back(at.sky_radiance(camera, view, sun, lambda, &t_test));
        l.truth.push_back(ref.sky_radiance_stored(camera, view, sun, static_cast<int>(w), &t_truth));
        if (t_truth > 0.0) {  // rays that meet the ground have none
          t.test.push_back(t_test);
          t.truth.push_back(t_truth);
        }
      }
      double sky_test = 0.0, sky_truth = 0.0;
      e.test.push_back(at.sun_and_sky_irradiance(ground, up, sun, lambda, &sky_test));
      e.truth.push_back(ref.sun_and_sky_irradiance_stored(ground, up, sun, static_cast<int>(w), &sky_truth));
      e.test.push_back(sky_test);
      e.truth.push_back(sky_truth);
    }
    l.errors_into(radiance);
    t.errors_into(transmittance);
    e.errors_into(irradiance);
  }
  return {summarize_errors(radiance), summarize_errors(transmittance), summarize_errors(irradiance)};
}

// With sizes: auto / spectrum: auto the plan runs the search (it bakes its tries on the device
// and publishes nothing) and shows the chosen settings and their predicted bake time. The search
// is kept in the output's result store, where `run` finds it and bakes the choice without
// searching again; a search kept by an earlier plan or run is shown without baking anything.
json plan(const AtmosphereSpec& spec, JobContext& ctx) {
  if (!spec.auto_sizes && !spec.auto_spectrum) return parameters_json(spec);
  Memo local;
  Memo& memo = ctx.memo ? *ctx.memo : local;
  AtmosphereSpec resolved;
  json record;
  bool met = false;
  std::string failure;
  if (std::optional<KeptSearch> k = find_kept_search(spec, ctx.device, memo)) {
    resolved = with_settings(spec, k->chosen);
    resolved.scene.relative_se = k->relative_se;
    record = k->record;
    record["reused"] = k->entry;
    met = k->met;
    failure = k->failure;
  } else {
    AutoSearch found = kept_search_settings(spec, ctx.device, ctx.progress, memo);
    resolved = found.resolved;
    record = found.record;
    met = found.met;
    failure = found.failure;
  }
  json p = parameters_json(resolved);
  p["auto"] = record;
  if (!met) {
    if (ctx.judge) throw BakeFailed(failure, p);  // as `run` would fail: its best try reported
    p["auto"]["failure"] = failure;
  }
  return p;
}

namespace {

// The job's progress fractions: the compute ends at compute_end (the passes report 0..0.9 of
// their own), the scene check and the twilight strip at check_end (the strip from strip_from),
// the files and previews take the rest. From the cost model (bake_seconds, check_seconds,
// twilight_strip_seconds) so that the progress line's rate-based ETA holds in a twilight scene,
// whose check takes several times its bake, and after a run that kept the scene's truth, whose
// check takes ~0 s.
struct Shares {
  double compute_end = 0.9, strip_from = 0.92, check_end = 0.92;
};

Shares job_shares(const AtmosphereSpec& spec, JobContext& ctx) {
  const bool kept = ctx.memo && scene_truth_kept(spec, spec.orders, ctx.device, *ctx.memo);
  const double check = kept ? 0.0 : check_seconds(spec), strip = kept ? 0.0 : twilight_strip_seconds(spec);
  const double files = bake_files_seconds(spec);
  const double compute = std::max(bake_seconds(spec) - files, 0.1);
  const double total = compute + check + strip + files;
  return {compute / total, (compute + check) / total, (compute + check + strip) / total};
}

// What the manifest says of the orders and passes of a bake.
void record_orders(const AtmosphereSpec& spec, const Baked& b, BakeResult& r) {
  r.parameters["orders"] = {{"requested", spec.orders ? json(*spec.orders) : json("auto")},
                            {"used", b.orders_used},
                            {"tail", takes_geometric_tail(spec) ? "geometric" : "none"},
                            {"converged", b.converged},
                            {"tolerance", spec.tolerance},
                            {"per_order", b.orders},
                            {"note", "order 1 = single scattering; 'scattering' is what the order adds to "
                                     "scattering.bin (order 1: single Rayleigh; n >= 2: deltaS_n / P_R(nu)), "
                                     "'irradiance' what its light adds to irradiance.bin (orders 1..used-1; with tail: "
                                     "geometric the last order's deltaS and irradiance are those of every order "
                                     "from it on); "
                                     "relative_change = max over texels above 1e-4 of their channel's maximum of "
                                     "added / accumulated, over scattering (order n) and irradiance (order n-1)"}};
  r.parameters["pass_details"] = b.passes;
  if (!b.converged)
    r.warnings.push_back("orders: auto stopped at the cap of " + std::to_string(kMaxAutoOrders) +
                         " orders before an order added less than the tolerance " + format_g(spec.tolerance));
}

void compute_step(const AtmosphereSpec& spec, const Shares& share, JobContext& ctx, BakeResult& r, Baked& b) {
  ctx.enter(Stage::compute);
  const double scale = share.compute_end / 0.9;
  b = bake_luts(spec, ctx.device, [&](std::string_view what, double f) { ctx.progress(what, f * scale); }, 24);
  record_orders(spec, b, r);
}

// sizes: auto / spectrum: auto: the search's bakes are the compute step; the chosen one is kept.
// The search judges its choice itself: after it only the files are left (and the strip).
constexpr double kSearchShare = 0.9;
AtmosphereSpec search_step(const AtmosphereSpec& spec, JobContext& ctx, BakeResult& r, Baked& b,
                           std::optional<SceneCheck>& checked, SceneCheck& held_out, int& held_out_first) {
  ctx.enter(Stage::compute);
  AutoSearch found = kept_search_settings(
      spec, ctx.device, [&](std::string_view what, double f) { ctx.progress(what, f * kSearchShare); }, *ctx.memo);
  b = std::move(found.baked);
  checked = std::move(found.check);  // the search judged its choice already, and at held-out points
  held_out = std::move(found.held_out);
  held_out_first = found.held_out_first;
  const AtmosphereSpec& use = found.resolved;
  const json auto_record = found.record;
  r.parameters = parameters_json(use);
  r.parameters["auto"] = auto_record;
  record_orders(use, b, r);
  if (!found.met) {
    if (ctx.judge) throw BakeFailed(found.failure, r.parameters, accuracy_json({checked->record}), r.warnings);
    r.warnings.push_back(found.failure);
  }
  return use;
}

// The chosen settings as the search judged them at an independent point set of the same scene
// (the last round's held-out points).
void held_out_step(SceneCheck held, int first, BakeResult& r) {
  Accuracy a = std::move(held.record);
  a.name = "vs_path_traced_held_out";
  a.metric += " (an independent point set of the same scene: the search did not see it)";
  a.details["first_point"] = first;
  const std::size_t rounds = r.parameters.contains("auto") ? r.parameters["auto"].value("rounds", json::array()).size() : 1;
  if (!a.passed)
    r.warnings.push_back("auto settings: the held-out points' p99 " + format_g(a.value) +
                         " exceeds the tolerance " + format_g(*a.tolerance) + " (the search judged " +
                         std::to_string(first) + " points in " + std::to_string(rounds) +
                         " round(s)): more scene.points pin the p99 better");
  // after the headline (vs_path_traced) and before the self-check
  r.accuracy.insert(r.accuracy.begin() + 1, a);
}

// Where interpolation_error compares (the manifest's words).
std::string interpolation_points() {
  std::string suns;
  for (const FisheyeView& v : kFisheyeViews) suns += (suns.empty() ? "" : ", ") + format_g(v.sun_elevation_deg);
  const std::string n = std::to_string(kInterpolationGrid);
  return "the preview fisheyes (sun at " + suns + " deg; " + n + " x " + n + " directions each, " +
         format_g(kFisheyeAltitudeKm * 1e3) + " m above the ground) and each sun's sun and sky irradiance on the ground";
}

// `store: radiance`: the interpolation between stored wavelengths measured against a bake at
// wavelengths halfway between them (same model, sizes and orders; one more pass on the device),
// recorded as reported accuracy (not judged: the wavelength count is the user's choice).
void interpolation_step(const AtmosphereSpec& spec, const Shares& share, const Baked& b, JobContext& ctx,
                        BakeResult& r) {
  ctx.enter(Stage::check);
  const std::vector<double> lambdas = interpolation_test_wavelengths(b.radiance.lambda_nm);
  if (lambdas.empty()) return;
  ctx.progress("spectral interpolation check", share.check_end);
  const Model& m = b.luts.model;
  const Channels ch = channels_at(spec, lambdas);
  const int width = pass_width_for(lambdas.size());
  auto backend = make_device_backend(ctx.device, m, ch, width, spec.double_precision);
  PassPlan plan;  // the stored bake's order count, all textures kept
  plan.orders = b.orders_used;
  plan.tolerance = spec.tolerance;
  const PassResult pass = run_pass(*backend, plan, [](std::string_view, double) {}, 0.0, 1.0);
  SpectralLuts exact;
  exact.lambda_nm = ch.lambda_nm;
  exact.solar_irradiance = ch.solar_irradiance;
  keep_radiance(exact, m.sizes, 0, static_cast<int>(lambdas.size()), width, pass);
  const InterpolationError e = interpolation_error(m, b.radiance, exact);
  r.accuracy.push_back(Accuracy::judged(
      "spectral_interpolation", "max relative error of the sky radiance interpolated between stored wavelengths",
      e.radiance.max, std::nullopt,
      "a bake at wavelengths halfway between stored ones (same model, sizes and " + std::to_string(b.orders_used) +
          " orders)",
      {{"test_wavelengths_nm", lambdas},
       {"stored_step_nm", b.radiance.step_nm()},
       {"sky_radiance", summary_json(e.radiance)},
       {"transmittance", summary_json(e.transmittance)},
       {"sun_and_sky_irradiance", summary_json(e.irradiance)},
       {"points", interpolation_points()},
       {"floor", "errors relative to max(|exact|, 1e-3 x the largest exact value at that wavelength)"},
       {"functions", "GetSkyRadianceAtWavelength, GetSunAndSkyIrradianceAtWavelength (sampling_spectral.glsl)"}}));
}

}  // namespace



namespace {

// `checked`: the scene check already made of these LUTs (an auto search's), not made again.
void check_step(const AtmosphereSpec& spec, const Shares& share, const Baked& b, JobContext& ctx, BakeResult& r,
                std::optional<SceneCheck> checked = std::nullopt) {
  ctx.enter(Stage::check);
  r.accuracy.push_back(judge_self_checks(b));
  if (!spec.scene.check) return;
  // the error in the user's scene: the LUTs against the path-traced truth at the scene's points
  SceneCheck sc = checked ? std::move(*checked)
                          : check_scene(spec, b.luts, b.orders_used, ctx.device, [&](std::string_view what, double f) {
                              ctx.progress(what, share.compute_end + (share.strip_from - share.compute_end) * f);
                            }, ctx.memo);
  r.accuracy.insert(r.accuracy.begin(), sc.record);  // the headline: the error the user sees
  r.files.push_back(std::move(sc.points_csv));
  r.manifest_blocks["atmosphere"]["scene_check_s"] = sc.seconds;
  if (wants_twilight_strip(spec)) {
    // the sunset beside the truth (a preview; its own walks, kept as the scene's)
    Memo local;
    TwilightStrip strip = twilight_strip(spec, b.luts, ctx.device, ctx.memo ? *ctx.memo : local,
                                         [&](std::string_view, double f) {
                                           ctx.progress("twilight strip",
                                                        share.strip_from + (share.check_end - share.strip_from) * f);
                                         });
    r.files.push_back(std::move(strip.png));
    r.manifest_blocks["atmosphere"]["twilight_strip"] = std::move(strip.record);
  }
  for (std::string& w : sc.warnings) r.warnings.push_back(std::move(w));
  if (!sc.failure.empty()) {
    if (ctx.judge) throw BakeFailed(sc.failure, r.parameters, accuracy_json(r.accuracy), r.warnings);
    r.warnings.push_back(sc.failure);
  }
}

// The scattering sizes as the KTX2 files' specbake.sizes value.
std::string sizes_key(const Sizes& s) {
  return "r=" + std::to_string(s.r) + " mu=" + std::to_string(s.mu) + " mu_s=" + std::to_string(s.mu_s) +
         " nu=" + std::to_string(s.nu);
}

// `ktx2: {scattering: rgba-combined}`: scattering.ktx2 holds the scattering texture's RGB and
// single Mie's red in alpha (Bruneton's combined textures), and single Mie's other channels are
// rebuilt in the shader (GetCombinedScattering3D). What that rebuild costs is measured at every
// texel from the float32 data and recorded (reported, not judged: it is the model's choice).
void combined_ktx2_file(const AtmosphereSpec& spec, const Luts& L, const std::string& units, const std::string& param,
                        const std::string& sizes, const JobContext& ctx, BakeResult& r) {
  const Sizes& s = L.model.sizes;
  const std::size_t texels = L.scattering.size() / 3;
  std::vector<float> rgba(4 * texels);
  double m_max = 0.0;
  for (double v : L.single_mie) m_max = std::max(m_max, std::fabs(static_cast<double>(static_cast<float>(v))));
  const auto& br = L.rgb.rayleigh_scattering;
  const auto& bm = L.rgb.mie_scattering;
  double worst = 0.0;
  std::vector<double> errors;
  std::size_t worst_at = 0;
  for (std::size_t i = 0; i < texels; ++i) {
    for (int c = 0; c < 3; ++c) rgba[4 * i + c] = static_cast<float>(L.scattering[3 * i + c]);
    rgba[4 * i + 3] = static_cast<float>(L.single_mie[3 * i]);
    for (int c = 1; c < 3; ++c) {  // red is stored as it is
      const double truth = static_cast<float>(L.single_mie[3 * i + c]);
      if (std::fabs(truth) < 1e-3 * m_max) continue;
      const double rebuilt =
          ref3::extrapolated_single_mie(rgba[4 * i + c], rgba[4 * i], rgba[4 * i + 3], br[0], bm[0], br[c], bm[c]);
      const double e = std::fabs(rebuilt - truth) / std::fabs(truth);
      errors.push_back(e);
      if (e > worst) {
        worst = e;
        worst_at = i;
      }
    }
  }
  const ErrorSummary summary = summarize_errors(errors);
  const std::uint32_t wd = static_cast<std::uint32_t>(s.scattering_width());
  const std::string layout = "3D: x = nu_slice*MU_S + mu_s, y = mu, z = r; RGB = scattering, A = single Mie red";
  add_ktx2_file(spec.ktx2,
                {"scattering.ktx2", wd, std::uint32_t(s.mu), std::uint32_t(s.r), 0, 4, rgba, layout, units,
                 "scattering with single Mie's red in alpha (rgba-combined; GetCombinedScattering3D rebuilds single "
                 "Mie's green and blue)",
                 {{"specbake.parameterisation", param}, {"specbake.sizes", sizes}}},
                ctx, r);
  r.accuracy.push_back(Accuracy::judged(
      "rgba_combined:single_mie", "max relative error of single Mie's green and blue rebuilt from the combined texture",
      worst, std::nullopt, "single_mie_scattering.bin (float32)",
      {{"values_counted", summary.count},
       {"floor", "green and blue values of single Mie at least 1e-3 of its largest value"},
       {"median_relative_error", summary.median},
       {"p99_relative_error", summary.p99},
       {"worst_texel", worst_at},
       {"formula", "s_c * m_r / s_r * (beta_R,r / beta_M,r) * (beta_M,c / beta_R,c) (lookup.cl, extrapolated_single_mie)"}}));
}

// KTX2 copies of the textures: 2D transmittance [r][mu] and irradiance [r][mu_s], 3D
// scattering and single Mie (x = nu*mu_s, y = mu, z = r), RGB padded to RGBA with alpha 1. Half
// files carry an accuracy record of their rounding against the float32 data (.bin).
void ktx2_files(const AtmosphereSpec& spec, const Luts& L, const std::string& units, const std::string& param,
                const JobContext& ctx, BakeResult& r) {
  const Sizes& s = L.model.sizes;
  struct Texture {
    bool wanted;
    const char* name;
    const std::vector<double>* data;
    std::uint32_t width, height, depth;
    const char* layout;
    const std::string& units;
  };
  const std::uint32_t wd = static_cast<std::uint32_t>(s.scattering_width());
  const std::string unitless = "1";  // transmittance is a ratio, as in its .bin and .exr
  const Texture textures[] = {
      {spec.out_transmittance, "transmittance", &L.transmittance, std::uint32_t(s.transmittance_w),
       std::uint32_t(s.transmittance_h), 0, "2D: x = mu coordinate, y = r coordinate", unitless},
      {spec.out_irradiance, "irradiance", &L.irradiance, std::uint32_t(s.irradiance_w), std::uint32_t(s.irradiance_h), 0,
       "2D: x = mu_s coordinate, y = r coordinate", units},
      {spec.out_scattering && !spec.ktx2_combined, "scattering", &L.scattering, wd, std::uint32_t(s.mu),
       std::uint32_t(s.r), "3D: x = nu_slice*MU_S + mu_s, y = mu, z = r", units},
      {spec.out_single_mie && !spec.ktx2_combined, "single_mie_scattering", &L.single_mie, wd, std::uint32_t(s.mu),
       std::uint32_t(s.r), "3D: x = nu_slice*MU_S + mu_s, y = mu, z = r", units}};
  const SkyView& v = L.model.sky_view;
  const std::uint32_t sv_w = std::uint32_t(v.azimuth), sv_h = std::uint32_t(v.view),
                      sv_d = std::uint32_t(v.sun * v.altitude);
  const char* sv_layout = "3D: x = azimuth, y = view, z = sun*ALTITUDE + altitude";
  const Texture tables[] = {{v.on(), "sky_view", &L.sky_view, sv_w, sv_h, sv_d, sv_layout, units},
                            {v.on(), "sky_view_single_mie", &L.sky_view_mie, sv_w, sv_h, sv_d, sv_layout, units}};
  const std::string sizes = sizes_key(s);
  for (const Texture& t : tables) {
    if (!t.wanted) continue;
    const std::vector<float> f(t.data->begin(), t.data->end());
    add_ktx2_file(spec.ktx2,
                  {std::string(t.name) + ".ktx2", t.width, t.height, t.depth, 0, 3, f, t.layout, t.units,
                   std::string(t.name) + " (KTX2 copy)", {{"specbake.parameterisation", "the sky-view table (sampling.glsl)"}}},
                  ctx, r);
  }
  for (const Texture& t : textures) {
    if (!t.wanted) continue;
    const std::vector<float> f(t.data->begin(), t.data->end());
    add_ktx2_file(spec.ktx2,
                  {std::string(t.name) + ".ktx2", t.width, t.height, t.depth, 0, 3, f, t.layout, t.units,
                   std::string(t.name) + " (KTX2 copy)",
                   {{"specbake.parameterisation", param}, {"specbake.sizes", sizes}}},
                  ctx, r);
  }
  // rgba-combined: scattering.ktx2 holds single Mie's red in alpha; there is no single_mie_scattering.ktx2
  if (spec.ktx2_combined) combined_ktx2_file(spec, L, units, param, sizes, ctx, r);
}

// Spectral OpenEXR channel names (Fichet et al. 2021): "S0.<nm>nm" for emitted (radiance-like)
// values, "T.<nm>nm" for transmittance, the wavelength with a comma for its decimal point.
std::string spectral_channel(const char* prefix, double nm) {
  char v[32];
  std::snprintf(v, sizeof v, "%.6f", nm);
  std::string d = v;
  std::replace(d.begin(), d.end(), '.', ',');
  return std::string(prefix) + "." + d + "nm";
}

// `spectrum: {store: radiance}`: the radiance at every stored wavelength, four per RGBA texel and
// the sets outermost (.bin; KTX2 2D array textures of one layer per set), one Spectral OpenEXR per
// texture with a channel per wavelength, sampling_spectral.glsl, and the wavelengths in the
// manifest's parameters.
void spectral_files(const AtmosphereSpec& spec, const SpectralLuts& L, const Model& m, const JobContext& ctx,
                    BakeResult& r) {
  const Sizes& s = m.sizes;
  const int sets = L.sets(), n = static_cast<int>(L.lambda_nm.size());
  std::string lambdas;
  for (int i = 0; i < n; ++i) lambdas += (i ? "," : "") + format_g(L.lambda_nm[i]);
  const std::string le = "little-endian float32, C order; texel channels R, G, B, A = wavelengths 4k..4k+3 of set k";
  struct Texture {
    bool wanted;
    std::string name;
    const std::vector<float>* data;
    int width, height;
    const char* exr_prefix;
    std::string units, axes, what;
  };
  const int tiled_w = s.r * s.scattering_width();
  const std::string tiled_axes = "x = r_index*NU*MU_S + nu_slice*MU_S + mu_s_index, y = mu";
  const Texture textures[] = {
      {spec.out_transmittance, "spectral_transmittance", &L.transmittance, s.transmittance_w, s.transmittance_h, "T",
       "1", "x = mu coordinate, y = r coordinate", "transmittance to the top of the atmosphere per wavelength"},
      {spec.out_irradiance, "spectral_irradiance", &L.irradiance, s.irradiance_w, s.irradiance_h, "S0",
       "W m^-2 nm^-1", "x = mu_s coordinate, y = r coordinate",
       "sky (indirect) irradiance on a horizontal surface per wavelength (the direct sun not included)"},
      {spec.out_scattering, "spectral_scattering_tiled2d", &L.scattering, tiled_w, s.mu, "S0", "W m^-2 sr^-1 nm^-1",
       tiled_axes, "single Rayleigh (no phase function) + sum over orders n >= 2 of deltaS_n / P_R(nu), per wavelength"},
      {spec.out_single_mie, "spectral_single_mie_scattering_tiled2d", &L.single_mie, tiled_w, s.mu, "S0",
       "W m^-2 sr^-1 nm^-1", tiled_axes, "single Mie scattering (no phase function) per wavelength"}};
  json files = json::array();
  for (const Texture& t : textures) {
    if (!t.wanted) continue;
    const std::size_t texels = 1ULL * t.width * t.height;
    const std::string lay = "[set=" + std::to_string(sets) + "][" + std::to_string(t.height) + "][" +
                            std::to_string(t.width) + "][4]; " + t.axes;
    if (spec.write_bin) {
      r.files.push_back({t.name + ".bin", float32_le(*t.data, t.name), "float32", {sets, t.height, t.width, 4},
                         le + "; " + lay, t.units, t.what});
      files.push_back(t.name + ".bin");
    }
    if (spec.write_exr) {
      ExrImage img;
      img.width = t.width;
      img.height = t.height;
      for (int i = 0; i < n; ++i) img.channels.push_back(spectral_channel(t.exr_prefix, L.lambda_nm[i]));
      img.pixels.resize(texels * n);
      for (std::size_t p = 0; p < texels; ++p)
        for (int i = 0; i < n; ++i) img.pixels[p * n + i] = (*t.data)[4 * ((i / 4) * texels + p) + i % 4];
      img.attributes = {{"specbake.layout", std::string("channel per wavelength (Spectral OpenEXR names); ") + t.axes},
                        {"specbake.content", t.what},
                        {"specbake.units", t.units},
                        {"specbake.wavelengths_nm", lambdas}};
      r.files.push_back({t.name + ".exr", exr_bytes(img), "", {t.height, t.width, n},
                         "EXR float32, one channel per wavelength", t.units, t.what + " (Spectral OpenEXR)"});
      files.push_back(t.name + ".exr");
    }
    if (spec.ktx2.enabled) {
      add_ktx2_file(spec.ktx2,
                    {t.name + ".ktx2", std::uint32_t(t.width), std::uint32_t(t.height), 0, std::uint32_t(sets), 4,
                     *t.data, "2D array: layer k = wavelength set k (RGBA = wavelengths 4k..4k+3); " + t.axes, t.units,
                     t.what,
                     {{"specbake.wavelengths_nm", lambdas},
                      {"specbake.sizes", sizes_key(s)}}},
                    ctx, r);
      files.push_back(t.name + ".ktx2");
    }
  }
  r.files.push_back({"sampling_spectral.glsl",
                     sampling_spectral_glsl(m, L, "Values: transmittance 1, irradiance W m^-2 nm^-1, radiance "
                                                  "W m^-2 sr^-1 nm^-1."),
                     "", {}, "", "", "GLSL lookup functions at any wavelength, for spectral renderers"});
  files.push_back("sampling_spectral.glsl");
  json set_list = json::array();
  for (int k = 0; k < sets; ++k)
    set_list.push_back(std::vector<double>(L.lambda_nm.begin() + 4 * k, L.lambda_nm.begin() + std::min(n, 4 * k + 4)));
  r.parameters["spectral_radiance"] = {
      {"wavelengths_nm", L.lambda_nm},
      {"sets", set_list},
      {"lambda_first_nm", L.lambda_nm.front()},
      {"lambda_step_nm", L.step_nm()},
      {"solar_irradiance_W_m2_nm", L.solar_irradiance},
      {"files", files},
      {"interpolation", "linear between the stored wavelengths (sampling_spectral.glsl, ...AtWavelength); its "
                        "error: the spectral_interpolation accuracy record"}};
}

// The R,G,B textures' .bin and .exr files. They are listed in `listed` in their bundle order
// with their bytes encoded later (encode_all, given the same list), all at once on the host's
// threads (each task fills its own files' bytes: the same bundle whatever the thread count).
// The textures and the strings the tasks read outlive the tasks, and so does this object.
class TextureFiles {
 public:
  TextureFiles(const Luts& L, const std::string& units, const std::string& param, bool bin, bool exr,
               std::vector<OutputFile>& listed)
      : L_(L), s_(L.model.sizes), units_(units), param_(param), bin_(bin), exr_(exr), listed_(listed) {}

  void transmittance() {
    const std::string lay = "[r=" + std::to_string(s_.transmittance_h) + "][mu=" + std::to_string(s_.transmittance_w) +
                            "][RGB]; u = mu coordinate, v = r coordinate";
    later({"transmittance.bin", "", "float32", {s_.transmittance_h, s_.transmittance_w, 3}, kLe + "; " + lay, "1",
           "transmittance to the top of the atmosphere at 680/550/440 nm"},
          [&] { return float32_le(L_.transmittance, "transmittance"); });
    later({"transmittance.exr", "", "", {s_.transmittance_h, s_.transmittance_w, 3}, "EXR float32, row j = r index",
           "1", "transmittance (EXR copy)"},
          [&, a = attrs(lay, "transmittance to the top boundary", "1")] {
            return exr_of(s_.transmittance_w, s_.transmittance_h, L_.transmittance, a);
          });
  }

  void irradiance() {
    const std::string lay = "[r=" + std::to_string(s_.irradiance_h) + "][mu_s=" + std::to_string(s_.irradiance_w) +
                            "][RGB]";
    later({"irradiance.bin", "", "float32", {s_.irradiance_h, s_.irradiance_w, 3}, kLe + "; " + lay, units_,
           "sky (indirect) irradiance on a horizontal surface, orders 1..N-1, as the reference stores "
           "it: the direct sun is NOT included (add solar_irradiance * T_sun * cos)"},
          [&] { return float32_le(L_.irradiance, "irradiance"); });
    later({"irradiance.exr", "", "", {s_.irradiance_h, s_.irradiance_w, 3}, "EXR float32, row j = r index", units_,
           "irradiance (EXR copy)"},
          [&, a = attrs(lay, "indirect (sky) irradiance only")] {
            return exr_of(s_.irradiance_w, s_.irradiance_h, L_.irradiance, a);
          });
  }

  // A 4D texture (scattering, single Mie) in the 3D layout [r][mu][nu·mu_s].
  void scattering_3d(const std::string& name, const std::vector<double>* data, const char* what) {
    const int wd = s_.scattering_width();
    const std::string lay = "[r=" + std::to_string(s_.r) + "][mu=" + std::to_string(s_.mu) + "][nu*mu_s=" +
                            std::to_string(s_.nu) + "*" + std::to_string(s_.mu_s) + "][RGB]; x = nu_slice*MU_S + mu_s";
    later({name + ".bin", "", "float32", {s_.r, s_.mu, wd, 3}, kLe + "; " + lay, units_, what},
          [&, data, name] { return float32_le(*data, name); });
    later({name + ".exr", "", "", {s_.r, s_.mu, wd, 3}, "EXR float32, row = r*MU + mu", units_, what},
          [&, data, wd, a = attrs(lay + "; EXR rows = r*MU + mu (3D depth slices stacked)", what)] {
            return exr_of(wd, s_.mu * s_.r, *data, a);
          });
  }

  // The same texture in the tiled 2D layout [mu][r·nu·mu_s].
  void scattering_tiled2d(const std::string& name, const std::vector<double>* data, const char* what) {
    const int wd = s_.scattering_width();
    // one tiled copy for both files, made by the first task to need it
    const auto tiled = std::make_shared<std::vector<double>>();
    const auto once = std::make_shared<std::once_flag>();
    const auto tiled_of = [&s = s_, data, tiled, once]() -> const std::vector<double>& {
      std::call_once(*once, [&] { *tiled = to_tiled2d(*data, s); });
      return *tiled;
    };
    const std::string lay = "[mu=" + std::to_string(s_.mu) + "][r*nu*mu_s=" + std::to_string(s_.r) + "*" +
                            std::to_string(s_.nu) + "*" + std::to_string(s_.mu_s) +
                            "][RGB]; column = r*NU*MU_S + nu_slice*MU_S + mu_s";
    later({name + "_tiled2d.bin", "", "float32", {s_.mu, s_.r * wd, 3}, kLe + "; " + lay, units_,
           std::string(what) + " (tiled 2D layout)"},
          [tiled_of, name] { return float32_le(tiled_of(), name); });
    later({name + "_tiled2d.exr", "", "", {s_.mu, s_.r * wd, 3}, "EXR float32", units_,
           std::string(what) + " (tiled 2D, EXR)"},
          [&, wd, tiled_of, a = attrs(lay, what)] { return exr_of(s_.r * wd, s_.mu, tiled_of(), a); });
  }

  // The sky-view table (lookup.cl, "The sky-view table"): [sun][altitude][view][azimuth][RGB].
  void sky_view(const std::string& name, const std::vector<double>* data, const char* what) {
    const SkyView& v = L_.model.sky_view;
    const std::string lay = "[sun=" + std::to_string(v.sun) + "][altitude=" + std::to_string(v.altitude) + "][view=" +
                            std::to_string(v.view) + "][azimuth=" + std::to_string(v.azimuth) +
                            "][RGB]; a 3D texture x = azimuth, y = view, z = sun*ALTITUDE + altitude";
    later({name + ".bin", "", "float32", {v.sun, v.altitude, v.view, v.azimuth, 3}, kLe + "; " + lay, units_, what},
          [&, data, name] { return float32_le(*data, name); });
    later({name + ".exr", "", "", {v.sun, v.altitude, v.view, v.azimuth, 3},
           "EXR float32, row = (sun*ALTITUDE + altitude)*VIEW + view", units_, what},
          [&, data, a = attrs(lay + "; EXR rows = (sun*ALTITUDE + altitude)*VIEW + view", what)] {
            return exr_of(v.azimuth, v.view * v.altitude * v.sun, *data, a);
          });
  }

  // The listed files' bytes, into `files`: the list they were listed in (moved or not).
  void encode_all(std::vector<OutputFile>& files) {
    parallel_for(static_cast<long long>(encode_.size()), [&](long long i) { encode_[i](files); });
  }

 private:
  inline static const std::string kLe = "little-endian float32, C order, channels R,G,B innermost";

  // A file whose bytes are encoded in encode_all, if `formats` holds its kind (.bin or .exr).
  void later(OutputFile f, std::function<std::string()> bytes) {
    const bool is_exr = f.path.size() > 4 && f.path.compare(f.path.size() - 4, 4, ".exr") == 0;
    if (is_exr ? !exr_ : !bin_) return;
    const std::size_t at = listed_.size();
    listed_.push_back(std::move(f));
    encode_.push_back([at, bytes = std::move(bytes)](std::vector<OutputFile>& files) { files[at].bytes = bytes(); });
  }
  std::map<std::string, std::string> attrs(const std::string& layout, const std::string& content,
                                           const std::string& of = "") const {
    return std::map<std::string, std::string>{{"specbake.layout", layout},
                                              {"specbake.content", content},
                                              {"specbake.parameterisation", param_},
                                              {"specbake.units", of.empty() ? units_ : of}};
  }

  const Luts& L_;
  const Sizes& s_;
  const std::string& units_;
  const std::string& param_;
  const bool bin_, exr_;
  std::vector<OutputFile>& listed_;  // only while listing
  std::vector<std::function<void(std::vector<OutputFile>&)>> encode_;
};

// Lists the R,G,B textures the spec asks for, in their layouts (`files` encodes them).
void texture_files(const AtmosphereSpec& spec, const Luts& L, TextureFiles& files) {
  if (spec.out_transmittance) files.transmittance();
  if (spec.out_irradiance) files.irradiance();
  struct Tex3 {
    bool wanted;
    const char* name;
    const std::vector<double>* data;
    const char* what;
  };
  for (const Tex3& t : {Tex3{spec.out_scattering, "scattering", &L.scattering,
                             "single Rayleigh (no phase function) + sum over orders n >= 2 of deltaS_n / P_R(nu)"},
                        Tex3{spec.out_single_mie, "single_mie_scattering", &L.single_mie,
                             "single Mie scattering (no phase function)"}}) {
    if (!t.wanted) continue;
    if (spec.layout_3d) files.scattering_3d(t.name, t.data, t.what);
    if (spec.layout_tiled2d) files.scattering_tiled2d(t.name, t.data, t.what);
  }
  if (L.model.sky_view.on()) {
    files.sky_view("sky_view", &L.sky_view,
                   "the sky-view table: single Rayleigh x P_R(nu) + orders n >= 2, along each view's exact ray");
    files.sky_view("sky_view_single_mie", &L.sky_view_mie, "the sky-view table's single Mie (no phase function)");
  }
}

// The manifest's timings: the bake's stages, then the files' and previews' seconds.
void record_timings(const Baked& b, double files_s, double previews_s, json& manifest_blocks) {
  json timings = b.timings;
  const auto host_only = [](double s) { return json{{"device_s", 0.0}, {"host_s", s}, {"wall_s", s}}; };
  timings["total"]["files"] = host_only(files_s);
  timings["total"]["previews"] = host_only(previews_s);
  timings["note"] = "per stage: device_s = sum of the OpenCL profiling times (end - start) of its commands, "
                    "host_s = wall_s minus the time the host waited for the device, wall_s = elapsed; "
                    "'self_check' = the double recomputation after each stage, 'host' = reads and sums between "
                    "stages; in total only: 'setup' = each pass's program build, allocations and layout "
                    "check, 'combine' = adding each pass into the bundle's textures; per_order[0] = "
                    "transmittance and direct irradiance, per_order[n] = the stages of order n "
                    "(indirect_irradiance of order n is computed during order n + 1); 'files' and "
                    "'previews' (host only): `run` encodes the textures and draws the previews while the "
                    "next job bakes";
  manifest_blocks["atmosphere"]["timings_s"] = timings;
  for (const auto& [stage, sec] : timings["total"].items())
    spdlog::debug("atmosphere: {} total: device {:.3f} s, host {:.3f} s (wall {:.3f} s)", stage,
                  sec["device_s"].get<double>(), sec["host_s"].get<double>(), sec["wall_s"].get<double>());
}

// The files: listed here (texture files, KTX2 copies with their half-precision records, the
// spectral files, sampling.glsl); the .bin/.exr textures' bytes and the previews — host work
// that cannot change the job's verdict — are left to BakeResult::finish, which owns the tables.
void files_step(const AtmosphereSpec& spec, const Shares& share, Baked&& baked, JobContext& ctx, BakeResult& r) {
  ctx.enter(Stage::files);
  const auto t_files = std::chrono::steady_clock::now();
  ctx.progress("files", share.check_end);
  struct Later {
    Baked b;
    std::string units, param;
    std::optional<TextureFiles> textures;
  };
  auto later = std::make_shared<Later>();
  later->b = std::move(baked);
  const Baked& b = later->b;
  const Luts& L = b.luts;
  later->units = b.spectrum.spectral ? "linear sRGB luminance / 683 (W m^-2 sr^-1 CIE-weighted)"
                                     : "W m^-2 nm^-1 (radiance textures: per sr) at 680/550/440 nm";
  later->param = "Bruneton 2017 (r, mu, mu_s, nu) parameterisation, texel centres";
  const std::string& units = later->units;
  const std::string& param = later->param;
  later->textures.emplace(L, units, param, spec.write_bin, spec.write_exr, r.files);
  texture_files(spec, L, *later->textures);
  if (spec.ktx2.enabled) ktx2_files(spec, L, units, param, ctx, r);
  if (!b.radiance.lambda_nm.empty()) spectral_files(spec, b.radiance, L.model, ctx, r);
  r.files.push_back({"sampling.glsl",
                     sampling_glsl(L.model, L.rgb, spec.layout_3d, spec.layout_tiled2d, "Values: " + units + "."), "",
                     {}, "", "", "GLSL lookup functions for the shipped layouts"});
  const double listed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_files).count();
  r.finish = [later, listed_s, preview_size = spec.preview_size, tone = spec.preview_tone](
                 std::vector<OutputFile>& files, json& manifest_blocks) {
    const Baked& b = later->b;
    const auto t_encode = std::chrono::steady_clock::now();
    later->textures->encode_all(files);
    const auto t_previews = std::chrono::steady_clock::now();
    if (preview_size > 0)
      for (auto& f : preview_files(b.luts, b.spectrum.sky_radiance_to_luminance, b.spectrum.sun_radiance_to_luminance,
                                   preview_size, tone))
        files.push_back(std::move(f));
    const auto t_done = std::chrono::steady_clock::now();
    record_timings(b, listed_s + std::chrono::duration<double>(t_previews - t_encode).count(),
                   std::chrono::duration<double>(t_done - t_previews).count(), manifest_blocks);
  };
}

}  // namespace

BakeResult bake(const AtmosphereSpec& spec, JobContext& ctx) {
  BakeResult r;
  ctx.enter(Stage::plan);
  ctx.progress("planning", 0.0);
  Memo local;  // the scene's traces, shared by an auto search and the checks
  Memo* const given = ctx.memo;
  if (!ctx.memo) ctx.memo = &local;
  struct Restore {
    JobContext& c;
    Memo* m;
    ~Restore() { c.memo = m; }
  } restore{ctx, given};
  Baked b;
  if (spec.auto_sizes || spec.auto_spectrum) {
    std::optional<SceneCheck> checked;
    SceneCheck held_out;
    int held_out_first = 0;
    const AtmosphereSpec use = search_step(spec, ctx, r, b, checked, held_out, held_out_first);
    const Shares share{kSearchShare, kSearchShare, 0.92};
    check_step(use, share, b, ctx, r, std::move(checked));
    held_out_step(std::move(held_out), held_out_first, r);
    if (use.store_radiance) interpolation_step(use, share, b, ctx, r);
    files_step(use, share, std::move(b), ctx, r);
  } else {
    r.parameters = parameters_json(spec);
    const Shares share = job_shares(spec, ctx);
    compute_step(spec, share, ctx, r, b);
    check_step(spec, share, b, ctx, r);
    if (spec.store_radiance) interpolation_step(spec, share, b, ctx, r);
    files_step(spec, share, std::move(b), ctx, r);
  }
  ctx.progress("done", 1.0);
  return r;
}

}  // namespace specbake::atmosphere
