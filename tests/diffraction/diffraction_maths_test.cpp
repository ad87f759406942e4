// The diffraction maths through the library: the device path (term kernels + VkFFT float32)
// against the reference data (mpmath-exact DFTs), analytic Jacobi–Anger orders, Parseval, the
// DFT sign convention, the double-precision host reference, hard cases (tall fields,
// non-square and non-power-of-two sizes) and the error bounds used for planning.
#include <gtest/gtest.h>

#include <boost/math/special_functions/bessel.hpp>

#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "cl/device.hpp"
#include "cl/fft.hpp"
#include "kinds/diffraction/diffraction_job.hpp"
#include "kinds/diffraction/planning.hpp"
#include "kinds/diffraction/reference.hpp"
#include "kinds/diffraction/terms.hpp"
#include "support/testing.hpp"

using namespace specbake;
using namespace specbake::diffraction;
namespace tst = specbake::testing;

namespace {

constexpr double kU = kUnitRoundoffF32;

cl_util::Device& device() {
  static cl_util::Device dev(cl_util::select_device("auto"));
  return dev;
}

using Row = std::map<std::string, std::string>;
std::vector<Row> read_csv(const fs::path& p) {
  std::ifstream in(p);
  EXPECT_TRUE(in.good()) << p;
  std::string line;
  std::getline(in, line);
  if (!line.empty() && line.back() == '\r') line.pop_back();
  std::vector<std::string> head;
  std::stringstream hs(line);
  for (std::string f; std::getline(hs, f, ',');) head.push_back(f);
  std::vector<Row> rows;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::stringstream ls(line);
    Row r;
    std::size_t i = 0;
    for (std::string f; std::getline(ls, f, ',') && i < head.size(); ++i) r[head[i]] = f;
    rows.push_back(r);
  }
  return rows;
}
double d(const Row& r, const char* k) { return std::stod(r.at(k)); }

Heightfield sinusoid_field() {
  Heightfield hf;
  hf.width = hf.height = 256;
  hf.dx_um = 0.0625;
  std::vector<double> row;
  for (const auto& r : read_csv(tst::refdata_dir() / "diffraction/sinusoid_grating_heightrow.csv"))
    row.push_back(d(r, "h_um"));
  EXPECT_EQ(row.size(), 256u);
  for (int iy = 0; iy < 256; ++iy) hf.h_um.insert(hf.h_um.end(), row.begin(), row.end());
  return hf;
}

Heightfield random_field() {
  Heightfield hf;
  hf.width = hf.height = 128;
  hf.dx_um = 0.05;
  const std::string bytes = tst::read_file(tst::refdata_dir() / "diffraction/random_smooth_128_f32le.raw");
  EXPECT_EQ(bytes.size(), 65536u);
  for (std::size_t i = 0; i < bytes.size() / 4; ++i) {
    float v;
    std::memcpy(&v, bytes.data() + 4 * i, 4);
    hf.h_um.push_back(v);
  }
  return hf;
}

// An asymmetric smooth field of w × h samples (dx = 0.1 µm).
Heightfield asymmetric_field(int w, int h) {
  Heightfield hf;
  hf.width = w;
  hf.height = h;
  hf.dx_um = 0.1;
  for (int iy = 0; iy < h; ++iy)
    for (int ix = 0; ix < w; ++ix)
      hf.h_um.push_back(0.2 * std::sin(0.3 * ix + 0.1 * iy * iy / 7.0) + 0.05 * std::cos(0.7 * iy) + 0.01 * ix / 37.0);
  return hf;
}

Bins full_bins(int w, int h) { return {-(w / 2), w - 1 - w / 2, -(h / 2), h - 1 - h / 2}; }

// A plan with one plain Taylor band about κ_0 = 0 (Single's form), T terms, all bins.
Plan plain_taylor(const Field& f, int terms, double kappa_hi) {
  Plan p;
  p.kappa_hi = kappa_hi;
  Band b;
  b.kappa_hi = kappa_hi;
  b.terms = terms;
  p.bands = {b};
  p.total_terms = terms;
  p.bins = full_bins(f.width, f.height);
  return p;
}

