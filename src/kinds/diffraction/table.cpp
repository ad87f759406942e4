#include "kinds/diffraction/table.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <tuple>
#include <utility>

#include "cl/buffers.hpp"
#include "cl/fft.hpp"
#include "core/parallel.hpp"
#include "kinds/diffraction/reference.hpp"
#include "kinds/diffraction/terms.hpp"

namespace specbake::diffraction {

namespace {
constexpr double kPi = 3.141592653589793238462643;
constexpr double kTwoPi = 2.0 * kPi;

// Phasors e^{−2πi·f_k·x_j} for every frequency k and sample j of one axis: [k][j] as re, im.
void axis_phasors(const std::vector<double>& freqs, int samples, double dx, std::vector<double>& re,
                  std::vector<double>& im) {
  const std::size_t n = freqs.size();
  re.resize(n * samples);
  im.resize(n * samples);
  const double x0 = 0.5 * (samples - 1);
  for (std::size_t k = 0; k < n; ++k)
    for (int j = 0; j < samples; ++j) {
      // The phase reduced to [0, 1) cycles before the trigonometry keeps it exact to ~1e-16
      // whatever f·x is.
      double cyc = freqs[k] * (j - x0) * dx;
      cyc -= std::floor(cyc);
      re[k * samples + j] = std::cos(kTwoPi * cyc);
      im[k * samples + j] = -std::sin(kTwoPi * cyc);
    }
}

// Σ_j (ar + i·ai)_j·(er + i·ei)_j over n samples: one row against one frequency's phasors.
std::pair<double, double> row_dot(const double* ar, const double* ai, const double* er, const double* ei, int n) {
  double sr = 0, si = 0;
  for (int j = 0; j < n; ++j) {
    sr += ar[j] * er[j] - ai[j] * ei[j];
    si += ar[j] * ei[j] + ai[j] * er[j];
  }
  return {sr, si};
}

double percentile99(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(std::floor(0.99 * static_cast<double>(v.size() - 1)))];
}

// A fixed linear congruential sequence (Knuth's MMIX constants): the same points every run.
struct Lcg {
  std::uint64_t x = 0x9E3779B97F4A7C15ull;
  double next() {
    x = x * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(x >> 11) * (1.0 / 9007199254740992.0);
  }
};
}  // namespace

double disc_coherence_length_um(double theta_rad, double lambda_um) { return 2.0 * lambda_um / (kPi * theta_rad); }

double coherence_reference_lambda_um(const DiffractionSpec& spec) {
  return 0.5 * (spec.range_nm.lo + spec.range_nm.hi) * 1e-3;
}

double coherence_length_um(const DiffractionSpec& spec) {
  if (spec.coherence.length_um) return *spec.coherence.length_um;
  return disc_coherence_length_um(spec.coherence.source_angular_diameter_deg * kPi / 180.0,
                                  coherence_reference_lambda_um(spec));
}

double TableGeometry::freq_at_s(double sv) const {
  const double a = std::pow(std::fabs(sv), power) * f_max;
  return sv < 0 ? -a : a;
}

double TableGeometry::width(int i) const {
  const double sv = std::fabs(s(i));
  return power * (power == 1.0 ? 1.0 : std::pow(sv, power - 1.0)) * f_max * 2.0 / size;
}

double TableGeometry::texel_of(double f) const { return ref::diffraction_texel(f, f_max, power, size); }

TableGeometry table_geometry(const DiffractionSpec& spec, int size) {
  TableGeometry g;
  g.size = size;
  g.power = spec.table ? spec.table->power : 1.0;
  g.f_max = spec.table && spec.table->f_max_per_um ? *spec.table->f_max_per_um : 2.0 / (spec.range_nm.lo * 1e-3);
  return g;
}

Window make_window(const Field& f, double sigma_um) {
  Window w;
  w.sigma_um = sigma_um;
  auto axis = [&](int m, std::vector<double>& out) {
    out.resize(m);
    const double x0 = 0.5 * (m - 1);
    for (int j = 0; j < m; ++j) {
      const double x = (j - x0) * f.dx_um;
      out[j] = std::exp(-x * x / (2.0 * sigma_um * sigma_um));
    }
  };
  axis(f.width, w.wx);
  axis(f.height, w.wy);
  double sx = 0, sy = 0, qx = 0, qy = 0;
  for (double v : w.wx) sx += v, qx += v * v;
  for (double v : w.wy) sy += v, qy += v * v;
  w.sum = sx * sy;
  w.sum_sq = qx * qy;
  return w;
}

