#include "kinds/diffraction/planning.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/parallel.hpp"
#include "core/text.hpp"
#include "kinds/diffraction/reference.hpp"

namespace specbake::diffraction {

namespace {
constexpr double kTwoPi = 6.283185307179586476925287;

int procedural_type(ProceduralField::Type t) {
  switch (t) {
    case ProceduralField::Type::sine_grating: return 0;
    case ProceduralField::Type::binary_grating: return 1;
    case ProceduralField::Type::blazed_grating: return 2;
    case ProceduralField::Type::eggcrate: return 3;
  }
  return 0;
}
}  // namespace

Field centre_field(Heightfield hf, Centre centre) {
  Field f;
  f.width = hf.width;
  f.height = hf.height;
  f.dx_um = hf.dx_um;
  f.h_um = std::move(hf.h_um);
  // Per row on the hardware threads, combined in row order: the same values on any thread count.
  std::vector<double> lo(f.height), hi(f.height), sum(f.height);
  parallel_for(f.height, [&](long long iy) {
    const auto row = f.h_um.begin() + iy * static_cast<std::ptrdiff_t>(f.width);
    const auto [mn, mx] = std::minmax_element(row, row + f.width);
    lo[iy] = *mn;
    hi[iy] = *mx;
    double s = 0.0;
    for (auto it = row; it != row + f.width; ++it) s += *it;
    sum[iy] = s;
  });
  f.h_min = *std::min_element(lo.begin(), lo.end());
  f.h_max = *std::max_element(hi.begin(), hi.end());
  double total = 0.0;
  for (double s : sum) total += s;
  f.h_mean = total / static_cast<double>(f.h_um.size());
  f.c = centre == Centre::mid_range ? 0.5 * (f.h_min + f.h_max) : centre == Centre::mean ? f.h_mean : 0.0;
  f.s = std::max(std::fabs(f.h_max - f.c), std::fabs(f.h_min - f.c));
  return f;
}

Field make_field(const DiffractionSpec& spec) {
  if (spec.field) return centre_field(*spec.field, spec.center);
  const ProceduralField& p = *spec.procedural;
  Heightfield hf;
  hf.width = hf.height = p.size;
  hf.dx_um = p.dx_um;
  hf.h_um.resize(static_cast<std::size_t>(p.size) * p.size);
  parallel_for(p.size, [&](long long iy) {  // each sample on its own: the same heights on any thread count
    for (int ix = 0; ix < p.size; ++ix)
      hf.h_um[static_cast<std::size_t>(iy) * p.size + ix] = ref::procedural_height(
          procedural_type(p.type), ix, static_cast<int>(iy), p.dx_um, p.period_um, p.amplitude_um);
  });
  return centre_field(std::move(hf), spec.center);
}

std::vector<double> abs_g_moments(const Field& f, int n_max) {
  // 4096 bins: a sample's |g| is overstated by < 1/4096, i.e. by < 0.25 % relative wherever
  // |g| ≥ 0.1 (< 10 % in |g|^n for n ≤ 40); the samples below 0.1 add at most 0.1^n.
  constexpr int kBins = 4096;
  std::vector<double> mu(n_max + 1, 1.0);
  if (f.s <= 0.0 || f.h_um.empty()) return mu;
  std::vector<long long> hist(kBins, 0);
  const double inv_s = 1.0 / f.s;
  for (double h : f.h_um) {
    const double g = std::min(1.0, std::fabs(h - f.c) * inv_s);
    ++hist[std::min(kBins - 1, static_cast<int>(g * kBins))];
  }
  std::vector<double> power(kBins, 1.0);  // (upper edge)^n
  const double inv_count = 1.0 / static_cast<double>(f.h_um.size());
  for (int n = 1; n <= n_max; ++n) {
    double sum = 0.0;
    for (int b = 0; b < kBins; ++b) {
      power[b] *= (b + 1.0) / kBins;
      sum += static_cast<double>(hist[b]) * power[b];
    }
    mu[n] = std::min(1.0, sum * inv_count);
  }
  return mu;
}

double truncation_bound(Expansion e, double half_y, int terms, double moment) {
  // Both bounds are x^T/T! (x = half_y or half_y/2), computed as a product to avoid overflow.
  // Per sample the remainder is that of x·|g_j| ≤ x, which carries |g_j|^T: the mean over
  // the samples (what one bin's error sums, over M²) carries μ_T.
  const double x = e == Expansion::taylor ? half_y : 0.5 * half_y;
  double b = moment;
  for (int n = 1; n <= terms; ++n) b *= x / n;
  if (e == Expansion::taylor) return b;
  // Σ_{n≥T} ε_n|J_n(z)| ≤ 2 Σ_{n≥T} (z/2)^n/n! ≤ 2 (z/2)^T/T! · 1/(1 − (z/2)/(T+1)).
  const double ratio = x / (terms + 1);
  if (ratio >= 1.0) return std::numeric_limits<double>::infinity();
  return 2.0 * b / (1.0 - ratio);
}

double roundoff_estimate(Expansion e, double half_y, int terms, double u, const std::vector<double>& moments) {
  // Σ_n max|coef_n|·rms|q_n|: taylor |coef_n| ≤ y^n/n!, |q_n| = |g|^n;
  // chebyshev |T_n| ≤ 1, |q_n| ≤ ε_n·min(1, (z/2)^n/n!·|g|^n). A float FFT's error in a bin
  // scales with the rms of its input, √μ_2n.
  auto rms = [&](int n) {
    return 2 * n < static_cast<int>(moments.size()) ? std::sqrt(moments[2 * n]) : 1.0;
  };
  double sum = 0.0, c = 1.0;
  const double x = e == Expansion::taylor ? half_y : 0.5 * half_y;
  for (int n = 0; n < terms; ++n) {
    if (n > 0) c *= x / n;
    sum += e == Expansion::taylor ? c * rms(n) : (n == 0 ? 1.0 : 2.0) * std::min(1.0, c * rms(n));
  }
  return 4.0 * u * sum;
}

namespace {
double moment_of(const std::vector<double>& moments, int n) {
  return n < static_cast<int>(moments.size()) ? moments[n] : 1.0;
}
}  // namespace

std::vector<Band> make_bands(Expansion e, double lo, double hi, double s, int count, int terms, double u,
                             const std::vector<double>& moments) {
  std::vector<Band> bands;
  const double width = (hi - lo) / count;
  for (int b = 0; b < count; ++b) {
    Band band;
    band.expansion = e;
    band.kappa_lo = lo + b * width;
    band.kappa_hi = b + 1 == count ? hi : lo + (b + 1) * width;
    band.kappa0 = 0.5 * (band.kappa_lo + band.kappa_hi);
    band.delta = 0.5 * (band.kappa_hi - band.kappa_lo);
    band.first_term = b * terms;
    band.terms = terms;
    band.bound_truncation = truncation_bound(e, band.delta * s, terms, moment_of(moments, terms));
    band.bound_roundoff = roundoff_estimate(e, band.delta * s, terms, u, moments);
    bands.push_back(band);
  }
  return bands;
}

std::vector<Band> auto_bands(Expansion e, double lo, double hi, double s, double target, double u,
                             const std::vector<double>& moments) {
  int best_count = 0, best_terms = 0;
  long best_cost = std::numeric_limits<long>::max();
  for (int count = 1; count <= kMaxDiffractionTerms && count < best_cost; ++count) {
    const double half_y = 0.5 * (hi - lo) / count * s;
    for (int t = 1; t * count <= kMaxDiffractionTerms && static_cast<long>(t) * count < best_cost; ++t) {
      if (truncation_bound(e, half_y, t, moment_of(moments, t)) + roundoff_estimate(e, half_y, t, u, moments) <=
          target) {
        best_count = count;
        best_terms = t;
        best_cost = static_cast<long>(t) * count;
        break;
      }
    }
  }
  if (!best_count) return {};
  return make_bands(e, lo, hi, s, best_count, best_terms, u, moments);
}

Bins crop_bins(const DiffractionSpec& spec, int width, int height, double dx_um) {
  auto axis = [&](int m, int& lo, int& hi) {
    lo = -(m / 2);
    hi = m - 1 - m / 2;
    if (!spec.crop) return;
    // The shader reaches |u|/λ ≤ 2/λ_min cycles/µm; bin k is k/(m·dx) cycles/µm.
    const double reach = 2.0 / (spec.range_nm.lo * 1e-3) * m * dx_um;
    const double k = std::ceil(reach) + kWindowReachBins;
    if (k < hi) {
      lo = -static_cast<int>(k);
      hi = static_cast<int>(k);
    }
  };
  Bins b;
  axis(width, b.ku_min, b.ku_max);
  axis(height, b.kv_min, b.kv_max);
  return b;
}

Plan make_plan(const DiffractionSpec& spec, const Field& f, double target) {
  Plan p;
  p.kappa_lo = 0.0;
  p.kappa_hi = kTwoPi * spec.w_max / (spec.range_nm.lo * 1e-3);
  p.y_max = p.kappa_hi * f.s;
  p.bins = crop_bins(spec, f.width, f.height, f.dx_um);
  const std::vector<double> moments = abs_g_moments(f, 2 * kMaxDiffractionTerms);
  if (spec.terms) {
    p.bands = make_bands(spec.expansion, p.kappa_lo, p.kappa_hi, f.s, 1, *spec.terms, kUnitRoundoffF32, moments);
  } else {
    p.bands = auto_bands(spec.expansion, p.kappa_lo, p.kappa_hi, f.s, target, kUnitRoundoffF32, moments);
    if (p.bands.empty())
      throw JobError("terms: auto cannot meet tolerance " + format_g(target) + " with at most " +
                     std::to_string(kMaxDiffractionTerms) + " FFT terms for y_max = kappa_hi*s = " +
                     format_g(p.y_max) + " in float32; raise the tolerance or narrow range_nm / w_max");
  }
  for (const auto& b : p.bands) {
    p.total_terms += b.terms;
    p.estimated_error = std::max(p.estimated_error, b.bound_truncation + b.bound_roundoff);
  }
  p.estimate_meets_tolerance = p.estimated_error <= spec.tolerance;
  return p;
}

nlohmann::json bands_json(const std::vector<Band>& bands) {
  // JSON has no infinity: a bound that does not converge is written as the string "infinite".
  auto finite = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json("infinite"); };
  nlohmann::json a = nlohmann::json::array();
  for (const auto& b : bands) {
    nlohmann::json j = {{"expansion", b.expansion == Expansion::taylor ? "taylor" : "chebyshev"},
                        {"kappa_range", {b.kappa_lo, b.kappa_hi}},
                        {"kappa_expansion", b.kappa0},
                        {"first_term", b.first_term},
                        {"terms", b.terms},
                        {"bound_truncation_over_M2", finite(b.bound_truncation)},
                        {"bound_roundoff_over_M2", finite(b.bound_roundoff)}};
    if (b.expansion == Expansion::chebyshev) j["delta"] = b.delta;
    a.push_back(j);
  }
  return a;
}

}  // namespace specbake::diffraction
