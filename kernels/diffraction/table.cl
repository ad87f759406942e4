/* table.cl — the previews' lookups of stored terms: the diffraction BRDF evaluated from a baked
 * table (docs/diffraction.md, "The BRDF the previews draw") and the non-table job's preview from its
 * bins, shared by the previews' kernels (kernels/diffraction/kernels.cl) and the C++ double
 * reference (src/kinds/diffraction/brdf.cpp, table.cpp and diffraction_job.cpp, via reference.hpp).
 * The bundle's GLSL shader evaluates the same maths with a sampler2DArray in place of `terms`
 * (src/kinds/diffraction/shader.cpp); its scalar parts are brdf.cl's, which this file uses.
 *
 * Table: float32 terms [T][size][size][re, im] (table_terms.bin), texel i's centre at continuous
 * coordinate i on each axis. A band b is five reals in `bands`: κ_hi, first term, term count,
 * expansion point κ_0 (κ_m), half-width Δ; the band holding κ is the first whose κ_hi ≥ κ, else
 * the last (terms.hpp, band_for). Units: λ in µm, κ in rad/µm, s (the field's scale) in µm.
 * P(f; κ) = W·H·e^{iκc}·Σ_n coef_n(κ)·F_n(f), so |P/Σw| = p_scale·|Σ_n coef_n·F_n| with
 * p_scale = W·H/Σw.
 */
#include "common/real.h"

#define DIFFRACTION_BAND_REALS 5
/* Most wavelengths the fast variants' few may hold (a private array of this size). */
#define DIFFRACTION_MAX_FEW 32

/* Σ_n coef_n(κ)·F_{first+n} of one band, bilinearly interpolated at continuous texel coordinates
 * (tu, tv) clamped to the table (a shader's CLAMP_TO_EDGE filtered fetch): the four texels' sums in
 * one pass over the terms, the coefficients by expansion_coefficients' recurrences as the pass
 * runs (taylor c_n = c_{n−1}·y/n, y = (κ − κ_0)·s; chebyshev T_n = 2t·T_{n−1} − T_{n−2},
 * t = (κ − κ_m)/Δ), then the bilinear weights. */
FN void table_bilinear_sum(GLOBAL const float* terms, int size, int first, int count, int expansion, real kappa,
                           real kappa0, real delta, real s, real tu, real tv, real* re, real* im) {
  real cu = fmin(fmax(tu, R(0.0)), (real)(size - 1));
  real cv = fmin(fmax(tv, R(0.0)), (real)(size - 1));
  int u0 = (int)floor(cu);
  int v0 = (int)floor(cv);
  if (u0 > size - 2) u0 = size - 2;
  if (v0 > size - 2) v0 = size - 2;
  real a = cu - (real)u0;
  real b = cv - (real)v0;
  long per = (long)size * size;
  long i00 = 2 * ((long)v0 * size + u0);
  long i01 = i00 + 2 * (long)size;
  real x = expansion_variable(expansion, kappa, kappa0, delta, s);
  real c = R(1.0);
  real previous = R(0.0);
  real r00 = R(0.0), j00 = R(0.0), r10 = R(0.0), j10 = R(0.0), r01 = R(0.0), j01 = R(0.0), r11 = R(0.0),
       j11 = R(0.0);
  for (int n = 0; n < count; ++n) {
    if (n > 0) {
      real next = expansion_next(expansion, n, x, c, previous);
      previous = c;
      c = next;
    }
    long at = 2 * (long)(first + n) * per;
    r00 += c * terms[at + i00];
    j00 += c * terms[at + i00 + 1];
    r10 += c * terms[at + i00 + 2];
    j10 += c * terms[at + i00 + 3];
    r01 += c * terms[at + i01];
    j01 += c * terms[at + i01 + 1];
    r11 += c * terms[at + i01 + 2];
    j11 += c * terms[at + i01 + 3];
  }
  *re = (R(1.0) - a) * (R(1.0) - b) * r00 + a * (R(1.0) - b) * r10 + (R(1.0) - a) * b * r01 + a * b * r11;
  *im = (R(1.0) - a) * (R(1.0) - b) * j00 + a * (R(1.0) - b) * j10 + (R(1.0) - a) * b * j01 + a * b * j11;
}

