// Sampling schemes of the dispersion job (src/kinds/dispersion/sampling.*): Gauss–Legendre
// exactness and its known error term, uniform midpoints, the visible-wavelength pdf
// (pbrt-v4 / Mitsuba 3) inverted at stratum midpoints, and samples even in 1/λ².
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <vector>

#include "kinds/dispersion/sampling.hpp"

namespace {

using namespace specbake;
using namespace specbake::dispersion;

constexpr double u53 = 1.1102230246251565e-16;  // 2^-53

double factorial(int n) { return std::tgamma(n + 1.0); }

// ∫_{-1}^{1} x^k dx
double moment(int k) { return k % 2 ? 0.0 : 2.0 / (k + 1); }

const int kOrders[] = {1, 2, 3, 4, 5, 7, 8, 16, 33, 64};

// N-point Gauss–Legendre integrates every polynomial of degree ≤ 2N−1 exactly. In floating
// point: Σ w_i x_i^k with nodes and weights within a few roundings (Newton converged to
// |Δx| ≤ 2 u, weights ≤ 4 u relative) — the node error contributes Σ w_i·k|x_i|^{k−1}·2u ≤ 4k u
// (Σ w = 2, |x| < 1), the weights 8u, the power k roundings of each term (≤ 2k u), the sum
// N roundings of partial sums ≤ 2: (6k + 2N + 8)·u·2 in all.
TEST(GaussLegendre, IntegratesDegree2NMinus1Exactly) {
  for (int n : kOrders) {
    std::vector<double> x, w;
    gauss_legendre(n, x, w);
    ASSERT_EQ(x.size(), static_cast<std::size_t>(n));
    for (int k = 0; k <= 2 * n - 1; ++k) {
      double q = 0.0;
      for (int i = 0; i < n; ++i) q += w[i] * std::pow(x[i], k);
      EXPECT_NEAR(q, moment(k), (6.0 * k + 2.0 * n + 8.0) * u53 * 2.0) << "N=" << n << " degree " << k;
    }
  }
}

// Degree 2N is not exact, and the error is known in closed form (Abramowitz & Stegun 25.4.29
// with f^(2N) = (2N)!): ∫x^{2N} − Q = 2^{2N+1}(N!)^4 / ((2N+1)·((2N)!)^2). This pins the nodes
// to the Legendre zeros (any other N-point rule exact to 2N−1 does not exist, but a rule
// that is wrong shows here at once). Relative bound: the same rounding as above over the
// (not small, ≥ 1e-20 for N ≤ 16) error term, which we check for N ≤ 16 only.
TEST(GaussLegendre, KnownErrorAtDegree2N) {
  for (int n : {1, 2, 3, 4, 5, 8, 16}) {
    std::vector<double> x, w;
    gauss_legendre(n, x, w);
    double q = 0.0;
    for (int i = 0; i < n; ++i) q += w[i] * std::pow(x[i], 2 * n);
    const double expected = std::pow(2.0, 2 * n + 1) * std::pow(factorial(n), 4) / ((2 * n + 1) * std::pow(factorial(2 * n), 2));
    EXPECT_NEAR(moment(2 * n) - q, expected, (12.0 * n + 2.0 * n + 8.0) * u53 * 2.0 + 1e-12 * expected) << "N=" << n;
  }
}

// Closed forms of the first rules: ±1/√3 (w 1); 0, ±√(3/5) (w 8/9, 5/9);
// ±√(3/7 ∓ 2/7·√(6/5)) (w (18 ± √30)/36). A few roundings each: 8 u.
TEST(GaussLegendre, ClosedFormsForSmallN) {
  std::vector<double> x, w;
  gauss_legendre(1, x, w);
  EXPECT_NEAR(x[0], 0.0, 8 * u53);
  EXPECT_NEAR(w[0], 2.0, 8 * u53);
  gauss_legendre(2, x, w);
  EXPECT_NEAR(x[0], -1.0 / std::sqrt(3.0), 8 * u53);
  EXPECT_NEAR(x[1], 1.0 / std::sqrt(3.0), 8 * u53);
  EXPECT_NEAR(w[0], 1.0, 8 * u53);
  EXPECT_NEAR(w[1], 1.0, 8 * u53);
  gauss_legendre(3, x, w);
  EXPECT_NEAR(x[0], -std::sqrt(0.6), 8 * u53);
  EXPECT_NEAR(x[1], 0.0, 8 * u53);
  EXPECT_NEAR(x[2], std::sqrt(0.6), 8 * u53);
  EXPECT_NEAR(w[0], 5.0 / 9.0, 8 * u53);
  EXPECT_NEAR(w[1], 8.0 / 9.0, 8 * u53);
  EXPECT_NEAR(w[2], 5.0 / 9.0, 8 * u53);
  gauss_legendre(4, x, w);
  const double inner = std::sqrt(3.0 / 7.0 - 2.0 / 7.0 * std::sqrt(1.2)), outer = std::sqrt(3.0 / 7.0 + 2.0 / 7.0 * std::sqrt(1.2));
  EXPECT_NEAR(x[0], -outer, 8 * u53);
  EXPECT_NEAR(x[1], -inner, 8 * u53);
  EXPECT_NEAR(x[2], inner, 8 * u53);
  EXPECT_NEAR(x[3], outer, 8 * u53);
  EXPECT_NEAR(w[0], (18.0 - std::sqrt(30.0)) / 36.0, 8 * u53);
  EXPECT_NEAR(w[1], (18.0 + std::sqrt(30.0)) / 36.0, 8 * u53);
}

TEST(GaussLegendre, NodesAscendingSymmetricWeightsPositive) {
  for (int n : kOrders) {
    std::vector<double> x, w;
    gauss_legendre(n, x, w);
    for (int i = 0; i < n; ++i) {
      EXPECT_GT(w[i], 0.0) << "N=" << n;
      EXPECT_GT(x[i], -1.0) << "N=" << n;
      EXPECT_LT(x[i], 1.0) << "N=" << n;
      if (i) EXPECT_LT(x[i - 1], x[i]) << "N=" << n;
      EXPECT_NEAR(x[i], -x[n - 1 - i], 4 * u53) << "N=" << n;
      EXPECT_NEAR(w[i], w[n - 1 - i], 4 * u53 * w[i]) << "N=" << n;
    }
  }
}

// make_samples(gauss-legendre) on [lo, hi]: λ = (lo+hi)/2 + (hi−lo)/2·x, w = (hi−lo)/2·w_GL,
// so ∫_lo^hi p(λ) dλ is exact for deg p ≤ 2N−1. Test p(λ) = ((λ−c)/h)^k with c the midpoint
// and h the half width (keeps the values ≤ 1): the rule gives h·Σ w_GL x^k up to the mapping's
// roundings (≤ 4 u relative on each λ, amplified by k·c/h in ((λ−c)/h)^k).
TEST(Sampling, GaussLegendreOnRange) {
  const RangeNm r{380.0, 780.0};
  const double c = 580.0, h = 200.0;
  for (int n : {1, 4, 16, 64}) {
    const Samples s = make_samples(Sampling::gauss_legendre, r, n);
    EXPECT_NEAR(std::accumulate(s.weight_nm.begin(), s.weight_nm.end(), 0.0), r.hi - r.lo, (n + 4) * u53 * 400.0);
    for (int k = 0; k <= 2 * n - 1; ++k) {
      double q = 0.0;
      for (int i = 0; i < n; ++i) q += s.weight_nm[i] * std::pow((s.lambda_nm[i] - c) / h, k);
      const double tol = h * (6.0 * k + 2.0 * n + 8.0 + 4.0 * k * (c / h + 1.0)) * u53 * 2.0;
      EXPECT_NEAR(q, h * moment(k), tol) << "N=" << n << " degree " << k;
    }
    for (int i = 0; i < n; ++i) {
      EXPECT_GT(s.lambda_nm[i], r.lo);
      EXPECT_LT(s.lambda_nm[i], r.hi);
      if (i) EXPECT_LT(s.lambda_nm[i - 1], s.lambda_nm[i]);
    }
  }
}

// Uniform: midpoints λ_n = lo + (n+½)Δ, w_n = Δ = (hi−lo)/N. Each is one or two roundings
// (≤ 2 u·|λ|); the midpoint rule is exact for linear functions.
TEST(Sampling, UniformMidpoints) {
  for (const RangeNm r : {RangeNm{380.0, 780.0}, RangeNm{360.0, 830.0}, RangeNm{400.5, 700.25}})
    for (int n : {1, 3, 4, 7, 16, 100}) {
      const Samples s = make_samples(Sampling::uniform, r, n);
      ASSERT_EQ(s.lambda_nm.size(), static_cast<std::size_t>(n));
      const double d = (r.hi - r.lo) / n;
      double sum_w = 0.0, first_moment = 0.0;
      for (int i = 0; i < n; ++i) {
        EXPECT_NEAR(s.lambda_nm[i], r.lo + (i + 0.5) * d, 4 * u53 * r.hi) << "N=" << n << " i=" << i;
        EXPECT_NEAR(s.weight_nm[i], d, 2 * u53 * d);
        // The midpoint of stratum i: equally far from its two ends.
        EXPECT_NEAR(s.lambda_nm[i] - (r.lo + i * d), (r.lo + (i + 1) * d) - s.lambda_nm[i], 8 * u53 * r.hi);
        sum_w += s.weight_nm[i];
        first_moment += s.weight_nm[i] * s.lambda_nm[i];
      }
      EXPECT_NEAR(sum_w, r.hi - r.lo, (n + 2) * u53 * (r.hi - r.lo));
      EXPECT_NEAR(first_moment, 0.5 * (r.hi * r.hi - r.lo * r.lo), (n + 6) * u53 * r.hi * (r.hi - r.lo));
    }
}

// The visible-wavelength pdf of pbrt-v4 / Mitsuba 3 as pbrt-v4 writes it, unnormalised.
double visible_pdf_raw(double l) {
  const double ch = std::cosh(0.0072 * (l - 538.0));
  return 0.0039398042 / (ch * ch);
}
// ∫_lo^hi of it, by composite Simpson with 20000 panels (error ≤ (hi−lo)·h^4/180·max|f''''|,
// with |f''''| ≲ 16·0.004·a⁴ ≈ 2e-10: below 1e-16 here; computed independently of the
// closed form (tanh) the code uses). The terms are summed with Kahan compensation, so the
// rounding stays at a few u instead of growing with the 20000 terms.
double visible_pdf_norm(RangeNm r) {
  const int m = 20000;
  const double h = (r.hi - r.lo) / m;
  double s = visible_pdf_raw(r.lo) + visible_pdf_raw(r.hi), comp = 0.0;
  for (int i = 1; i < m; ++i) {
    const double y = (i % 2 ? 4.0 : 2.0) * visible_pdf_raw(r.lo + i * h) - comp;
    const double t = s + y;
    comp = (t - s) - y;
    s = t;
  }
  return s * h / 3.0;
}

// visible-pdf: λ_n inverts the truncated CDF at u = (n+½)/N and w_n = 1/(N·p(λ_n)) with p the
// pdf renormalised to the range. Then:
//  - p(λ_n)·N·w_n = 1, with p from that formula and a numerical normalisation
//    (relative ≤ 1e-12: Simpson error ≪ that, plus a few roundings);
//  - Σ w_n approximates ∫_0^1 g(u) du = hi − lo with g(u) = dλ/du = 1/p(λ(u)), by the midpoint
//    rule, whose error is at most max|g''|/(24 N²). With t = tanh(a(λ−538)) linear in u
//    (t = t_lo + u·Δt), g = Δt/(a(1−t²)) and g'' = Δt³/a·(2 + 6t²)/(1−t²)³; we bound max|g''|
//    over the range by its value at the end with the largest |t| (it grows with |t|).
TEST(Sampling, VisiblePdf) {
  const double a = 0.0072;
  for (const RangeNm r : {RangeNm{380.0, 780.0}, RangeNm{360.0, 830.0}, RangeNm{450.0, 650.0}})
    for (int n : {1, 2, 4, 16, 64, 256}) {
      SCOPED_TRACE("range [" + std::to_string(r.lo) + ", " + std::to_string(r.hi) + "] N=" + std::to_string(n));
      const Samples s = make_samples(Sampling::visible_pdf, r, n);
      const double norm = visible_pdf_norm(r);
      double sum_w = 0.0;
      for (int i = 0; i < n; ++i) {
        EXPECT_GT(s.lambda_nm[i], r.lo);
        EXPECT_LT(s.lambda_nm[i], r.hi);
        if (i) EXPECT_LT(s.lambda_nm[i - 1], s.lambda_nm[i]);
        const double p = visible_pdf_raw(s.lambda_nm[i]) / norm;
        EXPECT_NEAR(p * n * s.weight_nm[i], 1.0, 1e-12) << "i=" << i;
        // CDF(λ_n) = (n+½)/N, the CDF by Simpson from lo (independent of the code's tanh form).
        RangeNm part{r.lo, s.lambda_nm[i]};
        EXPECT_NEAR(visible_pdf_norm(part) / norm, (i + 0.5) / n, 1e-12) << "i=" << i;
        sum_w += s.weight_nm[i];
      }
      const double t_lo = std::tanh(a * (r.lo - 538.0)), t_hi = std::tanh(a * (r.hi - 538.0));
      const double dt = t_hi - t_lo, tmax = std::max(std::fabs(t_lo), std::fabs(t_hi));
      const double g2 = dt * dt * dt / a * (2.0 + 6.0 * tmax * tmax) / std::pow(1.0 - tmax * tmax, 3);
      const double bound = g2 / (24.0 * n * n) + (n + 8) * u53 * (r.hi - r.lo) * 4.0;
      EXPECT_NEAR(sum_w, r.hi - r.lo, bound);
      // And the error is really of that order (a midpoint rule, not exact): for N ≥ 4 it is
      // at least a tenth of the leading term (g'(1) − g'(0))/(24N²), which is not small here.
      if (n >= 4 && n <= 64) {
        auto g1 = [&](double t) { return dt * dt / a * 2.0 * t / ((1.0 - t * t) * (1.0 - t * t)); };
        const double lead = (g1(t_hi) - g1(t_lo)) / (24.0 * n * n);
        EXPECT_GT(std::fabs(sum_w - (r.hi - r.lo)), 0.1 * std::fabs(lead));
      }
    }
}

// inverse-square: σ = 1/λ² at the midpoints of N equal strata of [1/hi², 1/lo²], λ ascending,
// w_n = Δσ·λ_n³/2 = Δσ·|dλ/dσ|. Even spacing: consecutive σ differ by exactly Δσ (to the
// roundings of 1/λ², ≤ 4 u·σ each). Σ w_n is the midpoint rule for ∫ λ³/2 dσ = hi − lo with
// g(σ) = σ^{-3/2}/2, g'' = 15/8·σ^{-7/2}, largest at σ = 1/hi²: error ≤ (Σ)^3/(24N²)·max g''.
TEST(Sampling, InverseSquare) {
  for (const RangeNm r : {RangeNm{380.0, 780.0}, RangeNm{390.0, 780.0}, RangeNm{360.0, 830.0}})
    for (int n : {1, 2, 4, 16, 64, 256}) {
      SCOPED_TRACE("N=" + std::to_string(n));
      const Samples s = make_samples(Sampling::inverse_square, r, n);
      const double s_lo = 1.0 / (r.hi * r.hi), s_hi = 1.0 / (r.lo * r.lo), ds = (s_hi - s_lo) / n;
      double sum_w = 0.0;
      for (int i = 0; i < n; ++i) {
        const double sigma = 1.0 / (s.lambda_nm[i] * s.lambda_nm[i]);
        EXPECT_GT(s.lambda_nm[i], r.lo);
        EXPECT_LT(s.lambda_nm[i], r.hi);
        // Stratum i counted from the blue end holds σ_i = s_hi − (i+½)Δσ.
        EXPECT_NEAR(sigma, s_hi - (i + 0.5) * ds, 8 * u53 * s_hi);
        if (i) {
          EXPECT_LT(s.lambda_nm[i - 1], s.lambda_nm[i]);
          const double prev = 1.0 / (s.lambda_nm[i - 1] * s.lambda_nm[i - 1]);
          EXPECT_NEAR(prev - sigma, ds, 16 * u53 * s_hi);
        }
        EXPECT_NEAR(s.weight_nm[i], ds * std::pow(s.lambda_nm[i], 3) / 2.0, 8 * u53 * s.weight_nm[i]);
        sum_w += s.weight_nm[i];
      }
      const double g2max = 15.0 / 8.0 * std::pow(s_lo, -3.5);
      const double bound = std::pow(s_hi - s_lo, 3) / (24.0 * n * n) * g2max + (n + 8) * u53 * (r.hi - r.lo) * 4.0;
      EXPECT_NEAR(sum_w, r.hi - r.lo, bound);
    }
}

TEST(Sampling, RejectsNonPositiveCounts) {
  EXPECT_THROW(make_samples(Sampling::uniform, {380.0, 780.0}, 0), std::invalid_argument);
  EXPECT_THROW(make_samples(Sampling::gauss_legendre, {380.0, 780.0}, -3), std::invalid_argument);
}

}  // namespace
