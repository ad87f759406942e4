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

/* The row stage of a table's non-uniform FFT (src/kinds/diffraction/table.hpp): one work item per
 * padded sample l < n_pad of kept row r < rows, field sample (ix_lo + l, iy_first + r) of a
 * `width`-wide field. For the terms n = n_first … n_first+n_count−1 it writes
 *   q_n(h)·weight_x[l]·weight_y[iy]     (window × the x axis's deconvolution 1/φ̂; l < count_x)
 * or 0 (the zero padding, l ≥ count_x), as float complex into q[(j·rows + r)·n_pad + l], j = n − n_first:
 * the rows the batched row transform takes next. */
__kernel void diffraction_table_row_inputs(__global const real* h, int width, int ix_lo, int count_x, int n_pad,
                                           __global const real* weight_x, __global const real* weight_y,
                                           int iy_first, int rows, real c, real inv_s, int expansion, real kappa0,
                                           real delta, int n_first, int n_count, __global float* q) {
  const int l = get_global_id(0), r = get_global_id(1);
  if (l >= n_pad || r >= rows) return;
  const size_t at = (size_t)r * n_pad + l, per_term = (size_t)rows * n_pad;
  if (l >= count_x) {
    for (int j = 0; j < n_count; ++j) {
      q[2 * (j * per_term + at)] = 0.0f;
      q[2 * (j * per_term + at) + 1] = 0.0f;
    }
    return;
  }
  const int iy = iy_first + r;
  real re[DIFFRACTION_MAX_BATCH], im[DIFFRACTION_MAX_BATCH];
  term_inputs(h[(size_t)iy * width + ix_lo + l], c, inv_s, expansion, kappa0, delta, n_first, n_count, re, im);
  const real a = weight_x[l] * weight_y[iy];
  for (int j = 0; j < n_count; ++j) {
    q[2 * (j * per_term + at)] = (float)(a * re[j]);
    q[2 * (j * per_term + at) + 1] = (float)(a * im[j]);
  }
}
