/* kernels.cl — OpenCL entry points of the diffraction job; the maths is in diffraction.cl.
 * Complex arrays are interleaved float pairs (re, im), the layout VkFFT transforms. */
#include "diffraction/diffraction.cl"
#include "diffraction/brdf.cl"
#include "diffraction/table.cl"

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

/* The spread of the table's non-uniform FFT (src/kinds/diffraction/table.cpp): one target frequency
 * from one transformed array b (n_pad interleaved float pairs), over the Kaiser–Bessel kernel's
 * DIFFRACTION_TAPS grid points from k0 (0 ≤ k0 < n_pad, wrapping: b is periodic),
 *   Σ_j wt_j·b[(k0 + j) mod n_pad],   wt_j = φ(n t − k)·e^{2πikc/n} (real pairs, from the host),
 * summed in j order in `real`. */
void spread_sum(__global const float* b, int n_pad, int k0, __global const real* wt, real* sr, real* si) {
  real ar = R(0.0), ai = R(0.0);
  int k = k0;
  for (int j = 0; j < DIFFRACTION_TAPS; ++j) {
    const real br = b[2 * k], bi = b[2 * k + 1], wr = wt[2 * j], wi = wt[2 * j + 1];
    ar += wr * br - wi * bi;
    ai += wr * bi + wi * br;
    if (++k == n_pad) k = 0;
  }
  *sr = ar;
  *si = ai;
}

/* The row stage's spread: one work item per (table column `col` < sum_n, transformed row a <
 * n_terms·rows), a = j·rows + r for term j of the group and kept row row_first + r. Column col's
 * k0 and weights (every table of the pass, concatenated) give the row's value at the column's
 * f_u, stored as float complex in out[j·per_term + (row_first + r)·sum_n + col]: the rows the
 * column stage gathers. */
__kernel void diffraction_table_spread_rows(__global const float* b, int n_pad, int rows, int n_terms,
                                            __global const int* k0, __global const real* wt, int sum_n,
                                            long per_term, int row_first, __global float* out) {
  const int col = get_global_id(0), a = get_global_id(1);
  if (col >= sum_n || a >= n_terms * rows) return;
  const int j = a / rows, r = a % rows;
  real sr, si;
  spread_sum(b + (size_t)2 * a * n_pad, n_pad, k0[col], wt + (size_t)2 * DIFFRACTION_TAPS * col, &sr, &si);
  const size_t at = (size_t)j * per_term + (size_t)(row_first + r) * sum_n + col;
  out[2 * at] = (float)sr;
  out[2 * at + 1] = (float)si;
}

/* The column stage's inputs: one work item per (column i < n_cols of the batch from column c0,
 * kept row l < n_pad). Column ci = c0 + i is term j = ci / sum_n's table column ci mod sum_n of
 * the row stage's results; its samples are multiplied by the y axis's deconvolution 1/φ̂ and
 * zero-padded (l ≥ count_y), into col[i·n_pad + l] (float complex): the arrays the column
 * transforms take next. */
__kernel void diffraction_table_gather_columns(__global const float* rows, int sum_n, long per_term, int count_y,
                                               int n_pad, __global const real* deconv_y, long c0, int n_cols,
                                               __global float* col) {
  const int i = get_global_id(0), l = get_global_id(1);
  if (i >= n_cols || l >= n_pad) return;
  const size_t at = (size_t)i * n_pad + l;
  if (l >= count_y) {
    col[2 * at] = 0.0f;
    col[2 * at + 1] = 0.0f;
    return;
  }
  const long ci = c0 + i;
  const size_t from = (size_t)(ci / sum_n) * per_term + (size_t)l * sum_n + (size_t)(ci % sum_n);
  col[2 * at] = (float)(rows[2 * from] * deconv_y[l]);
  col[2 * at + 1] = (float)(rows[2 * from + 1] * deconv_y[l]);
}

/* The column stage's spread for one table of the pass (its columns offset … offset+size−1 of
 * each term's sum_n, its f_v spreads at offset … in k0, wt): one work item per (column i of the
 * batch, texel row iv < size); items whose column belongs to another table return. Writes
 *   F[term_first + j][iv][iu] = inv·Σ_taps,   j = ci / sum_n, iu = ci mod sum_n − offset,
 * as float complex into out (the table's [T][size][size] pairs). */