std::vector<cplx> table_terms(const Field& f, const Window& w, const std::vector<Band>& bands, const TableGeometry& g) {
  const int n = g.size, W = f.width, H = f.height;
  std::vector<double> freqs(n);
  for (int i = 0; i < n; ++i) freqs[i] = g.freq(i);
  std::vector<double> eur, eui, evr, evi;
  axis_phasors(freqs, W, f.dx_um, eur, eui);
  axis_phasors(freqs, H, f.dx_um, evr, evi);
  int total = 0;
  for (const auto& b : bands) total = std::max(total, b.first_term + b.terms);
  const std::size_t per = static_cast<std::size_t>(n) * n;
  std::vector<cplx> out(per * total);
  const double inv = 1.0 / (static_cast<double>(W) * H);
  std::vector<double> ar(static_cast<std::size_t>(W) * H), ai(ar.size());
  std::vector<double> gr(static_cast<std::size_t>(H) * n), gi(gr.size());
  for (const auto& band : bands)
    for (int t = 0; t < band.terms; ++t) {
      const auto q = reference_inputs(f, band, t, 1);
      for (int iy = 0; iy < H; ++iy)
        for (int ix = 0; ix < W; ++ix) {
          const std::size_t j = static_cast<std::size_t>(iy) * W + ix;
          const double wj = w.wx[ix] * w.wy[iy];
          ar[j] = wj * q[j].real();
          ai[j] = wj * q[j].imag();
        }
      // Rows: G[iy][iu] = Σ_ix a[iy][ix]·e^{−2πi f_u x}.
      parallel_for(H, [&](long long iy) {
        const double* rr = ar.data() + iy * W;
        const double* ri = ai.data() + iy * W;
        for (int iu = 0; iu < n; ++iu) {
          const std::size_t at = static_cast<std::size_t>(iu) * W;
          std::tie(gr[iy * n + iu], gi[iy * n + iu]) = row_dot(rr, ri, eur.data() + at, eui.data() + at, W);
        }
      });
      // Columns: F[iv][iu] = Σ_iy e^{−2πi f_v y}·G[iy][iu].
      cplx* dst = out.data() + per * (band.first_term + t);
      parallel_for(n, [&](long long iv) {
        std::vector<double> sr(n, 0.0), si(n, 0.0);
        for (int iy = 0; iy < H; ++iy) {
          const double er = evr[iv * H + iy], ei = evi[iv * H + iy];
          const double* pr = gr.data() + static_cast<std::size_t>(iy) * n;
          const double* pi = gi.data() + static_cast<std::size_t>(iy) * n;
          for (int iu = 0; iu < n; ++iu) {
            sr[iu] += er * pr[iu] - ei * pi[iu];
            si[iu] += er * pi[iu] + ei * pr[iu];
          }
        }
        for (int iu = 0; iu < n; ++iu) dst[iv * n + iu] = {sr[iu] * inv, si[iu] * inv};
      });
    }
  return out;
}

// ---- table terms by a separable non-uniform FFT (type 2, Kaiser–Bessel gridding) ----------
//
// One axis, samples a_l (l = 0 … L−1) at y_l = l − c sample spacings from the patch centre, a
// target t = f·dx cycles per sample: with φ the Kaiser–Bessel kernel of width w grid points,
//   φ(ξ) = I₀(β·√(1 − (2ξ/w)²)),  |ξ| ≤ w/2,      φ̂(ν) = w·sinh(√(β² − (πwν)²))/√(β² − (πwν)²),
// Poisson summation over the grid k/n gives
//   Σ_l a_l e^{−2πi t y_l} = Σ_k φ(n t − k)·e^{2πi k c/n}·B[k mod n],   B = FFT_n(a_l / φ̂(y_l/n)),
// up to the aliased images φ̂((y + m n)/n)/φ̂(y/n), m ≠ 0: about 1e-8 for n ≥ 1.5·L, w = 10 and
// β = π·√((w/R)²(R − ½)² − 0.8) with R = 1.5 (Beatty, Nishimura & Pauly 2005), below the
// float32 FFT's rounding. The t are any
// frequencies (beyond the sampling's Nyquist too: B is periodic, the phase is not).
namespace {

constexpr int kKernelWidth = 10;
constexpr double kOversampling = 1.5;

double kb_beta() {
  const double w = kKernelWidth, r = kOversampling;
  return kPi * std::sqrt(w * w / (r * r) * (r - 0.5) * (r - 0.5) - 0.8);
}
double kb(double xi, double beta) {
  const double z = 2.0 * xi / kKernelWidth;
  return std::fabs(z) > 1.0 ? 0.0 : std::cyl_bessel_i(0.0, beta * std::sqrt(1.0 - z * z));
}
double kb_hat(double nu, double beta) {
  const double a = kPi * kKernelWidth * nu, z2 = beta * beta - a * a;
  if (z2 > 0) return kKernelWidth * std::sinh(std::sqrt(z2)) / std::sqrt(z2);
  if (z2 < 0) return kKernelWidth * std::sin(std::sqrt(-z2)) / std::sqrt(-z2);
  return kKernelWidth;
}

// The smallest n ≥ m whose prime factors are 2, 3, 5, 7 (VkFFT's radix kernels, no Bluestein).
int smooth_length(int m) {
  for (int n = std::max(m, 1);; ++n) {
    int r = n;
    for (int p : {2, 3, 5, 7})
      while (r % p == 0) r /= p;
    if (r == 1) return n;
  }
}

// The first kept sample of an axis (the window is symmetric: the kept range is centred).
int first_kept(const std::vector<double>& window) {
  const int m = static_cast<int>(window.size());
  int lo = 0;
  while (lo < m / 2 && window[lo] < kWindowFloor) ++lo;
  return lo;
}

// One axis: the samples the window keeps, the padded length, the deconvolution 1/φ̂.
struct Axis {
  int lo = 0, count = 0, n = 0;
  double c = 0.0;  // the patch centre in kept-sample indices
  std::vector<double> deconv;
};
Axis make_axis(const std::vector<double>& window, double beta) {
  Axis a;
  a.lo = first_kept(window);
  a.count = static_cast<int>(window.size()) - 2 * a.lo;  // the window is symmetric about the centre
  a.n = smooth_length(static_cast<int>(std::ceil(kOversampling * a.count)));
  a.c = 0.5 * (a.count - 1);
  a.deconv.resize(a.count);
  for (int l = 0; l < a.count; ++l) a.deconv[l] = 1.0 / kb_hat((l - a.c) / a.n, beta);
  return a;
}

// Per target frequency of one axis: the first grid index (reduced mod n) and kKernelWidth + 1
// complex weights φ(u − k)·e^{2πikc/n} as (re, im) pairs, for every table of a pass concatenated
// in table order (diffraction_table_spread_rows / _columns read them on the device).
static_assert(kKernelWidth + 1 == DIFFRACTION_TAPS, "the kernels' tap count");
struct Spreads {
  std::vector<int> k0;
  std::vector<double> wt;
};
void add_spread(const Axis& a, const TableGeometry& g, double dx, double beta, Spreads& s) {
  for (int i = 0; i < g.size; ++i) {
    const double u = a.n * g.freq(i) * dx;
    const long long k0 = static_cast<long long>(std::ceil(u - 0.5 * kKernelWidth));
    long long first = k0 % a.n;
    if (first < 0) first += a.n;
    s.k0.push_back(static_cast<int>(first));
    for (int j = 0; j < DIFFRACTION_TAPS; ++j) {
      const long long k = k0 + j;
      const double cyc = std::fmod(static_cast<double>(k) * a.c, static_cast<double>(a.n)) / a.n;
      const cplx w = kb(u - static_cast<double>(k), beta) * std::polar(1.0, kTwoPi * cyc);
      s.wt.push_back(w.real());
      s.wt.push_back(w.imag());
    }
  }
}

constexpr std::size_t kRowChunkBytes = 128u << 20;  // device buffer per batch of transformed rows
constexpr std::size_t kGroupBytes = 768u << 20;     // row-stage results held per group of terms

}  // namespace

