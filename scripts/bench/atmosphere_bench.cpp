// Speed against error of the atmosphere bake: orders 1..8 and auto, sizes half / default /
// double, spectrum rgb / spectral 16 / 48. Error: GetSkyRadiance from our LUTs at the 60
// reference sky-radiance points, max over points and channels of
// |ours − ref| / (|ref| + 1e-3 max|ref|), against Bruneton's reference implementation (rgb
// runs, sky_max_rel_err) and against a higher-resolution run of ours (vs_finer_run: the 200 %
// sizes for rgb, 48 wavelengths for spectral). process_cpu_s counts every thread (PoCL's
// workers too). AroundKernels: what a bake spends beside its kernels (sums, self-checks, reads).
//   build-atmosphere/scripts/bench/atmosphere_bench --benchmark_filter='Rgb/4/1'
#include <benchmark/benchmark.h>

#include "bench_device.hpp"
#include <sys/resource.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "kinds/atmosphere/atmosphere_job.hpp"

using namespace specbake;
using namespace specbake::atmosphere;

namespace {

double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

using specbake::bench::device;

AtmosphereSpec earth(int scale_percent) {
  AtmosphereSpec s;
  set_earth_profiles(s);  // Bruneton's demo Earth, as `preset: earth`
  auto sc = [&](int v) { return std::max(2, v * scale_percent / 100); };
  s.transmittance_mu = sc(256);
  s.transmittance_r = sc(64);
  s.irradiance_mu_s = sc(64);
  s.irradiance_r = sc(16);
  s.scattering_r = sc(32);
  s.scattering_mu = sc(128) / 2 * 2;
  s.scattering_mu_s = sc(32);
  s.scattering_nu = sc(8);
  return s;
}

struct SkyPoint {
  double alt_km, view_mu, sun_mu, az, rad[3];
};
std::vector<SkyPoint> sky_points() {
  std::ifstream f(std::string(SPECBAKE_BENCH_REFDATA) + "/atmosphere/sky_radiance_points.csv");
  std::vector<SkyPoint> out;
  std::string line;
  bool header = true;
  while (std::getline(f, line)) {
    if (line.empty() || line[0] == '#') continue;
    if (header) {
      header = false;
      continue;
    }
    std::stringstream ss(line);
    std::vector<double> v;
    std::string t;
    while (std::getline(ss, t, ',')) v.push_back(std::stod(t));
    out.push_back({v[0] * 1e-3, v[1], v[2], v[3], {v[5], v[6], v[7]}});
  }
  return out;
}

// Sky radiance from a bake's LUTs at the reference points (3 channels each).
std::vector<double> sky_values(const Baked& b) {
  static const auto pts = sky_points();
  const Renderer render(b.luts);
  std::vector<double> out;
  for (const auto& p : pts) {
    const Vec3 camera{0, 0, b.luts.model.bottom_radius_km + p.alt_km};
    const Vec3 view{std::sqrt(1 - p.view_mu * p.view_mu), 0, p.view_mu};
    const double s = std::sqrt(1 - p.sun_mu * p.sun_mu);
    const Vec3 sun{s * std::cos(p.az), s * std::sin(p.az), p.sun_mu};
    const Vec3 l = render.sky_radiance(camera, view, sun, nullptr);
    for (int c = 0; c < 3; ++c) out.push_back(l[c]);
  }
  return out;
}
// max |a − ref| / (|ref| + 1e-3 max|ref|)
double max_rel_err(const std::vector<double>& a, const std::vector<double>& ref) {
  double mx = 0.0, e = 0.0;
  for (double v : ref) mx = std::max(mx, std::fabs(v));
  for (std::size_t i = 0; i < ref.size(); ++i) e = std::max(e, std::fabs(a[i] - ref[i]) / (std::fabs(ref[i]) + 1e-3 * mx));
  return e;
}
const std::vector<double>& reference_sky() {
  static const std::vector<double> v = [] {
    std::vector<double> out;
    for (const auto& p : sky_points())
      for (double r : p.rad) out.push_back(r);
    return out;
  }();
  return v;
}

const auto kQuiet = [](std::string_view, double) {};

// The finer runs of "against a higher-resolution run": 200 % rgb and 48 wavelengths at 100 %,
// both 4 orders.
AtmosphereSpec finer_spec(bool spectral) {
  AtmosphereSpec s = earth(spectral ? 100 : 200);
  s.orders = 4;
  s.spectral = spectral;
  s.count = 48;
  return s;
}
std::vector<double>* g_keep_sky = nullptr;  // where the running row stores its sky, if it is a finer run

// Bakes once and reports process CPU seconds; `finer` (if given) is the sky of a
// higher-resolution run to compare with.
void run(benchmark::State& state, AtmosphereSpec spec, bool rgb_error, const std::vector<double>* finer = nullptr) {
  double err = 0.0, cpu = 0.0, err_finer = 0.0;
  int orders = 0;
  for (auto _ : state) {
    const double c0 = cpu_seconds();
    const Baked b = bake_luts(spec, device(), kQuiet, 0);
    cpu += cpu_seconds() - c0;
    orders = b.orders_used;
    const auto sky = sky_values(b);
    if (g_keep_sky) *g_keep_sky = sky;
    if (rgb_error) err = max_rel_err(sky, reference_sky());
    if (finer) err_finer = max_rel_err(sky, *finer);
  }
  state.counters["process_cpu_s"] = cpu / state.iterations();
  state.counters["orders_used"] = orders;
  if (rgb_error) state.counters["sky_max_rel_err"] = err;
  if (finer) state.counters["vs_finer_run"] = err_finer;
}

// Args: orders (0 = auto), size percent
void Rgb(benchmark::State& state) {
  AtmosphereSpec s = earth(static_cast<int>(state.range(1)));
  if (state.range(0) == 0) s.orders.reset();
  else s.orders = static_cast<int>(state.range(0));
  run(state, s, true);
}
BENCHMARK(Rgb)
    ->ArgsProduct({{1, 2, 3, 4, 5, 6, 7, 8, 0}, {50}})
    ->Args({4, 100})
    ->Args({8, 100})
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);