const Progress kQuiet = [](std::string_view, double) {};

// Reference-data check: for every f32 row, the device terms (first N+1) reconstruct P within
// trunc_bound_tight + 4·roundoff_scale of the mpmath-exact value (the README's acceptance test).
void check_against_refdata(const Heightfield& hf, const char* taylor_csv, const char* dft_csv, double center) {
  Field f = centre_field(hf, Centre::none);
  f.c = center;
  f.s = 0.0;
  for (double h : f.h_um) f.s = std::max(f.s, std::fabs(h - center));
  std::map<std::tuple<double, int, int>, cplx> exact;
  for (const auto& r : read_csv(tst::refdata_dir() / "diffraction" / dft_csv))
    exact[{d(r, "kappa_rad_per_um"), std::stoi(r.at("ku")), std::stoi(r.at("kv"))}] = {d(r, "P_re"), d(r, "P_im")};
  const Plan p = plain_taylor(f, 41, 1.0);
  const Terms t = device_terms(DeviceHeights(device(), f), f, p, kQuiet);
  int checked = 0;
  double worst = 0.0;
  for (const auto& r : read_csv(tst::refdata_dir() / "diffraction" / taylor_csv)) {
    if (r.at("precision") != "f32" || d(r, "center_um") != center) continue;
    const double kappa = d(r, "kappa_rad_per_um");
    const int N = std::stoi(r.at("N")), ku = std::stoi(r.at("ku")), kv = std::stoi(r.at("kv"));
    Band b = p.bands[0];
    b.terms = N + 1;
    std::vector<double> coef(b.terms);
    ref::expansion_coefficients(0, kappa, 0.0, 0.0, f.s, b.terms, coef.data());
    cplx s = 0.0;
    for (int n = 0; n < b.terms; ++n) s += coef[n] * t.at(n, ku, kv);
    const cplx P = static_cast<double>(f.count()) * std::polar(1.0, kappa * f.c) * s;
    const cplx ex = exact.at({kappa, ku, kv});
    // README: |P_impl − P_exact| ≤ trunc_bound_tight + 4·roundoff_scale (absolute, not over M²).
    const double tol = d(r, "trunc_bound_tight") + 4.0 * d(r, "roundoff_scale");
    EXPECT_LE(std::abs(P - ex), tol) << taylor_csv << " kappa " << kappa << " N " << N << " bin " << ku << "," << kv;
    worst = std::max(worst, std::abs(P - ex) / tol);
    ++checked;
  }
  EXPECT_GT(checked, 500);
  std::printf("%s (center %.2f): %d rows, worst |P - P_exact| / (tight + 4 roundoff) = %.3g\n", taylor_csv, center,
              checked, worst);
}

}  // namespace

TEST(DiffractionRefdata, SinusoidGratingTaylorSums) {
  check_against_refdata(sinusoid_field(), "sinusoid_grating_taylor.csv", "sinusoid_grating_dft.csv", 0.0);
}

TEST(DiffractionRefdata, RandomSmoothFieldTaylorSums) {
  check_against_refdata(random_field(), "random_smooth_taylor.csv", "random_smooth_dft.csv", 0.0);
  check_against_refdata(random_field(), "random_smooth_taylor.csv", "random_smooth_dft.csv", 0.25);
}

TEST(DiffractionRefdata, TightBoundTermCountsMatchTable) {
  for (const auto& r : read_csv(tst::refdata_dir() / "diffraction/taylor_bounds.csv")) {
    const double x = d(r, "x_max"), tol = d(r, "tolerance");
    int n = 0;
    while (truncation_bound(Expansion::taylor, x, n + 1) > tol) ++n;  // N terms beyond n = 0 → T = N + 1
    EXPECT_EQ(n, std::stoi(r.at("N_tight"))) << "x " << x << " tol " << tol;
    EXPECT_LE(std::stoi(r.at("N_actual_mpmath")), n);  // the bound is rigorous: never fewer terms than needed
  }
}