double dropped_window_fraction(const Window& w) {
  const auto kept = [](const std::vector<double>& v) {
    const int lo = first_kept(v);
    double s = 0;
    for (std::size_t i = lo; i + lo < v.size(); ++i) s += v[i];
    return s;
  };
  return std::max(0.0, 1.0 - kept(w.wx) * kept(w.wy) / w.sum);
}

AxisExtent fft_extent(int m, double dx_um, double sigma_um) {
  std::vector<double> w(m);
  for (int j = 0; j < m; ++j) {
    const double x = (j - 0.5 * (m - 1)) * dx_um;
    w[j] = std::exp(-x * x / (2.0 * sigma_um * sigma_um));
  }
  const Axis a = make_axis(w, kb_beta());
  return {a.count, a.n};
}

std::vector<std::vector<float>> table_terms_fft(const DeviceHeights& on, const Field& f, const Window& w,
                                                const std::vector<Band>& bands, const std::vector<TableGeometry>& tables,
                                                const std::function<void(double)>& progress) {
  cl_util::Device& dev = on.dev;
  const double beta = kb_beta();
  const Axis ax = make_axis(w.wx, beta), ay = make_axis(w.wy, beta);
  int total = 0;
  for (const auto& b : bands) total = std::max(total, b.first_term + b.terms);
  Spreads su, sv;
  std::vector<int> offset;  // each table's columns among the sum_n of a term's row-stage results
  int sum_n = 0;
  for (const auto& g : tables) {
    add_spread(ax, g, f.dx_um, beta, su);
    add_spread(ay, g, f.dx_um, beta, sv);
    offset.push_back(sum_n);
    sum_n += g.size;
  }
  const double inv = 1.0 / (static_cast<double>(f.width) * f.height);
  const double inv_s = f.s > 0 ? 1.0 / f.s : 0.0;
  // Row-stage results are held on the device as float32 pairs (they feed a float32 transform next).
  const std::size_t per_term = static_cast<std::size_t>(ay.count) * sum_n, pair = 2 * sizeof(float);
  const std::size_t max_alloc = dev.info().max_alloc_bytes ? dev.info().max_alloc_bytes : kGroupBytes;
  const std::size_t group_bytes = std::min<std::size_t>(kGroupBytes, max_alloc);
  const int group = static_cast<int>(std::clamp<std::size_t>(group_bytes / (per_term * pair), 1, DIFFRACTION_MAX_BATCH));
  std::vector<std::vector<float>> out;
  for (const auto& g : tables) out.emplace_back(2 * static_cast<std::size_t>(total) * g.size * g.size);
  return cl_util::checked("table terms", [&] {
    cl::Program program = dev.build(kProgram, dev.real_options());
    cl::Kernel row_inputs(program, "diffraction_table_row_inputs"), spread_rows(program, "diffraction_table_spread_rows"),
        gather(program, "diffraction_table_gather_columns"), spread_columns(program, "diffraction_table_spread_columns");
    const auto run = [&](cl::Kernel& k, std::size_t x, std::size_t y) {
      cl::Event ev;
      dev.queue().enqueueNDRangeKernel(k, cl::NullRange, cl::NDRange(x, y), cl::NullRange, nullptr, &ev);
      dev.profiler().record(ev);
    };
    // The x axis's kept-sample weights (window × deconvolution), the y window and deconvolution,
    // the spreads; the tables' terms, filled term group by term group.
    std::vector<double> weight_x(ax.count);
    for (int l = 0; l < ax.count; ++l) weight_x[l] = w.wx[ax.lo + l] * ax.deconv[l];
    const cl::Buffer& h_dev = on.h;
    const cl::Buffer wx_dev = cl_util::upload_real(dev, weight_x),
                     wy_dev = cl_util::upload_real(dev, w.wy), deconv_y = cl_util::upload_real(dev, ay.deconv),
                     wt_u = cl_util::upload_real(dev, su.wt), wt_v = cl_util::upload_real(dev, sv.wt);
    const cl::Buffer k0_u(dev.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, su.k0.size() * sizeof(int), su.k0.data()),
        k0_v(dev.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, sv.k0.size() * sizeof(int), sv.k0.data());
    std::vector<cl::Buffer> out_dev;
    for (const auto& o : out) out_dev.emplace_back(dev.context(), CL_MEM_READ_WRITE, o.size() * sizeof(float));
    for (const auto& band : bands)
      for (int t0 = 0; t0 < band.terms; t0 += group) {
        const int g = std::min(group, band.terms - t0);
        const cl::Buffer rows(dev.context(), CL_MEM_READ_WRITE, per_term * g * pair);  // [term][kept row][sum_n]
        const int chunk = static_cast<int>(
            std::clamp<std::size_t>(kRowChunkBytes / (static_cast<std::size_t>(g) * ax.n * pair), 1, ay.count));
        for (int r0 = 0; r0 < ay.count; r0 += chunk) {
          const int c = std::min(chunk, ay.count - r0);
          const std::size_t arrays = static_cast<std::size_t>(g) * c;
          // Term inputs q_n·w / φ̂ of the kept samples, [term][row][n] (zero-padded), transformed,
          // then spread to every table's f_u columns.
          cl::Buffer q = cl_util::fft_rows_buffer(dev, ax.n, arrays);
          int arg = 0;
          row_inputs.setArg(arg++, h_dev);
          row_inputs.setArg(arg++, f.width);
          row_inputs.setArg(arg++, ax.lo);
          row_inputs.setArg(arg++, ax.count);
          row_inputs.setArg(arg++, ax.n);
          row_inputs.setArg(arg++, wx_dev);
          row_inputs.setArg(arg++, wy_dev);
          row_inputs.setArg(arg++, ay.lo + r0);
          row_inputs.setArg(arg++, c);
          cl_util::set_real_arg(dev, row_inputs, arg++, f.c);
          cl_util::set_real_arg(dev, row_inputs, arg++, inv_s);
          row_inputs.setArg(arg++, expansion_id(band.expansion));
          cl_util::set_real_arg(dev, row_inputs, arg++, band.kappa0);
          cl_util::set_real_arg(dev, row_inputs, arg++, band.delta);
          row_inputs.setArg(arg++, t0);
          row_inputs.setArg(arg++, g);
          row_inputs.setArg(arg++, q);
          run(row_inputs, ax.n, c);
          cl_util::fft_rows(dev, q, ax.n, arrays);
          arg = 0;
          spread_rows.setArg(arg++, q);
          spread_rows.setArg(arg++, ax.n);
          spread_rows.setArg(arg++, c);
          spread_rows.setArg(arg++, g);
          spread_rows.setArg(arg++, k0_u);
          spread_rows.setArg(arg++, wt_u);
          spread_rows.setArg(arg++, sum_n);
          spread_rows.setArg(arg++, static_cast<cl_long>(per_term));
          spread_rows.setArg(arg++, r0);
          spread_rows.setArg(arg++, rows);
          run(spread_rows, sum_n, arrays);
          dev.profiler().wait([&] { dev.queue().finish(); });
          if (progress) progress((band.first_term + t0 + g * 0.8 * (r0 + c) / ay.count) / total);
        }
        // Columns: for each table column, Σ over the kept rows by the y axis's transform; the
        // columns of all tables and terms of the group in batches.
        const std::size_t columns = static_cast<std::size_t>(sum_n) * g;
        const std::size_t batch = std::clamp<std::size_t>(kRowChunkBytes / (ay.n * pair), 1, columns);
        for (std::size_t c0 = 0; c0 < columns; c0 += batch) {
          const int cn = static_cast<int>(std::min(batch, columns - c0));
          cl::Buffer col = cl_util::fft_rows_buffer(dev, ay.n, cn);
          int arg = 0;
          gather.setArg(arg++, rows);
          gather.setArg(arg++, sum_n);
          gather.setArg(arg++, static_cast<cl_long>(per_term));
          gather.setArg(arg++, ay.count);
          gather.setArg(arg++, ay.n);
          gather.setArg(arg++, deconv_y);
          gather.setArg(arg++, static_cast<cl_long>(c0));
          gather.setArg(arg++, cn);
          gather.setArg(arg++, col);
          run(gather, cn, ay.n);
          cl_util::fft_rows(dev, col, ay.n, cn);
          for (std::size_t k = 0; k < tables.size(); ++k) {
            arg = 0;
            spread_columns.setArg(arg++, col);
            spread_columns.setArg(arg++, ay.n);
            spread_columns.setArg(arg++, static_cast<cl_long>(c0));
            spread_columns.setArg(arg++, cn);
            spread_columns.setArg(arg++, sum_n);
            spread_columns.setArg(arg++, offset[k]);
            spread_columns.setArg(arg++, tables[k].size);
            spread_columns.setArg(arg++, k0_v);
            spread_columns.setArg(arg++, wt_v);
            spread_columns.setArg(arg++, band.first_term + t0);
            cl_util::set_real_arg(dev, spread_columns, arg++, inv);
            spread_columns.setArg(arg++, out_dev[k]);
            run(spread_columns, cn, tables[k].size);
          }
          dev.profiler().wait([&] { dev.queue().finish(); });
          if (progress) progress((band.first_term + t0 + g * (0.8 + 0.2 * static_cast<double>(c0 + cn) / columns)) / total);
        }
      }
    for (std::size_t k = 0; k < out.size(); ++k) {
      cl::Event read;
      dev.queue().enqueueReadBuffer(out_dev[k], CL_FALSE, 0, out[k].size() * sizeof(float), out[k].data(), nullptr, &read);
      dev.profiler().record(read);
    }
    dev.profiler().wait([&] { dev.queue().finish(); });
    return out;
  });
}

