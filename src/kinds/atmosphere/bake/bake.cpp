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

// The seconds of a bake's stages, summed over passes: in total by stage name and per order.
struct StageClock {
  std::map<std::string, cl_util::StageSeconds> total;
  std::map<int, std::map<std::string, cl_util::StageSeconds>> per_order;

  // a host-only step of the job: the backend's set-up (program build, allocations, layout check)
  template <class F>
  void host(const char* stage, F&& f) {
    cl_util::accumulate(total[stage], cl_util::host_only(stage, f));
  }
  // a step with device commands, on b's profiler (a host backend enqueues nothing)
  template <class F>
  void device(PassBackend& b, const char* stage, F&& f) {
    cl_util::Profiler own;
    cl_util::Profiler& prof = b.profiler() ? *b.profiler() : own;
    cl_util::Profiler::Stage st(prof, stage);
    f();
    st.close();
    prof.settle();
    cl_util::accumulate(total[stage], *st.record());
  }
  // a pass's own stage times
  void add(const std::vector<StageTime>& timings) {
    for (const StageTime& t : timings) {
      cl_util::accumulate(total[t.stage], t.seconds);
      cl_util::accumulate(per_order[t.order][t.stage], t.seconds);
    }
  }
  // {"total": {stage: seconds}, "per_order": [{stage: seconds, "order": n}]}
  json to_json() const {
    json out = {{"total", json::object()}, {"per_order", json::array()}};
    for (const auto& [stage, sec] : total) out["total"][stage] = cl_util::seconds_json(sec);
    for (const auto& [order, stages] : per_order) {
      json o = json::object();
      for (const auto& [stage, sec] : stages) o[stage] = cl_util::seconds_json(sec);
      o["order"] = order;
      out["per_order"].push_back(o);
    }
    return out;
  }
};

// The plan of the pass of channels [first, first + count) of n, `width` wide: the spec's orders
// and tolerance, and its channels → R,G,B weights (identity in rgb mode, the CIE weights in
// spectral mode).
PassPlan pass_plan(const AtmosphereSpec& spec, const Spectrum& sp, int n, int first, int count, int width,
                   bool last_pass) {
  PassPlan plan;
  plan.orders = spec.orders.value_or(kMaxAutoOrders);
  plan.auto_orders = !spec.orders.has_value();
  plan.tolerance = spec.tolerance;
  plan.to_rgb.assign(3 * width, 0.0);
  for (int k = 0; k < 3; ++k)
    for (int i = 0; i < count; ++i) plan.to_rgb[k * width + i] = sp.spectral ? sp.to_rgb[k * n + first + i] : (k == i);
  plan.keep_textures = spec.store_radiance;
  plan.last_pass = last_pass;
  plan.sky_view = sky_view_of(spec).on();
  plan.tail = takes_geometric_tail(spec);
  return plan;
}

// A pass's sky-view table ([texels][2 · width]: radiance without single Mie, then single Mie) in
// R,G,B by W (3 × width), added into rgb and mie ([texels][3], sized on first use).
void add_sky_view_rgb(const std::vector<double>& v, int width, const std::vector<double>& W, std::vector<double>& rgb,
                      std::vector<double>& mie) {
  const std::size_t n = v.size() / (2 * width);
  if (rgb.empty()) rgb.assign(3 * n, 0.0);
  if (mie.empty()) mie.assign(3 * n, 0.0);
  for (std::size_t t = 0; t < n; ++t)
    for (int k = 0; k < 3; ++k)
      for (int c = 0; c < width; ++c) {
        rgb[3 * t + k] += W[k * width + c] * v[(2 * t) * width + c];
        mie[3 * t + k] += W[k * width + c] * v[(2 * t + 1) * width + c];
      }
}

// What the manifest says of order o: the max and mean it adds to scattering and irradiance, and
// its relative change (the largest over passes; none for order 1).
json order_json(int o, const OrderRgb& st_o, double rel) {
  return {{"order", o},
          {"scattering", {{"max", st_o.scattering_max}, {"mean", st_o.scattering_mean}}},
          {"irradiance", st_o.irradiance_max.empty() ? json(nullptr)
                                                     : json{{"max", st_o.irradiance_max}, {"mean", st_o.irradiance_mean}}},
          {"relative_change", o == 1 ? json(nullptr) : json(rel)}};
}