// Rows compared with a finer run of their group: the finest row of the group runs first and
// keeps its sky; the others compare with it (baking it first if run alone, e.g. by filter).
void run_against_finer(benchmark::State& state, const AtmosphereSpec& s, bool finest, bool spectral) {
  static std::vector<double> fine[2];
  std::vector<double>& f = fine[spectral ? 1 : 0];
  if (finest) {
    g_keep_sky = &f;
    run(state, s, !spectral);
    g_keep_sky = nullptr;
  } else {
    if (f.empty()) f = sky_values(bake_luts(finer_spec(spectral), device(), kQuiet, 0));
    run(state, s, !spectral, &f);
  }
}

// Args: size percent (4 orders); vs_finer_run: against the 200 % bake.
void RgbSize(benchmark::State& state) {
  AtmosphereSpec s = earth(static_cast<int>(state.range(0)));
  s.orders = 4;
  run_against_finer(state, s, state.range(0) == 200, false);
}
BENCHMARK(RgbSize)->Arg(200)->Arg(100)->Arg(50)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(1);

// Args: wavelengths, size percent (4 orders); vs_finer_run: against 48 wavelengths at 100 %.
void Spectral(benchmark::State& state) {
  AtmosphereSpec s = earth(static_cast<int>(state.range(1)));
  s.spectral = true;
  s.count = static_cast<int>(state.range(0));
  s.orders = 4;
  run_against_finer(state, s, state.range(0) == 48 && state.range(1) == 100, true);
}
BENCHMARK(Spectral)
    ->Args({48, 100})
    ->Args({16, 100})
    ->Args({16, 50})
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);

// The work around the kernels of a bake with its self-checks (24 texels a stage, as a job runs
// them), from the bake's own stage records: `kernels_s` the kernel stages' device seconds,
// `sums_s` and `self_check_s` those stages' wall seconds (their device part in `_device_s`),
// `combine_s` the final reads. Args: wavelengths (3 = rgb), size percent (4 orders).
void AroundKernels(benchmark::State& state) {
  AtmosphereSpec s = earth(static_cast<int>(state.range(1)));
  s.spectral = state.range(0) != 3;
  s.count = static_cast<int>(state.range(0));
  s.orders = 4;
  nlohmann::json total;
  for (auto _ : state) total = bake_luts(s, device(), kQuiet, 24).timings["total"];
  double kernels = 0.0;
  for (const auto& [stage, sec] : total.items())
    if (stage != "sums" && stage != "self_check" && stage != "combine" && stage != "setup")
      kernels += sec.value("device_s", 0.0);
  const auto wall = [&](const char* stage, const char* field) { return total.contains(stage) ? total[stage].value(field, 0.0) : 0.0; };
  state.counters["kernels_s"] = kernels;
  state.counters["sums_s"] = wall("sums", "wall_s");
  state.counters["sums_device_s"] = wall("sums", "device_s");
  state.counters["self_check_s"] = wall("self_check", "wall_s");
  state.counters["self_check_device_s"] = wall("self_check", "device_s");
  state.counters["combine_s"] = wall("combine", "wall_s");
}
BENCHMARK(AroundKernels)
    ->Args({3, 100})
    ->Args({48, 100})
    ->Args({3, 200})
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