std::vector<cplx> windowed_field(const Field& f, const Window& w, double kappa) {
  std::vector<cplx> a(static_cast<std::size_t>(f.count()));
  for (int iy = 0; iy < f.height; ++iy)
    for (int ix = 0; ix < f.width; ++ix) {
      const std::size_t j = static_cast<std::size_t>(iy) * f.width + ix;
      a[j] = w.wx[ix] * w.wy[iy] * std::polar(1.0, kappa * f.h_um[j]);
    }
  return a;
}

cplx direct_transform(const std::vector<cplx>& a, const Field& f, double fu, double fv) {
  const double x0 = 0.5 * (f.width - 1), y0 = 0.5 * (f.height - 1);
  double sr = 0, si = 0;
  for (int iy = 0; iy < f.height; ++iy)
    for (int ix = 0; ix < f.width; ++ix) {
      // The full 2D phase per sample, reduced to [0, 1) cycles.
      double cyc = (fu * (ix - x0) + fv * (iy - y0)) * f.dx_um;
      cyc -= std::floor(cyc);
      const double c = std::cos(kTwoPi * cyc), s = -std::sin(kTwoPi * cyc);
      const cplx v = a[static_cast<std::size_t>(iy) * f.width + ix];
      sr += v.real() * c - v.imag() * s;
      si += v.real() * s + v.imag() * c;
    }
  return {sr, si};
}

