#pragma once
// Shared by the dispersion tests: the SPECGEN reference data (refdata/specgen/, independent
// float64 numpy values), the cases they hold, and the error bounds our values must meet.
//
// Error model used for every tolerance. u is the unit roundoff of the path under test
// (2^-53 for the double reference and for fp64 devices, 2^-24 for a float-only device).
// The reference data carry their own double rounding (unit roundoff u53 = 2^-53), so a bound
// is always (our rounding, in u) + (theirs, in u53) + (input differences propagated).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "core/colour_space.hpp"
#include "core/spectral_data.hpp"
#include "kinds/dispersion/dispersion_job.hpp"
#include "kinds/dispersion/sampling.hpp"
#include "support/testing.hpp"

namespace specbake::testing::specgen {

using namespace specbake::dispersion;
using nlohmann::json;

inline constexpr double u53 = 1.1102230246251565e-16;  // 2^-53, double unit roundoff

inline const json& refdata() {
  static const json j = read_json(refdata_dir() / "specgen" / "specgen_reference_subset.json");
  return j;
}

struct Case {
  const char* key;
  Sampling sampling;
  int n;
};
inline const Case kCases[] = {{"a_uniform_mid_380_780", Sampling::uniform, 4},
                              {"a_uniform_mid_380_780", Sampling::uniform, 16},
                              {"b_gauss_legendre_380_780", Sampling::gauss_legendre, 4},
                              {"b_gauss_legendre_380_780", Sampling::gauss_legendre, 16}};

inline const json& case_of(const Case& c) { return refdata().at("cases").at(c.key).at(std::to_string(c.n)); }

inline std::vector<double> flat(const json& j) {
  std::vector<double> out;
  if (j.is_array()) {
    for (const auto& e : j) {
      const auto sub = flat(e);
      out.insert(out.end(), sub.begin(), sub.end());
    }
  } else {
    out.push_back(j.get<double>());
  }
  return out;
}

// Fails with the worst offender when |actual − expected| > tol elementwise.
inline void expect_within(const std::vector<double>& actual, const std::vector<double>& expected,
                   const std::vector<double>& tol, const std::string& what) {
  ASSERT_EQ(actual.size(), expected.size()) << what;
  ASSERT_EQ(tol.size(), expected.size()) << what;
  std::size_t worst = 0;
  double worst_ratio = 0.0;
  for (std::size_t i = 0; i < actual.size(); ++i) {
    const double r = std::fabs(actual[i] - expected[i]) / tol[i];
    if (!(r <= worst_ratio)) worst_ratio = r, worst = i;  // NaN lands here too
  }
  EXPECT_LE(worst_ratio, 1.0) << what << ": worst at flat index " << worst << ": got " << actual[worst]
                              << ", expected " << expected[worst] << ", |diff| "
                              << std::fabs(actual[worst] - expected[worst]) << " > tolerance " << tol[worst];
}

// The largest |CMF(λ+1) − CMF(λ)| in the table: a bound on |dCMF/dλ| (per nm) of the
// linear interpolant, used to propagate a wavelength difference into W_raw.
inline double cmf_slope_max(const CmfTable& t) {
  double m = 0.0;
  for (int i = 0; i + 1 < t.count(); ++i)
    for (int c = 0; c < 3; ++c) m = std::max(m, std::fabs(t.xyz[3 * (i + 1) + c] - t.xyz[3 * i + c]));
  return m;
}
inline double cmf_max(const CmfTable& t) { return *std::max_element(t.xyz.begin(), t.xyz.end()); }

// Tolerances for one case, derived from the sampling differences.
struct Bounds {
  std::vector<double> lambda, weight, w_raw, w_raw_sum, w_norm, K, offset;
};

// dlambda: bound on |λ_ours − λ_ref| (nm); dweight: on |w_ours − w_ref| (nm);
// u: our path's unit roundoff; lines: the Abbe lines of the offsets.
inline Bounds bounds_for(const json& rc, const std::vector<double>& dlambda, const std::vector<double>& dweight, double u,
                  Lines lines) {
  const CmfTable& cmf = cmf_table(CmfSet::cie1931_2deg);
  const double slope = cmf_slope_max(cmf), peak = cmf_max(cmf);
  const auto lam = flat(rc.at("lambda_nm")), w = flat(rc.at("weight_nm"));
  const auto W = flat(rc.at("W_raw")), S = flat(rc.at("W_raw_sum")), Wn = flat(rc.at("W_norm"));
  const std::size_t n = lam.size();
  Bounds b;
  b.lambda = dlambda;
  b.weight = dweight;
  // W_raw = CMF(λ)·w. Interpolation (1−f)·y0 + f·y1 and the product: ≤ 4 roundings of
  // values ≤ peak, in each path; plus |dCMF/dλ|·Δλ·w and CMF·Δw from the inputs. On a device
  // the wavelength itself is also rounded to the device's precision (780 nm · u).
  for (std::size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c)
      b.w_raw.push_back(4.0 * (u + u53) * peak * w[i] + slope * (dlambda[i] + 780.0 * u) * w[i] +
                        peak * dweight[i] + 1e-300);
  // ΣW: the sum of the element bounds plus N roundings of the partial sums (≤ S) per path.
  for (int c = 0; c < 3; ++c) {
    double e = static_cast<double>(n) * (u53 + u53) * S[c];  // the sums are done in double on the host
    for (std::size_t i = 0; i < n; ++i) e += b.w_raw[3 * i + c];
    b.w_raw_sum.push_back(e);
  }
  // Ŵ = W/S: |ΔŴ| ≤ |ΔW|/S + Ŵ·|ΔS|/S + 2 roundings (the reciprocal and the product) per path.
  for (std::size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c)
      b.w_norm.push_back(b.w_raw[3 * i + c] / S[c] + Wn[3 * i + c] * b.w_raw_sum[c] / S[c] +
                         2.0 * (u + u53) * Wn[3 * i + c] + 1e-300);
  // K_rc = Σ_k Minv_rk·Ŵ_k·M_kc: each of the 3 terms carries ≤ 3 roundings and the sum 2 more
  // (≤ 5 per path), the matrices themselves differ from the reference's by ≤ 32 u53 relative
  // (checked in SrgbMatrices below), and ΔŴ propagates through |Minv|·|ΔŴ|·|M|.
  const Mat3 M = srgb_to_xyz(), Minv = xyz_to_srgb();
  for (std::size_t i = 0; i < n; ++i)
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        double e = 0.0;
        for (int k = 0; k < 3; ++k)
          e += std::fabs(Minv[3 * r + k]) * std::fabs(M[3 * k + c]) *
               ((5.0 * (u + u53) + 2.0 * 32.0 * u53) * Wn[3 * i + k] + b.w_norm[3 * i + k]);
        b.K.push_back(e + 1e-300);
      }
  // Offset = (1/λ² − 1/λ_ref²)/(1/λ_F² − 1/λ_C²). Numerator: ≤ 3 roundings on each of its two
  // terms (≤ 1/λ² + 1/λ_ref²) — the subtraction cancels, so the bound is absolute, not
  // relative to the (possibly small) result; the denominator (condition ≈ 2.2) adds ≤ 8
  // roundings of |Offset|; Δλ adds |dOffset/dλ|·Δλ = 2/λ³/den·Δλ. The lines enter the
  // device in its precision too (relative u each): d/dλ_ref gives 2u/(λ_ref²·den), d/dλ_F and
  // d/dλ_C give 2u·|Offset|·(1/λ_F² + 1/λ_C²)/den.
  const double F2 = 1.0 / (lines.F_nm * lines.F_nm), C2 = 1.0 / (lines.C_nm * lines.C_nm);
  const double ref2 = 1.0 / (lines.ref_nm * lines.ref_nm), den = F2 - C2;
  for (std::size_t i = 0; i < n; ++i) {
    const double l = lam[i], off_mag = (1.0 / (l * l) + ref2) / den;
    const double d_off_d_lambda = 2.0 / (l * l * l) / den;
    const double off = (1.0 / (l * l) - ref2) / den;
    b.offset.push_back(3.0 * (u + u53) * off_mag + 8.0 * (u + u53) * std::fabs(off) +
                       d_off_d_lambda * (dlambda[i] + 780.0 * u) + 2.0 * u * (ref2 + std::fabs(off) * (F2 + C2)) / den);
  }
  return b;
}

