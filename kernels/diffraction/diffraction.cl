/* diffraction.cl — the maths of a diffraction bake (Stam 1999; Dhillon, Single et al. 2014),
 * shared by the OpenCL kernels (kernels/diffraction/kernels.cl) and the C++ double-precision
 * reference (src/kinds/diffraction/reference.hpp).
 *
 * Units: heights h, centre c and scale s in µm; κ = k·w = 2π·w/λ in rad/µm (λ in µm).
 * A bake approximates, for every κ in a band [κ_a, κ_b], the DFT of p = e^{iκh}:
 *   P(k;κ) = M²·e^{iκc}·Σ_n coef_n(κ)·F_n[k],   F_n = DFT(q_n)/M²,
 * with the per-sample term inputs q_n and coefficients coef_n of the band's expansion:
 *   taylor about κ_0:      q_n = e^{iκ_0(h−c)}·(i·g)^n,             coef_n = ((κ−κ_0)·s)^n / n!
 *                          g = (h − c)/s ∈ [−1, 1]; the remainder of e^{iy} after N terms is
 *                          ≤ |y|^{N+1}/(N+1)! for real y (Taylor, Lagrange form).
 *   chebyshev (Jacobi–Anger) with κ_m = (κ_a+κ_b)/2, Δ = (κ_b−κ_a)/2, t = (κ−κ_m)/Δ ∈ [−1, 1]:
 *                          q_n = e^{iκ_m(h−c)}·ε_n·i^n·J_n(Δ·(h−c)), coef_n = T_n(t),
 *                          ε_0 = 1, ε_n = 2; from e^{izt} = Σ_n ε_n i^n J_n(z) T_n(t).
 * |T_n| ≤ 1 and |J_n| ≤ 1, so Chebyshev sums do not cancel; Taylor sums do when (κ−κ_0)s is large.
 */
#include "common/real.h"
/* DIFFRACTION_TAYLOR, DIFFRACTION_CHEBYSHEV and the expansion recurrence, shared with the shader: */
#include "diffraction/brdf.cl"

/* Most terms one kernel call produces per sample (a private array of this size). */
#define DIFFRACTION_MAX_BATCH 32
/* Grid points a table's Kaiser–Bessel spread visits per target frequency (kernel width 10 + 1;
 * src/kinds/diffraction/table.cpp). */
#define DIFFRACTION_TAPS 11

/* g^n for n >= 0 by binary powering (exact zero stays zero; 0^0 = 1). */
FN real ipow(real g, int n) {
  real r = R(1.0);
  real b = g;
  while (n > 0) {
    if (n & 1) r *= b;
    b *= b;
    n >>= 1;
  }
  return r;
}

/* Bessel functions of the first kind J_n(x) for n = n_first … n_first+n_count−1 into out[].
 * |x| ≤ 1: the power series Σ_k (−1)^k (x/2)^{2k+n} / (k!(k+n)!), whose terms fall by ≥ 4×
 * per step (stopped when they no longer change the sum).
 * |x| > 1: Miller's backward recurrence J_{k−1} = (2k/x)·J_k − J_{k+1} from an even start
 * m ≥ max(n_max, |x|) + 16 + √(40·max(n_max, |x|)) (where J_m is negligible), normalised by
 * J_0 + 2·Σ_k J_{2k} = 1 and rescaled by 1e−10 whenever values pass 1e10 (per-step growth
 * ≤ 2m/|x| < 2m keeps them far from float overflow). J_n(−x) = (−1)^n J_n(x). */
FN void bessel_j_range(real x, int n_first, int n_count, real* out) {
  const real ax = fabs(x);
  const int n_last = n_first + n_count - 1;
  if (ax <= R(1.0)) {
    const real hx = R(0.5) * ax;
    for (int j = 0; j < n_count; ++j) {
      const int n = n_first + j;
      real lead = R(1.0);
      for (int k = 1; k <= n; ++k) lead *= hx / (real)k;
      real term = lead, sum = lead;
      for (int k = 1; k < 60; ++k) {
        term *= -hx * hx / ((real)k * (real)(k + n));
        const real next = sum + term;
        if (next == sum) break;
        sum = next;
      }
      out[j] = sum;
    }
  } else {
    const real big = R(1e10), small = R(1e-10);
    const real top = fmax((real)n_last, ax);
    int m = (int)(top + R(16.0) + sqrt(R(40.0) * top));
    m += m & 1;
    real jp = R(0.0), j = R(1e-30) * big, norm = R(0.0);
    for (int i = 0; i < n_count; ++i) out[i] = R(0.0);
    for (int k = m; k >= 1; --k) {
      /* j = J_k (unnormalised), jp = J_{k+1} */
      const real jm = (R(2.0) * (real)k / ax) * j - jp;
      jp = j;
      j = jm; /* now J_{k-1} */
      const int order = k - 1;
      if (order >= n_first && order <= n_last) out[order - n_first] = j;
      if ((order & 1) == 0) norm += (order == 0 ? R(1.0) : R(2.0)) * j;
      if (fabs(j) > big) {
        j *= small;
        jp *= small;
        norm *= small;
        for (int i = 0; i < n_count; ++i) out[i] *= small;
      }
    }
    for (int i = 0; i < n_count; ++i) out[i] /= norm;
  }
  if (x < R(0.0))
    for (int i = 0; i < n_count; ++i)
      if ((n_first + i) & 1) out[i] = -out[i];
}