namespace {
// The column stage of the grid's direct sums: out[b][a] = Σ_iy e^{−2πi fv[b] y_iy}·R[iy][a], in iy
// order (R from the host's or the device's row stage).
std::vector<cplx> grid_columns(const Field& f, const std::vector<double>& fv, int nu, const std::vector<double>& rr,
                               const std::vector<double>& ri) {
  const int H = f.height, nv = static_cast<int>(fv.size());
  std::vector<double> evr, evi;
  axis_phasors(fv, H, f.dx_um, evr, evi);
  std::vector<cplx> out(static_cast<std::size_t>(nu) * nv);
  parallel_for(nv, [&](long long b) {
    for (int a = 0; a < nu; ++a) {
      double sr = 0, si = 0;
      for (int iy = 0; iy < H; ++iy) {
        const double er = evr[b * H + iy], ei = evi[b * H + iy], pr = rr[iy * nu + a], pi = ri[iy * nu + a];
        sr += er * pr - ei * pi;
        si += er * pi + ei * pr;
      }
      out[b * nu + a] = {sr, si};
    }
  });
  return out;
}
}  // namespace

std::vector<cplx> direct_transform_grid(const Field& f, const Window& w, double kappa, const std::vector<double>& fu,
                                        const std::vector<double>& fv) {
  const int W = f.width, H = f.height, nu = static_cast<int>(fu.size());
  std::vector<double> eur, eui;
  axis_phasors(fu, W, f.dx_um, eur, eui);
  // Rows: R[iy][a] = Σ_ix w·e^{iκh}·e^{−2πi fu[a] x}, each row on its own (deterministic).
  std::vector<double> rr(static_cast<std::size_t>(H) * nu), ri(rr.size());
  parallel_for(H, [&](long long iy) {
    std::vector<double> ar(W), ai(W);
    for (int ix = 0; ix < W; ++ix) {
      const double wj = w.wx[ix] * w.wy[iy], ph = kappa * f.h_um[static_cast<std::size_t>(iy) * W + ix];
      ar[ix] = wj * std::cos(ph);
      ai[ix] = wj * std::sin(ph);
    }
    for (int a = 0; a < nu; ++a) {
      const std::size_t at = static_cast<std::size_t>(a) * W;
      std::tie(rr[iy * nu + a], ri[iy * nu + a]) = row_dot(ar.data(), ai.data(), eur.data() + at, eui.data() + at, W);
    }
  });
  return grid_columns(f, fv, nu, rr, ri);
}

