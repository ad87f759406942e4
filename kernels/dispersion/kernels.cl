/* kernels.cl — OpenCL entry points of the dispersion job; the maths is in dispersion.cl
 * and colour.cl. One work item per sample (n) or per pixel (p). */
#include "dispersion/dispersion.cl"
#include "common/colour.cl"

/* Per sample: raw weights W_n = CMF(λ_n)·w_n [N,3], Offset(λ_n) [N] and n(λ_n) [N].
 * lines = (λ_ref, λ_F, λ_C) nm. material: 0 = Cauchy/Abbe (n_ref, v), 1 = Sellmeier (B, C, terms). */
__kernel void dispersion_samples(__global const real* lambda_nm, __global const real* weight_nm, int n_samples,
                                 __global const real* cmf, int cmf_count, real cmf_first_nm,
                                 real line_ref, real line_F, real line_C,
                                 int material, real n_ref, real v, __global const real* sellmeier_bc, int terms,
                                 __global real* w_raw, __global real* offset, __global real* ior) {
  const int n = get_global_id(0);
  if (n >= n_samples) return;
  const real l = lambda_nm[n];
  real xyz[3];
  cmf_lerp(cmf, cmf_count, cmf_first_nm, l, xyz);
  for (int c = 0; c < 3; ++c) w_raw[3 * n + c] = xyz[c] * weight_nm[n];
  const real off = abbe_offset(l, line_ref, line_F, line_C);
  offset[n] = off;
  if (material == 0) {
    ior[n] = cauchy_abbe_ior(n_ref, v, off);
  } else {
    real B[4], C[4];
    for (int i = 0; i < terms; ++i) {
      B[i] = sellmeier_bc[i];
      C[i] = sellmeier_bc[4 + i];
    }
    ior[n] = sellmeier_ior(B, C, terms, l);
  }
}

/* Per sample: Ŵ_n = W_n ∘ norm [N,3] and K_n [N,3,3]. m = (M_sRGB→XYZ, M_XYZ→sRGB) row-major. */
__kernel void dispersion_matrices(__global const real* w_raw, int n_samples, real norm_x, real norm_y, real norm_z,
                                  __global const real* m, __global real* w_norm, __global real* K) {
  const int n = get_global_id(0);
  if (n >= n_samples) return;
  real M[9], Minv[9], w[3], k[9];
  for (int i = 0; i < 9; ++i) {
    M[i] = m[i];
    Minv[i] = m[9 + i];
  }
  w[0] = w_raw[3 * n + 0] * norm_x;
  w[1] = w_raw[3 * n + 1] * norm_y;
  w[2] = w_raw[3 * n + 2] * norm_z;
  k_matrix(M, Minv, w, k);
  for (int c = 0; c < 3; ++c) w_norm[3 * n + c] = w[c];
  for (int i = 0; i < 9; ++i) K[9 * n + i] = k[i];
}

/* Per pixel p of the thin-prism picture (pixel p spans [x0 + p·dx, x0 + (p+1)·dx]): its XYZ
 * [pixels,3]. white = XYZ of sRGB (1,1,1). */
__kernel void prism_image(__global const real* x, __global const real* w_norm, int n_samples, real x0, real dx,
                          int pixels, real white_x, real white_y, real white_z, __global real* xyz) {
  const int p = get_global_id(0);
  if (p >= pixels) return;
  const real white[3] = {white_x, white_y, white_z};
  real v[3];
  prism_pixel(x, w_norm, n_samples, x0 + dx * (real)p, dx, white, v);
  for (int c = 0; c < 3; ++c) xyz[3 * p + c] = v[c];
}

/* Per pixel: CIEDE2000 between a test and a reference picture, −1 where the reference is
 * unlit (Y_ref ≤ lit_y). The Lab white is the XYZ of sRGB (1,1,1). */
__kernel void prism_delta_e(__global const real* test_xyz, __global const real* ref_xyz, int pixels,
                            real white_x, real white_y, real white_z, real lit_y, __global real* delta_e) {
  const int p = get_global_id(0);
  if (p >= pixels) return;
  if (!(ref_xyz[3 * p + 1] > lit_y)) {
    delta_e[p] = R(-1.0);
    return;
  }
  real L1, a1, b1, L2, a2, b2;
  xyz_to_lab(test_xyz[3 * p], test_xyz[3 * p + 1], test_xyz[3 * p + 2], white_x, white_y, white_z, &L1, &a1, &b1);
  xyz_to_lab(ref_xyz[3 * p], ref_xyz[3 * p + 1], ref_xyz[3 * p + 2], white_x, white_y, white_z, &L2, &a2, &b2);
  delta_e[p] = ciede2000(L1, a1, b1, L2, a2, b2);
}
