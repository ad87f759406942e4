// The error a user sees, against what it costs: the scene check (src/kinds/atmosphere/
// scene_check.hpp) of the hard cases and the default ground scene, for texture sizes, orders
// and spectrum. Each atmosphere (Earth, hazy Earth, Mars) is baked once per setting (its wall
// time is the `bake_s` counter) and judged at every scene of that atmosphere (128 points,
// 1 % target se, as a bake's check); `check_s` is the check's wall time.
// Arguments: {scene, setting}; scenes and settings are listed below.
//   build/scripts/bench/scene_bench --benchmark_filter='Scene/0/'
#include <benchmark/benchmark.h>

#include "bench_device.hpp"

#include <chrono>
#include <map>
#include <string>

#include "registry/registry.hpp"
#include "kinds/atmosphere/atmosphere_job.hpp"
#include "kinds/atmosphere/truth/scene_check.hpp"

using namespace specbake;
using namespace specbake::atmosphere;

namespace {

using specbake::bench::device;

struct Scene {
  const char* name;
  int atmosphere;     // 0 Earth, 1 hazy Earth, 2 Mars
  const char* yaml;   // the scene block
};
const Scene kScenes[] = {
    {"default ground scene", 0, "{camera_altitude_km: [0, 2], sun_elevation_deg: [-6, 90]}"},
    {"sun at -6 deg", 0, "{camera_altitude_km: [0, 2], sun_elevation_deg: -6}"},
    {"sun at -12 deg (towards the sun)", 0,
     "{camera_altitude_km: [0, 2], sun_elevation_deg: -12, view_elevation_deg: [0, 8], view_sun_azimuth_deg: [0, 30]}"},
    {"grazing from 0 m", 0, "{camera_altitude_km: 0, sun_elevation_deg: [2, 40], view_elevation_deg: [0, 2]}"},
    {"grazing from 10 km", 0,
     "{camera_altitude_km: 10, sun_elevation_deg: [2, 40], views: all, view_elevation_deg: [-4.2, -2.2]}"},
    {"terminator from space", 0, "{camera_altitude_km: 400, sun_elevation_deg: [-8, 4], views: ground}"},
    {"hazy Earth", 1, "{sun_elevation_deg: [-6, 60]}"},
    {"Mars", 2, "{sun_elevation_deg: [-10, 60]}"},
    {"daylight ground scene", 0, "{camera_altitude_km: [0, 2], sun_elevation_deg: [2, 90]}"},
};
const char* kAtmospheres[] = {
    "    preset: earth\n",
    "    preset: earth\n    ground_albedo: 0.3\n"
    "    mie: {scale_height_km: 2.0, extinction_per_m: 3.5e-5, single_scattering_albedo: 0.95, phase_g: 0.75}\n",
    "    preset: earth\n    bottom_radius_km: 3389.5\n    top_radius_km: 3469.5\n    sun_angular_radius_rad: 0.00307\n"
    "    solar_irradiance_scale: 0.431\n    ground_albedo: 0.25\n    max_sun_zenith_deg: 110\n"
    "    rayleigh: {scale_height_km: 11.1, scattering_per_m_at_1um: 2.0e-8}\n"
    "    mie: {scale_height_km: 11.0, extinction_per_m: 4.5e-5, angstrom_alpha: 0.0, single_scattering_albedo: 0.95, "
    "phase_g: 0.7}\n    ozone: false\n",
};
// Settings: sizes (percent of the defaults, every axis), orders (0: the atmosphere's own: 4,
// hazy 10, Mars 6; -1: auto), spectrum (0: rgb, else wavelengths over 360-830 nm).
struct Setting {
  const char* name;
  int percent, orders, wavelengths;
};
const Setting kSettings[] = {
    {"50 %, rgb", 50, 0, 0},
    {"100 %, rgb", 100, 0, 0},
    {"100 %, rgb, orders auto", 100, -1, 0},
    {"100 %, 16 wavelengths", 100, 0, 16},
    {"50 %, 16 wavelengths", 50, 0, 16},
};

std::string job_yaml(int atmosphere, const Setting& s, const char* scene) {
  const int own_orders[] = {4, 10, 6};
  auto scaled = [&](int v) { return std::max(2, v * s.percent / 100); };
  std::string y = kAtmospheres[atmosphere];
  y += "    orders: " + (s.orders < 0 ? std::string("auto") : std::to_string(s.orders ? s.orders : own_orders[atmosphere])) + "\n";
  if (s.wavelengths) y += "    spectrum: {min_nm: 360, max_nm: 830, count: " + std::to_string(s.wavelengths) + "}\n";
  y += "    sizes: {transmittance: [" + std::to_string(scaled(256)) + ", " + std::to_string(scaled(64)) +
       "], irradiance: [" + std::to_string(scaled(64)) + ", " + std::to_string(scaled(16)) +
       "], scattering: {r: " + std::to_string(scaled(32)) + ", mu: " + std::to_string(scaled(128) / 2 * 2) +
       ", mu_s: " + std::to_string(scaled(32)) + ", nu: " + std::to_string(scaled(8)) + "}}\n";
  y += std::string("    scene: ") + scene + "\n";
  return y;
}

AtmosphereSpec spec_of(const std::string& job) {
  const Config c = parse_config("specbake: 1\njobs:\n  - name: sky\n    kind: atmosphere\n" + job, "bench.yaml");
  return c.jobs.at(0).as<AtmosphereSpec>();
}

struct BakedOnce {
  Baked b;
  double seconds = 0.0;
};
const BakedOnce& baked(int atmosphere, int setting, const AtmosphereSpec& spec) {
  static std::map<std::pair<int, int>, BakedOnce> cache;
  auto it = cache.find({atmosphere, setting});
  if (it != cache.end()) return it->second;
  const auto t0 = std::chrono::steady_clock::now();
  BakedOnce o;
  o.b = bake_luts(spec, device(), [](std::string_view, double) {}, 24);
  o.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return cache.emplace(std::pair{atmosphere, setting}, std::move(o)).first->second;
}

void SceneCheckBench(benchmark::State& state) {
  const Scene& sc = kScenes[state.range(0)];
  const Setting& st = kSettings[state.range(1)];
  const AtmosphereSpec spec = spec_of(job_yaml(sc.atmosphere, st, sc.yaml));
  const BakedOnce& b = baked(sc.atmosphere, static_cast<int>(state.range(1)), spec);
  SceneCheck c;
  for (auto _ : state) c = check_scene(spec, b.b.luts, b.b.orders_used, device(), [](std::string_view, double) {});
  const auto& d = c.record.details;
  const auto& total = d["parts"]["total"];
  double rel = 0.0;
  for (const char* ch : {"R", "G", "B"}) rel = std::max(rel, total["relative"][ch]["p99"].get<double>());
  state.SetLabel(std::string(sc.name) + " | " + st.name);
  state.counters["bake_s"] = b.seconds;
  state.counters["check_s"] = c.seconds;
  state.counters["orders"] = b.b.orders_used;
  state.counters["de_p99"] = total["de2000"]["p99"].get<double>();
  state.counters["de_max"] = total["de2000"]["max"].get<double>();
  state.counters["de_mean"] = total["de2000"]["mean"].get<double>();
  state.counters["rel_p99"] = rel;
  state.counters["lut_p99"] = d["parts"]["lut_discretisation"]["de2000"]["p99"].get<double>();
  state.counters["orders_p99"] = d["parts"]["order_truncation"]["de2000"]["p99"].get<double>();
  state.counters["spectral_p99"] =
      d["parts"].contains("spectral_sampling") ? d["parts"]["spectral_sampling"]["de2000"]["p99"].get<double>() : 0.0;
  state.counters["se_de_mean"] = d["standard_error"]["de2000"]["mean"].get<double>();
}

void AllArgs(benchmark::internal::Benchmark* b) {
  for (int s = 0; s < static_cast<int>(std::size(kScenes)); ++s)
    for (int k = 0; k < static_cast<int>(std::size(kSettings)); ++k) b->Args({s, k});
}

}  // namespace

BENCHMARK(SceneCheckBench)->Name("Scene")->Apply(AllArgs)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(1);

BENCHMARK_MAIN();