struct ExactGrid::Impl {
  cl_util::Device* dev = nullptr;
  cl::Kernel windowed, rows;
  cl::Buffer h, wx, wy;
};

// Rows of the windowed field held on the device at once (two double arrays of W each).
constexpr std::size_t kExactChunkBytes = 64u << 20;

ExactGrid::ExactGrid(const DeviceHeights* on, const Field& f, const Window& w)
    : f_(f), w_(w), impl_(std::make_shared<Impl>()) {
  if (!on || !on->dev.info().fp64) return;
  cl_util::Device& dev = on->dev;
  cl_util::checked("exact transform: device set-up", [&] {
    const cl::Program program = dev.build(kProgram, dev.real_options());
    impl_->windowed = cl::Kernel(program, "diffraction_windowed_rows");
    impl_->rows = cl::Kernel(program, "diffraction_exact_rows");
    impl_->h = on->h;
    impl_->wx = cl_util::upload_real(dev, w.wx);
    impl_->wy = cl_util::upload_real(dev, w.wy);
    return 0;
  });
  impl_->dev = &dev;
}

bool ExactGrid::on_device() const { return impl_->dev != nullptr; }

std::vector<cplx> ExactGrid::operator()(double kappa, const std::vector<double>& fu,
                                        const std::vector<double>& fv) const {
  if (!impl_->dev) return direct_transform_grid(f_, w_, kappa, fu, fv);
  cl_util::Device& dev = *impl_->dev;
  const int W = f_.width, H = f_.height, nu = static_cast<int>(fu.size());
  if (nu == 0 || fv.empty()) return {};
  // The phasors as [ix][a] (the host's [a][ix] transposed).
  std::vector<double> eur, eui, er_t, ei_t;
  axis_phasors(fu, W, f_.dx_um, eur, eui);
  er_t.resize(eur.size());
  ei_t.resize(eui.size());
  for (int a = 0; a < nu; ++a)
    for (int ix = 0; ix < W; ++ix) {
      er_t[static_cast<std::size_t>(ix) * nu + a] = eur[static_cast<std::size_t>(a) * W + ix];
      ei_t[static_cast<std::size_t>(ix) * nu + a] = eui[static_cast<std::size_t>(a) * W + ix];
    }
  const std::size_t n = static_cast<std::size_t>(H) * nu;
  const int chunk = static_cast<int>(std::clamp<std::size_t>(kExactChunkBytes / (2 * sizeof(double) * W), 1, H));
  std::vector<double> rr(n), ri(n);
  cl_util::checked("exact transform: rows", [&] {
    const cl::Buffer er = cl_util::upload_real(dev, er_t), ei = cl_util::upload_real(dev, ei_t);
    const cl::Buffer r_re = cl_util::device_real(dev, n), r_im = cl_util::device_real(dev, n);
    const cl::Buffer a_re = cl_util::device_real(dev, static_cast<std::size_t>(chunk) * W),
                     a_im = cl_util::device_real(dev, static_cast<std::size_t>(chunk) * W);
    cl::Kernel& kw = impl_->windowed;
    cl::Kernel& kr = impl_->rows;
    for (int y0 = 0; y0 < H; y0 += chunk) {
      const int rows = std::min(chunk, H - y0);
      int arg = 0;
      for (const cl::Buffer* b : {&impl_->h, &impl_->wx, &impl_->wy}) kw.setArg(arg++, *b);
      kw.setArg(arg++, W);
      kw.setArg(arg++, y0);
      kw.setArg(arg++, rows);
      kw.setArg(arg++, kappa);
      kw.setArg(arg++, a_re);
      kw.setArg(arg++, a_im);
      arg = 0;
      kr.setArg(arg++, a_re);
      kr.setArg(arg++, a_im);
      kr.setArg(arg++, W);
      kr.setArg(arg++, y0);
      kr.setArg(arg++, rows);
      kr.setArg(arg++, er);
      kr.setArg(arg++, ei);
      kr.setArg(arg++, nu);
      kr.setArg(arg++, r_re);
      kr.setArg(arg++, r_im);
      cl::Event e1, e2;
      dev.queue().enqueueNDRangeKernel(kw, cl::NullRange, cl::NDRange(W, rows), cl::NullRange, nullptr, &e1);
      dev.profiler().record(e1);
      dev.queue().enqueueNDRangeKernel(kr, cl::NullRange, cl::NDRange(nu, rows), cl::NullRange, nullptr, &e2);
      dev.profiler().record(e2);
    }
    cl::Event a, b;
    dev.queue().enqueueReadBuffer(r_re, CL_FALSE, 0, n * sizeof(double), rr.data(), nullptr, &a);
    dev.queue().enqueueReadBuffer(r_im, CL_FALSE, 0, n * sizeof(double), ri.data(), nullptr, &b);
    dev.profiler().record(a);
    dev.profiler().record(b);
    dev.profiler().wait([&] { dev.queue().finish(); });
    return 0;
  });
  return grid_columns(f_, fv, nu, rr, ri);
}

