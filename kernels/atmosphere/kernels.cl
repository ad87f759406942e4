/* kernels.cl — OpenCL entry points of the atmosphere job: one work item per texel (or per
 * table entry, or per ν row for the density); the multiple scattering runs one work group per
 * (μ, r) texel row. The maths is in atmosphere.cl. Textures are row-major with NCH channels
 * innermost:
 *   transmittance [h][w][NCH], irradiance [h][w][NCH], scattering [R][MU][NU·MU_S][NCH],
 *   ray samples [R][MU][SCATTERING_STEPS + 1][RAY_STRIDE],
 *   density incidence [R][MU_S][density_theta][incidence_stride].
 * Built with -DNCH=<channels> -DNU_MAX=<NU> (real = float unless SPECBAKE_REAL_DOUBLE). */
#include "atmosphere/atmosphere.cl"

/* Echoes the parameter block, so the host can check that both sides agree on its layout. */
__kernel void atmosphere_layout(AtmosphereParameters a, __global real* reals, __global int* ints) {
  if (get_global_id(0) != 0) return;
  reals[0] = a.solar_irradiance[0];
  reals[1] = a.ground_albedo[NCH - 1];
  reals[2] = a.absorption_density.constant_term[1];
  reals[3] = a.bottom_radius;
  reals[4] = a.mie_g;
  reals[5] = a.density_theta_power;
  reals[6] = a.density_phase_norm;
  ints[0] = a.transmittance_w;
  ints[1] = a.nu_size;
  ints[2] = (int)sizeof(AtmosphereParameters);
}

__kernel void transmittance_texture(AtmosphereParameters a, __global real* T) {
  const int id = get_global_id(0);
  if (id >= a.transmittance_w * a.transmittance_h) return;
  real h, mu, t[NCH];
  transmittance_texel_params(&a, id, &h, &mu);
  transmittance_to_top_integral(&a, h, mu, 1, t);
  for (int c = 0; c < NCH; ++c) T[id * NCH + c] = t[c];
}

__kernel void direct_irradiance_texture(AtmosphereParameters a, __global const real* T, __global real* delta_E) {
  const int id = get_global_id(0);
  if (id >= a.irradiance_w * a.irradiance_h) return;
  real h, mu_s, e[NCH];
  irradiance_texel_params(&a, id, &h, &mu_s);
  direct_irradiance(&a, T, h, mu_s, e);
  for (int c = 0; c < NCH; ++c) delta_E[id * NCH + c] = e[c];
}

/* id → (x, y, z) of the scattering texture and its parameters. */
void texel_params(const AtmosphereParameters* a, int id, int* x, int* y, int* z, real* h, real* mu, real* mu_s,
                  real* nu, int* ground) {
  const int wd = a->nu_size * a->mu_s_size;
  *x = id % wd;
  *y = (id / wd) % a->mu_size;
  *z = id / (wd * a->mu_size);
  scattering_params_from_texel(a, *x, *y, *z, h, mu, mu_s, nu, ground);
}

/* Entry i of the ray of texel row (z, y): one work item per entry. */
__kernel void ray_sample_table(AtmosphereParameters a, __global const real* T, __global real* samples) {
  const int id = get_global_id(0);
  const int n = SCATTERING_STEPS + 1;
  if (id >= a.r_size * a.mu_size * n) return;
  const int i = id % n, y = (id / n) % a.mu_size, z = id / (n * a.mu_size);
  real h, mu, d, fixed[NCH], s[RAY_STRIDE];
  int ground;
  scattering_ray_of_texel(&a, y, z, &h, &mu, &d, &ground);
  transmittance_fixed_end(&a, T, h, mu, ground, fixed);
  ray_sample(&a, T, h, mu, ground, d, fixed, i, s);
  for (int k = 0; k < RAY_STRIDE; ++k) samples[id * RAY_STRIDE + k] = s[k];
}

/* One work item per LANES texels of a (μ, r) row (x = chunk·LANES + k; lanes past the
 * row's end compute a texel at μ_s = ν = 0 that is not written): every texel of the row shares
 * its ray samples. */
