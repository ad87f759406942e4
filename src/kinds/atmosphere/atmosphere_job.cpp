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
#include "kinds/atmosphere/auto_settings.hpp"
#include "kinds/atmosphere/reference.hpp"
#include "kinds/atmosphere/scene_check.hpp"

namespace specbake::atmosphere {

using nlohmann::json;

namespace {

// Self-check: float32 kernels against the double reference path on the same inputs, relative
// to |reference| + 1e-2 × the channel's maximum. One stage is a quadrature of ≤ 1024 terms of
// one sign (≤ 1024 · 2⁻²⁴ ≈ 6e-5 relative) of lookups whose coordinates come from the
// altitude-based geometry of atmosphere.cl (no cancellation beyond ~10 ulps: ~1e-6 in a
// coordinate, ≲ 1e-5 in a value where the texture changes by ≲ 10× per texel). Where it
// changes faster — the sun's edge at the horizon, a texel from ~0 to near the maximum — the
// same 1e-6 moves a lookup by up to N × 1e-6 of the maximum (N ≤ ~150 texels per axis:
// ~1.5e-4), and the few such lookups of a quadrature move a value near 0 by ~1e-6–1e-5 of the
// channel's maximum (measured: 2.3e-6 in the indirect irradiance of a 16-wavelength bake with
// 144 μ texels, at the ground with the sun just below the horizon). So values under 1 % of the
// maximum are judged against 1 % of it: 2e-3 × 1e-2 = 2e-5 of the maximum. The transmittance's
// 500-term optical depth τ carries ≤ 3e-5 relative, so T carries ≤ 3e-5 τ, ≤ 2e-4 where
// T ≥ 1e-3 T_max (τ ≲ 7). 2e-3 bounds a stage with a factor > 5 to spare; wrong layouts, orders
// or formulas give O(1) errors.
constexpr double kCheckFloor = 1e-2;
constexpr double kCheckTolerance = 2e-3;

using MakeBackend = std::function<std::unique_ptr<PassBackend>(const Channels&, int width)>;

// Channels [first, first + count) of a pass's textures ([texels][width]) into the spectral store
// (`store: radiance`): set g / 4, channel g % 4 of wavelength g; scattering and single Mie from the
// 3D texel order [r][mu][x] to the tiled 2D one [mu][r][x].
void keep_radiance(SpectralLuts& L, const Sizes& s, int first, int count, int width, const PassResult& r) {
  const std::size_t sets = static_cast<std::size_t>(L.sets());
  const std::size_t n_t = 1ULL * s.transmittance_w * s.transmittance_h, n_e = 1ULL * s.irradiance_w * s.irradiance_h,
                    n_s = s.scattering_texels();
  const auto put = [&](std::vector<float>& dst, const std::vector<double>& src, std::size_t texels, bool tiled) {
    if (dst.empty()) dst.assign(4 * sets * texels, 0.0f);
    parallel_chunks(texels, kSumChunk, [&](std::size_t t0, std::size_t t1, std::size_t) {
      for (std::size_t t = t0; t < t1; ++t) {
        const std::size_t at = tiled ? tiled2d_index(t, s) : t;
        for (int i = 0; i < count; ++i) {
          const std::size_t g = static_cast<std::size_t>(first + i);
          dst[4 * ((g / 4) * texels + at) + g % 4] = static_cast<float>(src[t * width + i]);
        }
      }
    });
  };
  put(L.transmittance, r.transmittance, n_t, false);
  put(L.irradiance, r.irradiance, n_e, false);
  put(L.scattering, r.scattering, n_s, true);
  put(L.single_mie, r.single_mie, n_s, true);
}

Baked bake_impl(const AtmosphereSpec& spec, const MakeBackend& make, const Progress& progress, int check_texels) {
  Baked out;
  const Model m = model_of(spec);
  const Spectrum sp = spectrum_of(spec);
  const Channels all = channels_at(spec, sp.lambda_nm);
  const Channels rgb = channels_at(spec, {kLambdaR, kLambdaG, kLambdaB});
  out.spectrum = sp;
  out.luts.model = m;
  out.luts.rgb = rgb;
  const int n = static_cast<int>(all.size());
  const int width = channels_per_pass(spec);
  const int passes = (n + width - 1) / width;
  const Sizes& s = m.sizes;
  const std::size_t n_t = 1ULL * s.transmittance_w * s.transmittance_h;
  out.passes = json::array();
  out.self_checks = json::array();
  std::map<std::string, cl_util::StageSeconds> stage_total;
  std::map<int, std::map<std::string, cl_util::StageSeconds>> per_order;
  std::map<int, double> relative;  // per order, the largest over passes
  // host-only steps of the job: the backend's set-up (program build, allocations, layout check)
  const auto host_stage = [&](const char* stage, auto&& f) {
    cl_util::accumulate(stage_total[stage], cl_util::host_only(stage, f));
  };
  // a step with device commands, on b's profiler (a host backend enqueues nothing)
  const auto device_stage = [&](PassBackend& b, const char* stage, auto&& f) {
    cl_util::Profiler own;
    cl_util::Profiler& prof = b.profiler() ? *b.profiler() : own;
    cl_util::Profiler::Stage st(prof, stage);
    f();
    st.close();
    prof.settle();
    cl_util::accumulate(stage_total[stage], *st.record());
  };
  // One backend serves every pass (its sums over passes stay where it is).
  std::unique_ptr<PassBackend> backend;
  host_stage("setup", [&] { backend = make(all.slice(0, std::min(width, n)), width); });
  if (spec.store_radiance) {
    out.radiance.lambda_nm = all.lambda_nm;
    out.radiance.solar_irradiance = all.solar_irradiance;
  }
  for (int p = 0; p < passes; ++p) {
    const int first = p * width, count = std::min(width, n - first);
    const Channels ch = all.slice(first, count);
    if (p > 0) backend->use_channels(ch);
    std::unique_ptr<StageChecker> checker;
    if (check_texels > 0) checker = make_stage_checker(m, ch, width, check_texels, kCheckFloor);
    const CheckHook on_check = [&](const StageCheck& c) {
      out.self_checks.push_back({{"pass", p}, {"stage", c.stage}, {"order", c.order}, {"texels", c.texels},
                                 {"max_relative_error", c.max_rel}});
      out.self_check_worst = std::max(out.self_check_worst, c.max_rel);
      // stop here: later stages would only spread the NaN
      if (c.non_finite > 0) throw non_finite_error({c.stage, c.order, p, c.non_finite});
    };
    // pass channels → R,G,B: identity in rgb mode, the CIE weights in spectral mode
    PassPlan plan;
    plan.orders = spec.orders.value_or(kMaxAutoOrders);
    plan.auto_orders = !spec.orders.has_value();
    plan.tolerance = spec.tolerance;
    plan.to_rgb.assign(3 * width, 0.0);
    for (int k = 0; k < 3; ++k)
      for (int i = 0; i < count; ++i) plan.to_rgb[k * width + i] = sp.spectral ? sp.to_rgb[k * n + first + i] : (k == i);
    plan.keep_textures = spec.store_radiance;
    plan.last_pass = p + 1 == passes;
    const double p0 = 0.9 * p / passes, p1 = 0.9 * (p + 1) / passes;
    const PassResult r = run_pass(*backend, plan, progress, p0, p1, checker.get(), on_check);
    for (const StageTime& t : r.timings) {
      cl_util::accumulate(stage_total[t.stage], t.seconds);
      cl_util::accumulate(per_order[t.order][t.stage], t.seconds);
    }
    for (const auto& o : r.orders) relative[o.order] = std::max(relative[o.order], o.relative);
    if (spec.store_radiance) host_stage("combine", [&] { keep_radiance(out.radiance, s, first, count, width, r); });
    out.orders_used = std::max(out.orders_used, r.orders_used);
    out.converged = out.converged && r.converged;
    out.passes.push_back({{"wavelengths_nm", ch.lambda_nm}, {"orders_used", r.orders_used}, {"converged", r.converged}});
  }
  // The bake's R,G,B textures and each order's statistics, from the sums over the passes.
  device_stage(*backend, "combine", [&] {
    Sums& sums = backend->sums();
    sums.read_rgb(Sum::irradiance, out.luts.irradiance);
    sums.read_rgb(Sum::scattering, out.luts.scattering);
    sums.read_rgb(Sum::single_mie, out.luts.single_mie);
    if (!sp.spectral) out.luts.transmittance = backend->read(Tex::transmittance);
    out.orders = json::array();
    for (const auto& [o, rel] : relative) {
      const OrderRgb st_o = sums.order_rgb(o);
      out.orders.push_back(
          {{"order", o},
           {"scattering", {{"max", st_o.scattering_max}, {"mean", st_o.scattering_mean}}},
           {"irradiance", st_o.irradiance_max.empty() ? json(nullptr)
                                                      : json{{"max", st_o.irradiance_max}, {"mean", st_o.irradiance_mean}}},
           {"relative_change", o == 1 ? json(nullptr) : json(rel)}});
    }
  });
  if (sp.spectral) {
    // The render-time transmittance is at 680/550/440 nm, as the GPU model's luminance mode.
    std::unique_ptr<PassBackend> b;
    cl_util::accumulate(stage_total["transmittance_rgb"],  // the 3-channel program's build
                        cl_util::host_only("transmittance_rgb", [&] { b = make(rgb, 3); }));
    device_stage(*b, "transmittance_rgb", [&] {
      b->transmittance();
      out.luts.transmittance = b->read(Tex::transmittance);
    });
  }
  out.timings = {{"total", json::object()}, {"per_order", json::array()}};
  for (const auto& [stage, sec] : stage_total) out.timings["total"][stage] = cl_util::seconds_json(sec);
  for (const auto& [order, stages] : per_order) {
    json o = json::object();
    for (const auto& [stage, sec] : stages) o[stage] = cl_util::seconds_json(sec);
    o["order"] = order;
    out.timings["per_order"].push_back(o);
  }
  if (out.luts.transmittance.size() != 3 * n_t) throw JobError("atmosphere: transmittance texture has the wrong size");
  return out;
}

json profile_json(const DensityLayer* p) {
  return {{"layers", density_profile_json(p)},
          {"meaning", "density(h) = clamp(exp_term*exp(exp_scale*h) + linear_term*h + constant_term, 0, 1), h = "
                      "altitude in km; layer 0 below its width_km"}};
}


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

Baked bake_luts(const AtmosphereSpec& spec, cl_util::Device& dev, const Progress& progress, int self_check_texels) {
  const Model m = model_of(spec);
  return bake_impl(
      spec, [&](const Channels& ch, int width) { return make_device_backend(dev, m, ch, width, spec.double_precision); },
      progress, self_check_texels);
}

Baked bake_luts_reference(const AtmosphereSpec& spec) {
  const Model m = model_of(spec);
  return bake_impl(
      spec, [&](const Channels& ch, int width) { return make_host_backend(m, ch, width); },
      [](std::string_view, double) {}, 0);
}

int channels_per_pass(const AtmosphereSpec& spec) {
  return spec.spectral ? pass_width_for(static_cast<std::size_t>(spec.count)) : 3;  // spectral: count wavelengths
}

double estimated_seconds(const AtmosphereSpec& spec) {
  if (spec.auto_sizes || spec.auto_spectrum) {
    const AtmosphereSpec start = search_start(spec);
    AtmosphereSpec bare = start;  // what each try costs; the check and the interpolation pass run once
    bare.scene.check = false;
    bare.store_radiance = false;
    return kTypicalTries * estimated_seconds(bare) + (estimated_seconds(start) - estimated_seconds(bare));
  }
  const double texels = double(spec.scattering_r) * spec.scattering_mu * spec.scattering_mu_s * spec.scattering_nu;
  const int width = channels_per_pass(spec);
  const int channels = spec.spectral ? spec.count : 3;
  const int passes = (channels + width - 1) / width;
  const int orders = spec.orders ? *spec.orders : 10;
  // the scene check: ~0.07 s per point (default Earth rgb, 128 points: 9.2 s, both traces)
  const double check = spec.scene.check ? 0.07 * spec.scene.points : 0.0;
  // transmittance (once per pass) and indirect irradiance (per order) texels: small beside the
  // scattering texels at the default sizes (0.2-0.4 s), but what refining those textures costs
  const double transmittance = double(spec.transmittance_mu) * spec.transmittance_r;
  const double irradiance = double(spec.irradiance_mu_s) * spec.irradiance_r;
  // store: radiance: one more pass of up to kInterpolationTests wavelengths (the interpolation check)
  const int tests = std::min(kInterpolationTests, channels - 1);
  const double interpolation =
      spec.store_radiance ? orders * (texels / 1048576.0) * (4.6 + 0.14 * pass_width_for(tests)) : 0.0;
  return 1.0 + orders * passes * (texels / 1048576.0) * (4.6 + 0.14 * width) +
         passes * (1e-5 * transmittance + orders * 6e-5 * irradiance) + check + interpolation;
}

json parameters_json(const AtmosphereSpec& spec) {
  const Model m = model_of(spec);
  const Spectrum sp = spectrum_of(spec);
  const Channels ch = channels_at(spec, sp.lambda_nm);
  auto per_m = [](std::vector<double> v) {
    for (double& x : v) x *= 1e-3;
    return v;
  };
  json p;
  p["atmosphere"] = {
      {"bottom_radius_km", m.bottom_radius_km},
      {"top_radius_km", m.top_radius_km},
      {"sun_angular_radius_rad", m.sun_angular_radius_rad},
      {"max_sun_zenith_deg", spec.max_sun_zenith_deg},
      {"mu_s_min", m.mu_s_min},
      {"ground_albedo", spec.ground_albedo},
      {"solar_irradiance_scale", spec.solar_irradiance_scale},
      {"rayleigh", spec.rayleigh ? json{{"scattering_per_m_at_1um", spec.rayleigh_scattering_per_m_at_1um},
                                        {"law", "beta(l) = b * (l / 1 um)^-4, extinction = scattering"},
                                        {"density", profile_json(m.rayleigh_density)}}
                                 : json(false)},
      {"mie", spec.mie ? json{{"extinction_per_m_at_1um", spec.mie_extinction_per_m},
                              {"angstrom_alpha", spec.mie_angstrom_alpha},
                              {"single_scattering_albedo", spec.mie_single_scattering_albedo},
                              {"phase_g", spec.mie_phase_g},
                              {"phase", "Cornette-Shanks"},
                              {"density", profile_json(m.mie_density)}}
                       : json(false)},
      {"ozone", spec.ozone ? json{{"column_du", spec.ozone_column_du},
                                  {"peak_number_density_per_m3", m.ozone_peak_number_density_per_m3},
                                  {"density", profile_json(m.absorption_density)},
                                  {"cross_section", "Bremen IUP 233 K, 10 nm bin means (see docs)"}}
                           : json(false)}};
  p["channels"] = {{"wavelengths_nm", ch.lambda_nm},
                   {"solar_irradiance_W_m2_nm", ch.solar_irradiance},
                   {"rayleigh_scattering_per_m", per_m(ch.rayleigh_scattering)},
                   {"mie_scattering_per_m", per_m(ch.mie_scattering)},
                   {"mie_extinction_per_m", per_m(ch.mie_extinction)},
                   {"absorption_extinction_per_m", per_m(ch.absorption_extinction)},
                   {"ground_albedo", ch.ground_albedo}};
  p["wavelengths_nm"] = sp.lambda_nm;
  json lum = {{"sky_spectral_radiance_to_luminance_lm_per_W", sp.sky_radiance_to_luminance},
              {"sun_spectral_radiance_to_luminance_lm_per_W", sp.sun_radiance_to_luminance},
              {"max_luminous_efficacy_lm_per_W", kMaxLuminousEfficacy},
              {"cmf", "cie1931-2deg (1 nm table, linear interpolation)"},
              {"xyz_to_srgb", "exact inverse of the BT.709/D65 primaries matrix"}};
  if (sp.spectral) {
    lum["mode"] = "precomputed luminance: scattering, single_mie and irradiance hold sum_i to_rgb[c][i] * value(l_i) "
                  "= linear sRGB luminance / 683 (multiply by sky_spectral_radiance_to_luminance = 683 for cd/m2 "
                  "and lux); transmittance is at 680/550/440 nm, and the sun's own light converts with "
                  "sun_spectral_radiance_to_luminance";
    lum["bin_nm"] = sp.bin_nm;
    json rows = json::array();
    const int n = static_cast<int>(sp.lambda_nm.size());
    for (int c = 0; c < 3; ++c) rows.push_back(std::vector<double>(sp.to_rgb.begin() + c * n, sp.to_rgb.begin() + (c + 1) * n));
    lum["to_rgb"] = rows;
  } else {
    lum["mode"] = "radiance at 680/550/440 nm (R, G, B); luminance at render time: sky * "
                  "sky_spectral_radiance_to_luminance, sun * sun_spectral_radiance_to_luminance (Bruneton's "
                  "non-luminance mode)";
  }
  p["luminance_conversion"] = lum;
  // `store: radiance`: the radiance per wavelength as well (spectral_radiance: after the bake)
  p["store"] = spec.store_radiance ? "luminance and radiance" : (sp.spectral ? "luminance" : "radiance");
  p["scene_check"] = spec.scene.check ? json{{"points", spec.scene.points}, {"relative_se", spec.scene.relative_se}}
                                      : json(false);
  const Sizes& s = m.sizes;
  p["sizes"] = {{"transmittance", {{"mu", s.transmittance_w}, {"r", s.transmittance_h}}},
                {"irradiance", {{"mu_s", s.irradiance_w}, {"r", s.irradiance_h}}},
                {"scattering", {{"r", s.r}, {"mu", s.mu}, {"mu_s", s.mu_s}, {"nu", s.nu}}}};
  // what an engine holds: transmittance, irradiance, scattering and single Mie as float32 R,G,B
  p["texture_memory_bytes"] = 12LL * (1LL * s.transmittance_w * s.transmittance_h + 1LL * s.irradiance_w * s.irradiance_h +
                                      2LL * s.scattering_texels());
  json layouts = json::array();
  if (spec.layout_3d) layouts.push_back("3d");
  if (spec.layout_tiled2d) layouts.push_back("tiled2d");
  p["layout"] = layouts;
  p["orders_requested"] = spec.orders ? json(*spec.orders) : json("auto");
  p["tolerance"] = spec.tolerance;
  p["precision"] = spec.double_precision ? "float64" : "float32";
  const int width = channels_per_pass(spec);
  p["passes"] = (sp.lambda_nm.size() + width - 1) / width;
  p["channels_per_pass"] = width;
  p["length_unit"] = "km (texture values do not depend on it)";
  p["quadrature"] = {{"transmittance", "trapezoid, 500 intervals"},
                     {"single_and_multiple_scattering", "trapezoid, 50 intervals to the nearest boundary"},
                     {"scattering_density", "midpoint " + std::to_string(m.density_theta) + " x 32 over the sphere, theta " +
                                                (m.density_theta_power == 1.0 ? "uniform" : "packed towards the horizon")},
                     {"density_theta", m.density_theta},
                     {"density_rule", m.density_theta_power == 1.0 ? "uniform" : "horizon"},
                     {"mu_s_blend", m.mu_s_geometric ? "geometric" : "linear"},
                     {"indirect_irradiance", "midpoint 16 x 64 over the upper hemisphere"}};
  return p;
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
// and writes nothing) and shows the chosen settings and their predicted bake time.
json plan(const AtmosphereSpec& spec, JobContext& ctx) {
  if (!spec.auto_sizes && !spec.auto_spectrum) return parameters_json(spec);
  Memo local;
  AutoSearch found = search_settings(spec, ctx.device, ctx.progress, ctx.memo ? *ctx.memo : local);
  json p = parameters_json(found.resolved);
  p["auto"] = found.record;
  if (!found.met) {
    if (ctx.judge) throw BakeFailed(found.failure, p);  // as `run` would fail: its best try reported
    p["auto"]["failure"] = found.failure;
  }
  return p;
}

namespace {

// Job fractions: the passes report 0..0.9 of their own; with a scene check they get 0..kComputeShare.
constexpr double kComputeShare = 0.75, kSceneCheckEnd = 0.92;

// What the manifest says of the orders and passes of a bake.
void record_orders(const AtmosphereSpec& spec, const Baked& b, BakeResult& r) {
  r.parameters["orders"] = {{"requested", spec.orders ? json(*spec.orders) : json("auto")},
                            {"used", b.orders_used},
                            {"converged", b.converged},
                            {"tolerance", spec.tolerance},
                            {"per_order", b.orders},
                            {"note", "order 1 = single scattering; 'scattering' is what the order adds to "
                                     "scattering.bin (order 1: single Rayleigh; n >= 2: deltaS_n / P_R(nu)), "
                                     "'irradiance' what its light adds to irradiance.bin (orders 1..used-1); "
                                     "relative_change = max over texels above 1e-4 of their channel's maximum of "
                                     "added / accumulated, over scattering (order n) and irradiance (order n-1)"}};
  r.parameters["pass_details"] = b.passes;
  if (!b.converged)
    r.warnings.push_back("orders: auto stopped at the cap of " + std::to_string(kMaxAutoOrders) +
                         " orders before an order added less than the tolerance " + format_g(spec.tolerance));
}

void compute_step(const AtmosphereSpec& spec, JobContext& ctx, BakeResult& r, Baked& b) {
  ctx.enter(Stage::compute);
  const double scale = spec.scene.check ? kComputeShare / 0.9 : 1.0;
  b = bake_luts(spec, ctx.device, [&](std::string_view what, double f) { ctx.progress(what, f * scale); }, 24);
  record_orders(spec, b, r);
}

// sizes: auto / spectrum: auto: the search's bakes are the compute step; the chosen one is kept.
AtmosphereSpec search_step(const AtmosphereSpec& spec, JobContext& ctx, BakeResult& r, Baked& b,
                           std::optional<SceneCheck>& checked, SceneCheck& held_out, int& held_out_first) {
  ctx.enter(Stage::compute);
  AutoSearch found = search_settings(
      spec, ctx.device, [&](std::string_view what, double f) { ctx.progress(what, f * kComputeShare); }, *ctx.memo);
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
void held_out_step(const AtmosphereSpec& use, SceneCheck held, int first, BakeResult& r) {
  Accuracy a = std::move(held.record);
  a.name = "vs_path_traced_held_out";
  a.metric += " (an independent point set of the same scene: the search did not see it)";
  a.details["first_point"] = first;
  if (!a.passed)
    r.warnings.push_back("auto settings: the held-out points' p99 " + format_g(a.value) +
                         " exceeds the tolerance " + format_g(*a.tolerance) + " (the search judged " +
                         std::to_string(first) + " points in " + std::to_string(first / std::max(use.scene.points, 1)) +
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
void interpolation_step(const AtmosphereSpec& spec, const Baked& b, JobContext& ctx, BakeResult& r) {
  ctx.enter(Stage::check);
  const std::vector<double> lambdas = interpolation_test_wavelengths(b.radiance.lambda_nm);
  if (lambdas.empty()) return;
  ctx.progress("spectral interpolation check", 0.94);
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

JobError non_finite_error(const NonFiniteStage& f) {
  return JobError("self-check failed: the device's " + f.stage + " (order " + std::to_string(f.order) + ", pass " +
                  std::to_string(f.pass) + ") wrote " + std::to_string(f.values) +
                  " non-finite values (NaN or inf). Try another device (`specbake devices`, `device:` or "
                  "`--device`) or `precision: double`");
}

Accuracy judge_self_checks(const Baked& b) {
  if (!(b.self_check_worst <= kCheckTolerance)) {
    std::string stage = "?";
    for (const auto& c : b.self_checks)
      if (!(c.value("max_relative_error", 0.0) < b.self_check_worst)) stage = c.value("stage", "?");
    throw JobError("self-check failed in " + stage + ": the float32 kernels differ from the double reference by " +
                   format_g(b.self_check_worst) + " (relative) > " + format_g(kCheckTolerance) +
                   ". Check the atmosphere's inputs first (optical depths far beyond any planet's make the float "
                   "sums lose their digits); `precision: double` computes in float64 on devices that have it");
  }
  return Accuracy::judged(
      "self_check", "max relative error |device - reference| / (|reference| + 1e-2 * channel max)",
      b.self_check_worst, kCheckTolerance,
      "double reference path recomputing 24 texels of each stage from the device's own inputs",
      {{"stages", b.self_checks}});
}

namespace {

// `checked`: the scene check already made of these LUTs (an auto search's), not made again.
void check_step(const AtmosphereSpec& spec, const Baked& b, JobContext& ctx, BakeResult& r,
                std::optional<SceneCheck> checked = std::nullopt) {
  ctx.enter(Stage::check);
  r.accuracy.push_back(judge_self_checks(b));
  if (!spec.scene.check) return;
  // the error in the user's scene: the LUTs against the path-traced truth at the scene's points
  SceneCheck sc = checked ? std::move(*checked)
                          : check_scene(spec, b.luts, b.orders_used, ctx.device, [&](std::string_view what, double f) {
                              ctx.progress(what, kComputeShare + (kSceneCheckEnd - kComputeShare) * f);
                            }, ctx.memo);
  r.accuracy.insert(r.accuracy.begin(), sc.record);  // the headline: the error the user sees
  r.files.push_back(std::move(sc.points_csv));
  r.manifest_blocks["atmosphere"]["scene_check_s"] = sc.seconds;
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
  const std::string sizes = sizes_key(s);
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
    r.files.push_back({t.name + ".bin", float32_le(*t.data, t.name), "float32", {sets, t.height, t.width, 4},
                       le + "; " + lay, t.units, t.what});
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
    files.push_back(t.name + ".bin");
    files.push_back(t.name + ".exr");
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

void files_step(const AtmosphereSpec& spec, const Baked& b, JobContext& ctx, BakeResult& r) {
  ctx.enter(Stage::files);
  const Luts& L = b.luts;
  const Sizes& s = L.model.sizes;
  const auto t_files = std::chrono::steady_clock::now();
  ctx.progress("files", 0.92);
  const std::string le = "little-endian float32, C order, channels R,G,B innermost";
  const std::string units = b.spectrum.spectral ? "linear sRGB luminance / 683 (W m^-2 sr^-1 CIE-weighted)"
                                                : "W m^-2 nm^-1 (radiance textures: per sr) at 680/550/440 nm";
  const std::string param = "Bruneton 2017 (r, mu, mu_s, nu) parameterisation, texel centres";
  const int wd = s.scattering_width();
  // The textures' files are listed here in their bundle order with their bytes encoded later, all
  // at once on the host's threads (each task fills its own files' bytes: the same bundle whatever
  // the thread count). The textures and the strings the tasks read outlive the tasks.
  std::vector<std::function<void()>> encode;
  const auto later = [&](OutputFile f, std::function<std::string()> bytes) {
    const std::size_t at = r.files.size();
    r.files.push_back(std::move(f));
    encode.push_back([&r, at, bytes = std::move(bytes)] { r.files[at].bytes = bytes(); });
  };
  auto attrs = [&](const std::string& layout, const std::string& content, const std::string& of = "") {
    return std::map<std::string, std::string>{{"specbake.layout", layout},
                                              {"specbake.content", content},
                                              {"specbake.parameterisation", param},
                                              {"specbake.units", of.empty() ? units : of}};
  };
  if (spec.out_transmittance) {
    const std::string lay = "[r=" + std::to_string(s.transmittance_h) + "][mu=" + std::to_string(s.transmittance_w) +
                            "][RGB]; u = mu coordinate, v = r coordinate";
    later({"transmittance.bin", "", "float32", {s.transmittance_h, s.transmittance_w, 3}, le + "; " + lay, "1",
           "transmittance to the top of the atmosphere at 680/550/440 nm"},
          [&] { return float32_le(L.transmittance, "transmittance"); });
    later({"transmittance.exr", "", "", {s.transmittance_h, s.transmittance_w, 3}, "EXR float32, row j = r index",
           "1", "transmittance (EXR copy)"},
          [&, a = attrs(lay, "transmittance to the top boundary", "1")] {
            return exr_of(s.transmittance_w, s.transmittance_h, L.transmittance, a);
          });
  }
  if (spec.out_irradiance) {
    const std::string lay = "[r=" + std::to_string(s.irradiance_h) + "][mu_s=" + std::to_string(s.irradiance_w) +
                            "][RGB]";
    later({"irradiance.bin", "", "float32", {s.irradiance_h, s.irradiance_w, 3}, le + "; " + lay, units,
           "sky (indirect) irradiance on a horizontal surface, orders 1..N-1, as the reference stores "
           "it: the direct sun is NOT included (add solar_irradiance * T_sun * cos)"},
          [&] { return float32_le(L.irradiance, "irradiance"); });
    later({"irradiance.exr", "", "", {s.irradiance_h, s.irradiance_w, 3}, "EXR float32, row j = r index", units,
           "irradiance (EXR copy)"},
          [&, a = attrs(lay, "indirect (sky) irradiance only")] {
            return exr_of(s.irradiance_w, s.irradiance_h, L.irradiance, a);
          });
  }
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
    const std::string name = t.name;
    if (spec.layout_3d) {
      const std::string lay = "[r=" + std::to_string(s.r) + "][mu=" + std::to_string(s.mu) + "][nu*mu_s=" +
                              std::to_string(s.nu) + "*" + std::to_string(s.mu_s) + "][RGB]; x = nu_slice*MU_S + mu_s";
      later({name + ".bin", "", "float32", {s.r, s.mu, wd, 3}, le + "; " + lay, units, t.what},
            [&, data = t.data, name] { return float32_le(*data, name); });
      later({name + ".exr", "", "", {s.r, s.mu, wd, 3}, "EXR float32, row = r*MU + mu", units, t.what},
            [&, data = t.data, a = attrs(lay + "; EXR rows = r*MU + mu (3D depth slices stacked)", t.what)] {
              return exr_of(wd, s.mu * s.r, *data, a);
            });
    }
    if (spec.layout_tiled2d) {
      // one tiled copy for both files, made by the first task to need it
      const auto tiled = std::make_shared<std::vector<double>>();
      const auto once = std::make_shared<std::once_flag>();
      const auto tiled_of = [&s, data = t.data, tiled, once]() -> const std::vector<double>& {
        std::call_once(*once, [&] { *tiled = to_tiled2d(*data, s); });
        return *tiled;
      };
      const std::string lay = "[mu=" + std::to_string(s.mu) + "][r*nu*mu_s=" + std::to_string(s.r) + "*" +
                              std::to_string(s.nu) + "*" + std::to_string(s.mu_s) +
                              "][RGB]; column = r*NU*MU_S + nu_slice*MU_S + mu_s";
      later({name + "_tiled2d.bin", "", "float32", {s.mu, s.r * wd, 3}, le + "; " + lay, units,
             std::string(t.what) + " (tiled 2D layout)"},
            [tiled_of, name] { return float32_le(tiled_of(), name); });
      later({name + "_tiled2d.exr", "", "", {s.mu, s.r * wd, 3}, "EXR float32", units,
             std::string(t.what) + " (tiled 2D, EXR)"},
            [&, tiled_of, a = attrs(lay, t.what)] { return exr_of(s.r * wd, s.mu, tiled_of(), a); });
    }
  }
  parallel_for(static_cast<long long>(encode.size()), [&](long long i) { encode[i](); });
  if (spec.ktx2.enabled) ktx2_files(spec, L, units, param, ctx, r);
  if (!b.radiance.lambda_nm.empty()) spectral_files(spec, b.radiance, L.model, ctx, r);
  r.files.push_back({"sampling.glsl",
                     sampling_glsl(L.model, L.rgb, spec.layout_3d, spec.layout_tiled2d, "Values: " + units + "."), "",
                     {}, "", "", "GLSL lookup functions for the shipped layouts"});
  const auto t_previews = std::chrono::steady_clock::now();
  ctx.progress("previews", 0.95);
  if (spec.preview_size > 0)
    for (auto& f : preview_files(L, b.spectrum.sky_radiance_to_luminance, b.spectrum.sun_radiance_to_luminance,
                                 spec.preview_size, spec.preview_tone))
      r.files.push_back(std::move(f));
  const auto t_done = std::chrono::steady_clock::now();
  json timings = b.timings;
  const auto host_only = [](double s) { return json{{"device_s", 0.0}, {"host_s", s}, {"wall_s", s}}; };
  timings["total"]["files"] = host_only(std::chrono::duration<double>(t_previews - t_files).count());
  timings["total"]["previews"] = host_only(std::chrono::duration<double>(t_done - t_previews).count());
  timings["note"] = "per stage: device_s = sum of the OpenCL profiling times (end - start) of its commands, "
                    "host_s = wall_s minus the time the host waited for the device, wall_s = elapsed; "
                    "'self_check' = the double recomputation after each stage, 'host' = reads and sums between "
                    "stages; in total only: 'setup' = each pass's program build, allocations and layout "
                    "check, 'combine' = adding each pass into the bundle's textures; per_order[0] = "
                    "transmittance and direct irradiance, per_order[n] = the stages of order n "
                    "(indirect_irradiance of order n is computed during order n + 1)";
  r.manifest_blocks["atmosphere"]["timings_s"] = timings;
  for (const auto& [stage, sec] : timings["total"].items())
    spdlog::debug("atmosphere: {} total: device {:.3f} s, host {:.3f} s (wall {:.3f} s)", stage,
                  sec["device_s"].get<double>(), sec["host_s"].get<double>(), sec["wall_s"].get<double>());
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
    check_step(use, b, ctx, r, std::move(checked));
    held_out_step(use, std::move(held_out), held_out_first, r);
    if (use.store_radiance) interpolation_step(use, b, ctx, r);
    files_step(use, b, ctx, r);
  } else {
    r.parameters = parameters_json(spec);
    compute_step(spec, ctx, r, b);
    check_step(spec, b, ctx, r);
    if (spec.store_radiance) interpolation_step(spec, b, ctx, r);
    files_step(spec, b, ctx, r);
  }
  ctx.progress("done", 1.0);
  return r;
}

}  // namespace specbake::atmosphere