namespace {
// P from the table at texel coordinates, with the band's coefficients computed once.
struct Evaluator {
  const std::vector<float>& terms;
  const TableGeometry& g;
  const Band& band;
  double kappa, s;
  std::vector<double> coef;
  cplx scale;
  Evaluator(const std::vector<float>& t, const TableGeometry& geo, const Field& f, const Band& b, double k)
      : terms(t), g(geo), band(b), kappa(k), s(f.s), coef(b.terms) {
    ref::expansion_coefficients(expansion_id(b.expansion), k, b.kappa0, b.delta, f.s, b.terms,
                                coef.data());
    scale = static_cast<double>(f.count()) * std::polar(1.0, k * f.c);
  }
  // The value at texel (iu, iv): Σ_n coef_n·F_n there, the coefficients made once.
  cplx at(int iu, int iv) const {
    const std::size_t per = static_cast<std::size_t>(g.size) * g.size, at = static_cast<std::size_t>(iv) * g.size + iu;
    double sr = 0, si = 0;
    for (int t = 0; t < band.terms; ++t) {
      const std::size_t i = 2 * ((band.first_term + t) * per + at);
      sr += coef[t] * terms[i];
      si += coef[t] * terms[i + 1];
    }
    return scale * cplx(sr, si);
  }
  // A shader's filtered fetch (table.cl, the previews' lookup).
  cplx bilinear(double tu, double tv) const {
    double re, im;
    ref::table_bilinear_sum(terms.data(), g.size, band.first_term, band.terms,
                            expansion_id(band.expansion), kappa,
                            band.kappa0, band.delta, s, tu, tv, &re, &im);
    return scale * cplx(re, im);
  }
};
}  // namespace

cplx table_value(const std::vector<float>& terms, const TableGeometry& g, const Field& f, const Band& band,
                 double kappa, int iu, int iv) {
  return Evaluator(terms, g, f, band, kappa).at(iu, iv);
}

cplx table_bilinear(const std::vector<float>& terms, const TableGeometry& g, const Field& f, const Band& band,
                    double kappa, double tu, double tv) {
  return Evaluator(terms, g, f, band, kappa).bilinear(tu, tv);
}

nlohmann::json TableError::json() const {
  return {{"at_texels", {{"max_over_window_sum", texel_max}, {"p99_over_window_sum", texel_p99},
                         {"at_kappa", texel_at_kappa}, {"points_per_kappa", texel_points},
                         {"per_kappa", texel_per_kappa}}},
          {"between_texels_bilinear", {{"max_over_window_sum", between_max}, {"p99_over_window_sum", between_p99},
                                       {"at_kappa", between_at_kappa}, {"points_per_kappa", between_points},
                                       {"per_kappa", between_per_kappa}}},
          {"kappas", kappas},
          {"energy_ratio_per_kappa", energy_ratio},
          {"reference", "direct double-precision sum over the samples of w * exp(i kappa h) * exp(-2 pi i f.x)"},
          {"reference_computed_on", reference_on}};
}

namespace {
// Pseudo-random values per axis: as many as keep one κ's direct sums near kVisits sample visits
// (the grid's cost is (fixed + random)·W·H), between `lo` and `hi`.
constexpr double kVisits = 1e9;
int random_count(const Field& f, int fixed, int lo, int hi) {
  return static_cast<int>(std::clamp(kVisits / static_cast<double>(f.count()) - fixed, double(lo), double(hi)));
}

}  // namespace

const DeviceHeights* TableMeasurement::exact_device(const DeviceHeights* on) {
  return on && on->dev.info().fp64 && unless_cpu(on->dev) ? on : nullptr;
}

