#include "kinds/atmosphere/bake/bake.hpp"

#include <algorithm>
#include <functional>
#include <map>
#include <memory>

#include "core/parallel.hpp"
#include "core/text.hpp"
#include "kinds/atmosphere/bake/reference.hpp"

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

}  // namespace

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

double bake_seconds(const AtmosphereSpec& spec) {
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

}  // namespace specbake::atmosphere
