/* kernels.cl — OpenCL entry points of the diffraction job; the maths is in diffraction.cl.
 * Complex arrays are interleaved float pairs (re, im), the layout VkFFT transforms. */
#include "diffraction/diffraction.cl"

/* One work item per sample i of a W×H field (row-major [iy][ix]): writes the term inputs
 * q_n for n = n_first … n_first+n_count−1 as float complex into q[(n − n_first)·count + i]. */
__kernel void diffraction_term_inputs(__global const real* h, int count, real c, real inv_s, int expansion,
                                      real kappa0, real delta, int n_first, int n_count, __global float* q) {
  const int i = get_global_id(0);
  if (i >= count) return;
  real re[DIFFRACTION_MAX_BATCH], im[DIFFRACTION_MAX_BATCH];
  term_inputs(h[i], c, inv_s, expansion, kappa0, delta, n_first, n_count, re, im);
  for (int j = 0; j < n_count; ++j) {
    q[2 * ((size_t)j * count + i)] = (float)re[j];
    q[2 * ((size_t)j * count + i) + 1] = (float)im[j];
  }
}

/* One work item per output value: copies bins ku ∈ [ku_min, ku_min+ku_count), kv likewise, of
 * n_count transformed arrays (unshifted, [n][H][W]) into terms[(term0 + n)][kv][ku], scaled by
 * `scale` = 1/(W·H). */
__kernel void diffraction_crop(__global const float* spectrum, int width, int height, int n_count, int ku_min,
                               int ku_count, int kv_min, int kv_count, float scale, int term0,
                               __global float* terms) {
  const size_t id = get_global_id(0);
  const size_t per_term = (size_t)ku_count * kv_count;
  if (id >= per_term * n_count) return;
  const int n = (int)(id / per_term);
  const int rest = (int)(id % per_term);
  const int kv = kv_min + rest / ku_count, ku = ku_min + rest % ku_count;
  const size_t src = ((size_t)n * height + bin_index(kv, height)) * width + bin_index(ku, width);
  const size_t dst = (size_t)(term0 + n) * per_term + rest;
  terms[2 * dst] = spectrum[2 * src] * scale;
  terms[2 * dst + 1] = spectrum[2 * src + 1] * scale;
}