__kernel void single_scattering_texture(AtmosphereParameters a, __global const real* T,
                                        __global const real* samples, __global real* delta_R,
                                        __global real* delta_M) {
  const int wd = a.nu_size * a.mu_s_size, chunks = (wd + LANES - 1) / LANES;
  const int id = get_global_id(0);
  if (id >= a.r_size * a.mu_size * chunks) return;
  const int row_id = id / chunks, x0 = (id % chunks) * LANES, y = row_id % a.mu_size, z = row_id / a.mu_size;
  real mu_s[LANES], nu[LANES], sum_r[LANES * NCH], sum_m[LANES * NCH], s[RAY_STRIDE];
  for (int k = 0; k < LANES; ++k) {
    real h, mu;
    int ground;
    mu_s[k] = nu[k] = R(0.0);
    if (x0 + k < wd) scattering_params_from_texel(&a, x0 + k, y, z, &h, &mu, &mu_s[k], &nu[k], &ground);
  }
  __global const real* row = samples + row_id * (SCATTERING_STEPS + 1) * RAY_STRIDE;
  for (int k = 0; k < LANES * NCH; ++k) sum_r[k] = sum_m[k] = R(0.0);
  for (int i = 0; i <= SCATTERING_STEPS; ++i) {
    for (int k = 0; k < RAY_STRIDE; ++k) s[k] = row[i * RAY_STRIDE + k];
    single_scattering_add_lanes(&a, T, s, mu_s, nu, sum_r, sum_m);
  }
  for (int k = 0; k < LANES && x0 + k < wd; ++k) {
    real ray[NCH], mie[NCH];
    single_scattering_finish(&a, sum_r + k * NCH, sum_m + k * NCH, ray, mie);
    const int texel = row_id * wd + x0 + k;
    for (int c = 0; c < NCH; ++c) {
      delta_R[texel * NCH + c] = ray[c];
      delta_M[texel * NCH + c] = mie[c];
    }
  }
}

/* Entry (z, mu_s index, θ index) of the density-incidence table. */
__kernel void density_incidence_table(AtmosphereParameters a, __global const real* T,
                                      __global const real* delta_R, __global const real* delta_M,
                                      __global const real* delta_S, int order, __global real* incidence) {
  const int id = get_global_id(0);
  if (id >= a.r_size * a.mu_s_size * a.density_theta) return;
  const int l = id % a.density_theta, xs = (id / a.density_theta) % a.mu_s_size,
            z = id / (a.density_theta * a.mu_s_size);
  real h, mu, mu_s, nu, e[INC_MAX];
  int ground;
  scattering_params_from_texel(&a, xs, 0, z, &h, &mu, &mu_s, &nu, &ground);
  density_incidence(&a, T, delta_R, delta_M, delta_S, h, mu_s, order, l, e);
  const int stride = incidence_stride(&a);
  for (int k = 0; k < stride; ++k) incidence[id * stride + k] = e[k];
}

/* The density's phase factors per (μ, r) texel row (density_phase_factors): [R][MU][2]. */
__kernel void density_phase_table(AtmosphereParameters a, __global real* factors) {
  const int id = get_global_id(0);
  if (id >= a.r_size * a.mu_size) return;
  real h, mu, d, f_r, f_m;
  int ground;
  scattering_ray_of_texel(&a, id % a.mu_size, id / a.mu_size, &h, &mu, &d, &ground);
  density_phase_factors(&a, mu, &f_r, &f_m);
  factors[2 * id] = f_r;
  factors[2 * id + 1] = f_m;
}

/* One work item per texel row along ν: (z, y, mu_s index), all NU slices. */
__kernel void scattering_density_texture(AtmosphereParameters a, __global const real* incidence,
                                         __global const real* phase_factors, __global const real* delta_E, int order,
                                         __global real* J) {
  const int id = get_global_id(0);
  if (id >= a.r_size * a.mu_size * a.mu_s_size) return;
  const int xs = id % a.mu_s_size, y = (id / a.mu_s_size) % a.mu_size, z = id / (a.mu_s_size * a.mu_size);
  real h, mu, mu_s, nu[NU_MAX], j[NU_MAX * NCH];
  int ground;
  for (int k = 0; k < a.nu_size; ++k)
    scattering_params_from_texel(&a, k * a.mu_s_size + xs, y, z, &h, &mu, &mu_s, &nu[k], &ground);
  __global const real* block = incidence + (z * a.mu_s_size + xs) * a.density_theta * incidence_stride(&a);
  const int row_id = z * a.mu_size + y;
  scattering_density(&a, block, delta_E, h, mu, mu_s, nu, a.nu_size, order, phase_factors[2 * row_id],
                     phase_factors[2 * row_id + 1], j);
  const int row = row_id * a.nu_size * a.mu_s_size;
  for (int k = 0; k < a.nu_size; ++k)
    for (int c = 0; c < NCH; ++c) J[(row + k * a.mu_s_size + xs) * NCH + c] = j[k * NCH + c];
}