// A bake in passes of `width` channels on backends from `make`: each pass self-checked, its
// statistics and times kept, then the R,G,B textures read from the sums over the passes.
class Baking {
 public:
  Baking(const AtmosphereSpec& spec, const MakeBackend& make, int check_texels)
      : spec_(spec), make_(make), check_texels_(check_texels), m_(model_of(spec)), sp_(spectrum_of(spec)),
        all_(channels_at(spec, sp_.lambda_nm)), n_(static_cast<int>(all_.size())), width_(channels_per_pass(spec)),
        passes_((n_ + width_ - 1) / width_) {
    out_.spectrum = sp_;
    out_.luts.model = m_;
    out_.luts.rgb = channels_at(spec, {kLambdaR, kLambdaG, kLambdaB});
    out_.passes = json::array();
    out_.self_checks = json::array();
    if (spec.store_radiance) {
      out_.radiance.lambda_nm = all_.lambda_nm;
      out_.radiance.solar_irradiance = all_.solar_irradiance;
    }
  }

  Baked run(const Progress& progress) {
    // One backend serves every pass (its sums over passes stay where it is).
    clock_.host("setup", [&] { backend_ = make_(all_.slice(0, std::min(width_, n_)), width_); });
    for (int p = 0; p < passes_; ++p) pass(p, progress);
    combine();
    if (spec_.store_half_mu_s || spec_.store_half_nu)
      clock_.host("combine", [&] {
        const Sizes stored = stored_sizes(spec_);
        store_sun_axes(out_.luts, stored.mu_s, stored.nu);
      });
    if (sp_.spectral) transmittance_rgb();
    out_.timings = clock_.to_json();
    const Sizes& s = m_.sizes;
    if (out_.luts.transmittance.size() != 3ULL * s.transmittance_w * s.transmittance_h)
      throw JobError("atmosphere: transmittance texture has the wrong size");
    return std::move(out_);
  }

 private:
  // Pass p: channels [p · width, ...), self-checked, its textures kept for `store: radiance`.
  void pass(int p, const Progress& progress) {
    const int first = p * width_, count = std::min(width_, n_ - first);
    const Channels ch = all_.slice(first, count);
    if (p > 0) backend_->use_channels(ch);
    std::unique_ptr<StageChecker> checker;
    if (check_texels_ > 0) checker = make_stage_checker(m_, ch, width_, check_texels_, kCheckFloor);
    const CheckHook on_check = [&](const StageCheck& c) {
      out_.self_checks.push_back({{"pass", p}, {"stage", c.stage}, {"order", c.order}, {"texels", c.texels},
                                  {"max_relative_error", c.max_rel}});
      out_.self_check_worst = std::max(out_.self_check_worst, c.max_rel);
      // stop here: later stages would only spread the NaN
      if (c.non_finite > 0) throw non_finite_error({c.stage, c.order, p, c.non_finite});
    };
    const PassPlan plan = pass_plan(spec_, sp_, n_, first, count, width_, p + 1 == passes_);
    const double p0 = 0.9 * p / passes_, p1 = 0.9 * (p + 1) / passes_;
    const PassResult r = run_pass(*backend_, plan, progress, p0, p1, checker.get(), on_check);
    clock_.add(r.timings);
    if (!r.sky_view.empty())
      clock_.host("combine", [&] { add_sky_view_rgb(r.sky_view, width_, plan.to_rgb, out_.luts.sky_view, out_.luts.sky_view_mie); });
    for (const auto& o : r.orders) relative_[o.order] = std::max(relative_[o.order], o.relative);
    if (spec_.store_radiance)
      clock_.host("combine", [&] { keep_radiance(out_.radiance, m_.sizes, first, count, width_, r); });
    out_.orders_used = std::max(out_.orders_used, r.orders_used);
    out_.converged = out_.converged && r.converged;
    out_.passes.push_back({{"wavelengths_nm", ch.lambda_nm}, {"orders_used", r.orders_used}, {"converged", r.converged}});
  }

