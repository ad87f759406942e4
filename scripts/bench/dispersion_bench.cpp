// Speed against error for the dispersion job: for each sampling scheme and N, the time of
// the device bake (weights + matrices) and the thin-prism colour error (mean CIEDE2000 vs a
// 0.1 nm spectrum, spread 4 beam widths) reported as the counter `dE2000`.
#include <benchmark/benchmark.h>

#include "bench_device.hpp"

#include "cl/device.hpp"
#include "kinds/dispersion/dispersion_job.hpp"

using namespace specbake;

namespace {
using specbake::bench::device;

void BM_Dispersion(benchmark::State& state) {
  DispersionSpec spec;
  spec.sampling = static_cast<Sampling>(state.range(0));
  spec.material.n_ref = 1.5168;
  spec.material.v = 64.17;
  const int n = static_cast<int>(state.range(1));
  const auto samples = dispersion::make_samples(spec.sampling, spec.range_nm, n);
  const dispersion::MaterialModel m = dispersion::resolve_material(spec.material, dispersion::lines_for(spec.abbe_lines));
  dispersion::Tables t;
  for (auto _ : state) {
    t = dispersion::compute_device(device(), spec, samples, m);
    benchmark::DoNotOptimize(t.K.data());
  }
  dispersion::PrismJudge judge(device(), spec);
  state.counters["dE2000"] = judge.mean_delta_e(t);
  state.SetLabel(to_string(spec.sampling));
}
}  // namespace

BENCHMARK(BM_Dispersion)
    ->ArgsProduct({{0, 1, 2, 3}, {8, 16, 32, 64, 128, 256}})
    ->Unit(benchmark::kMicrosecond);

BENCHMARK_MAIN();
