#pragma once
// Diffraction tables a shader can afford (docs/diffraction-method.md, "Coherence and tables").
//
// Coherence window. The field is weighted by the amplitude window
//   w(x, y) = exp(−(x² + y²)/(2σ²)),   σ = L/√2,
// x, y measured from the patch centre. Its autocorrelation is exp(−|Δr|²/(2L²)): the Gaussian
// degree of coherence of rms width L that the window stands for. A uniform disc source of
// angular diameter θ gives, by van Cittert–Zernike, γ(d) = 2J₁(x)/x with x = πθd/λ; the Gaussian
// of the same curvature at d = 0 (1 − x²/8 = 1 − d²/(2L²)) has L = 2λ/(πθ): 39.9 µm for the sun
// (θ = 0.53°) at λ = 580 nm.
//
// Table. N×N texels; texel centre s_i = 2(i + 0.5)/N − 1 per axis maps to the spatial frequency
// f = sign(s)·|s|^p·f_max (cycles/µm), p = 1 for the linear mapping. The terms at a texel are
//   F_n(f_u, f_v) = Σ_j w_j·q_n(h_j)·e^{−2πi(f_u x_j + f_v y_j)} / (W·H),
// x_j = (ix − (W − 1)/2)·dx, y_j = (iy − (H − 1)/2)·dx (centred, so F_n varies smoothly between
// texels). The job evaluates them by a separable non-uniform FFT (type 2, Kaiser–Bessel
// gridding; table_terms_fft): per axis, the samples the window keeps are divided by the kernel's
// Fourier transform, zero-padded to n ≥ 1.5× their count, transformed on the device in float32 and
// spread to the texel frequencies by the kernel; rows, then columns. table_terms evaluates the
// same sums directly in double (the reference the tests compare with).
// The reconstruction is the one of the full-bin terms: P(f;κ) = W·H·e^{iκc}·Σ_n coef_n(κ)·F_n(f).
#include <complex>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "cl/device.hpp"
#include "kinds/diffraction/planning.hpp"
#include "kinds/diffraction/terms.hpp"

namespace specbake::diffraction {

using cplx = std::complex<double>;

// Coherence length (µm) of a uniform disc source of angular diameter `theta_rad` at `lambda_um`.
double disc_coherence_length_um(double theta_rad, double lambda_um);
// The job's coherence length: `length_um`, else the disc's at the middle of range_nm.
double coherence_length_um(const DiffractionSpec& spec);
// The wavelength (µm) a disc source's length is derived at: the middle of range_nm.
double coherence_reference_lambda_um(const DiffractionSpec& spec);

// The table's texel → frequency map.
struct TableGeometry {
  int size = 0;
  double power = 1.0;  // p
  double f_max = 0.0;  // cycles/µm
  double s(double i) const { return 2.0 * (i + 0.5) / size - 1.0; }
  double freq_at_s(double s) const;  // sign(s)·|s|^p·f_max
  double freq(int i) const { return freq_at_s(s(i)); }
  // df/ds at texel i times the texel's width in s (2/N): the texel's width in cycles/µm.
  double width(int i) const;
  // The continuous texel coordinate (i + 0.5 at a texel's centre... as i) of frequency f:
  // the inverse map, i = (s + 1)·N/2 − 0.5 with s = sign(f)·(|f|/f_max)^{1/p}.
  double texel_of(double f) const;
};
TableGeometry table_geometry(const DiffractionSpec& spec, int size);

// The separable amplitude window over the samples (σ in µm; wx[ix]·wy[iy]).
struct Window {
  double sigma_um = 0.0;
  std::vector<double> wx, wy;
  double sum = 0.0;     // Σ_j w_j (P's value at f = 0, κ = 0)
  double sum_sq = 0.0;  // Σ_j w_j² (Parseval: ∫∫|P|² df over one period = Σ w²/dx²)
};
Window make_window(const Field& f, double sigma_um);

// F_n of every band's terms at every texel, over W·H: [T][iv][iu] (iv: f_v rows, iu: f_u columns),
// by direct sums in double (the reference; O(N·W·H) per term).
std::vector<cplx> table_terms(const Field& f, const Window& w, const std::vector<Band>& bands, const TableGeometry& g);

// The same terms for every table in `tables` at once, by the separable non-uniform FFT on the
// heights' device (the header's method), as the bundle stores them: out[k] is float32 [T][iv][iu][re, im] for
// tables[k]. One pass over the field serves all sizes; everything between the field's upload and
// the tables' download runs on the device (term inputs, row transforms, row spreads, column
// gather, column transforms, column spreads). Its error against table_terms is float32 FFT
// rounding (≈ 1e-7 of the window's sum) plus the gridding's (below 1e-9) and the float32 storage
// (tests/diffraction/diffraction_table_test.cpp).
// `progress` is called with the fraction done after every batch of transforms (a safe point: it
// may throw to stop the bake).
std::vector<std::vector<float>> table_terms_fft(const DeviceHeights& on, const Field& f, const Window& w,
                                                const std::vector<Band>& bands, const std::vector<TableGeometry>& tables,
                                                const std::function<void(double)>& progress = {});

// The window's samples the FFT path keeps: per axis, those with weight ≥ kWindowFloor, |x| ≤ 5.68σ
// (a patch narrower than the window keeps every sample). What the rest hold, as a fraction of
// Σw, is dropped_window_fraction (recorded; ~1e-8 for a window inside the patch).
inline constexpr double kWindowFloor = 1e-7;
double dropped_window_fraction(const Window& w);
// One axis of m samples at dx under a window of σ: the samples the FFT path keeps and its padded
// transform length (for plan's estimates).
struct AxisExtent {
  int kept = 0, n = 0;
};
AxisExtent fft_extent(int m, double dx_um, double sigma_um);

// The windowed field a_j = w_j·e^{iκh_j} ([iy][ix]) and its transform at one frequency by the
// direct 2D sum (the ground truth: no expansion, no separable pass shared with table_terms).
std::vector<cplx> windowed_field(const Field& f, const Window& w, double kappa);
cplx direct_transform(const std::vector<cplx>& a, const Field& f, double fu, double fv);
// The same transform at every pair (fu[a], fv[b]) of a product grid, [b][a], by direct sums in
// double, row by row (the field's e^{iκh} is formed one row at a time: no W·H array).
std::vector<cplx> direct_transform_grid(const Field& f, const Window& w, double kappa, const std::vector<double>& fu,
                                        const std::vector<double>& fv);

// The same grid sums for many κ over one field: on the heights' device when given and it has fp64
// (the windowed field by diffraction_windowed_rows, each row's sums by diffraction_exact_rows, one
// work item per frequency and row, in four interleaved partial sums; the window uploaded once), else
// direct_transform_grid on the host's threads (each row summed in ix order). The rows are then
// combined on the host in iy order. The two differ by rounding only (the device's cos/sin,
// contractions and summation order: a few units of 1e-16 of Σw per row and column).
class ExactGrid {
 public:
  ExactGrid(const DeviceHeights* on, const Field& f, const Window& w);  // on may be null: the host
  std::vector<cplx> operator()(double kappa, const std::vector<double>& fu, const std::vector<double>& fv) const;
  bool on_device() const;