// Sample-point differences for a scheme: uniform midpoints are exact in both paths for
// N = 4, 16 (400/N is exact, (n+½)·Δ is exact, the sum with 380 rounds once: ≤ u53·780 nm
// each). Gauss–Legendre nodes: ours converge by Newton to |Δx| ≤ ~2 u53, numpy's leggauss
// (eigenvalues + one Newton step) likewise, so ≤ 8 u53 together; mapped by 200x + 580
// this is ≤ 200·8 u53 + 2 roundings of 780. GL weights: numpy rescales them to Σ = 2 and
// both paths carry O(N) roundings: ≤ 16·N u53 relative.
inline void sample_bounds(const Case& c, const json& rc, std::vector<double>& dl, std::vector<double>& dw) {
  const auto lam = flat(rc.at("lambda_nm")), w = flat(rc.at("weight_nm"));
  dl.assign(lam.size(), 0.0);
  dw.assign(lam.size(), 0.0);
  for (std::size_t i = 0; i < lam.size(); ++i) {
    if (c.sampling == Sampling::uniform) {
      dl[i] = 2.0 * u53 * 780.0;
      dw[i] = 2.0 * u53 * w[i];
    } else {
      dl[i] = 200.0 * 8.0 * u53 + 4.0 * u53 * 780.0;
      dw[i] = 16.0 * c.n * u53 * w[i];
    }
  }
}

inline DispersionSpec spec_for(const Case& c, AbbeLines lines) {
  DispersionSpec s;
  s.samples = c.n;
  s.sampling = c.sampling;
  s.range_nm = {380.0, 780.0};
  s.cmf = CmfSet::cie1931_2deg;
  s.abbe_lines = lines;
  s.material.kind = Material::Kind::abbe;
  s.material.n_ref = 1.5168;
  s.material.v = 64.17;
  return s;
}

inline std::string label(const Case& c) { return std::string(c.key) + " N=" + std::to_string(c.n); }

}  // namespace specbake::testing::specgen