__kernel void diffraction_table_spread_columns(__global const float* col, int n_pad, long c0, int n_cols, int sum_n,
                                               int offset, int size, __global const int* k0,
                                               __global const real* wt, int term_first, real inv,
                                               __global float* out) {
  const int i = get_global_id(0), iv = get_global_id(1);
  if (i >= n_cols || iv >= size) return;
  const long ci = c0 + i;
  const int iu = (int)(ci % sum_n) - offset;
  if (iu < 0 || iu >= size) return;
  real sr, si;
  spread_sum(col + (size_t)2 * i * n_pad, n_pad, k0[offset + iv], wt + (size_t)2 * DIFFRACTION_TAPS * (offset + iv),
             &sr, &si);
  const size_t at = ((size_t)(term_first + ci / sum_n) * size + iv) * size + iu;
  out[2 * at] = (float)(sr * inv);
  out[2 * at + 1] = (float)(si * inv);
}

/* The exact transform's input e^{iκh} of every sample i < count (src/kinds/diffraction/terms.cpp,
 * ExactDft; host twin: std::polar), interleaved (re, im) into p, the layout the double VkFFT
 * transforms. Built in double only (SPECBAKE_REAL_DOUBLE): it feeds a ground truth. */
__kernel void diffraction_phase_field(__global const real* h, int count, real kappa, __global real* p) {
  const int i = get_global_id(0);
  if (i >= count) return;
  real c;
  const real sn = sincos(kappa * h[i], &c);
  p[2 * (size_t)i] = c;
  p[2 * (size_t)i + 1] = sn;
}

/* The error of a reconstruction from stored terms (src/kinds/diffraction/terms.cpp, ExactDft::max_error;
 * host twin: reconstruct and a maximum): work item g < n_items visits the bins j = g, g + n_items, …
 * < ku_count·kv_count of the cropped terms (float32 [T][kv][ku][re, im], bin (ku_min + j mod ku_count,
 * kv_min + j / ku_count)), forms P_rec = front·Σ_n coef[n]·F_{first+n}[j] (in term order) and takes
 * P_exact from the unshifted W×H transform p (interleaved double) at (ku mod W, kv mod H); out[g] =
 * max_j |P_rec − P_exact|. Built in double only: it measures against a ground truth. */
__kernel void diffraction_reconstruction_error(__global const float* terms, int ku_min, int kv_min, int ku_count,
                                               int kv_count, int width, int height, int first, int count,
                                               __global const real* coef, real front_re, real front_im,
                                               __global const real* p, int n_items, __global real* out) {
  const int g = get_global_id(0);
  if (g >= n_items) return;
  const size_t per = (size_t)ku_count * kv_count;
  real worst = R(0.0);
  for (size_t j = g; j < per; j += n_items) {
    real sr = R(0.0), si = R(0.0);
    for (int n = 0; n < count; ++n) {
      const size_t at = 2 * ((size_t)(first + n) * per + j);
      sr += coef[n] * terms[at];
      si += coef[n] * terms[at + 1];
    }
    int ku = ku_min + (int)(j % ku_count), kv = kv_min + (int)(j / ku_count);
    ku %= width;
    kv %= height;
    if (ku < 0) ku += width;
    if (kv < 0) kv += height;
    const size_t e = 2 * ((size_t)kv * width + ku);
    worst = fmax(worst, hypot(front_re * sr - front_im * si - p[e], front_re * si + front_im * sr - p[e + 1]));
  }
  out[g] = worst;
}

/* The windowed field of `rows` field rows from iy_first (the exact transform's input; host twin
 * direct_transform_grid in src/kinds/diffraction/table.cpp): one work item per sample,
 *   a[r][ix] = wx[ix]·wy[iy]·e^{iκh[iy][ix]},   iy = iy_first + r,
 * into ar/ai[r·width + ix]. Built in double only (SPECBAKE_REAL_DOUBLE): it feeds a ground truth. */
__kernel void diffraction_windowed_rows(__global const real* h, __global const real* wx, __global const real* wy,
                                        int width, int iy_first, int rows, real kappa, __global real* ar,
                                        __global real* ai) {
  const int ix = get_global_id(0), r = get_global_id(1);
  if (ix >= width || r >= rows) return;
  const int iy = iy_first + r;
  const real w = wx[ix] * wy[iy], ph = kappa * h[(size_t)iy * width + ix];
  real c;
  const real sn = sincos(ph, &c);
  ar[(size_t)r * width + ix] = w * c;
  ai[(size_t)r * width + ix] = w * sn;
}

/* The row stage of the exact transform on a product grid: one work item per (frequency a, row r),
 *   R[iy_first + r][a] = Σ_ix a[r][ix]·e_a[ix],   e_a[ix] = e^{−2πi·fu[a]·x_ix},
 * with a[r][ix] from diffraction_windowed_rows and the phasors tabulated by the host ([ix][a]:
 * neighbouring work items read neighbouring phasors), summed in ix order, into rr/ri[iy·nu + a]. */
