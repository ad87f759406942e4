#include "kinds/diffraction/terms.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "cl/buffers.hpp"
#include "cl/fft.hpp"
#include "kinds/diffraction/reference.hpp"

namespace specbake::diffraction {

namespace {
constexpr double kTwoPi = 6.283185307179586476925287;
constexpr std::size_t kWorkspaceBytes = 64u << 20;  // FFT batch buffer cap

// Signed bins [lo, hi] (hi − lo < m) as runs contiguous in an unshifted array of length m:
// bins first_offset … first_offset+count−1 (from lo) sit at indices first_index … .
struct BinRun {
  std::size_t first_offset, first_index, count;
};
std::vector<BinRun> bin_runs(int lo, int hi, int m) {
  std::vector<BinRun> runs;
  for (int k = lo; k <= hi;) {
    const int index = static_cast<int>(ref::bin_index(k, m));
    const int count = std::min(hi - k + 1, m - index);
    runs.push_back({static_cast<std::size_t>(k - lo), static_cast<std::size_t>(index), static_cast<std::size_t>(count)});
    k += count;
  }
  return runs;
}

// Twiddles e^{−2πi·k·j/m} for j = 0…m−1.
std::vector<cplx> twiddles(int k, int m) {
  std::vector<cplx> t(m);
  for (int j = 0; j < m; ++j) {
    const long long r = (static_cast<long long>(k) * j) % m;  // exact reduction keeps the angle small
    const double a = -kTwoPi * static_cast<double>(r) / m;
    t[j] = {std::cos(a), std::sin(a)};
  }
  return t;
}
}  // namespace

int expansion_id(Expansion e) { return e == Expansion::taylor ? DIFFRACTION_TAYLOR : DIFFRACTION_CHEBYSHEV; }

std::vector<double> packed_bands(const std::vector<Band>& bands) {
  std::vector<double> b;
  for (const auto& band : bands)
    b.insert(b.end(), {band.kappa_hi, static_cast<double>(band.first_term), static_cast<double>(band.terms), band.kappa0,
                       band.delta});
  return b;
}

DeviceHeights::DeviceHeights(cl_util::Device& d, const Field& f) : dev(d), h(cl_util::upload_real(d, f.h_um)) {}

const Band& band_for(const std::vector<Band>& bands, double kappa) {
  for (const auto& b : bands)
    if (kappa <= b.kappa_hi) return b;
  return bands.back();
}

namespace {
void log_run(const cl_util::StageSeconds& s) {
  spdlog::debug("diffraction: {}: device {:.3f} s, host {:.3f} s (wall {:.3f} s)", s.stage, s.device_s, s.host_s(),
                s.wall_s);
}
}  // namespace

void Timings::add(const cl_util::Profiler::Record& r) {
  if (r->pending == 0) log_run(*r);
  runs_.push_back(r);
}

nlohmann::json Timings::json() {
  if (prof_->pending()) {
    prof_->settle();
    for (const auto& r : runs_)
      if (r->commands && r->pending == 0) log_run(*r);  // (again, now complete)
  }
  std::map<std::string, cl_util::StageSeconds> total;
  for (const auto& r : runs_) cl_util::accumulate(total[r->stage], *r);
  nlohmann::json j = nlohmann::json::object();
  for (const auto& [name, sec] : total) j[name] = cl_util::seconds_json(sec);
  return j;
}

Terms device_terms(const DeviceHeights& on, const Field& f, const Plan& plan, const Progress& progress,
                   Timings* timings) {
  cl_util::Device& dev = on.dev;
  Timings local;
  local.use(&dev.profiler());
  Timings& tm = timings ? *timings : local;
  const std::size_t count = static_cast<std::size_t>(f.count());
  int max_terms = 0;
  for (const auto& b : plan.bands) max_terms = std::max(max_terms, b.terms);
  const std::size_t fit = std::max<std::size_t>(1, kWorkspaceBytes / (count * 2 * sizeof(float)));
  const int batch = static_cast<int>(std::min<std::size_t>({static_cast<std::size_t>(max_terms),
                                                            static_cast<std::size_t>(DIFFRACTION_MAX_BATCH), fit}));
  Terms t;
  t.bins = plan.bins;
  t.count = plan.total_terms;
  cl::Program program = tm.time("terms: kernel build", [&] { return dev.build(kProgram, dev.real_options()); });
  // One transform per launch: on PoCL a batched VkFFT plan is slower per array than single ones.
  cl_util::Fft2d& fft = *tm.time("terms: FFT plan", [&] {
    return &cl_util::shared_fft(dev, f.width, f.height, 1, cl_util::FftPrecision::single);
  });
  return cl_util::checked("diffraction terms", [&] {
    const cl::Buffer& h = on.h;
    cl::Buffer work(dev.context(), CL_MEM_READ_WRITE, fft.bytes() * batch);
    t.values.resize(2 * t.per_term() * t.count);
    cl::Kernel inputs(program, "diffraction_term_inputs"), taylor(program, "diffraction_taylor_inputs");
    // The 1/M² of F_n = DFT(q_n)/M² is applied to the inputs (the FFT is linear), so the
    // transformed arrays are read straight into the cropped terms.
    const float scale = static_cast<float>(1.0 / static_cast<double>(count));
    const auto rows = bin_runs(t.bins.kv_min, t.bins.kv_max, f.height);
    const auto cols = bin_runs(t.bins.ku_min, t.bins.ku_max, f.width);
    const std::size_t pair = 2 * sizeof(float);
    int done = 0;
    for (const auto& band : plan.bands)
      for (int n0 = 0; n0 < band.terms; n0 += batch) {
        const int n = std::min(batch, band.terms - n0);
        // Taylor terms by running products (cheaper per sample); Chebyshev through the general kernel.
        if (band.expansion == Expansion::taylor) {
          taylor.setArg(0, h);
          taylor.setArg(1, static_cast<int>(count));
          cl_util::set_real_arg(dev, taylor, 2, f.c);
          cl_util::set_real_arg(dev, taylor, 3, f.s > 0 ? 1.0 / f.s : 0.0);
          cl_util::set_real_arg(dev, taylor, 4, band.kappa0);
          taylor.setArg(5, n0);
          taylor.setArg(6, n);
          taylor.setArg(7, scale);
          taylor.setArg(8, work);
        } else {
          inputs.setArg(0, h);
          inputs.setArg(1, static_cast<int>(count));
          cl_util::set_real_arg(dev, inputs, 2, f.c);
          cl_util::set_real_arg(dev, inputs, 3, f.s > 0 ? 1.0 / f.s : 0.0);
          inputs.setArg(4, expansion_id(band.expansion));
          cl_util::set_real_arg(dev, inputs, 5, band.kappa0);
          cl_util::set_real_arg(dev, inputs, 6, band.delta);
          inputs.setArg(7, n0);
          inputs.setArg(8, n);
          inputs.setArg(9, scale);
          inputs.setArg(10, work);
        }
        tm.time("terms: inputs", [&] {
          cl::Event ev;
          dev.queue().enqueueNDRangeKernel(band.expansion == Expansion::taylor ? taylor : inputs, cl::NullRange,
                                           cl::NDRange(count), cl::NullRange, nullptr, &ev);
          dev.profiler().record(ev);
          dev.profiler().wait([&] { dev.queue().finish(); });
        });
        tm.time("terms: FFT", [&] {
          for (int j = 0; j < n; ++j) fft.forward(work, j);
        });
        // Crop while reading: each term's bins are at most 2 × 2 rectangles of the unshifted array.
        tm.time("terms: crop + download", [&] {
          for (int j = 0; j < n; ++j)
            for (const auto& r : rows)
              for (const auto& c : cols) {
                const cl::array<cl::size_type, 3> from{c.first_index * pair, static_cast<cl::size_type>(r.first_index),
                                                       static_cast<cl::size_type>(j)};
                const cl::array<cl::size_type, 3> to{c.first_offset * pair, static_cast<cl::size_type>(r.first_offset),
                                                     static_cast<cl::size_type>(band.first_term + n0 + j)};
                const cl::array<cl::size_type, 3> region{c.count * pair, static_cast<cl::size_type>(r.count), 1};
                cl::Event ev;
                dev.queue().enqueueReadBufferRect(work, CL_FALSE, from, to, region, f.width * pair,
                                                  f.width * pair * f.height, t.bins.ku_count() * pair,
                                                  t.per_term() * pair, t.values.data(), nullptr, &ev);
                dev.profiler().record(ev);
              }
          dev.profiler().wait([&] { dev.queue().finish(); });
        });
        done += n;
        progress("FFT terms", 0.1 + 0.6 * done / std::max(1, t.count));
      }
    return t;
  });
}

std::vector<cplx> reference_inputs(const Field& f, const Band& band, int n_first, int count) {
  const std::size_t m = static_cast<std::size_t>(f.count());
  std::vector<cplx> q(m * count);
  double re[DIFFRACTION_MAX_BATCH], im[DIFFRACTION_MAX_BATCH];
  for (int n0 = 0; n0 < count; n0 += DIFFRACTION_MAX_BATCH) {
    const int n = std::min(DIFFRACTION_MAX_BATCH, count - n0);
    for (std::size_t i = 0; i < m; ++i) {
      ref::term_inputs(f.h_um[i], f.c, f.s > 0 ? 1.0 / f.s : 0.0, expansion_id(band.expansion), band.kappa0,
                       band.delta, n_first + n0, n, re, im);
      for (int j = 0; j < n; ++j) q[(n0 + j) * m + i] = {re[j], im[j]};
    }
  }
  return q;
}

std::vector<cplx> host_dft(const std::vector<cplx>& field, int width, int height, const Bins& bins) {
  // Rows first: R[iy][ku] = Σ_ix f[iy][ix]·e^{−2πi ku ix/W}; then columns over iy.
  const int nu = bins.ku_count(), nv = bins.kv_count();
  std::vector<cplx> rows(static_cast<std::size_t>(height) * nu);
  for (int a = 0; a < nu; ++a) {
    const auto tw = twiddles(bins.ku_min + a, width);
    for (int iy = 0; iy < height; ++iy) {
      cplx s = 0.0;
      const cplx* row = field.data() + static_cast<std::size_t>(iy) * width;
      for (int ix = 0; ix < width; ++ix) s += row[ix] * tw[ix];
      rows[static_cast<std::size_t>(iy) * nu + a] = s;
    }
  }
  std::vector<cplx> out(static_cast<std::size_t>(nv) * nu);
  const double inv = 1.0 / (static_cast<double>(width) * height);
  for (int b = 0; b < nv; ++b) {
    const auto tw = twiddles(bins.kv_min + b, height);
    for (int a = 0; a < nu; ++a) {
      cplx s = 0.0;
      for (int iy = 0; iy < height; ++iy) s += rows[static_cast<std::size_t>(iy) * nu + a] * tw[iy];
      out[static_cast<std::size_t>(b) * nu + a] = s * inv;
    }
  }
  return out;
}

std::vector<cplx> reference_terms(const Field& f, const std::vector<Band>& bands, const Bins& bins) {
  std::vector<cplx> out;
  const std::size_t m = static_cast<std::size_t>(f.count());
  for (const auto& band : bands) {
    const auto q = reference_inputs(f, band, 0, band.terms);
    for (int n = 0; n < band.terms; ++n) {
      std::vector<cplx> one(q.begin() + n * m, q.begin() + (n + 1) * m);
      const auto F = host_dft(one, f.width, f.height, bins);
      out.insert(out.end(), F.begin(), F.end());
    }
  }
  return out;
}

std::vector<cplx> reference_terms_at(const Field& f, const std::vector<Band>& bands,
                                     const std::vector<std::pair<int, int>>& bins) {
  int total = 0;  // indexed by first_term + n: bands may be subsets of a plan's terms
  for (const auto& b : bands) total = std::max(total, b.first_term + b.terms);
  const std::size_t nb = bins.size(), T = static_cast<std::size_t>(total);
  std::vector<std::vector<cplx>> tx, ty;
  for (const auto& [ku, kv] : bins) {
    tx.push_back(twiddles(ku, f.width));
    ty.push_back(twiddles(kv, f.height));
  }
  // One pass over the samples, rows in parallel: row iy's sums Σ_ix q_n·tx go into its own
  // slot, then the rows are added in order (the result does not depend on the thread count).
  std::vector<cplx> per_row(static_cast<std::size_t>(f.height) * T * nb);
  const double inv_s = f.s > 0 ? 1.0 / f.s : 0.0;
  parallel_for(f.height, [&](long long iy) {
    cplx* row_sum = per_row.data() + static_cast<std::size_t>(iy) * T * nb;
    std::vector<cplx> acc(T * nb);
    double re[DIFFRACTION_MAX_BATCH], im[DIFFRACTION_MAX_BATCH];
    for (int ix = 0; ix < f.width; ++ix) {
      const double h = f.h_um[static_cast<std::size_t>(iy) * f.width + ix];
      for (const auto& band : bands)
        for (int n0 = 0; n0 < band.terms; n0 += DIFFRACTION_MAX_BATCH) {
          const int n = std::min(DIFFRACTION_MAX_BATCH, band.terms - n0);
          ref::term_inputs(h, f.c, inv_s, expansion_id(band.expansion), band.kappa0, band.delta, n0, n, re, im);
          for (int j = 0; j < n; ++j) {
            cplx* a = acc.data() + static_cast<std::size_t>(band.first_term + n0 + j) * nb;
            for (std::size_t b = 0; b < nb; ++b) {  // real arithmetic: no NaN-recovery call per product
              const double wr = tx[b][ix].real(), wi = tx[b][ix].imag();
              a[b] += cplx(re[j] * wr - im[j] * wi, re[j] * wi + im[j] * wr);
            }
          }
        }
    }
    for (std::size_t k = 0; k < T; ++k)
      for (std::size_t b = 0; b < nb; ++b) row_sum[k * nb + b] = acc[k * nb + b] * ty[b][iy];
  });
  std::vector<cplx> out(T * nb, 0.0);
  for (int iy = 0; iy < f.height; ++iy)
    for (std::size_t k = 0; k < T * nb; ++k) out[k] += per_row[static_cast<std::size_t>(iy) * T * nb + k];
  for (auto& v : out) v /= static_cast<double>(f.count());
  return out;
}

struct ExactDft::Impl {
  cl_util::Device* dev = nullptr;
  const Field* f = nullptr;
  Bins bins;
  cl_util::Fft2d* fft = nullptr;  // the device's shared double-precision plan
  cl::Kernel phase;               // diffraction_phase_field
  cl::Buffer h, p;                // the heights (uploaded once) and the transformed array
  // The error of a reconstruction (prepare, transform, max_error).
  cl::Kernel error;               // diffraction_reconstruction_error
  const Terms* terms = nullptr;
  cl::Buffer terms_dev;
  double kappa = 0.0;
  bool errors_on_device = false;  // prepare's choice
  bool exact_on_device = false;   // the last transform is in p, else in `exact`
  std::vector<cplx> exact;
  // e^{iκh} formed on the device from the heights, transformed in place into p.
  void transform_on_device(double k) {
    phase.setArg(0, h);
    phase.setArg(1, static_cast<int>(f->count()));
    phase.setArg(2, k);
    phase.setArg(3, p);
    cl::Event ev;
    dev->queue().enqueueNDRangeKernel(phase, cl::NullRange, cl::NDRange(f->count()), cl::NullRange, nullptr, &ev);
    dev->profiler().record(ev);
    fft->forward(p);
  }
};

ExactDft::ExactDft(const DeviceHeights* on, const Field& f, const Bins& bins) : impl_(std::make_unique<Impl>()) {
  impl_->f = &f;
  impl_->bins = bins;
  cl_util::Device* dev = on ? &on->dev : nullptr;
  if (dev && dev->info().fp64) {
    impl_->fft = &cl_util::shared_fft(*dev, f.width, f.height, 1, cl_util::FftPrecision::double_);
    cl_util::checked("exact DFT: device set-up", [&] {
      const cl::Program program = dev->build(kProgram, dev->real_options());
      impl_->phase = cl::Kernel(program, "diffraction_phase_field");
      impl_->error = cl::Kernel(program, "diffraction_reconstruction_error");
      impl_->h = on->h;
      impl_->p = cl::Buffer(dev->context(), CL_MEM_READ_WRITE, static_cast<std::size_t>(f.count()) * sizeof(cplx));
      return 0;
    });
    impl_->dev = dev;
  }
}
ExactDft::~ExactDft() = default;
bool ExactDft::on_device() const { return impl_->fft != nullptr; }

std::vector<cplx> ExactDft::operator()(double kappa) {
  const Field& f = *impl_->f;
  const Bins& bins = impl_->bins;
  const std::size_t m = static_cast<std::size_t>(f.count());
  if (kappa == 0.0) {
    // e^{i·0·h} = 1: the transform is M² at the DC bin and exactly 0 elsewhere.
    std::vector<cplx> out(static_cast<std::size_t>(bins.ku_count()) * bins.kv_count(), 0.0);
    if (bins.ku_min <= 0 && bins.ku_max >= 0 && bins.kv_min <= 0 && bins.kv_max >= 0)
      out[static_cast<std::size_t>(-bins.kv_min) * bins.ku_count() - bins.ku_min] = static_cast<double>(m);
    return out;
  }
  if (!impl_->fft) {
    std::vector<cplx> p(m);
    parallel_for(f.height, [&](long long iy) {
      for (std::size_t i = iy * static_cast<std::size_t>(f.width), e = i + f.width; i < e; ++i)
        p[i] = std::polar(1.0, kappa * f.h_um[i]);
    });
    auto out = host_dft(p, f.width, f.height, bins);
    for (auto& v : out) v *= static_cast<double>(m);
    return out;
  }
  cl_util::Device& dev = *impl_->dev;
  return cl_util::checked("exact DFT", [&] {
    impl_->transform_on_device(kappa);
    cl::Buffer& buf = impl_->p;
    // Read only the bins, as rectangles of the unshifted transform.
    const std::size_t nu = bins.ku_count(), nv = bins.kv_count(), pair = sizeof(cplx);
    std::vector<cplx> out(nu * nv);
    for (const auto& r : bin_runs(bins.kv_min, bins.kv_max, f.height))
      for (const auto& c : bin_runs(bins.ku_min, bins.ku_max, f.width)) {
        cl::Event ev;
        dev.queue().enqueueReadBufferRect(
            buf, CL_FALSE, {c.first_index * pair, r.first_index, 0}, {c.first_offset * pair, r.first_offset, 0},
            {c.count * pair, r.count, 1}, f.width * pair, m * pair, nu * pair, nu * nv * pair, out.data(), nullptr,
            &ev);
        dev.profiler().record(ev);
      }
    dev.profiler().wait([&] { dev.queue().finish(); });
    return out;
  });
}

namespace {
template <class Get>
std::vector<cplx> reconstruct_with(Get get, const Bins& bins, const Band& band, const Field& f, double kappa) {
  std::vector<double> coef(band.terms);
  ref::expansion_coefficients(expansion_id(band.expansion), kappa, band.kappa0, band.delta, f.s, band.terms,
                              coef.data());
  const std::size_t per = static_cast<std::size_t>(bins.ku_count()) * bins.kv_count();
  std::vector<cplx> p(per);
  const cplx front = static_cast<double>(f.count()) * std::polar(1.0, kappa * f.c);
  // Runs of bins on the hardware threads; each bin's sum in term order (any split, same values).
  constexpr std::size_t kRun = 4096;
  parallel_for(static_cast<long long>((per + kRun - 1) / kRun), [&](long long run) {
    const std::size_t lo = static_cast<std::size_t>(run) * kRun, hi = std::min(per, lo + kRun);
    for (std::size_t i = lo; i < hi; ++i) p[i] = 0.0;
    for (int n = 0; n < band.terms; ++n)
      for (std::size_t i = lo; i < hi; ++i) p[i] += coef[n] * get(band.first_term + n, i);
    for (std::size_t i = lo; i < hi; ++i) p[i] *= front;
  });
  return p;
}
}  // namespace

std::vector<cplx> reconstruct(const Terms& t, const Band& band, const Field& f, double kappa) {
  const std::size_t per = t.per_term();
  return reconstruct_with(
      [&](int n, std::size_t i) {
        const std::size_t k = n * per + i;
        return cplx(t.values[2 * k], t.values[2 * k + 1]);
      },
      t.bins, band, f, kappa);
}

std::vector<cplx> reconstruct(const std::vector<cplx>& terms, const Bins& bins, const Band& band, const Field& f,
                              double kappa) {
  const std::size_t per = static_cast<std::size_t>(bins.ku_count()) * bins.kv_count();
  return reconstruct_with([&](int n, std::size_t i) { return terms[n * per + i]; }, bins, band, f, kappa);
}

namespace {
// max_j |a_j − b_j| over runs of elements on the hardware threads (a maximum: the same in any order).
double max_abs_difference(const std::vector<cplx>& a, const std::vector<cplx>& b) {
  constexpr std::size_t kRun = 1 << 16;
  const std::size_t runs = (a.size() + kRun - 1) / kRun;
  std::vector<double> worst(runs, 0.0);
  parallel_for(static_cast<long long>(runs), [&](long long r) {
    double m = 0.0;
    for (std::size_t j = static_cast<std::size_t>(r) * kRun, e = std::min(a.size(), j + kRun); j < e; ++j)
      m = std::max(m, std::abs(a[j] - b[j]));
    worst[r] = m;
  });
  return worst.empty() ? 0.0 : *std::max_element(worst.begin(), worst.end());
}
constexpr std::size_t kErrorItems = 1 << 15;  // work items of diffraction_reconstruction_error
}  // namespace

void ExactDft::prepare(const Terms& terms, bool on_device) {
  impl_->terms = &terms;
  impl_->errors_on_device = impl_->fft && on_device;
  if (!impl_->errors_on_device) return;
  cl_util::Device& dev = *impl_->dev;
  impl_->terms_dev = cl_util::checked("reconstruction error: terms upload", [&] {
    return cl::Buffer(dev.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, terms.values.size() * sizeof(float),
                      const_cast<float*>(terms.values.data()));
  });
}

void ExactDft::transform(double kappa) {
  impl_->kappa = kappa;
  impl_->exact_on_device = impl_->errors_on_device && kappa != 0.0;
  if (impl_->exact_on_device)
    cl_util::checked("exact DFT", [&] {
      impl_->transform_on_device(kappa);
      return 0;
    });
  else
    impl_->exact = (*this)(kappa);
}

double ExactDft::max_error(const Band& band) {
  const Terms& t = *impl_->terms;
  const Field& f = *impl_->f;
  const double kappa = impl_->kappa;
  if (!impl_->exact_on_device) return max_abs_difference(reconstruct(t, band, f, kappa), impl_->exact);
  cl_util::Device& dev = *impl_->dev;
  std::vector<double> coef(band.terms);
  ref::expansion_coefficients(expansion_id(band.expansion), kappa, band.kappa0, band.delta, f.s, band.terms,
                              coef.data());
  const cplx front = static_cast<double>(f.count()) * std::polar(1.0, kappa * f.c);
  const std::size_t items = std::min<std::size_t>(kErrorItems, t.per_term());
  return cl_util::checked("reconstruction error", [&] {
    const cl::Buffer coef_dev = cl_util::upload_real(dev, coef), out = cl_util::device_real(dev, items);
    cl::Kernel& k = impl_->error;
    int arg = 0;
    k.setArg(arg++, impl_->terms_dev);
    k.setArg(arg++, t.bins.ku_min);
    k.setArg(arg++, t.bins.kv_min);
    k.setArg(arg++, t.bins.ku_count());
    k.setArg(arg++, t.bins.kv_count());
    k.setArg(arg++, f.width);
    k.setArg(arg++, f.height);
    k.setArg(arg++, band.first_term);
    k.setArg(arg++, band.terms);
    k.setArg(arg++, coef_dev);
    k.setArg(arg++, front.real());
    k.setArg(arg++, front.imag());
    k.setArg(arg++, impl_->p);
    k.setArg(arg++, static_cast<int>(items));
    k.setArg(arg++, out);
    cl_util::run_1d(dev, k, items);
    const auto worst = cl_util::download_real(dev, out, items);
    return *std::max_element(worst.begin(), worst.end());
  });
}

}  // namespace specbake::diffraction
