// Speed of the path-traced truth (kernels/atmosphere/path_tracer.cl): 256 points of a scene
// (the default Earth, rgb, all orders), traced until every channel's standard error is at
// most 0.3 % of its radiance (TruthOptions::target_relative_se, first 2048 walks per point).
// Counters: process CPU seconds (PoCL's worker threads included), walks per point, the worst
// relative se, events per walk. Arguments: the scene's views (0 sky, 1 ground, 2 all) and
// the ratio-tracking boost is fixed in the kernel (TRUTH_RATIO_BOOST).
//   build/scripts/bench/truth_bench --benchmark_filter='Truth256/2'
#include <benchmark/benchmark.h>

#include "bench_device.hpp"
#include <sys/resource.h>

#include <algorithm>
#include <cmath>

#include "kinds/atmosphere/truth/truth.hpp"

using namespace specbake;
using namespace specbake::atmosphere;

namespace {

double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

using specbake::bench::device;

AtmosphereSpec earth() {
  AtmosphereSpec s;
  set_earth_profiles(s);  // Bruneton's demo Earth, as `preset: earth`
  return s;
}

// Cameras 0–15 km, the sun 5–85° above the horizon.
void Truth256(benchmark::State& state) {
  const AtmosphereSpec s = earth();
  const TruthViews views[3] = {TruthViews::sky, TruthViews::ground, TruthViews::all};
  const auto points = scene_points(TruthScene{0.0, 15.0, 5.0, 85.0, views[state.range(0)], 256}, s);
  TruthOptions o;
  o.paths = 2048;
  o.target_relative_se = 0.003;
  trace_truth(s, device(), {points[0]}, TruthOptions{});  // build the kernel outside the timing
  TruthResult r;
  double cpu = 0.0;
  for (auto _ : state) {
    const double c0 = cpu_seconds();
    r = trace_truth(s, device(), points, o);
    cpu += cpu_seconds() - c0;
  }
  double worst = 0.0, walks = 0.0;
  long long most = 0;
  for (std::size_t p = 0; p < r.points; ++p) {
    walks += static_cast<double>(r.paths[p]);
    most = std::max(most, r.paths[p]);
    for (std::size_t c = 0; c < r.channels; ++c) worst = std::max(worst, r.se(p, c) / r.L(p, c));
  }
  state.counters["process_cpu_s"] = cpu / state.iterations();
  state.counters["walks_per_point_mean"] = walks / r.points;
  state.counters["walks_per_point_max"] = static_cast<double>(most);
  state.counters["worst_rel_se"] = worst;
  state.counters["events_per_walk"] = r.mean_events;
}
BENCHMARK(Truth256)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