/* The index of the band holding κ. */
FN int table_band(int n_bands, GLOBAL const real* bands, real kappa) {
  int b = 0;
  while (b + 1 < n_bands && kappa > bands[DIFFRACTION_BAND_REALS * b]) ++b;
  return b;
}

/* |P(f; κ)/Σw|² at f (cycles/µm) for κ: 0 beyond f_max on either axis (the table's reach). */
FN real table_intensity(GLOBAL const float* terms, int size, real f_max, real power, int n_bands,
                        GLOBAL const real* bands, int expansion, real s, real p_scale, real fu, real fv, real kappa) {
  if (fabs(fu) > f_max || fabs(fv) > f_max) return R(0.0);
  GLOBAL const real* band = bands + DIFFRACTION_BAND_REALS * table_band(n_bands, bands, kappa);
  real re, im;
  table_bilinear_sum(terms, size, (int)band[1], (int)band[2], expansion, kappa, band[3], band[4], s,
                     diffraction_texel(fu, f_max, power, (real)size), diffraction_texel(fv, f_max, power, (real)size),
                     &re, &im);
  return p_scale * p_scale * (re * re + im * im);
}

/* Stam's gain C(ω_i, ω_o) of brdf.cl from the two unit vectors (tangent frame, z the normal). */
FN real table_gain(real wix, real wiy, real wiz, real wox, real woy, real woz, real ior) {
  real hx = wix + wox;
  real hy = wiy + woy;
  real hz = wiz + woz;
  real l = sqrt(hx * hx + hy * hy + hz * hz);
  return stam_gain(wiz, woz, wix * wox + wiy * woy + wiz * woz, (wix * hx + wiy * hy + wiz * hz) / l, ior);
}

/* ρ_λ(ω_i, ω_o) = C·|P(f; κ)/Σw|², f = −(ω_i + ω_o)_xy/λ, κ = 2π(cos θ_i + cos θ_o)/λ; 0 below
 * either horizon. */
FN real table_brdf(GLOBAL const float* terms, int size, real f_max, real power, int n_bands, GLOBAL const real* bands,
                   int expansion, real s, real p_scale, real ior, real wix, real wiy, real wiz, real wox, real woy,
                   real woz, real lambda_um) {
  if (wiz <= R(0.0) || woz <= R(0.0)) return R(0.0);
  real p2 = table_intensity(terms, size, f_max, power, n_bands, bands, expansion, s, p_scale,
                            -(wix + wox) / lambda_um, -(wiy + woy) / lambda_um,
                            R(6.283185307179586) * (wiz + woz) / lambda_um);
  return table_gain(wix, wiy, wiz, wox, woy, woz, ior) * p2;
}

/* CIE XYZ of one pair of directions: Σ_λ ρ_λ·(X, Y, Z)_λ over `n_wl` wavelengths, `wl` holding
 * four reals per wavelength (λ µm, then the X, Y, Z weights). */
FN void table_xyz(GLOBAL const float* terms, int size, real f_max, real power, int n_bands, GLOBAL const real* bands,
                  int expansion, real s, real p_scale, real ior, real wix, real wiy, real wiz, real wox, real woy,
                  real woz, int n_wl, GLOBAL const real* wl, real* xyz) {
  xyz[0] = R(0.0);
  xyz[1] = R(0.0);
  xyz[2] = R(0.0);
  for (int k = 0; k < n_wl; ++k) {
    real rho = table_brdf(terms, size, f_max, power, n_bands, bands, expansion, s, p_scale, ior, wix, wiy, wiz, wox,
                          woy, woz, wl[4 * k]);
    xyz[0] += rho * wl[4 * k + 1];
    xyz[1] += rho * wl[4 * k + 2];
    xyz[2] += rho * wl[4 * k + 3];
  }
}

