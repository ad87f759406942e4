#pragma once
// Sample wavelengths λ_n (nm, ascending) and quadrature weights w_n (nm) for the schemes of
// the dispersion job:
//   uniform         midpoints λ_n = lo + (n+½)·Δ, w_n = Δ = (hi−lo)/N
//   gauss-legendre  Gauss–Legendre nodes x_n on [−1,1] mapped to [lo,hi], w_n = (hi−lo)/2·w_GL
//   visible-pdf     importance sampling by p(λ) ∝ sech²(0.0072(λ−538)) (pbrt-v4/Mitsuba 3's
//                   visible-wavelength pdf), truncated to [lo,hi], inverted at stratum midpoints
//                   u = (n+½)/N, w_n = 1/(N·p(λ_n))
//   inverse-square  midpoints evenly spaced in σ = 1/λ², w_n = Δσ·|dλ/dσ| = Δσ·λ_n³/2
#include <vector>

#include "kinds/dispersion/spec.hpp"

namespace specbake::dispersion {

struct Samples {
  std::vector<double> lambda_nm;
  std::vector<double> weight_nm;
};

Samples make_samples(Sampling scheme, RangeNm range, int n);

// Nodes and weights of n-point Gauss–Legendre quadrature on [−1, 1], ascending.
void gauss_legendre(int n, std::vector<double>& x, std::vector<double>& w);

}  // namespace specbake::dispersion