/* Taylor term inputs one at a time: taylor_first sets z = q_{n_first} = e^{iκ_0(h−c)}·(i·g)^{n_first}
 * and g; each taylor_next turns q_n into q_{n+1} = q_n·(i·g). */
FN void taylor_first(real h, real c, real inv_s, real kappa0, int n_first, real* zr, real* zi, real* g) {
  const real d = h - c;
  const real phase = kappa0 * d;
  const real pc = cos(phase), ps = sin(phase);
  *g = d * inv_s;
  const real a = ipow(*g, n_first);
  real re = pc * a, im = ps * a;
  for (int k = 0; k < (n_first & 3); ++k) { /* × i */
    const real t = re;
    re = -im;
    im = t;
  }
  *zr = re;
  *zi = im;
}
FN void taylor_next(real g, real* zr, real* zi) {
  const real re = *zr;
  *zr = -*zi * g;
  *zi = re * g;
}

/* Term inputs q_n (see the header) of one sample with height h, for n = n_first … +n_count−1.
 * kappa0 is κ_0 (taylor) or κ_m (chebyshev); delta is Δ (chebyshev only); inv_s = 1/s (0 for a
 * flat field). The phase e^{iκ_0(h−c)} is evaluated in `real` before any product. */
FN void term_inputs(real h, real c, real inv_s, int expansion, real kappa0, real delta, int n_first, int n_count,
                    real* re, real* im) {
  if (expansion == DIFFRACTION_TAYLOR) {
    real zr, zi, g;
    taylor_first(h, c, inv_s, kappa0, n_first, &zr, &zi, &g);
    for (int j = 0; j < n_count; ++j) {
      re[j] = zr;
      im[j] = zi;
      taylor_next(g, &zr, &zi);
    }
    return;
  }
  const real d = h - c;
  const real phase = kappa0 * d;
  const real pc = cos(phase), ps = sin(phase);
  real amp[DIFFRACTION_MAX_BATCH];
  bessel_j_range(delta * d, n_first, n_count, amp);
  for (int j = 0; j < n_count; ++j)
    if (n_first + j > 0) amp[j] *= R(2.0);
  for (int j = 0; j < n_count; ++j) {
    /* (pc + i·ps)·i^n·amp */
    real a = pc * amp[j], b = ps * amp[j];
    switch ((n_first + j) & 3) {
      case 0: re[j] = a; im[j] = b; break;
      case 1: re[j] = -b; im[j] = a; break;
      case 2: re[j] = -a; im[j] = -b; break;
      default: re[j] = b; im[j] = -a; break;
    }
  }
}

/* The band's coefficients coef_n(κ), n = 0 … n_count−1, by expansion_next. */
FN void expansion_coefficients(int expansion, real kappa, real kappa0, real delta, real s, int n_count, real* coef) {
  if (n_count <= 0) return;
  const real x = expansion_variable(expansion, kappa, kappa0, delta, s);
  coef[0] = R(1.0);
  for (int n = 1; n < n_count; ++n) coef[n] = expansion_next(expansion, n, x, coef[n - 1], n > 1 ? coef[n - 2] : R(0.0));
}

/* Procedural heightfields (µm), x = ix·dx, y = iy·dx, p = period/dx samples:
 * 0 sine-grating    h = a·sin(2π·x/period)
 * 1 binary-grating  h = a if (ix mod p) < p/2 else 0                 (a = depth)
 * 2 blazed-grating  h = a·(ix mod p)/p                               (a = depth)
 * 3 eggcrate        h = (a/4)·(2 + cos(2π·x/period) + cos(2π·y/period)) (a = peak-to-valley) */
FN real procedural_height(int type, int ix, int iy, real dx, real period, real a) {
  const real two_pi = R(6.283185307179586476925287);
  const real x = (real)ix * dx, y = (real)iy * dx;
  const real p = period / dx;
  const real phase = fmod((real)ix, p);
  if (type == 0) return a * sin(two_pi * x / period);
  if (type == 1) return phase < R(0.5) * p ? a : R(0.0);
  if (type == 2) return a * phase / p;
  return R(0.25) * a * (R(2.0) + cos(two_pi * x / period) + cos(two_pi * y / period));
}

/* Index of signed frequency bin k in an unshifted DFT array of length m (k mod m). */
FN int bin_index(int k, int m) {
  REQUIRE(m > 0);
  const int r = k % m;
  return r < 0 ? r + m : r;
}