  // The bake's R,G,B textures and each order's statistics, from the sums over the passes.
  void combine() {
    clock_.device(*backend_, "combine", [&] {
      Sums& sums = backend_->sums();
      sums.read_rgb(Sum::irradiance, out_.luts.irradiance);
      sums.read_rgb(Sum::scattering, out_.luts.scattering);
      sums.read_rgb(Sum::single_mie, out_.luts.single_mie);
      if (!sp_.spectral) out_.luts.transmittance = backend_->read(Tex::transmittance);
      out_.orders = json::array();
      for (const auto& [o, rel] : relative_) out_.orders.push_back(order_json(o, sums.order_rgb(o), rel));
    });
  }

  // Spectral bakes: the render-time transmittance is at 680/550/440 nm, as the GPU model's
  // luminance mode.
  void transmittance_rgb() {
    std::unique_ptr<PassBackend> b;
    clock_.host("transmittance_rgb", [&] { b = make_(out_.luts.rgb, 3); });  // the 3-channel program's build
    clock_.device(*b, "transmittance_rgb", [&] {
      b->transmittance();
      out_.luts.transmittance = b->read(Tex::transmittance);
    });
  }

  const AtmosphereSpec& spec_;
  const MakeBackend& make_;
  const int check_texels_;
  const Model m_;
  const Spectrum sp_;
  const Channels all_;
  const int n_, width_, passes_;
  Baked out_;
  StageClock clock_;
  std::map<int, double> relative_;  // per order, the largest over passes
  std::unique_ptr<PassBackend> backend_;
};