// The planner's per-field bound, x^T/T!·μ_T over M², against the table's exact
// Σ_xy |κ(h − c)|^T/T! (T = N + 1): never below it (rigour), and the histogram of |g| costs
// at most ~10 % (bins of 1/4096, |g| ≥ 0.1 for the samples that matter, T ≤ 41).
TEST(DiffractionRefdata, FieldMomentBoundIsRigorousAndTight) {
  int checked = 0;
  double loosest = 0.0;
  for (const auto& [hf, csv] : {std::pair{sinusoid_field(), "sinusoid_grating_taylor.csv"},
                                std::pair{random_field(), "random_smooth_taylor.csv"}}) {
    for (const double center : {0.0, 0.25}) {
      Field f = centre_field(hf, Centre::none);
      f.c = center;
      f.s = 0.0;
      for (double h : f.h_um) f.s = std::max(f.s, std::fabs(h - center));
      const auto mu = abs_g_moments(f, 60);
      for (const auto& r : read_csv(tst::refdata_dir() / "diffraction" / csv)) {
        if (r.at("precision") != "f32" || d(r, "center_um") != center) continue;
        const int T = std::stoi(r.at("N")) + 1;
        const double tight = d(r, "trunc_bound_tight");
        const double ours = truncation_bound(Expansion::taylor, d(r, "kappa_rad_per_um") * f.s, T, mu[T]) * f.count();
        EXPECT_GE(ours, tight * (1 - 1e-12)) << csv << " N " << T - 1;
        if (tight > 0) loosest = std::max(loosest, ours / tight);
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 1000);
  EXPECT_LE(loosest, 1.1);
  std::printf("field moment bound / exact tight bound: at most %.4f over %d rows\n", loosest, checked);
}

TEST(DiffractionMaths, BesselMatchesBoost) {
  for (double x : {0.0, 1e-6, 0.3, -0.9, 1.0, 1.7, -4.2, 12.5, 33.0, 80.0}) {
    double j[DIFFRACTION_MAX_BATCH];
    for (int first : {0, 29, 60}) {
      ref::bessel_j_range(x, first, DIFFRACTION_MAX_BATCH, j);
      for (int i = 0; i < DIFFRACTION_MAX_BATCH; ++i) {
        const double want = boost::math::cyl_bessel_j(first + i, x);
        // Miller's recurrence and the series lose at most a few digits to the ~m steps of
        // rounding (m ≤ 200, |J| ≤ 1): 1e-13 absolute leaves two orders of magnitude.
        EXPECT_NEAR(j[i], want, 1e-13) << "J_" << first + i << "(" << x << ")";
      }
    }
  }
}

TEST(DiffractionMaths, JacobiAngerOrdersOfSineGrating) {
  for (Expansion e : {Expansion::taylor, Expansion::chebyshev}) {
    DiffractionSpec spec;
    spec.procedural = ProceduralField{ProceduralField::Type::sine_grating, 128, 0.0625, 2.0, 0.15};
    spec.expansion = e;
    spec.tolerance = 1e-5;
    spec.crop = false;
    const Field f = make_field(spec);
    const Plan p = make_plan(spec, f, spec.tolerance);
    const Terms t = device_terms(DeviceHeights(device(), f), f, p, kQuiet);
    const double M2 = 128.0 * 128.0, a = 0.15;
    for (double kappa : {0.0, 5.0, 17.3, p.kappa_hi}) {
      const auto P = reconstruct(t, band_for(p.bands, kappa), f, kappa);
      double worst = 0.0;
      for (int kv = p.bins.kv_min; kv <= p.bins.kv_max; ++kv)
        for (int ku = p.bins.ku_min; ku <= p.bins.ku_max; ++ku) {
          // 4 periods of 32 samples over 128: order m sits at ku = 4m; orders m and m ± 32 alias.
          cplx want = 0.0;
          if (kv == 0 && ku % 4 == 0)
            for (int j = -4; j <= 4; ++j) want += boost::math::cyl_bessel_j((ku / 4) + 32 * j, kappa * a);
          const std::size_t i = static_cast<std::size_t>(kv - p.bins.kv_min) * p.bins.ku_count() + (ku - p.bins.ku_min);
          worst = std::max(worst, std::abs(P[i] / M2 - want));
        }
      // The plan's bound (truncation + float32 roundoff estimate) is what the job promises.
      EXPECT_LE(worst, p.estimated_error) << (e == Expansion::taylor ? "taylor" : "chebyshev") << " kappa " << kappa;
      EXPECT_LE(p.estimated_error, spec.tolerance);
    }
  }
}

TEST(DiffractionMaths, ParsevalHoldsAndTruncationBreaksIt) {
  DiffractionSpec spec;
  spec.tolerance = 1e-5;
  spec.crop = false;
  Field f = centre_field(random_field(), Centre::mid_range);
  for (Expansion e : {Expansion::taylor, Expansion::chebyshev}) {
    spec.expansion = e;
    const Plan p = make_plan(spec, f, spec.tolerance);
    const Terms t = device_terms(DeviceHeights(device(), f), f, p, kQuiet);
    for (int i = 0; i <= 8; ++i) {
      const double kappa = p.kappa_hi * i / 8.0;
      const Band& b = band_for(p.bands, kappa);
      const auto P = reconstruct(t, b, f, kappa);
      double sum = 0.0;
      for (const auto& v : P) sum += std::norm(v);
      // ‖P_rec − P‖₂ ≤ M²·r with r the per-sample truncation bound plus the roundoff estimate
      // (Parseval applied to the error), so |Σ|P_rec|²/M⁴ − 1| ≤ 2r + r².
      const double r = b.bound_truncation + b.bound_roundoff;
      const double M4 = std::pow(static_cast<double>(f.count()), 2);
      EXPECT_LE(std::fabs(sum / M4 - 1.0), 2 * r + r * r) << "kappa " << kappa;
    }
  }
  // A truncated plain Taylor sum at y = κ·s ≈ 10 with 4 terms loses energy badly.
  const Plan bad = plain_taylor(f, 4, 40.0);
  const Terms t = device_terms(DeviceHeights(device(), f), f, bad, kQuiet);
  const auto P = reconstruct(t, bad.bands[0], f, 40.0);
  double sum = 0.0;
  for (const auto& v : P) sum += std::norm(v);
  EXPECT_GT(std::fabs(sum / std::pow(static_cast<double>(f.count()), 2) - 1.0), 0.1);
}

TEST(DiffractionMaths, SignConventionMirroredResultFails) {
  // The random field is asymmetric: P(ku, kv) ≠ P(−ku, kv). Reconstruct at κ = 10 (x = 5) with
  // an auto plan and compare against the mpmath-exact values, then against the mirror.
  DiffractionSpec spec;
  spec.tolerance = 1e-6;
  spec.crop = false;
  spec.center = Centre::none;
  const Field f = centre_field(random_field(), Centre::none);
  const Plan p = make_plan(spec, f, spec.tolerance);
  const Terms t = device_terms(DeviceHeights(device(), f), f, p, kQuiet);
  int compared = 0;
  double mirror_worst = 0.0, tol = 0.0;
  for (const auto& r : read_csv(tst::refdata_dir() / "diffraction/random_smooth_dft.csv")) {
    const double kappa = d(r, "kappa_rad_per_um");
    if (kappa > p.kappa_hi) continue;
    const int ku = std::stoi(r.at("ku")), kv = std::stoi(r.at("kv"));
    if (ku == 0) continue;
    const auto P = reconstruct(t, band_for(p.bands, kappa), f, kappa);
    auto at = [&](int u, int v) {
      return P[static_cast<std::size_t>(v - p.bins.kv_min) * p.bins.ku_count() + (u - p.bins.ku_min)];
    };
    const cplx ex(d(r, "P_re"), d(r, "P_im"));
    tol = p.estimated_error * f.count();  // the plan's bound, absolute
    EXPECT_LE(std::abs(at(ku, kv) - ex), tol) << "kappa " << kappa << " bin " << ku << "," << kv;
    mirror_worst = std::max(mirror_worst, std::abs(at(-ku, kv) - ex));
    ++compared;
  }
  EXPECT_GT(compared, 20);
  // Mirrored (u → −u, the single-sign-flip mistake) must fail the same acceptance test, by far.
  EXPECT_GT(mirror_worst, 100 * tol);
}

TEST(DiffractionMaths, DeviceMatchesDoubleReferenceNonSquarePrimeSizes) {
  // 37 × 29 (primes: VkFFT's Bluestein path), an asymmetric smooth field.
  const Field f = centre_field(asymmetric_field(37, 29), Centre::mid_range);
  for (Expansion e : {Expansion::taylor, Expansion::chebyshev}) {
    Plan p;
    p.kappa_hi = 33.0;
    p.bands = make_bands(e, 0.0, 33.0, f.s, 2, 12, kU);
    p.total_terms = 24;
    p.bins = full_bins(f.width, f.height);
    const Terms t = device_terms(DeviceHeights(device(), f), f, p, kQuiet);
    const auto want = reference_terms(f, p.bands, p.bins);
    // Float32 FFT bound per value, over M²: 2u (input and output rounding) + 6u·log2(4N)
    // (Bluestein: three power-of-two transforms of ≥ 2N points), times max|q_n| ≤ 2.
    const double tol = 2.0 * kU * (2.0 + 6.0 * std::log2(4.0 * f.count()));
    double worst = 0.0;
    for (std::size_t i = 0; i < want.size(); ++i)
      worst = std::max(worst, std::abs(cplx(t.values[2 * i], t.values[2 * i + 1]) - want[i]));
    EXPECT_LE(worst, tol);
    EXPECT_GT(worst, 0.0);  // float32 really differs from double: the comparison sees both paths
  }
  // The double-precision exact DFT (VkFFT double on the device) against the host DFT.
  const DeviceHeights heights(device(), f);
  ExactDft on_dev(&heights, f, full_bins(f.width, f.height));
  ExactDft on_host(nullptr, f, full_bins(f.width, f.height));
  ASSERT_TRUE(on_dev.on_device() || !device().info().fp64);
  const auto a = on_dev(21.0), b = on_host(21.0);
  double worst = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) worst = std::max(worst, std::abs(a[i] - b[i]));
  // Double FFT and O(N) direct sums: ≤ 1e3·2^-53·N (N = 1073 samples, |p| = 1).
  EXPECT_LE(worst, 1e3 * 1.1102230246251565e-16 * f.count());
}

namespace {
// Two Chebyshev bands of 12 terms over κ ∈ [0, 33] and cropped, non-symmetric bins: ku and kv
// both negative and positive, so they wrap around the unshifted transform.
Plan cropped_two_band_plan(const Field& f) {
  Plan p;
  p.kappa_hi = 33.0;
  p.bands = make_bands(Expansion::chebyshev, 0.0, 33.0, f.s, 2, 12, kU);
  p.total_terms = 24;
  p.bins = Bins{-7, 11, -9, 5};
  return p;
}
}  // namespace

TEST(DiffractionMaths, ReconstructionErrorOnTheDeviceMatchesTheHost) {
  // The error measurement's maximum over the bins (ExactDft::max_error): on the device the exact
  // transform stays there and each work item reduces its bins; on the host, reconstruct and a
  // maximum. Both reconstruct in double from the same float32 terms, so they differ by the exact
  // transforms' difference (≤ 1e3·2^-53·N, the bound above) plus the reconstruction's rounding
  // (≤ (T + 4)·2^-53·Σ_n|coef_n·F_n|·M² per bin, below 1e-12·M² here): 1e3·2^-53·N + 1e-12·M².
  // Cropped, non-symmetric bins (negative and positive ku, kv wrap around the unshifted array) and
  // a prime width (Bluestein). A shifted crop must give a different maximum: the bin mapping shows.
  const Field f = centre_field(asymmetric_field(37, 29), Centre::mid_range);
  if (!device().info().fp64) GTEST_SKIP() << "no fp64: the exact transform and its error stay on the host";
  const Plan p = cropped_two_band_plan(f);
  const Terms t = device_terms(DeviceHeights(device(), f), f, p, kQuiet);
  const DeviceHeights heights(device(), f);
  ExactDft on_dev(&heights, f, p.bins), on_host(nullptr, f, p.bins);
  ASSERT_TRUE(on_dev.on_device());
  on_dev.prepare(t, true);
  on_host.prepare(t, false);
  const double m2 = static_cast<double>(f.count()), bound = 1e3 * 0x1p-53 * m2 + 1e-12 * m2;
  for (double kappa : {0.0, 9.0, 20.0, 33.0}) {
    on_dev.transform(kappa);
    on_host.transform(kappa);
    const Band& band = band_for(p.bands, kappa);
    const double dev_err = on_dev.max_error(band), host_err = on_host.max_error(band);
    EXPECT_NEAR(dev_err, host_err, bound) << "kappa " << kappa;
    EXPECT_GT(host_err, 0.0) << "kappa " << kappa;
  }
  // The same terms read as if their bins started one column later: the maximum must move.
  Terms shifted = t;
  shifted.bins = Bins{-6, 12, -9, 5};
  ExactDft moved(&heights, f, shifted.bins);
  moved.prepare(shifted, true);
  moved.transform(20.0);
  on_host.transform(20.0);
  EXPECT_GT(std::fabs(moved.max_error(band_for(p.bands, 20.0)) - on_host.max_error(band_for(p.bands, 20.0))),
            1e3 * bound);
}

TEST(DiffractionMaths, BinsPreviewOnTheDeviceMatchesTheHost) {
  // The non-table job's preview on a GPU (diffraction_bins_preview over the bundle's [T][kv][ku]
  // terms) against the host's double evaluation of the same bins_preview_xyz over the terms
  // regrouped per bin. With fp64 both run in double and differ by contraction only: per pixel a
  // few ulps of Σ_λ Σ_bins w·|Σ_n coef_n·F_n|² with |T_n| ≤ 1 (Chebyshev), below 1e-12 of the
  // picture's largest value; 1e-9 is asserted. Without fp64 the kernel runs in float: (T + 8)·2^-24
  // relative per sum, 1e-4 of the largest. Terms read as if their bins started one column later
  // must draw differently (the bin mapping shows).
  const Field f = centre_field(asymmetric_field(37, 29), Centre::mid_range);
  const Plan p = cropped_two_band_plan(f);
  const Terms t = device_terms(DeviceHeights(device(), f), f, p, kQuiet);
  double y_norm = 0;
  const auto spectrum = spectrum_rows(RangeNm{380.0, 780.0}, y_norm);
  const auto host = preview_xyz(nullptr, f, p, t, spectrum, 2.0), dev = preview_xyz(&device(), f, p, t, spectrum, 2.0);
  ASSERT_EQ(host.size(), 3u * kPreviewSize * kPreviewSize);
  ASSERT_EQ(dev.size(), host.size());
  double largest = 0, worst = 0;
  for (std::size_t i = 0; i < host.size(); ++i) {
    largest = std::max(largest, std::fabs(host[i]));
    worst = std::max(worst, std::fabs(host[i] - dev[i]));
  }
  EXPECT_GT(largest, 0.0);
  EXPECT_LE(worst, (device().info().fp64 ? 1e-9 : 1e-4) * largest);
  Terms shifted = t;
  shifted.bins = Bins{-6, 12, -9, 5};
  const auto moved = preview_xyz(&device(), f, p, shifted, spectrum, 2.0);
  double diff = 0;
  for (std::size_t i = 0; i < host.size(); ++i) diff = std::max(diff, std::fabs(host[i] - moved[i]));
  EXPECT_GT(diff, 1e-3 * largest);
}

TEST(DiffractionMaths, SharedFftPlansAreReusedAndGiveTheSameTerms) {
  auto& a = cl_util::shared_fft(device(), 48, 40, 1, cl_util::FftPrecision::single);
  EXPECT_EQ(&a, &cl_util::shared_fft(device(), 48, 40, 1, cl_util::FftPrecision::single));
  EXPECT_NE(&a, &cl_util::shared_fft(device(), 40, 48, 1, cl_util::FftPrecision::single));
  if (device().info().fp64)
    EXPECT_NE(&a, &cl_util::shared_fft(device(), 48, 40, 1, cl_util::FftPrecision::double_));
  // A second bake through the reused plan gives the same bits.
  const Field f = centre_field(random_field(), Centre::mid_range);
  const Plan p = plain_taylor(f, 6, 10.0);
  const Terms t1 = device_terms(DeviceHeights(device(), f), f, p, kQuiet), t2 = device_terms(DeviceHeights(device(), f), f, p, kQuiet);
  EXPECT_EQ(t1.values, t2.values);
}

// A device without cl_khr_fp64 (PoCL with the capability masked): term inputs in float, the
// exact DFTs on the host. The terms must still match the double reference within the float32
// FFT bound plus the float evaluation of the inputs (u·(n + 2 + κ_0·s) per term, the job's
// self-check bound), and the whole plan must still meet its promise.
TEST(DiffractionMaths, FloatOnlyDeviceMeetsTheBounds) {
  cl_util::DeviceInfo info = cl_util::select_device("auto");
  info.fp64 = false;
  cl_util::Device float_only(info);
  const Field f = centre_field(asymmetric_field(40, 24), Centre::mid_range);
  DiffractionSpec spec;
  spec.tolerance = 1e-4;
  spec.crop = false;
  const DeviceHeights heights(float_only, f);
  ExactDft exact(&heights, f, full_bins(f.width, f.height));
  EXPECT_FALSE(exact.on_device());
  for (Expansion e : {Expansion::taylor, Expansion::chebyshev}) {
    spec.expansion = e;
    const Plan p = make_plan(spec, f, spec.tolerance);
    const Terms t = device_terms(DeviceHeights(float_only, f), f, p, kQuiet);
    const auto want = reference_terms(f, p.bands, p.bins);
    const std::size_t per = t.per_term();
    double worst_ratio = 0.0;
    for (const auto& band : p.bands)
      for (int n = 0; n < band.terms; ++n) {
        const double a = e == Expansion::taylor ? 1.0 : (n == 0 ? 1.0 : 2.0);
        const double tol = a * kU * (2.0 + 6.0 * std::log2(4.0 * f.count()) + n + 2.0 + band.kappa0 * f.s);
        for (std::size_t i = 0; i < per; ++i) {
          const std::size_t k = (band.first_term + n) * per + i;
          worst_ratio = std::max(worst_ratio, std::abs(cplx(t.values[2 * k], t.values[2 * k + 1]) - want[k]) / tol);
        }
      }
    EXPECT_LE(worst_ratio, 1.0) << (e == Expansion::taylor ? "taylor" : "chebyshev");
    double worst = 0.0;
    for (double kappa : {p.kappa_hi * 0.5, p.kappa_hi}) {
      const auto ex = exact(kappa);
      const auto P = reconstruct(t, band_for(p.bands, kappa), f, kappa);
      for (std::size_t j = 0; j < P.size(); ++j) worst = std::max(worst, std::abs(P[j] - ex[j]) / f.count());
    }
    EXPECT_LE(worst, spec.tolerance) << (e == Expansion::taylor ? "taylor" : "chebyshev");
  }
}

TEST(DiffractionMaths, ExactDftAtKappaZeroIsTheDcBin) {
  // The shortcut at κ = 0 against the host DFT of e^{i·0·h} = 1 (odd size, cropped bins
  // with DC inside, and bins without DC).
  const Field f = centre_field(random_field(), Centre::mid_range);
  for (const Bins& bins : {full_bins(f.width, f.height), Bins{-5, 7, -3, 2}, Bins{1, 9, -4, 4}}) {
    const DeviceHeights heights(device(), f);
    ExactDft exact(&heights, f, bins);
    const auto got = exact(0.0);
    auto want = host_dft(std::vector<cplx>(f.count(), 1.0), f.width, f.height, bins);
    ASSERT_EQ(got.size(), want.size());
    double worst = 0.0;
    for (std::size_t i = 0; i < got.size(); ++i)
      worst = std::max(worst, std::abs(got[i] - want[i] * static_cast<double>(f.count())));
    // host DFT of ones: O(M) terms of rounding per bin in double, |sum| ≤ M².
    EXPECT_LE(worst, 1e3 * 1.1102230246251565e-16 * f.count());
  }
}

TEST(DiffractionHardCases, TallFieldMeetsToleranceWithBandsOrChebyshev) {
  // A field with y_max = κ_hi·s ≈ 40: plain float32 Taylor cannot reach 1e-4 here.
  Heightfield hf;
  hf.width = hf.height = 64;
  hf.dx_um = 0.1;
  for (int iy = 0; iy < 64; ++iy)
    for (int ix = 0; ix < 64; ++ix)
      hf.h_um.push_back(std::sin(2 * M_PI * ix / 64.0) * std::cos(2 * M_PI * 2 * iy / 64.0) + 0.3 * std::sin(2 * M_PI * 3 * (ix + iy) / 64.0));
  Field f = centre_field(hf, Centre::mid_range);
  DiffractionSpec spec;
  spec.tolerance = 1e-4;
  spec.crop = false;
  const double kappa_hi = 2 * M_PI * 2.0 / 0.38;
  const double scale = 40.0 / (kappa_hi * f.s);
  for (auto& h : hf.h_um) h *= scale;
  f = centre_field(hf, Centre::mid_range);
  const DeviceHeights heights(device(), f);
  ExactDft exact(&heights, f, full_bins(64, 64));
  for (Expansion e : {Expansion::taylor, Expansion::chebyshev}) {
    spec.expansion = e;
    const Plan p = make_plan(spec, f, spec.tolerance);
    EXPECT_NEAR(p.y_max, 40.0, 1e-9);
    if (e == Expansion::taylor) EXPECT_GT(p.bands.size(), 1u);  // one band would need e^20·u ≫ 1e-4
    const Terms t = device_terms(DeviceHeights(device(), f), f, p, kQuiet);
    double worst = 0.0;
    for (int i = 0; i <= 12; ++i) {
      const double kappa = p.kappa_hi * i / 12.0;
      const auto ex = exact(kappa);
      for (const auto& b : p.bands) {
        if (kappa < b.kappa_lo || kappa > b.kappa_hi) continue;
        const auto P = reconstruct(t, b, f, kappa);
        for (std::size_t j = 0; j < P.size(); ++j) worst = std::max(worst, std::abs(P[j] - ex[j]) / f.count());
      }
    }
    EXPECT_LE(worst, spec.tolerance) << (e == Expansion::taylor ? "taylor" : "chebyshev") << " with " << p.total_terms
                                     << " terms in " << p.bands.size() << " bands";
    std::printf("y_max 40, %s: %zu bands, %d terms, measured %.3g\n", e == Expansion::taylor ? "taylor" : "chebyshev",
                p.bands.size(), p.total_terms, worst);
  }
  // A single plain float32 Taylor band cannot: the planner says so instead of shipping it.
  EXPECT_GT(truncation_bound(Expansion::taylor, 20.0, 60) + roundoff_estimate(Expansion::taylor, 20.0, 60, kU), 1e-4);
  spec.expansion = Expansion::taylor;
  spec.tolerance = 1e-12;
  EXPECT_THROW(make_plan(spec, f, spec.tolerance), JobError);
}
