/* kernels.cl — OpenCL entry points of the diffraction job; the maths is in diffraction.cl.
 * Complex arrays are interleaved float pairs (re, im), the layout VkFFT transforms. */
#include "diffraction/diffraction.cl"

/* One work item per sample i of a W×H field (row-major [iy][ix]): writes the term inputs
 * q_n for n = n_first … n_first+n_count−1, times `scale` (1/(W·H), so that the unnormalised
 * forward FFT gives F_n = DFT(q_n)/M² directly), as float complex into
 * q[(n − n_first)·count + i]. */
__kernel void diffraction_term_inputs(__global const real* h, int count, real c, real inv_s, int expansion,
                                      real kappa0, real delta, int n_first, int n_count, float scale,
                                      __global float* q) {
  const int i = get_global_id(0);
  if (i >= count) return;
  real re[DIFFRACTION_MAX_BATCH], im[DIFFRACTION_MAX_BATCH];
  term_inputs(h[i], c, inv_s, expansion, kappa0, delta, n_first, n_count, re, im);
  for (int j = 0; j < n_count; ++j) {
    q[2 * ((size_t)j * count + i)] = (float)re[j] * scale;
    q[2 * ((size_t)j * count + i) + 1] = (float)im[j] * scale;
  }
}

/* The Taylor case of diffraction_term_inputs (same arguments less expansion and delta), by
 * running products: no per-item arrays. */
__kernel void diffraction_taylor_inputs(__global const real* h, int count, real c, real inv_s, real kappa0,
                                        int n_first, int n_count, float scale, __global float* q) {
  const int i = get_global_id(0);
  if (i >= count) return;
  real zr, zi, g;
  taylor_first(h[i], c, inv_s, kappa0, n_first, &zr, &zi, &g);
  for (int j = 0; j < n_count; ++j) {
    q[2 * ((size_t)j * count + i)] = (float)zr * scale;
    q[2 * ((size_t)j * count + i) + 1] = (float)zi * scale;
    taylor_next(g, &zr, &zi);
  }
}
