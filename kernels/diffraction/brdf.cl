/* brdf.cl — the scalar maths of the diffraction BRDF a shader evaluates from a baked table
 * (docs/diffraction.md, "The BRDF the previews draw"), written once in the common subset of
 * C++ (the host's double reference, src/kinds/diffraction/brdf.cpp, via reference.hpp) and GLSL
 * (the bundle's shader/diffraction_brdf.glsl pastes this text after a prelude that defines real,
 * FN, R(x), fabs and fmax; src/kinds/diffraction/shader.cpp). Scalars only, no `const` locals
 * (compile-time constants in GLSL), no pointers, vectors or overloads. The expansion's
 * coefficient recurrence lives here too, so that the shader's table lookup, the kernels and the
 * host's reference run one text (diffraction.cl includes this file).
 *
 * Table map (Stam 1999 as Dhillon et al. 2014 use it; texel centre s_i = 2(i + 0.5)/N − 1 per
 * axis at f = sign(s)·|s|^p·f_max cycles/µm): the continuous texel coordinate of f, i.e. i at
 * texel i's centre, is (s + 1)·N/2 − 1/2 with s = sign(f)·(|f|/f_max)^{1/p}.
 *
 * Relative BRDF (the diffraction thesis, seeds/003, eqs. 19–20):
 *   ρ_λ(ω_i, ω_o) = C·|P(f; κ)/Σw|²,
 *   C = R(ω_i·h)·(1 + ω_i·ω_o)² / (R(1)·(cos θ_i + cos θ_o)²·cos θ_o),
 * R the unpolarised Fresnel reflectance of a dielectric of index n seen from air,
 * f = −(ω_i + ω_o)_xy/λ, κ = 2π(cos θ_i + cos θ_o)/λ.
 */
#include "common/real.h"
#ifndef SPECBAKE_DIFFRACTION_BRDF_CL
#define SPECBAKE_DIFFRACTION_BRDF_CL

#define DIFFRACTION_TAYLOR 0
#define DIFFRACTION_CHEBYSHEV 1

/* The variable of a band's expansion at κ (diffraction.cl's header): taylor y = (κ−κ_0)·s, chebyshev
 * t = (κ−κ_m)/Δ (0 for a band of zero width). */
FN real expansion_variable(int expansion, real kappa, real kappa0, real delta, real s) {
  if (expansion == DIFFRACTION_TAYLOR) return (kappa - kappa0) * s;
  return delta > R(0.0) ? (kappa - kappa0) / delta : R(0.0);
}

/* coef_n for n ≥ 1 from coef_{n−1} (c) and coef_{n−2} (previous; any value at n = 1), x the
 * expansion's variable: taylor c_n = c_{n−1}·y/n; chebyshev T_1 = t, T_n = 2t·T_{n−1} − T_{n−2}.
 * coef_0 = 1. */
FN real expansion_next(int expansion, int n, real x, real c, real previous) {
  if (expansion == DIFFRACTION_TAYLOR) return c * x / R(n);
  return n == 1 ? x : R(2.0) * x * c - previous;
}

/* Continuous texel coordinate (texel i's centre at i) of frequency f (cycles/µm) on a table of
 * `size` texels per axis with mapping power p and reach f_max. */
FN real diffraction_texel(real f, real f_max, real power, real size) {
  real a = pow(fabs(f) / f_max, R(1.0) / power);
  real s = f < R(0.0) ? -a : a;
  return (s + R(1.0)) * size * R(0.5) - R(0.5);
}

/* Unpolarised Fresnel reflectance at incidence cosine c ∈ [0, 1] from air into a dielectric of
 * index n ≥ 1: the mean of |r_s|² and |r_p|². */
FN real fresnel_dielectric(real c, real n) {
  real t = sqrt(fmax(R(0.0), n * n - (R(1.0) - c * c)));
  real rs = (c - t) / (c + t);
  real rp = (n * n * c - t) / (n * n * c + t);
  return R(0.5) * (rs * rs + rp * rp);
}

/* The gain C(ω_i, ω_o) from cos θ_i, cos θ_o, ω_i·ω_o and ω_i·h; 0 below either horizon. */
FN real stam_gain(real cos_i, real cos_o, real wi_dot_wo, real wi_dot_h, real n) {
  if (cos_i <= R(0.0) || cos_o <= R(0.0)) return R(0.0);
  real w = cos_i + cos_o;
  real g = R(1.0) + wi_dot_wo;
  return fresnel_dielectric(wi_dot_h, n) / fresnel_dielectric(R(1.0), n) * g * g / (w * w * cos_o);
}

/* The specular peak of the fast variant that evaluates it apart (src/kinds/diffraction/brdf.hpp,
 * xyz_fast_specular): the Gaussian coherence window's |Ŵ(f)/Ŵ(0)|² = exp(−4π²σ²|f|²) at
 * |f|² = d_sq/λ², d = (ω_i + ω_o)_xy (σ and λ in µm). */
FN real specular_peak(real d_sq, real lambda_um, real sigma_um) {
  real a = R(6.283185307179586) * sigma_um / lambda_um;
  return exp(-a * a * d_sq);
}

/* The weight of b in the linear interpolation of x between a and b (a < b), clamped to [0, 1]. */
FN real lerp_weight(real x, real a, real b) { return fmin(fmax((x - a) / (b - a), R(0.0)), R(1.0)); }

#endif