 private:
  struct Impl;
  const Field& f_;
  const Window& w_;
  std::shared_ptr<Impl> impl_;
};

// P from stored table terms (float32 [T][N][N][2]) at texel (iu, iv) for κ in `band`.
cplx table_value(const std::vector<float>& terms, const TableGeometry& g, const Field& f, const Band& band,
                 double kappa, int iu, int iv);
// Bilinear interpolation in texel coordinates (a shader's filtered fetch, clamped at the edges).
cplx table_bilinear(const std::vector<float>& terms, const TableGeometry& g, const Field& f, const Band& band,
                    double kappa, double tu, double tv);

// The measured error of a table (see docs): at texel centres and between texels, over Σw,
// against direct sums, at `kappas`; and Parseval's energy ratio per κ.
struct TableError {
  double texel_max = 0.0, texel_p99 = 0.0, texel_at_kappa = 0.0;
  double between_max = 0.0, between_p99 = 0.0, between_at_kappa = 0.0;
  int texel_points = 0, between_points = 0;
  std::vector<double> kappas, texel_per_kappa, between_per_kappa, energy_ratio;
  std::string reference_on = "host";  // where the direct sums ran: "device" or "host"
  nlohmann::json json() const;
};

// The measurement points and their exact values. Between texels the points are fixed frequencies
// (a product grid in s: 8 values around s = 0, where the specular peak is, and pseudo-random
// ones), the same for every size, so their direct sums are made once for all the sizes a
// `size: auto` bake compares; at texels they are a product grid of texel indices of each size
// (the 4 around the centre, both edges, pseudo-random ones). The number of pseudo-random values
// per axis keeps each κ's direct sums near 1e9 sample visits (fewer for large fields).
class TableMeasurement {
 public:
  // `shape`: the mapping (power, f_max) every measured table shares; its size is not used. The
  // direct sums run on the heights' device (ExactGrid) when exact_device says so, else on the host.
  TableMeasurement(const DeviceHeights* on, const Field& f, const Window& w, const TableGeometry& shape,
                   std::vector<double> kappas);
  // Between-texel error only (what `size: auto` compares), max over the points and κ.
  double between_max(const std::vector<Band>& bands, const TableGeometry& g, const std::vector<float>& terms) const;
  // Everything: texels (direct sums made now), between texels, energy.
  TableError measure(const std::vector<Band>& bands, const TableGeometry& g, const std::vector<float>& terms) const;
  // `on` when its device has fp64 and is not a CPU, else null (the host): on a CPU device (PoCL) the
  // host's threads and libm do these sums 2-3x faster (docs/diffraction.md, "Speed").
  static const DeviceHeights* exact_device(const DeviceHeights* on);

 private:
  std::vector<double> between_errors(const std::vector<Band>& bands, const TableGeometry& g,
                                     const std::vector<float>& terms, std::size_t k) const;
  const Field& f_;
  const Window& w_;
  std::vector<double> kappas_;
  std::vector<double> bu_, bv_;             // between-texel frequencies (cycles/µm)
  std::vector<std::vector<cplx>> exact_;    // per κ: [b][a] at (bu_[a], bv_[b])
  int random_per_axis_ = 0;
  ExactGrid exact_grid_;
};
TableError measure_table(const Field& f, const Window& w, const std::vector<Band>& bands, const TableGeometry& g,
                         const std::vector<float>& terms, const std::vector<double>& kappas);

// The ladder `size: auto` climbs.
inline constexpr int kTableLadder[] = {64, 96, 128, 192, 256, 384, 512, 768, 1024};

}  // namespace specbake::diffraction