__kernel void indirect_irradiance_texture(AtmosphereParameters a, __global const real* delta_R,
                                          __global const real* delta_M, __global const real* delta_S, int order,
                                          __global real* delta_E) {
  const int id = get_global_id(0);
  if (id >= a.irradiance_w * a.irradiance_h) return;
  real h, mu_s, e[NCH];
  irradiance_texel_params(&a, id, &h, &mu_s);
  indirect_irradiance(&a, delta_R, delta_M, delta_S, h, mu_s, order, e);
  for (int c = 0; c < NCH; ++c) delta_E[id * NCH + c] = e[c];
}

/* One work item per texel: the form for devices whose local memory cannot hold a row's columns
 * (multiple_scattering_texture below). */
__kernel void multiple_scattering_texels(AtmosphereParameters a, __global const real* samples,
                                         __global const real* J, __global real* delta_S) {
  const int id = get_global_id(0);
  if (id >= a.r_size * a.mu_size * a.nu_size * a.mu_s_size) return;
  real h, mu, mu_s, nu, out[NCH], s[RAY_STRIDE];
  int x, y, z, ground;
  texel_params(&a, id, &x, &y, &z, &h, &mu, &mu_s, &nu, &ground);
  __global const real* row = samples + (z * a.mu_size + y) * (SCATTERING_STEPS + 1) * RAY_STRIDE;
  for (int c = 0; c < NCH; ++c) out[c] = R(0.0);
  for (int i = 0; i <= SCATTERING_STEPS; ++i) {
    for (int k = 0; k < RAY_STRIDE; ++k) s[k] = row[i * RAY_STRIDE + k];
    multiple_scattering_add(&a, J, s, mu_s, nu, out);
  }
  for (int c = 0; c < NCH; ++c) delta_S[id * NCH + c] = out[c];
}

/* One work group per texel row (z, y) along x = ν·MU_S + μ_s (local size L; item lx takes the
 * LANES texels x = lx·LANES + k, then the same L·LANES further on, ...). Every
 * texel of the row samples its ray at the same (u_mu, u_r), so at each sample the group blends
 * J's rows into one value per column (texture_3d_column), in local memory `columns`
 * (MU_S·NU·NCH reals), and each texel filters along x from there: multiple_scattering_ray's
 * operations, with the row blends shared instead of repeated per texel. Lanes past the row's
 * end compute a texel at μ_s = ν = 0 that is not written. */
__kernel void multiple_scattering_texture(AtmosphereParameters a, __global const real* samples,
                                          __global const real* J, __global real* delta_S, __local real* columns) {
  const int wd = a.nu_size * a.mu_s_size, lx = get_local_id(0), L = get_local_size(0);
  const int row_id = get_group_id(0), y = row_id % a.mu_size, z = row_id / a.mu_size;
  __global const real* row = samples + row_id * (SCATTERING_STEPS + 1) * RAY_STRIDE;
  for (int base = 0; base < wd; base += L * LANES) {
    real mu_s[LANES], nu[LANES], out[LANES * NCH], s[RAY_STRIDE], v[NCH];
    for (int k = 0; k < LANES; ++k) {
      const int x = base + lx * LANES + k;
      real h, mu;
      int ground;
      mu_s[k] = nu[k] = R(0.0);
      if (x < wd) scattering_params_from_texel(&a, x, y, z, &h, &mu, &mu_s[k], &nu[k], &ground);
    }
    for (int k = 0; k < LANES * NCH; ++k) out[k] = R(0.0);
    for (int i = 0; i <= SCATTERING_STEPS; ++i) {
      for (int k = 0; k < RAY_STRIDE; ++k) s[k] = row[i * RAY_STRIDE + k];
      const TexelRows rows = texture_3d_rows(a.mu_size, a.r_size, s[RAY_U_MU], s[RAY_U_R]);
      for (int col = lx; col < wd; col += L) {
        texture_3d_column(J, wd, a.mu_size, &rows, col, v);
        for (int c = 0; c < NCH; ++c) columns[col * NCH + c] = v[c];
      }
      barrier(CLK_LOCAL_MEM_FENCE);
      multiple_scattering_add_lanes(&a, columns, s, mu_s, nu, out);
      barrier(CLK_LOCAL_MEM_FENCE);
    }
    for (int k = 0; k < LANES; ++k) {
      const int x = base + lx * LANES + k;
      if (x < wd)
        for (int c = 0; c < NCH; ++c) delta_S[(row_id * wd + x) * NCH + c] = out[k * NCH + c];
    }
  }
}