/* The fast variant with the specular peak apart (brdf.hpp, xyz_fast_specular): the diffracted
 * remainder C·(|P/Σw|² − |χ|²·G) over the `n_few` wavelengths of `few` (ascending, 2 ≤ n_few ≤
 * DIFFRACTION_MAX_FEW), χ(κ) = P(0; κ)/Σw, G = exp(−4π²σ²|f|²) (0 beyond the table's reach); the
 * peak C·|χ|²·G over the `n_all` wavelengths of `all`, |χ|² linear in λ between its values at
 * `few` (clamped at the ends). Wavelength rows as table_xyz's. */
FN void table_xyz_fast_specular(GLOBAL const float* terms, int size, real f_max, real power, int n_bands,
                                GLOBAL const real* bands, int expansion, real s, real p_scale, real ior, real sigma_um,
                                real wix, real wiy, real wiz, real wox, real woy, real woz, int n_few,
                                GLOBAL const real* few, int n_all, GLOBAL const real* all, real* xyz) {
  REQUIRE(n_few >= 2 && n_few <= DIFFRACTION_MAX_FEW);
  xyz[0] = R(0.0);
  xyz[1] = R(0.0);
  xyz[2] = R(0.0);
  if (wiz <= R(0.0) || woz <= R(0.0)) return;
  real gain = table_gain(wix, wiy, wiz, wox, woy, woz, ior);
  real du = -(wix + wox);
  real dv = -(wiy + woy);
  real chi2[DIFFRACTION_MAX_FEW];
  for (int k = 0; k < n_few; ++k) {
    real lambda = few[4 * k];
    real kappa = R(6.283185307179586) * (wiz + woz) / lambda;
    chi2[k] = table_intensity(terms, size, f_max, power, n_bands, bands, expansion, s, p_scale, R(0.0), R(0.0), kappa);
    real beyond = fabs(du / lambda) > f_max || fabs(dv / lambda) > f_max ? R(0.0) : R(1.0);
    real rest = table_brdf(terms, size, f_max, power, n_bands, bands, expansion, s, p_scale, ior, wix, wiy, wiz, wox,
                           woy, woz, lambda) -
                gain * chi2[k] * beyond * specular_peak(du * du + dv * dv, lambda, sigma_um);
    xyz[0] += rest * few[4 * k + 1];
    xyz[1] += rest * few[4 * k + 2];
    xyz[2] += rest * few[4 * k + 3];
  }
  for (int i = 0; i < n_all; ++i) {
    real lambda = all[4 * i];
    int k = 0;
    while (k + 2 < n_few && lambda > few[4 * (k + 1)]) ++k;
    real w = lerp_weight(lambda, few[4 * k], few[4 * (k + 1)]);
    real beyond = fabs(du / lambda) > f_max || fabs(dv / lambda) > f_max ? R(0.0) : R(1.0);
    real spec = gain * (chi2[k] * (R(1.0) - w) + chi2[k + 1] * w) * beyond *
                specular_peak(du * du + dv * dv, lambda, sigma_um);
    xyz[0] += spec * all[4 * i + 1];
    xyz[1] += spec * all[4 * i + 2];
    xyz[2] += spec * all[4 * i + 3];
  }
}

/* ---- The non-table job's preview from its bins (src/kinds/diffraction/diffraction_job.cpp) ----
 * Bins: float32 F_n at integer bins ku_min ≤ ku < ku_min + ku_count (kv likewise), term n of bin
 * (a, b) at terms[n·term_stride + (b·ku_count + a)·bin_stride] (re, then im): the bundle's
 * [T][kv][ku] (term_stride = 2·bins, bin_stride = 2) or regrouped per bin (2, 2T). */

/* |P/M²|² bilinear between the four bins around continuous bin coordinates (fu, fv) (bins outside
 * weigh 0), |P/M²| = |Σ_n coef_n(κ)·F_n| over the band's terms: the four bins' sums in one pass
 * over the terms, the coefficients by expansion_next as the pass runs. */
