// Speed against error of the diffraction bake (docs/diffraction.md has a measured table).
//   BM_Terms/<field>/<expansion>/<T>: the device path (term inputs + VkFFT float32 + crop) for
//     one band of T terms; counters: measured max |P_rec − P_exact|/M² over κ ∈ {κ_hi/2, κ_hi}
//     from float32 terms (err_f32) and from the same terms rounded to half (err_half).
//   BM_WholeJob/<field>: the complete bake (terms: auto, tolerance 1e-4: planning, terms,
//     error measurement with double DFTs, self-check, EXR, previews), counter ffts = terms,
//     fft_ms / other_stages_ms from the bake's stage timings, and, measured right after in
//     the same run, fftw_same_count_ms (FFTW as below, `ffts` transforms) and job_over_fftw
//     (the target is ≤ 1.5 on the 1024² field). SPECBAKE_BENCH_STAGES=1 prints every stage's
//     time of the last bake to stderr.
//   BM_VkFft/<field>/<count>: VkFFT float32 alone, `count` transforms as the job runs them.
//   BM_FftwBaseline/<field>/<count>: FFTW single precision, planned (FFTW_MEASURE), with as many
//     threads as the OpenCL device has compute units, `count` in-place 2D FFTs of the field size.
// Fields: 0 = the 128² random smooth reference field (refdata), 1 = a 1024² smooth random
// field with the same height range (0…0.5 µm, dx 0.05 µm). Scene: 380–780 nm, w_max 2.
#include <benchmark/benchmark.h>

#include "bench_device.hpp"
#include <Imath/half.h>
#include <spdlog/spdlog.h>

#ifdef SPECBAKE_HAVE_FFTW
#include <fftw3.h>
#endif

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>

#include "cl/device.hpp"
#include "cl/fft.hpp"
#include "kinds/diffraction/diffraction_job.hpp"
#include "kinds/diffraction/planning.hpp"
#include "kinds/diffraction/terms.hpp"

using namespace specbake;
using namespace specbake::diffraction;