/* The sky-view table (atmosphere.cl, sky_view_texel), grid = {h_min, h_max, e_min, e_max}: first
 * the samples of each (altitude, view) ray, [n_h · n_view][SCATTERING_STEPS + 1][SKY_RAY_STRIDE], one
 * work item per entry; then one work item per texel, 2·NCH values each (radiance without single
 * Mie, then single Mie), from its ray's samples. */
__kernel void sky_view_ray_samples(AtmosphereParameters a, __global const real* T, __global const real* grid,
                                   int n_h, int n_view, __global real* samples) {
  const int id = get_global_id(0);
  const int n = SCATTERING_STEPS + 1;
  if (id >= n_h * n_view * n) return;
  const int i = id % n, row = id / n;
  real g[4], h, mu, fixed[NCH], s[SKY_RAY_STRIDE];
  int ground;
  for (int k = 0; k < 4; ++k) g[k] = grid[k];
  sky_view_ray(&a, g, n_h, n_view, row / n_view, row % n_view, &h, &mu, &ground);
  transmittance_fixed_end(&a, T, h, mu, ground, fixed);
  sky_view_ray_sample(&a, T, h, mu, ground, distance_to_nearest_boundary(&a, h, mu, ground), fixed, i, s);
  for (int k = 0; k < SKY_RAY_STRIDE; ++k) samples[(long)id * SKY_RAY_STRIDE + k] = s[k];
}
__kernel void sky_view_texture(AtmosphereParameters a, __global const real* T, __global const real* J_sum,
                               int orders_above_one, int mu_s_geometric, __global const real* grid,
                               __global const real* samples, int n_h,
                               int n_sun, int n_view, int n_az, __global real* out) {
  const int id = get_global_id(0);
  if (id >= n_h * n_sun * n_view * n_az) return;
  const int i_az = id % n_az, i_v = (id / n_az) % n_view, k = id / (n_az * n_view), i_h = k % n_h, i_s = k / n_h;
  real g[4], h, mu, mu_s, nu, v[2 * NCH];
  int ground;
  for (int j = 0; j < 4; ++j) g[j] = grid[j];
  sky_view_ray(&a, g, n_h, n_view, i_h, i_v, &h, &mu, &ground);
  sky_view_sun(g, n_sun, n_az, i_s, i_az, mu, &mu_s, &nu);
  __global const real* row = samples + (long)(i_h * n_view + i_v) * (SCATTERING_STEPS + 1) * SKY_RAY_STRIDE;
  sky_view_texel_from_samples(&a, T, J_sum, orders_above_one, mu_s_geometric, row, mu_s, nu, v);
  for (int c = 0; c < 2 * NCH; ++c) out[(long)id * 2 * NCH + c] = v[c];
}

/* ---- a self-check's fetches: texels gathered, textures scanned --------------------------- */

/* Texels ids[k] (k < n) of tex, NCH values each, into out[k·NCH + c]: what a self-check
 * recomputes and the inputs its recomputation reads, and nothing else. */
__kernel void gather_texels(AtmosphereParameters a, __global const real* tex, __global const int* ids, int n,
                            __global real* out) {
  const int k = get_global_id(0);
  if (k >= n) return;
  const long at = (long)ids[k] * NCH;
  for (int c = 0; c < NCH; ++c) out[k * NCH + c] = tex[at + c];
}

/* Work item g of G scans texels g, g + G, g + 2G, … of tex: per channel the largest |value| of
 * its finite values, max_abs[g·NCH + c], and the count of values that are NaN or ±inf, bad[g].
 * The host takes the maximum and the sum over g (both independent of the order). */
__kernel void scan_texture(AtmosphereParameters a, __global const real* tex, int texels, __global real* max_abs,
                           __global int* bad) {
  const int g = get_global_id(0), G = get_global_size(0);
  real m[NCH];
  int count = 0;
  for (int c = 0; c < NCH; ++c) m[c] = R(0.0);
  for (int t = g; t < texels; t += G)
    for (int c = 0; c < NCH; ++c) {
      const real v = tex[(long)t * NCH + c];
      if (isfinite(v)) m[c] = fmax(m[c], fabs(v));
      else ++count;
    }
  for (int c = 0; c < NCH; ++c) max_abs[g * NCH + c] = m[c];
  bad[g] = count;
}

