/* dispersion.cl — the maths of a dispersion bake (SPECGEN), shared by the OpenCL kernels
 * (kernels/dispersion/kernels.cl) and the C++ double-precision reference.
 *
 * For N sample wavelengths λ_n (nm) with quadrature weights w_n (nm):
 *   W_n  = CMF(λ_n)·w_n                      CMF linearly interpolated from a 1 nm table, 0 outside it
 *                                            (cmf_lerp, common/colour.cl)
 *   Ŵ_n  = W_n / Σ_m W_m   (per component)   so Σ Ŵ_n = (1, 1, 1) — not normalised to D65
 *   K_n  = M_XYZ→sRGB · Diag(Ŵ_n) · M_sRGB→XYZ    so Σ K_n = I (white stays white)
 *   Offset(λ) = (1/λ² − 1/λ_ref²) / (1/λ_F² − 1/λ_C²)   (dimensionless; λ_ref, λ_F, λ_C are the
 *               Abbe lines: d 587.5618/486.1327/656.2725 nm, or the SPECGEN seed's D 589.3/486.13/656.27)
 *   n(λ) = n_ref + (n_ref − 1)/V · Offset(λ)    Cauchy model through the Abbe number (the shader's)
 *   n(λ)² = 1 + Σ_i B_i λ²/(λ² − C_i)           Sellmeier, λ in µm, C_i in µm² (catalogue glasses)
 * Matrices are 3×3 row-major: m[3*row + col].
 */
#include "common/real.h"
#include "common/colour.cl"

FN real abbe_offset(real lambda_nm, real ref_nm, real F_nm, real C_nm) {
  const real inv2 = R(1.0) / (lambda_nm * lambda_nm);
  const real ref2 = R(1.0) / (ref_nm * ref_nm);
  const real F2 = R(1.0) / (F_nm * F_nm), C2 = R(1.0) / (C_nm * C_nm);
  return (inv2 - ref2) / (F2 - C2);
}

FN real cauchy_abbe_ior(real n_ref, real v, real offset) { return n_ref + (n_ref - R(1.0)) / v * offset; }

/* B, C: `terms` coefficients (≤ 4) in private memory. */
FN real sellmeier_ior(const real* B, const real* C, int terms, real lambda_nm) {
  REQUIRE(lambda_nm > R(0.0));
  REQUIRE(terms >= 0 && terms <= 4);
  const real l2 = (lambda_nm * R(1e-3)) * (lambda_nm * R(1e-3));
  real n2 = R(1.0);
  for (int i = 0; i < terms; ++i) n2 += B[i] * l2 / (l2 - C[i]);
  return sqrt(n2);
}

/* K = Minv · Diag(w) · M. */
FN void k_matrix(const real* M, const real* Minv, const real* w, real* K) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      K[3 * r + c] = Minv[3 * r + 0] * w[0] * M[0 * 3 + c] + Minv[3 * r + 1] * w[1] * M[1 * 3 + c] +
                     Minv[3 * r + 2] * w[2] * M[2 * 3 + c];
}

/* Length of the overlap of [a0, a1] and [b0, b1]. */
FN real overlap(real a0, real a1, real b0, real b1) {
  const real lo = fmax(a0, b0), hi = fmin(a1, b1);
  return hi > lo ? hi - lo : R(0.0);
}

/* The thin-prism picture used by `samples: auto`: a white box beam of width 1 whose sample n
 * lands at x_n = spread·Offset(λ_n) with XYZ Ŵ_n ∘ white. Returns the XYZ of the pixel
 * [x0, x0 + dx] (mean over the pixel). */
FN void prism_pixel(GLOBAL const real* x, GLOBAL const real* w_norm, int n_samples, real x0, real dx,
                    const real* white, real* xyz) {
  real acc[3] = {R(0.0), R(0.0), R(0.0)};
  for (int n = 0; n < n_samples; ++n) {
    const real cover = overlap(x[n] - R(0.5), x[n] + R(0.5), x0, x0 + dx) / dx;
    if (cover > R(0.0))
      for (int c = 0; c < 3; ++c) acc[c] += cover * w_norm[3 * n + c];
  }
  for (int c = 0; c < 3; ++c) xyz[c] = acc[c] * white[c];
}