FN real bins_power(GLOBAL const float* terms, long term_stride, long bin_stride, int ku_min, int kv_min, int ku_count,
                   int kv_count, int first, int count, int expansion, real kappa, real kappa0, real delta, real s,
                   real fu, real fv) {
  int u0 = (int)floor(fu);
  int v0 = (int)floor(fv);
  real wt[4];
  long at[4];
  for (int k = 0; k < 4; ++k) {
    int du = k & 1;
    int dv = k >> 1;
    int a = u0 + du - ku_min;
    int b = v0 + dv - kv_min;
    bool inside = a >= 0 && a < ku_count && b >= 0 && b < kv_count;
    wt[k] = inside ? (du ? fu - (real)u0 : R(1.0) - (fu - (real)u0)) * (dv ? fv - (real)v0 : R(1.0) - (fv - (real)v0))
                   : R(0.0);
    at[k] = inside ? ((long)b * ku_count + a) * bin_stride + (long)first * term_stride : -1;
  }
  real x = expansion_variable(expansion, kappa, kappa0, delta, s);
  real c = R(1.0);
  real previous = R(0.0);
  real re[4] = {R(0.0), R(0.0), R(0.0), R(0.0)};
  real im[4] = {R(0.0), R(0.0), R(0.0), R(0.0)};
  for (int n = 0; n < count; ++n) {
    if (n > 0) {
      real next = expansion_next(expansion, n, x, c, previous);
      previous = c;
      c = next;
    }
    for (int k = 0; k < 4; ++k) {
      if (at[k] < 0) continue;
      re[k] += c * terms[at[k] + n * term_stride];
      im[k] += c * terms[at[k] + n * term_stride + 1];
    }
  }
  real power = R(0.0);
  for (int k = 0; k < 4; ++k) power += wt[k] * (re[k] * re[k] + im[k] * im[k]);
  return power;
}

/* CIE XYZ of the preview's pixel (u, v) in the unit disk (white D65 light at normal incidence):
 * Σ over the n_rows spectrum rows (λ nm, D65·x̄, D65·ȳ, D65·z̄) of |P(u/λ, v/λ; κ)/M²|²·row·step_nm,
 * w = 1 + √(1 − u² − v²), κ = 2πw/λ, bins at (u/λ·W·dx, v/λ·H·dx); 0 where w > w_max. Bands as
 * table_xyz's. */
FN void bins_preview_xyz(GLOBAL const float* terms, long term_stride, long bin_stride, int ku_min, int kv_min,
                         int ku_count, int kv_count, int n_bands, GLOBAL const real* bands, int expansion, real s,
                         int width, int height, real dx, real u, real v, real w_max, int n_rows,
                         GLOBAL const real* rows, real step_nm, real* xyz) {
  xyz[0] = R(0.0);
  xyz[1] = R(0.0);
  xyz[2] = R(0.0);
  real r2 = u * u + v * v;
  if (r2 >= R(1.0)) return;
  real w = R(1.0) + sqrt(R(1.0) - r2);
  if (w > w_max) return;
  for (int k = 0; k < n_rows; ++k) {
    real lambda_um = rows[4 * k] * R(1e-3);
    real kappa = R(6.283185307179586476925287) * w / lambda_um;
    GLOBAL const real* band = bands + DIFFRACTION_BAND_REALS * table_band(n_bands, bands, kappa);
    real power = bins_power(terms, term_stride, bin_stride, ku_min, kv_min, ku_count, kv_count, (int)band[1],
                            (int)band[2], expansion, kappa, band[3], band[4], s, u / lambda_um * (real)width * dx,
                            v / lambda_um * (real)height * dx);
    xyz[0] += power * rows[4 * k + 1] * step_nm;
    xyz[1] += power * rows[4 * k + 2] * step_nm;
    xyz[2] += power * rows[4 * k + 3] * step_nm;
  }
}