/* ---- the sums (Algorithm 4.1's accumulation; pass.hpp's Sums) ------------------------------
 * A pass's sums are [texels][NCH] like its textures; the bake's R,G,B sums and each order's
 * R,G,B additions are [texels][3]. Reductions run in G work items, item g over texels g, g + G,
 * …; the host combines the G partial results in the order of g (the same bytes every run). */

/* The multiple scattering of an order into the pass's scattering: add = ΔS / P_R(ν), the
 * reference's scattering storing Rayleigh without its phase function, with 1/P_R(ν) of ν as the
 * texel decodes it given per texel (the host decodes it in double: near μ = ±1 the float decode
 * moves ν by up to ~1e-4), scattering += add. */
__kernel void add_multiple_scattering(AtmosphereParameters a, __global const real* delta_S,
                                      __global const real* inverse_phase, __global real* scattering,
                                      __global real* add) {
  const int id = get_global_id(0);
  if (id >= a.r_size * a.mu_size * a.mu_s_size * a.nu_size) return;
  for (int c = 0; c < NCH; ++c) {
    const real v = delta_S[id * NCH + c] * inverse_phase[id];
    add[id * NCH + c] = v;
    scattering[id * NCH + c] += v;
  }
}

/* sum += x over n values. */
__kernel void add_values(AtmosphereParameters a, __global const real* x, int n, __global real* sum) {
  const int id = get_global_id(0);
  if (id < n) sum[id] += x[id];
}

/* J ← J_{≥n} = geometric_tail(J, J_prev) for the n values of the last order's density J, where
 * J_prev holds the order before (`orders_tail: geometric`). */
__kernel void density_tail(AtmosphereParameters a, __global const real* J_prev, int n, __global real* J) {
  const int id = get_global_id(0);
  if (id < n) J[id] = geometric_tail(J[id], J_prev[id]);
}

/* rgb[t][k] += Σ_c w[k·NCH + c] x[t][c] for the n texels of x ([texels][NCH]); `= ` instead of
 * `+=` where first is 1 (the first addition into a sum, which then needs no zeroing). */
__kernel void add_rgb(AtmosphereParameters a, __global const real* x, __constant real* w, int n, int first,
                      __global real* rgb) {
  const int t = get_global_id(0);
  if (t >= n) return;
  for (int k = 0; k < 3; ++k) {
    real v = R(0.0);
    for (int c = 0; c < NCH; ++c) v += w[k * NCH + c] * x[t * NCH + c];
    rgb[t * 3 + k] = first ? v : rgb[t * 3 + k] + v;
  }
}

/* Partial channel statistics of x ([n][channels], channels ≤ NCH): max(0, largest value) and
 * the sum, per channel, of item g's texels; mx[g·channels + c], sum[g·channels + c]. */
__kernel void channel_stats_partial(AtmosphereParameters a, __global const real* x, int n, int channels,
                                    __global real* mx, __global real* sum) {
  const int g = get_global_id(0), G = get_global_size(0);
  real m[NCH], s[NCH];
  for (int c = 0; c < channels; ++c) m[c] = s[c] = R(0.0);
  for (int t = g; t < n; t += G)
    for (int c = 0; c < channels; ++c) {
      const real v = x[(long)t * channels + c];
      m[c] = fmax(m[c], v);
      s[c] += v;
    }
  for (int c = 0; c < channels; ++c) {
    mx[g * channels + c] = m[c];
    sum[g * channels + c] = s[c];
  }
}

/* Partial relative change: the largest |add| / sum of item g's texels and channels where the sum
 * exceeds floor[c] (kAutoFloor × the channel's maximum) and 0. */
__kernel void relative_change_partial(AtmosphereParameters a, __global const real* add, __global const real* sum,
                                      __constant real* floor, int n, __global real* out) {
  const int g = get_global_id(0), G = get_global_size(0);
  real r = R(0.0);
  for (int t = g; t < n; t += G)
    for (int c = 0; c < NCH; ++c) {
      const real s = sum[(long)t * NCH + c];
      if (s > floor[c] && s > R(0.0)) r = fmax(r, fabs(add[(long)t * NCH + c]) / s);
    }
  out[g] = r;
}