__kernel void diffraction_exact_rows(__global const real* ar, __global const real* ai, int width, int iy_first,
                                     int rows, __global const real* er, __global const real* ei, int nu,
                                     __global real* rr, __global real* ri) {
  const int a = get_global_id(0), r = get_global_id(1);
  if (a >= nu || r >= rows) return;
  /* four partial sums over ix ≡ 0, 1, 2, 3 (mod 4), added at the end: independent chains */
  real sr[4] = {R(0.0), R(0.0), R(0.0), R(0.0)}, si[4] = {R(0.0), R(0.0), R(0.0), R(0.0)};
  __global const real* pr = ar + (size_t)r * width;
  __global const real* pi = ai + (size_t)r * width;
  int ix = 0;
  for (; ix + 4 <= width; ix += 4)
    for (int k = 0; k < 4; ++k) {
      const real qr = er[(size_t)(ix + k) * nu + a], qi = ei[(size_t)(ix + k) * nu + a];
      sr[k] += pr[ix + k] * qr - pi[ix + k] * qi;
      si[k] += pr[ix + k] * qi + pi[ix + k] * qr;
    }
  for (; ix < width; ++ix) {
    const real qr = er[(size_t)ix * nu + a], qi = ei[(size_t)ix * nu + a];
    sr[ix & 3] += pr[ix] * qr - pi[ix] * qi;
    si[ix & 3] += pr[ix] * qi + pi[ix] * qr;
  }
  rr[(size_t)(iy_first + r) * nu + a] = (sr[0] + sr[1]) + (sr[2] + sr[3]);
  ri[(size_t)(iy_first + r) * nu + a] = (si[0] + si[1]) + (si[2] + si[3]);
}

/* The BRDF previews (src/kinds/diffraction/brdf.hpp, BrdfPictures): one work item per pair of
 * directions i < n_pairs (six reals in `pairs`: ω_i, then ω_o), its CIE XYZ into xyz[3i … 3i+2]:
 * table_xyz over the n_wl wavelengths of `wl` (variant 0), or table_xyz_fast_specular with the
 * n_few of `few` and the n_wl of `wl` (variant 1). */
__kernel void diffraction_brdf_xyz(__global const float* terms, int size, real f_max, real power, int n_bands,
                                   __global const real* bands, int expansion, real s, real p_scale, real ior,
                                   real sigma_um, int variant, int n_pairs, __global const real* pairs, int n_wl,
                                   __global const real* wl, int n_few, __global const real* few, __global real* xyz) {
  const int i = get_global_id(0);
  if (i >= n_pairs) return;
  __global const real* d = pairs + 6 * (size_t)i;
  real out[3];
  if (variant == 0)
    table_xyz(terms, size, f_max, power, n_bands, bands, expansion, s, p_scale, ior, d[0], d[1], d[2], d[3], d[4], d[5],
              n_wl, wl, out);
  else
    table_xyz_fast_specular(terms, size, f_max, power, n_bands, bands, expansion, s, p_scale, ior, sigma_um, d[0], d[1],
                            d[2], d[3], d[4], d[5], n_few, few, n_wl, wl, out);
  for (int c = 0; c < 3; ++c) xyz[3 * (size_t)i + c] = out[c];
}

/* The non-table job's preview (src/kinds/diffraction/diffraction_job.cpp): one work item per pixel
 * of a size × size picture of the unit disk (pixel centres, row 0 at v = 1), bins_preview_xyz over
 * the bundle's [T][kv][ku] terms, CIE XYZ into xyz[3·(py·size + px) …]. */
__kernel void diffraction_bins_preview(__global const float* terms, int ku_min, int kv_min, int ku_count, int kv_count,
                                       int n_bands, __global const real* bands, int expansion, real s, int width,
                                       int height, real dx, real w_max, int n_rows, __global const real* rows,
                                       real step_nm, int size, __global real* xyz) {
  const int px = get_global_id(0), py = get_global_id(1);
  if (px >= size || py >= size) return;
  const real v = R(1.0) - ((real)py + R(0.5)) * R(2.0) / (real)size;
  const real u = R(-1.0) + ((real)px + R(0.5)) * R(2.0) / (real)size;
  real out[3];
  bins_preview_xyz(terms, 2 * (long)ku_count * kv_count, 2, ku_min, kv_min, ku_count, kv_count, n_bands, bands,
                   expansion, s, width, height, dx, u, v, w_max, n_rows, rows, step_nm, out);
  for (int c = 0; c < 3; ++c) xyz[3 * ((size_t)py * size + px) + c] = out[c];
}
