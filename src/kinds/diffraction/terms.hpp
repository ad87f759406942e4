#pragma once
// Computing the FFT terms F_n of a plan: on the device (term-input kernel, batched VkFFT in
// float32, cropped while reading back) and, for checks, on the host in double precision with the same
// term-input maths (reference.hpp) and direct DFTs. Also the exact P(k;κ) = DFT(e^{iκh}) in
// double precision, and the reconstruction of P from stored terms.
#include <complex>
#include <string>
#include <thread>
#include <algorithm>
#include <vector>

#include "core/parallel.hpp"
#include "cl/device.hpp"
#include "kinds/diffraction/planning.hpp"
#include "job/kind.hpp"

namespace specbake::diffraction {

// The OpenCL program of the diffraction kernels (embedded path).
inline constexpr const char* kProgram = "kernels/diffraction/kernels.cl";

using cplx = std::complex<double>;

// A field's heights on a device, as the device's `real`: uploaded once per bake and read by every
// pass that needs them (the terms, the exact transforms or sums of the error measurement).
struct DeviceHeights {
  DeviceHeights(cl_util::Device& dev, const Field& f);
  cl_util::Device& dev;
  cl::Buffer h;
};

// Terms as the bundle stores them: float32 [T][kv][ku][re, im] over plan.bins.
struct Terms {
  Bins bins;
  int count = 0;
  std::vector<float> values;
  std::size_t per_term() const { return static_cast<std::size_t>(bins.ku_count()) * bins.kv_count(); }
  cplx at(int n, int ku, int kv) const {
    const std::size_t i = n * per_term() + static_cast<std::size_t>(kv - bins.kv_min) * bins.ku_count() + (ku - bins.ku_min);
    return {values[2 * i], values[2 * i + 1]};
  }
};


// Seconds per stage of a bake, summed over repeats of a stage, as cl_util::StageSeconds
// defines them: device_s from the profiling events of the commands enqueued inside the stage
// (recorded in the device's profiler), host_s = wall_s minus the time spent waiting for the
// device. Each stage run is logged at debug level.
class Timings {
 public:
  // Commands are recorded in `p` (the device's profiler); until then (or with null) in a
  // profiler of its own that sees no commands: device_s 0.
  void use(cl_util::Profiler* p) { prof_ = p ? p : &own_; }
  // Runs fn() as stage `stage`.
  template <class Fn>
  decltype(auto) time(const std::string& stage, Fn&& fn) {
    cl_util::Profiler::Stage st(*prof_, stage);
    struct Done {
      Timings* t;
      cl_util::Profiler::Stage* st;
      ~Done() { t->add(st->close()); }
    } done{this, &st};
    return fn();
  }
  // {"<stage>": {"device_s", "host_s", "wall_s"}, …}; reads the times of unfinished commands first.
  nlohmann::json json();

 private:
  void add(const cl_util::Profiler::Record& r);
  cl_util::Profiler own_;
  cl_util::Profiler* prof_ = &own_;
  std::vector<cl_util::Profiler::Record> runs_;
};

// The device path: float32 FFTs with VkFFT. Adds its sub-stages ("terms: …") to `timings`.
Terms device_terms(const DeviceHeights& on, const Field& f, const Plan& plan, const Progress& progress,
                   Timings* timings = nullptr);

// Host double-precision term inputs q_n of every sample for the band's terms [n_first, n_first+count).
std::vector<cplx> reference_inputs(const Field& f, const Band& band, int n_first, int count);
// Host DFT (separable, O(W·H·(W+H))) of a W×H complex field at the bins, over W·H: [kv][ku].
std::vector<cplx> host_dft(const std::vector<cplx>& field, int width, int height, const Bins& bins);
// Host reference terms F_n over the bins, double precision: [T][kv][ku].
std::vector<cplx> reference_terms(const Field& f, const std::vector<Band>& bands, const Bins& bins);
// F_n of every term at a few bins by direct sums (O(W·H) per bin and term), in one pass over
// the samples on the hardware threads: [T][bins.size()] with T = max(first_term + terms).
std::vector<cplx> reference_terms_at(const Field& f, const std::vector<Band>& bands,
                                     const std::vector<std::pair<int, int>>& bins);

// Exact P(k;κ) = Σ e^{iκh}·e^{−2πi(...)} over the bins ([kv][ku], not divided by M²), in double
// precision: VkFFT double on the heights' device when it has fp64 (e^{iκh} formed there by
// diffraction_phase_field from the heights), else the host DFT;
// κ = 0 needs no transform (M² at the DC bin, 0 elsewhere).
class ExactDft {
 public:
  ExactDft(const DeviceHeights* on, const Field& f, const Bins& bins);  // on may be null: the host
  ~ExactDft();
  std::vector<cplx> operator()(double kappa);
  bool on_device() const;

  // The error of a reconstruction: prepare(terms) once (terms must outlive the calls), then per κ
  // transform(κ) and, for each band holding κ, max_error(band): max over the bins of |P_rec −
  // P_exact(κ)| with P_rec = reconstruct(terms, band, f, κ). With `on_device` and the transform on
  // the device: the terms uploaded once, P_exact never read back, each work item's maximum over
  // its bins by diffraction_reconstruction_error (κ = 0 excepted: its exact values need no
  // transform); else on the host's threads. A maximum: the same whatever the split. The bake asks
  // for the device on a GPU only: on a CPU device (PoCL) the host's threads are ~4x faster.
  void prepare(const Terms& terms, bool on_device);
  void transform(double kappa);
  double max_error(const Band& band);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// P(k;κ) = M²·e^{iκc}·Σ_n coef_n(κ)·F_n[k] over the bins from `terms` ([kv][ku]).
std::vector<cplx> reconstruct(const Terms& terms, const Band& band, const Field& f, double kappa);
// The same from double terms [T][kv][ku] (reference path).
std::vector<cplx> reconstruct(const std::vector<cplx>& terms, const Bins& bins, const Band& band, const Field& f,
                              double kappa);

// The band whose range holds κ (the first one at a shared edge).
const Band& band_for(const std::vector<Band>& bands, double kappa);
// `dev` where a pass that a CPU device runs slower than the host's threads (the previews, the
// reconstruction error, the exact sums: PoCL's scalar double maths against the host's threads
// and libm; docs/diffraction.md, "Speed") should run on it: not a CPU; else null.
inline cl_util::Device* unless_cpu(cl_util::Device& dev) { return dev.info().type == "cpu" ? nullptr : &dev; }
// DIFFRACTION_TAYLOR or DIFFRACTION_CHEBYSHEV, as the .cl maths names an expansion.
int expansion_id(Expansion e);
// The bands as kernels/diffraction/table.cl takes them: κ_hi, first term, term count, κ_0, Δ per
// band (DIFFRACTION_BAND_REALS each; table_band picks as band_for does).
std::vector<double> packed_bands(const std::vector<Band>& bands);

}  // namespace specbake::diffraction