Baked bake_impl(const AtmosphereSpec& spec, const MakeBackend& make, const Progress& progress, int check_texels) {
  return Baking(spec, make, check_texels).run(progress);
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

double bake_files_seconds(const AtmosphereSpec& spec) {
  // set-up, files and previews: ~0.5 s and ~0.1 s per Mtexel (200 %: 1.9 s)
  return 0.5 + 0.1 * double(spec.scattering_r) * spec.scattering_mu * spec.scattering_mu_s * spec.scattering_nu /
                   1048576.0;
}

Sizes stored_sizes(const AtmosphereSpec& spec) {
  Sizes s = sizes_of(spec);
  if (spec.store_half_mu_s) s.mu_s = std::max(2, s.mu_s / 2);
  if (spec.store_half_nu) s.nu = std::max(2, (s.nu + 1) / 2);
  return s;
}

namespace {

// `in` laid out [outer][n_from][inner] resampled along its middle axis to n_to: stored slice j at
// unit coordinate j / (n_to − 1) is the baked texture's value there, baked slice i sitting at
// i / (n_from − 1) (coord_of_unit); its two neighbours joined by `blend` (g ∈ (0, 1)), a baked
// slice copied as it is (x = j (n_from − 1) / (n_to − 1) in one division is whole exactly there).
template <class Blend>
std::vector<double> resample_axis(const std::vector<double>& in, long long outer, int n_from, int n_to,
                                  long long inner, const Blend& blend) {
  std::vector<double> out(static_cast<std::size_t>(outer * n_to * inner));
  parallel_for(outer, [&](long long row) {
    for (int j = 0; j < n_to; ++j) {
      const double x = static_cast<double>(1LL * j * (n_from - 1)) / (n_to - 1);
      const int i0 = std::min(static_cast<int>(std::floor(x)), n_from - 1);
      const double g = x - i0;
      const double* a = &in[(row * n_from + i0) * inner];
      double* o = &out[(row * n_to + j) * inner];
      if (g == 0.0) {
        std::copy(a, a + inner, o);
        continue;
      }
      const double* b = a + inner;
      for (long long k = 0; k < inner; ++k) o[k] = blend(a[k], b[k], g);
    }
  });
  return out;
}

}  // namespace

void store_sun_axes(Luts& luts, int mu_s, int nu) {
  // the 3D layout [r][mu][ν slice][μ_s][RGB]: μ_s blended as the shader reads it, ν linearly
  const auto linear = [](double a, double b, double g) { return a + (b - a) * g; };
  const bool geometric = luts.model.mu_s_geometric;
  const auto along_mu_s = [geometric, linear](double a, double b, double g) {
    return geometric ? ref3::mu_s_blend(a, b, g) : linear(a, b, g);
  };
  Sizes& z = luts.model.sizes;
  for (auto* t : {&luts.scattering, &luts.single_mie}) {
    if (mu_s != z.mu_s) *t = resample_axis(*t, 1LL * z.r * z.mu * z.nu, z.mu_s, mu_s, 3, along_mu_s);
    if (nu != z.nu) *t = resample_axis(*t, 1LL * z.r * z.mu, z.nu, nu, 3LL * mu_s, linear);
  }
  z.mu_s = mu_s;
  z.nu = nu;
}

double bake_seconds(const AtmosphereSpec& spec) {
  const double mtexels =
      double(spec.scattering_r) * spec.scattering_mu * spec.scattering_mu_s * spec.scattering_nu / 1048576.0;
  const int width = channels_per_pass(spec);
  const int channels = spec.spectral ? spec.count : 3;
  const int passes = (channels + width - 1) / width;
  const int orders = spec.orders ? *spec.orders : 10;
  // Seconds per order, pass and million scattering texels: a geometry part and a per-channel
  // part. Measured compute steps on the idle 2-core CPU, 4 orders, 16 θ: rgb at 50 / 100 / 150 /
  // 200 % sizes 0.65 / 5.8 / 36.7 / 106 s (1.4–1.7 s per order and Mtexel past the smallest), 16
  // wavelengths at 100 % 7.5 s (one pass), 48 wavelengths 22.6 s (three).
  const double per_order = mtexels * (1.45 + 0.015 * width);
  // transmittance (once per pass) and indirect irradiance (per order) texels: small beside the
  // scattering texels at the default sizes (0.2-0.4 s), but what refining those textures costs
  const double transmittance = double(spec.transmittance_mu) * spec.transmittance_r;
  const double irradiance = double(spec.irradiance_mu_s) * spec.irradiance_r;
  // store: radiance: one more pass of up to kInterpolationTests wavelengths (the interpolation check)
  const int tests = std::min(kInterpolationTests, channels - 1);
  const double interpolation =
      spec.store_radiance ? orders * mtexels * (1.45 + 0.015 * pass_width_for(tests)) : 0.0;
  // the scattering density's share of an order grows with its θ nodes (rgb, default sizes: 5.8 /
  // 9.2 s of compute at 16 / 32 θ; 16 wavelengths: 7.5 / 11.4 / 19.5 s at 16 / 32 / 64)
  const double theta = 0.45 + 0.55 * spec.density_theta / 16.0;
  // the sky-view table, once per pass: each texel integrates single and multiple scattering along
  // its ray, whose samples every sun and azimuth share (rgb, 5 × 45 × 64 × 32 texels: 2.0 s, 4.4 s
  // per Mtexel), a per-channel part as the orders'; reading the density's μ_s texels geometrically
  // (mu_s_blend) adds a logarithm per channel and sample (measured: rgb 5 × 33 × 64 × 32 texels
  // 0.78 → 1.26 s, 16 wavelengths 5 × 45 × 64 × 32 1.5 → 5.3 s: 1.9 + 0.6 s per channel per Mtexel)
  const SkyView table = sky_view_of(spec);
  const double sky_view_per_mtexel = table.geometric_density ? 1.9 + 0.6 * width : 4.4 * (1.45 + 0.015 * width) / 1.5;
  const double sky_view = passes * table.texels() / 1048576.0 * sky_view_per_mtexel;
  return bake_files_seconds(spec) + orders * passes * theta * per_order +
         passes * (1e-5 * transmittance + orders * 6e-5 * irradiance) + interpolation + sky_view;
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
  const Sizes s = stored_sizes(spec);  // the files' sizes
  p["sizes"] = {{"transmittance", {{"mu", s.transmittance_w}, {"r", s.transmittance_h}}},
                {"irradiance", {{"mu_s", s.irradiance_w}, {"r", s.irradiance_h}}},
                {"scattering", {{"r", s.r}, {"mu", s.mu}, {"mu_s", s.mu_s}, {"nu", s.nu}}}};
  if (s.mu_s != m.sizes.mu_s)
    p["sizes"]["scattering"]["mu_s_baked"] = {
        {"mu_s", m.sizes.mu_s},
        {"meaning", "the bake's own mu_s texels (the densities of every order); the stored textures are resampled "
                    "to mu_s (each stored texel the baked texture's lookup at its mu_s): the sky-view table holds "
                    "the scene's views, the 4D textures the rest"}};
  if (s.nu != m.sizes.nu)
    p["sizes"]["scattering"]["nu_baked"] = {
        {"nu", m.sizes.nu},
        {"meaning", "the bake's own nu slices (the densities of every order); the stored textures hold every "
                    "other one (resampled linearly where the count is even): the sky-view table holds the "
                    "scene's views, the 4D textures the rest"}};
  // what an engine holds: transmittance, irradiance, scattering and single Mie (and the sky-view
  // table's two textures where there is one) as float32 R,G,B
  const SkyView& v = m.sky_view;
  p["texture_memory_bytes"] = 12LL * (1LL * s.transmittance_w * s.transmittance_h + 1LL * s.irradiance_w * s.irradiance_h +
                                      2LL * s.scattering_texels() + 2LL * v.texels());
  p["sky_view"] = v.on() ? json{{"altitude_km", {v.altitude_min_km, v.altitude_max_km}},
                                {"sun_elevation_deg", {v.sun_min_deg, v.sun_max_deg}},
                                {"nodes", {{"altitude", v.altitude}, {"sun", v.sun}, {"view", v.view}, {"azimuth", v.azimuth}}},
                                {"files", {"sky_view", "sky_view_single_mie"}},
                                {"density_mu_s_blend", v.geometric_density ? "geometric" : "linear"},
                                {"meaning", "the sky in the viewer's frame over the scene's cameras and suns: sky_view = "
                                            "single Rayleigh x P_R(nu) + orders >= 2, sky_view_single_mie = single Mie "
                                            "without its phase, each integrated along the view's exact ray; "
                                            "GetSkyRadianceWithSkyView (sampling.glsl) reads it where it holds the "
                                            "camera and the sun, the 4D textures elsewhere"}}
                         : json(false);
  json layouts = json::array();
  if (spec.layout_3d) layouts.push_back("3d");
  if (spec.layout_tiled2d) layouts.push_back("tiled2d");
  p["layout"] = layouts;
  p["orders_requested"] = spec.orders ? json(*spec.orders) : json("auto");
  p["orders_tail"] = takes_geometric_tail(spec) ? json("geometric: the last order's density at every texel and channel "
                                              "divided by 1 - rho, rho = J_n / J_(n-1) clamped to [0, 0.9]; the "
                                              "irradiance of orders >= n from its light")
                                      : json("none");
  p["tolerance"] = spec.tolerance;
  p["precision"] = spec.double_precision ? "float64" : "float32";
  const int width = channels_per_pass(spec);
  p["passes"] = (sp.lambda_nm.size() + width - 1) / width;
  p["channels_per_pass"] = width;
  p["length_unit"] = "km (texture values do not depend on it)";
  p["quadrature"] = {{"transmittance", "trapezoid, 500 intervals"},
                     {"single_and_multiple_scattering", std::string(m.ray_simpson ? "Simpson" : "trapezoid") +
                                                            ", 50 intervals to the nearest boundary"},
                     {"ray_rule", m.ray_simpson ? "simpson" : "trapezoid"},
                     {"phase_nu", m.phase_nu_slice ? "slice" : "clamped"},
                     {"scattering_density", "midpoint " + std::to_string(m.density_theta) + " x 32 over the sphere, theta " +
                                                (m.density_theta_power == 1.0 ? "uniform" : "packed towards the horizon") +
                                                (m.phase_weights_normalised ? ", phase weights normalised to sum 1" : "")},
                     {"density_theta", m.density_theta},
                     {"density_rule", m.density_theta_power == 1.0 ? "uniform" : "horizon"},
                     {"phase_weights", m.phase_weights_normalised ? "normalised" : "plain"},
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
