/* kernels.cl — OpenCL entry points of the atmosphere job: one work item per texel. The maths
 * is in atmosphere.cl. Textures are row-major with NCH channels innermost:
 *   transmittance [h][w][NCH], irradiance [h][w][NCH], scattering [R][MU][NU·MU_S][NCH].
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
  reals[5] = a.reserved;
  ints[0] = a.transmittance_w;
  ints[1] = a.nu_size;
  ints[2] = (int)sizeof(AtmosphereParameters);
}

__kernel void transmittance_texture(AtmosphereParameters a, __global real* T) {
  const int id = get_global_id(0);
  if (id >= a.transmittance_w * a.transmittance_h) return;
  const int i = id % a.transmittance_w, j = id / a.transmittance_w;
  real r, mu, t[NCH];
  r_mu_from_transmittance_uv(&a, ((real)i + R(0.5)) / (real)a.transmittance_w,
                             ((real)j + R(0.5)) / (real)a.transmittance_h, &r, &mu);
  transmittance_to_top_integral(&a, r, mu, 1, t);
  for (int c = 0; c < NCH; ++c) T[id * NCH + c] = t[c];
}

__kernel void direct_irradiance_texture(AtmosphereParameters a, __global const real* T, __global real* delta_E) {
  const int id = get_global_id(0);
  if (id >= a.irradiance_w * a.irradiance_h) return;
  const int i = id % a.irradiance_w, j = id / a.irradiance_w;
  real r, mu_s, e[NCH];
  r_mu_s_from_irradiance_uv(&a, ((real)i + R(0.5)) / (real)a.irradiance_w, ((real)j + R(0.5)) / (real)a.irradiance_h,
                            &r, &mu_s);
  direct_irradiance(&a, T, r, mu_s, e);
  for (int c = 0; c < NCH; ++c) delta_E[id * NCH + c] = e[c];
}

/* id → (x, y, z) of the scattering texture and its parameters. */
void texel_params(const AtmosphereParameters* a, int id, real* r, real* mu, real* mu_s, real* nu, int* ground) {
  const int wd = a->nu_size * a->mu_s_size;
  const int x = id % wd, y = (id / wd) % a->mu_size, z = id / (wd * a->mu_size);
  scattering_params_from_texel(a, x, y, z, r, mu, mu_s, nu, ground);
}

__kernel void single_scattering_texture(AtmosphereParameters a, __global const real* T, __global real* delta_R,
                                        __global real* delta_M) {
  const int id = get_global_id(0);
  if (id >= a.r_size * a.mu_size * a.nu_size * a.mu_s_size) return;
  real r, mu, mu_s, nu, ray[NCH], mie[NCH];
  int ground;
  texel_params(&a, id, &r, &mu, &mu_s, &nu, &ground);
  single_scattering(&a, T, r, mu, mu_s, nu, ground, ray, mie);
  for (int c = 0; c < NCH; ++c) {
    delta_R[id * NCH + c] = ray[c];
    delta_M[id * NCH + c] = mie[c];
  }
}

__kernel void scattering_density_texture(AtmosphereParameters a, __global const real* T,
                                         __global const real* delta_R, __global const real* delta_M,
                                         __global const real* delta_S, __global const real* delta_E, int order,
                                         __global real* J) {
  const int id = get_global_id(0);
  if (id >= a.r_size * a.mu_size * a.nu_size * a.mu_s_size) return;
  real r, mu, mu_s, nu, j[NCH];
  int ground;
  texel_params(&a, id, &r, &mu, &mu_s, &nu, &ground);
  scattering_density(&a, T, delta_R, delta_M, delta_S, delta_E, r, mu, mu_s, nu, order, j);
  for (int c = 0; c < NCH; ++c) J[id * NCH + c] = j[c];
}

__kernel void indirect_irradiance_texture(AtmosphereParameters a, __global const real* delta_R,
                                          __global const real* delta_M, __global const real* delta_S, int order,
                                          __global real* delta_E) {
  const int id = get_global_id(0);
  if (id >= a.irradiance_w * a.irradiance_h) return;
  const int i = id % a.irradiance_w, j = id / a.irradiance_w;
  real r, mu_s, e[NCH];
  r_mu_s_from_irradiance_uv(&a, ((real)i + R(0.5)) / (real)a.irradiance_w, ((real)j + R(0.5)) / (real)a.irradiance_h,
                            &r, &mu_s);
  indirect_irradiance(&a, delta_R, delta_M, delta_S, r, mu_s, order, e);
  for (int c = 0; c < NCH; ++c) delta_E[id * NCH + c] = e[c];
}

__kernel void multiple_scattering_texture(AtmosphereParameters a, __global const real* T, __global const real* J,
                                          __global real* delta_S) {
  const int id = get_global_id(0);
  if (id >= a.r_size * a.mu_size * a.nu_size * a.mu_s_size) return;
  real r, mu, mu_s, nu, s[NCH];
  int ground;
  texel_params(&a, id, &r, &mu, &mu_s, &nu, &ground);
  multiple_scattering(&a, T, J, r, mu, mu_s, nu, ground, s);
  for (int c = 0; c < NCH; ++c) delta_S[id * NCH + c] = s[c];
}