namespace {

using specbake::bench::device;

std::shared_ptr<const Heightfield> field(int which) {
  static std::shared_ptr<const Heightfield> cache[2];
  if (cache[which]) return cache[which];
  auto hf = std::make_shared<Heightfield>();
  if (which == 0) {
    hf->width = hf->height = 128;
    hf->dx_um = 0.05;
    std::ifstream in(SPECBAKE_BENCH_REFDATA "/diffraction/random_smooth_128_f32le.raw", std::ios::binary);
    std::vector<float> v(128 * 128);
    in.read(reinterpret_cast<char*>(v.data()), v.size() * 4);
    if (!in) throw std::runtime_error("cannot read the random smooth reference field");
    hf->h_um.assign(v.begin(), v.end());
  } else {
    const int m = 1024;
    hf->width = hf->height = m;
    hf->dx_um = 0.05;
    std::mt19937 rng(20240601);
    std::uniform_real_distribution<double> phase(0.0, 6.283185307179586);
    std::uniform_int_distribution<int> freq(-24, 24);
    struct Wave {
      int fx, fy;
      double ph, a;
    };
    std::vector<Wave> waves;
    for (int i = 0; i < 40; ++i) waves.push_back({freq(rng), freq(rng), phase(rng), 1.0 / (1 + i % 7)});
    hf->h_um.assign(static_cast<std::size_t>(m) * m, 0.0);
    for (int iy = 0; iy < m; ++iy)
      for (int ix = 0; ix < m; ++ix) {
        double s = 0.0;
        for (const auto& w : waves) s += w.a * std::sin(6.283185307179586 * (w.fx * ix + w.fy * iy) / m + w.ph);
        hf->h_um[static_cast<std::size_t>(iy) * m + ix] = s;
      }
    const auto [lo, hi] = std::minmax_element(hf->h_um.begin(), hf->h_um.end());
    const double a = *lo, b = *hi;
    for (auto& h : hf->h_um) h = 0.5 * (h - a) / (b - a);
  }
  cache[which] = hf;
  return hf;
}

DiffractionSpec spec_for(int which, Expansion e) {
  DiffractionSpec s;
  s.field = field(which);
  s.source = which == 0 ? "random smooth 128" : "smooth random 1024";
  s.expansion = e;
  return s;
}

const Progress kQuiet = [](std::string_view, double) {};

void BM_Terms(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  const Expansion e = state.range(1) == 0 ? Expansion::taylor : Expansion::chebyshev;
  const int T = static_cast<int>(state.range(2));
  DiffractionSpec spec = spec_for(which, e);
  spec.terms = T;
  const Field f = make_field(spec);
  const Plan p = make_plan(spec, f, spec.tolerance);
  const DeviceHeights heights(device(), f);  // uploaded once, as a bake does
  Terms t;
  device_terms(heights, f, p, kQuiet);  // warm-up: kernel and VkFFT plan builds
  for (auto _ : state) {
    t = device_terms(heights, f, p, kQuiet);
    benchmark::DoNotOptimize(t.values.data());
  }
  Terms h = t;
  for (auto& v : h.values) v = static_cast<float>(Imath::half(v));
  ExactDft exact(&heights, f, p.bins);
  double err = 0.0, err_half = 0.0;
  for (double kappa : {0.5 * p.kappa_hi, p.kappa_hi}) {
    const auto ex = exact(kappa);
    const auto a = reconstruct(t, p.bands[0], f, kappa), b = reconstruct(h, p.bands[0], f, kappa);
    for (std::size_t i = 0; i < ex.size(); ++i) {
      err = std::max(err, std::abs(a[i] - ex[i]) / f.count());
      err_half = std::max(err_half, std::abs(b[i] - ex[i]) / f.count());
    }
  }
  state.counters["err_f32"] = err;
  state.counters["err_half"] = err_half;
  state.counters["bound"] = p.estimated_error;
  state.counters["y_max"] = p.y_max;
  state.counters["K"] = p.bins.ku_count();
}

#ifdef SPECBAKE_HAVE_FFTW
// FFTW single precision, planned with FFTW_MEASURE (planning not timed), with as many threads
// as the OpenCL device has compute units, on one m × m array transformed in place.
struct FftwField {
  fftwf_complex* buf = nullptr;
  fftwf_plan plan = nullptr;
  explicit FftwField(int m) {
    static bool threads = (fftwf_init_threads(), true);
    (void)threads;
    fftwf_plan_with_nthreads(static_cast<int>(device().info().compute_units));
    buf = fftwf_alloc_complex(static_cast<std::size_t>(m) * m);
    plan = fftwf_plan_dft_2d(m, m, buf, buf, FFTW_FORWARD, FFTW_MEASURE);
    for (int i = 0; i < m * m; ++i) {
      buf[i][0] = std::sin(0.001f * i);
      buf[i][1] = 0.0f;
    }
  }
  ~FftwField() {
    fftwf_destroy_plan(plan);
    fftwf_free(buf);
  }
  void run(int count) {
    for (int k = 0; k < count; ++k) fftwf_execute(plan);
  }
};
// ms for `count` FFTs of m × m, best of 3.
double fftw_ms(int m, int count) {
  FftwField f(m);
  double best = 1e300;
  for (int rep = 0; rep < 3; ++rep) {
    const auto t0 = std::chrono::steady_clock::now();
    f.run(count);
    best = std::min(best, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  return best;
}
#endif

void BM_WholeJob(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  const Expansion e = state.range(1) == 0 ? Expansion::taylor : Expansion::chebyshev;
  DiffractionSpec spec = spec_for(which, e);
  JobContext ctx{device()};
  BakeResult r = bake(spec, ctx);  // warm-up
  double job_ms = 1e300;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    r = bake(spec, ctx);
    job_ms = std::min(job_ms, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    benchmark::DoNotOptimize(r.files.data());
  }
  const int ffts = r.parameters["terms"].get<int>();
  state.counters["ffts"] = ffts;
  state.counters["bands"] = static_cast<double>(r.parameters["bands"].size());
  state.counters["err_f32"] = find_accuracy(accuracy_json(r.accuracy), "vs_exact_transform")->at("value").get<double>();
  // Stages of the last bake (ms): the FFTs alone, and everything else.
  const auto& tm = r.manifest_blocks["diffraction"]["timings_s"];
  double total = 0.0;
  for (const auto& [stage, s] : tm.items()) total += s["wall_s"].get<double>();
  state.counters["fft_ms"] = 1e3 * tm["terms: FFT"]["wall_s"].get<double>();
  state.counters["other_stages_ms"] = 1e3 * (total - tm["terms: FFT"]["wall_s"].get<double>());
  if (std::getenv("SPECBAKE_BENCH_STAGES"))  // every stage of the last bake, for the docs' table
    std::fprintf(stderr, "BM_WholeJob/%d/%d stages (s): %s\n", which, static_cast<int>(state.range(1)), tm.dump().c_str());
#ifdef SPECBAKE_HAVE_FFTW
  // Side by side: FFTW doing the job's number of FFTs, right after the job.
  const double fftw = fftw_ms(which == 0 ? 128 : 1024, ffts);
  state.counters["fftw_same_count_ms"] = fftw;
  state.counters["job_over_fftw"] = job_ms / fftw;
#endif
}

// VkFFT alone: `count` in-place float32 transforms of one 1024² (or 128²) array, one per
// launch as the job runs them (each waits for completion).
void BM_VkFft(benchmark::State& state) {
  const int m = state.range(0) == 0 ? 128 : 1024;
  const int count = static_cast<int>(state.range(1));
  cl_util::Fft2d fft(device(), m, m, 1, cl_util::FftPrecision::single);
  std::vector<float> v(2 * static_cast<std::size_t>(m) * m, 0.0f);
  for (std::size_t i = 0; i < v.size(); i += 2) v[i] = std::sin(0.001f * static_cast<float>(i / 2));
  cl::Buffer buf(device().context(), CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, v.size() * sizeof(float), v.data());
  fft.forward(buf);  // warm-up
  for (auto _ : state)
    for (int k = 0; k < count; ++k) fft.forward(buf);
}

#ifdef SPECBAKE_HAVE_FFTW
void BM_FftwBaseline(benchmark::State& state) {
  FftwField f(state.range(0) == 0 ? 128 : 1024);
  const int count = static_cast<int>(state.range(1));
  for (auto _ : state) f.run(count);
  state.counters["threads"] = device().info().compute_units;
}
#endif

void sweep(benchmark::internal::Benchmark* b) {
  for (int which : {0, 1})
    for (int e : {0, 1})
      for (int T : {5, 10, 20, 30, 40, 60}) b->Args({which, e, T});
}

}  // namespace

BENCHMARK(BM_Terms)->Apply(sweep)->Unit(benchmark::kMillisecond)->Iterations(2);
BENCHMARK(BM_WholeJob)->Args({0, 0})->Args({0, 1})->Args({1, 0})->Args({1, 1})->Unit(benchmark::kMillisecond)->Iterations(2);
BENCHMARK(BM_VkFft)->Args({0, 10})->Args({0, 17})->Args({0, 12})->Args({1, 1})->Args({1, 12})->Args({1, 17})->Unit(benchmark::kMillisecond)->Iterations(3);
#ifdef SPECBAKE_HAVE_FFTW
BENCHMARK(BM_FftwBaseline)
    ->Args({0, 10})->Args({0, 17})->Args({0, 12})->Args({1, 1})->Args({1, 12})->Args({1, 17})
    ->Unit(benchmark::kMillisecond)->Iterations(3);
#endif

int main(int argc, char** argv) {
  spdlog::set_level(spdlog::level::warn);
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
}
