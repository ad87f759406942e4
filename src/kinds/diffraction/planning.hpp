#pragma once
// Planning a diffraction bake: the field's centre c and scale s, the κ range the scene
// reaches, the frequency bins it samples, and the bands and term counts whose error bound
// (truncation + float32 roundoff estimate) meets the tolerance. Host-only, no device.
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "kinds/diffraction/spec.hpp"

namespace specbake::diffraction {

inline constexpr double kUnitRoundoffF32 = 5.9604644775390625e-08;  // 2^-24
inline constexpr double kUnitRoundoffHalf = 4.8828125e-04;         // 2^-11
// Gaussian window of the shader (Single 2014, §2.3.2): 4σ_s spans the patch, so
// σ_f = 1/(2π σ_s) cycles/µm is 2/π bins; it reaches 3σ_f beyond the last frequency used.
inline constexpr double kWindowSigmaBins = 0.63661977236758134;  // 2/π
inline constexpr int kWindowReachBins = 2;                       // ceil(3·2/π)

// A heightfield with its centring: g = (h − c)/s ∈ [−1, 1].
struct Field {
  int width = 0, height = 0;
  double dx_um = 0.0;
  std::vector<double> h_um;  // [iy][ix]
  double h_min = 0.0, h_max = 0.0, h_mean = 0.0;
  double c = 0.0, s = 0.0;   // centre and scale (s = max|h − c|; 0 for a flat field)
  long long count() const { return static_cast<long long>(width) * height; }
};

struct Band {
  Expansion expansion = Expansion::taylor;
  double kappa_lo = 0.0, kappa_hi = 0.0;
  double kappa0 = 0.0;  // taylor: expansion point κ_0; chebyshev: κ_m
  double delta = 0.0;   // half-width (κ_hi − κ_lo)/2 (chebyshev's Δ)
  int first_term = 0, terms = 0;
  double bound_truncation = 0.0;  // rigorous, over M²
  double bound_roundoff = 0.0;    // estimate, over M²
};

struct Bins {
  int ku_min = 0, ku_max = 0, kv_min = 0, kv_max = 0;
  int ku_count() const { return ku_max - ku_min + 1; }
  int kv_count() const { return kv_max - kv_min + 1; }
};

struct Plan {
  double kappa_lo = 0.0, kappa_hi = 0.0;  // rad/µm
  double y_max = 0.0;                     // κ_hi·s
  std::vector<Band> bands;
  int total_terms = 0;
  Bins bins;
  double estimated_error = 0.0;  // max over bands of truncation + roundoff bounds
  bool estimate_meets_tolerance = true;
};

// Builds the field (file or procedural) and its centre and scale.
Field make_field(const DiffractionSpec& spec);
Field centre_field(Heightfield hf, Centre centre);

// Upper bounds of the moments μ_n = mean over the samples of |g|^n, n = 0…n_max, from a
// histogram of |g| (each sample counted at its bin's upper edge, so μ_n is never
// underestimated). The expansions' errors are sums over samples of |g_j|^n times the bounds
// below: a field whose heights stay mostly near the centre needs fewer terms than one at ±s
// everywhere (μ_n = 1 bounds every field).
std::vector<double> abs_g_moments(const Field& f, int n_max);

// Truncation bound of a band with half-width `half_y` = Δ·s after `terms` terms (over M²),
// times μ_T (`moment`, 1 for any field): taylor (half_y)^T/T!; chebyshev
// 2·(z/2)^T/T!/(1 − (z/2)/(T+1)), z = half_y (∞ if not convergent).
double truncation_bound(Expansion e, double half_y, int terms, double moment = 1.0);
// Roundoff estimate over M²: 4u·Σ_{n<T} max|coef_n|·rms|q_n| (see docs/diffraction.md), with
// rms|q_n| ≤ √μ_2n from `moments` (empty: 1).
double roundoff_estimate(Expansion e, double half_y, int terms, double unit_roundoff,
                         const std::vector<double>& moments = {});

// Bands for κ ∈ [lo, hi] split into `count` equal bands of `terms` terms each.
std::vector<Band> make_bands(Expansion e, double kappa_lo, double kappa_hi, double s, int count, int terms,
                             double unit_roundoff, const std::vector<double>& moments = {});
// The cheapest (fewest FFTs) equal-band split meeting `target`; empty if none within the term cap.
std::vector<Band> auto_bands(Expansion e, double kappa_lo, double kappa_hi, double s, double target,
                             double unit_roundoff, const std::vector<double>& moments = {});

Bins crop_bins(const DiffractionSpec& spec, int width, int height, double dx_um);
Plan make_plan(const DiffractionSpec& spec, const Field& f, double target);

nlohmann::json bands_json(const std::vector<Band>& bands);

}  // namespace specbake::diffraction