TableMeasurement::TableMeasurement(const DeviceHeights* on, const Field& f, const Window& w, const TableGeometry& shape,
                                   std::vector<double> kappas)
    : f_(f), w_(w), kappas_(std::move(kappas)), exact_grid_(exact_device(on), f, w) {
  // s-values: 8 around the centre spanning ±0.08 (the specular peak; not on any ladder size's
  // texel centres or cell edges), then pseudo-random ones in (−1, 1).
  random_per_axis_ = random_count(f, 8, 4, 24);
  Lcg rng;
  for (auto* axis : {&bu_, &bv_}) {
    for (int k = 0; k < 8; ++k) axis->push_back(shape.freq_at_s((k - 3.5 + 0.3) / 48.0));
    for (int k = 0; k < random_per_axis_; ++k) axis->push_back(shape.freq_at_s(2.0 * rng.next() - 1.0));
  }
  for (double kappa : kappas_) exact_.push_back(exact_grid_(kappa, bu_, bv_));
}

std::vector<double> TableMeasurement::between_errors(const std::vector<Band>& bands, const TableGeometry& g,
                                                     const std::vector<float>& terms, std::size_t k) const {
  const Evaluator ev(terms, g, f_, band_for(bands, kappas_[k]), kappas_[k]);
  const std::size_t nu = bu_.size();
  std::vector<double> e(nu * bv_.size());
  const double inv = 1.0 / w_.sum;
  parallel_for(static_cast<long long>(e.size()), [&](long long i) {
    const std::size_t a = static_cast<std::size_t>(i) % nu, b = static_cast<std::size_t>(i) / nu;
    e[i] = std::abs(ev.bilinear(g.texel_of(bu_[a]), g.texel_of(bv_[b])) - exact_[k][i]) * inv;
  });
  return e;
}

double TableMeasurement::between_max(const std::vector<Band>& bands, const TableGeometry& g,
                                     const std::vector<float>& terms) const {
  double m = 0;
  for (std::size_t k = 0; k < kappas_.size(); ++k)
    for (double e : between_errors(bands, g, terms, k)) m = std::max(m, e);
  return m;
}

TableError TableMeasurement::measure(const std::vector<Band>& bands, const TableGeometry& g,
                                     const std::vector<float>& terms) const {
  const int n = g.size;
  // Texel indices per axis: the 4 around the centre, both edges, pseudo-random ones.
  const int r = random_count(f_, 6, 2, 16);
  std::vector<int> tu, tv;
  Lcg rng;
  for (auto* axis : {&tu, &tv}) {
    for (int i : {n / 2 - 2, n / 2 - 1, n / 2, n / 2 + 1, 0, n - 1}) axis->push_back(i);
    for (int k = 0; k < r; ++k) axis->push_back(std::min(n - 1, static_cast<int>(rng.next() * n)));
  }
  std::vector<double> fu, fv;
  for (int i : tu) fu.push_back(g.freq(i));
  for (int i : tv) fv.push_back(g.freq(i));

  TableError e;
  e.kappas = kappas_;
  e.reference_on = exact_grid_.on_device() ? "device" : "host";
  e.texel_points = static_cast<int>(tu.size() * tv.size());
  e.between_points = static_cast<int>(bu_.size() * bv_.size());
  std::vector<double> all_t, all_b;
  const double inv = 1.0 / w_.sum;
  for (std::size_t k = 0; k < kappas_.size(); ++k) {
    const double kappa = kappas_[k];
    const Evaluator ev(terms, g, f_, band_for(bands, kappa), kappa);
    const auto exact = exact_grid_(kappa, fu, fv);
    std::vector<double> et(exact.size());
    for (std::size_t i = 0; i < et.size(); ++i)
      et[i] = std::abs(ev.at(tu[i % tu.size()], tv[i / tu.size()]) - exact[i]) * inv;
    const auto eb = between_errors(bands, g, terms, k);
    const double mt = *std::max_element(et.begin(), et.end()), mb = *std::max_element(eb.begin(), eb.end());
    e.texel_per_kappa.push_back(mt);
    e.between_per_kappa.push_back(mb);
    if (mt >= e.texel_max) e.texel_max = mt, e.texel_at_kappa = kappa;
    if (mb >= e.between_max) e.between_max = mb, e.between_at_kappa = kappa;
    all_t.insert(all_t.end(), et.begin(), et.end());
    all_b.insert(all_b.end(), eb.begin(), eb.end());
    // Parseval: Σ|P|²·(texel area) over the table against ∫∫|P|² df over a period = Σw²/dx².
    std::vector<double> rows(n);
    parallel_for(n, [&](long long iv) {
      double s = 0;
      for (int iu = 0; iu < n; ++iu) s += std::norm(ev.at(iu, static_cast<int>(iv))) * g.width(iu);
      rows[iv] = s * g.width(static_cast<int>(iv));
    });
    double energy = 0;
    for (double v : rows) energy += v;
    e.energy_ratio.push_back(energy / (w_.sum_sq / (f_.dx_um * f_.dx_um)));
  }
  e.texel_p99 = percentile99(all_t);
  e.between_p99 = percentile99(all_b);
  return e;
}

TableError measure_table(const Field& f, const Window& w, const std::vector<Band>& bands, const TableGeometry& g,
                         const std::vector<float>& terms, const std::vector<double>& kappas) {
  return TableMeasurement(nullptr, f, w, g, kappas).measure(bands, g, terms);
}

}  // namespace specbake::diffraction
