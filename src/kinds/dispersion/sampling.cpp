#include "kinds/dispersion/sampling.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace specbake::dispersion {

namespace {
// P_n(z) and its derivative, by the three-term recurrence.
void legendre(int n, double z, double& p, double& dp) {
  double p0 = 1.0, p1 = z;
  for (int k = 2; k <= n; ++k) {
    const double p2 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p0) / k;
    p0 = p1;
    p1 = p2;
  }
  p = p1;
  dp = n * (z * p1 - p0) / (z * z - 1.0);
}
}  // namespace

void gauss_legendre(int n, std::vector<double>& x, std::vector<double>& w) {
  x.assign(n, 0.0);
  w.assign(n, 0.0);
  for (int i = 0; i < (n + 1) / 2; ++i) {
    // Newton on P_n from Tricomi's initial guess; converges to double precision in a few steps.
    double z = std::cos(std::numbers::pi * (i + 0.75) / (n + 0.5));
    double p = 0.0, dp = 1.0;
    for (int it = 0; it < 100; ++it) {
      legendre(n, z, p, dp);
      const double dz = p / dp;
      z -= dz;
      if (std::fabs(dz) < 1e-16) break;
    }
    legendre(n, z, p, dp);
    const double wi = 2.0 / ((1.0 - z * z) * dp * dp);
    x[i] = -z;
    x[n - 1 - i] = z;
    w[i] = w[n - 1 - i] = wi;
  }
  if (n % 2 == 1) x[n / 2] = 0.0;
}

Samples make_samples(Sampling scheme, RangeNm r, int n) {
  if (n < 1) throw std::invalid_argument("sample count must be >= 1");
  Samples s;
  s.lambda_nm.resize(n);
  s.weight_nm.resize(n);
  const double lo = r.lo, hi = r.hi;
  switch (scheme) {
    case Sampling::uniform: {
      const double d = (hi - lo) / n;
      for (int i = 0; i < n; ++i) {
        s.lambda_nm[i] = lo + (i + 0.5) * d;
        s.weight_nm[i] = d;
      }
      break;
    }
    case Sampling::gauss_legendre: {
      std::vector<double> x, w;
      gauss_legendre(n, x, w);
      for (int i = 0; i < n; ++i) {
        s.lambda_nm[i] = 0.5 * (lo + hi) + 0.5 * (hi - lo) * x[i];
        s.weight_nm[i] = 0.5 * (hi - lo) * w[i];
      }
      break;
    }
    case Sampling::visible_pdf: {
      // p(λ) = a·sech²(a(λ−538)) / (t_hi − t_lo), CDF(λ) = (tanh(a(λ−538)) − t_lo)/(t_hi − t_lo).
      const double a = 0.0072, c = 538.0;
      const double t_lo = std::tanh(a * (lo - c)), t_hi = std::tanh(a * (hi - c));
      for (int i = 0; i < n; ++i) {
        const double u = (i + 0.5) / n;
        const double l = c + std::atanh(t_lo + u * (t_hi - t_lo)) / a;
        const double ch = std::cosh(a * (l - c));
        const double pdf = a / (ch * ch) / (t_hi - t_lo);
        s.lambda_nm[i] = l;
        s.weight_nm[i] = 1.0 / (n * pdf);
      }
      break;
    }
    case Sampling::inverse_square: {
      const double s_lo = 1.0 / (hi * hi), s_hi = 1.0 / (lo * lo);  // σ ascending = λ descending
      const double ds = (s_hi - s_lo) / n;
      for (int i = 0; i < n; ++i) {
        const double sigma = s_lo + (n - 1 - i + 0.5) * ds;  // so λ ascends with i
        const double l = 1.0 / std::sqrt(sigma);
        s.lambda_nm[i] = l;
        s.weight_nm[i] = ds * l * l * l / 2.0;
      }
      break;
    }
  }
  return s;
}

}  // namespace specbake::dispersion
