/* atmosphere.cl — precomputed atmospheric scattering after E. Bruneton, "Precomputed
 * Atmospheric Scattering: a New Implementation" (2017), itself an update of Bruneton &
 * Neyret, "Precomputed Atmospheric Scattering", EGSR 2008. Shared by the OpenCL kernels
 * (kernels/atmosphere/kernels.cl, real = float) and the C++ double reference
 * (src/jobs/atmosphere/reference.hpp, real = double).
 *
 * Model. A spherical planet of radius rb (bottom) under an atmosphere ending at rt (top).
 * A point is described by r (distance to the planet centre), a view direction by
 * mu = cos(view zenith angle), the sun by mu_s = cos(sun zenith angle), and
 * nu = cos(view-sun angle). Three constituents, each with a density profile in [0, 1]
 * (two layers: a·exp(b·h) + c·h + d, clamped to [0, 1], layer 0 below its width):
 *   Rayleigh: scattering β_R(λ) (= extinction), phase P_R(ν) = 3/(16π) (1 + ν²)
 *   Mie:      scattering β_M,s(λ), extinction β_M,e(λ), phase (Cornette–Shanks)
 *             P_M(ν) = 3/(8π) (1 − g²)/(2 + g²) (1 + ν²)/(1 + g² − 2gν)^{3/2}
 *   absorption (ozone): extinction β_A(λ), no scattering.
 * Radiance of order n at x towards −ω:  L_n = ∫_0^d T(x, x_t) J_n(x_t) dt  (paper Eq. 7),
 * with the scattering density J_n(x, ω) = Σ_i β_i,s ρ_i(x) ∫_4π P_i(ω·ω_i) L_{n−1}(x, ω_i) dω_i
 * plus the light reflected by the Lambertian ground (albedo a) lit by the irradiance of
 * order n − 2. Order 1 is single scattering of the sun, T(x, x_sun) E_sun.
 *
 * Quadratures (part of the model: the reference textures depend on them):
 *   transmittance    500-interval trapezoid over the distance to the top boundary;
 *   single/multiple  50-interval trapezoid over the distance to the nearest boundary;
 *   density J_n      16 × 32 midpoint rule over the sphere (θ, φ);
 *   indirect E       16 × 64 midpoint rule over the upper hemisphere.
 * Transmittance inside every integral is read from the transmittance texture (bilinear),
 * never integrated again; the same for the scattering textures (trilinear + a lerp in ν).
 *
 * Units: lengths in km, coefficients in km⁻¹, irradiance in the unit of solar_irradiance
 * (W m⁻² nm⁻¹), radiance in that unit per sr, the density J per km.
 *
 * Texture parameterisations (the reference's, texel centres at (i + 0.5)/n):
 *   coord(x, n) = 0.5/n + x (1 − 1/n),  unit(u, n) = (u − 0.5/n)/(1 − 1/n)
 *   transmittance [H][W]: u = coord((d − d_min)/(d_max − d_min), W), v = coord(ρ/H_, H)
 *   irradiance [H][W]:    u = coord(0.5 μ_s + 0.5, W), v = coord((r − rb)/(rt − rb), H)
 *   scattering [R][MU][NU·MU_S]: see scattering_uvwz(); ν is corner-sampled (divisor NU − 1).
 * A texture holds NCH channels per texel (wavelengths), innermost.
 *
 * Compile-time settings: NCH (channels), NU_MAX (largest NU the caller uses).
 * Deviations from the literal formulas, all algebraically exact: discriminants are written
 * as (r μ)² − (r − rb)(r + rb) and the distance r − rb as ρ²/(r + rb) where float32 would
 * otherwise cancel; a one-texel axis (MU/2 = 1) maps to its midpoint instead of 0/0; a
 * transmittance ratio with a zero denominator gives 0; ν entering a texture lookup is
 * clamped to [−1, 1] (it can leave it by a rounding error only).
 */
#include "common/real.h"

#ifndef NCH
#  error "NCH (channels per texel) must be defined before including atmosphere.cl"
#endif
#ifndef NU_MAX
#  define NU_MAX 64
#endif

#define ATM_PI R(3.14159265358979323846)
#define TRANSMITTANCE_STEPS 500
#define SCATTERING_STEPS 50
#define DENSITY_SPHERE_STEPS 16
#define IRRADIANCE_HEMISPHERE_STEPS 32

/* Two-layer density profile; layer 0 applies at altitudes below width[0] (km). */
typedef struct {
  real width[2];
  real exp_term[2];
  real exp_scale[2];     /* km⁻¹ */
  real linear_term[2];   /* km⁻¹ */
  real constant_term[2];
} DensityProfile;

/* Everything a bake needs. Crosses the host/device boundary by value: reals first, then an
 * even number of ints, so float and double builds have no padding (checked at run time by
 * the atmosphere_layout kernel). */
typedef struct {
  real solar_irradiance[NCH];       /* at the top of the atmosphere */
  real rayleigh_scattering[NCH];    /* km⁻¹ at density 1 */
  real mie_scattering[NCH];         /* km⁻¹ */
  real mie_extinction[NCH];         /* km⁻¹ */
  real absorption_extinction[NCH];  /* km⁻¹ */
  real ground_albedo[NCH];
  DensityProfile rayleigh_density;
  DensityProfile mie_density;
  DensityProfile absorption_density;
  real bottom_radius;               /* km */
  real top_radius;                  /* km */
  real sun_angular_radius;          /* rad */
  real mu_s_min;
  real mie_g;
  real reserved;
  int transmittance_w, transmittance_h;   /* mu, r */
  int irradiance_w, irradiance_h;         /* mu_s, r */
  int r_size, mu_size, mu_s_size, nu_size;
} AtmosphereParameters;

/* ---- small helpers ------------------------------------------------------------------- */
FN real clamp_real(real x, real lo, real hi) { return fmin(fmax(x, lo), hi); }
FN int clamp_int(int x, int lo, int hi) { return x < lo ? lo : (x > hi ? hi : x); }
FN real clamp_cosine(real mu) { return clamp_real(mu, R(-1.0), R(1.0)); }
FN real clamp_distance(real d) { return fmax(d, R(0.0)); }
FN real clamp_radius(const AtmosphereParameters* a, real r) {
  return clamp_real(r, a->bottom_radius, a->top_radius);
}
FN real safe_sqrt(real x) { return sqrt(fmax(x, R(0.0))); }
FN real smooth_step(real e0, real e1, real x) {
  const real t = clamp_real((x - e0) / (e1 - e0), R(0.0), R(1.0));
  return t * t * (R(3.0) - R(2.0) * t);
}
FN real dot3(const real* a, const real* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
/* sqrt(rt² − rb²): the distance to the top boundary along the horizon at the ground. */
FN real horizon_top(const AtmosphereParameters* a) {
  return sqrt((a->top_radius - a->bottom_radius) * (a->top_radius + a->bottom_radius));
}
/* ρ = sqrt(r² − rb²): the distance to the horizon from radius r. */
FN real horizon_distance(const AtmosphereParameters* a, real r) {
  return safe_sqrt((r - a->bottom_radius) * (r + a->bottom_radius));
}

/* ---- distances ----------------------------------------------------------------------- */
/* Distance from radius r along mu to the top boundary (r ≤ rt). */
FN real distance_to_top(const AtmosphereParameters* a, real r, real mu) {
  const real disc = (r * mu) * (r * mu) + (a->top_radius - r) * (a->top_radius + r);
  return clamp_distance(-r * mu + safe_sqrt(disc));
}
/* Distance from radius r along mu to the ground (r ≥ rb; meaningful when the ray hits it). */
FN real distance_to_bottom(const AtmosphereParameters* a, real r, real mu) {
  const real disc = (r * mu) * (r * mu) - (r - a->bottom_radius) * (r + a->bottom_radius);
  return clamp_distance(-r * mu - safe_sqrt(disc));
}
FN int ray_hits_ground(const AtmosphereParameters* a, real r, real mu) {
  return mu < R(0.0) && (r * mu) * (r * mu) - (r - a->bottom_radius) * (r + a->bottom_radius) >= R(0.0);
}
FN real distance_to_nearest_boundary(const AtmosphereParameters* a, real r, real mu, int hits_ground) {
  return hits_ground ? distance_to_bottom(a, r, mu) : distance_to_top(a, r, mu);
}
/* Radius after travelling d along (r, mu): |x + d ω|. */
FN real radius_along(real r, real mu, real d) { return sqrt(d * d + R(2.0) * r * mu * d + r * r); }
/* Altitude after travelling d along (r, mu), (r_d² − rb²)/(r_d + rb) with r_d² − rb² summed from
 * small terms: r_d − rb would round to ±0.5 m in float32 and could put a ground-level sample
 * below the ground, where the density profiles switch layers. */
FN real altitude_along(const AtmosphereParameters* a, real r, real mu, real d) {
  const real rho2 = d * d + R(2.0) * r * mu * d + (r - a->bottom_radius) * (r + a->bottom_radius);
  return rho2 / (sqrt(fmax(rho2, R(0.0)) + a->bottom_radius * a->bottom_radius) + a->bottom_radius);
}

/* ---- density profiles ---------------------------------------------------------------- */
FN real layer_density(const DensityProfile* p, int layer, real h) {
  const real y = p->exp_term[layer] * exp(p->exp_scale[layer] * h) + p->linear_term[layer] * h +
                 p->constant_term[layer];
  return clamp_real(y, R(0.0), R(1.0));
}
FN real profile_density(const DensityProfile* p, real h) {
  return layer_density(p, h < p->width[0] ? 0 : 1, h);
}

/* ---- transmittance (paper Eq. 5) ----------------------------------------------------- */
/* ∫ ρ_i dt from (r, mu) to the top boundary for the three profiles (trapezoid, 500 steps).
 * above_ground: the ray does not reach below the ground (every texel of the texture), so the
 * altitude is computed without cancellation and clamped at 0 — a tangent ray touches the
 * ground, where rounding would otherwise put a sample below it and switch density layers.
 * Otherwise (rays through the planet, which no texture uses) the altitude is r_d − rb as is. */
FN void optical_lengths_to_top(const AtmosphereParameters* a, real r, real mu, int above_ground, real* l_rayleigh,
                               real* l_mie, real* l_absorption) {
  const real dx = distance_to_top(a, r, mu) / (real)TRANSMITTANCE_STEPS;
  real sr = R(0.0), sm = R(0.0), sa = R(0.0);
  for (int i = 0; i <= TRANSMITTANCE_STEPS; ++i) {
    const real d_i = (real)i * dx;
    const real h = above_ground ? fmax(altitude_along(a, r, mu, d_i), R(0.0))
                                : radius_along(r, mu, d_i) - a->bottom_radius;
    const real w = (i == 0 || i == TRANSMITTANCE_STEPS) ? R(0.5) : R(1.0);
    sr += profile_density(&a->rayleigh_density, h) * w;
    sm += profile_density(&a->mie_density, h) * w;
    sa += profile_density(&a->absorption_density, h) * w;
  }
  *l_rayleigh = sr * dx;
  *l_mie = sm * dx;
  *l_absorption = sa * dx;
}
/* T(r, mu → top) by direct integration (above_ground: see optical_lengths_to_top). */
FN void transmittance_to_top_integral(const AtmosphereParameters* a, real r, real mu, int above_ground, real* t) {
  real lr, lm, la;
  optical_lengths_to_top(a, r, mu, above_ground, &lr, &lm, &la);
  for (int c = 0; c < NCH; ++c)
    t[c] = exp(-(a->rayleigh_scattering[c] * lr + a->mie_extinction[c] * lm + a->absorption_extinction[c] * la));
}

/* ---- texture coordinates ------------------------------------------------------------- */
FN real coord_from_unit(real x, int n) { return R(0.5) / (real)n + x * (R(1.0) - R(1.0) / (real)n); }
FN real unit_from_coord(real u, int n) {
  return n > 1 ? (u - R(0.5) / (real)n) / (R(1.0) - R(1.0) / (real)n) : R(0.5);
}

FN void transmittance_uv(const AtmosphereParameters* a, real r, real mu, real* u, real* v) {
  const real H = horizon_top(a);
  const real rho = horizon_distance(a, r);
  const real d = distance_to_top(a, r, mu);
  const real d_min = a->top_radius - r, d_max = rho + H;
  *u = coord_from_unit((d - d_min) / (d_max - d_min), a->transmittance_w);
  *v = coord_from_unit(rho / H, a->transmittance_h);
}
FN void r_mu_from_transmittance_uv(const AtmosphereParameters* a, real u, real v, real* r, real* mu) {
  const real x_mu = unit_from_coord(u, a->transmittance_w);
  const real x_r = unit_from_coord(v, a->transmittance_h);
  const real H = horizon_top(a);
  const real rho = H * x_r;
  *r = sqrt(rho * rho + a->bottom_radius * a->bottom_radius);
  /* rt − r = (H² − ρ²)/(rt + r), without cancellation */
  const real d_min = (H - rho) * (H + rho) / (a->top_radius + *r), d_max = rho + H;
  const real d = d_min + x_mu * (d_max - d_min);
  *mu = d == R(0.0) ? R(1.0) : clamp_cosine(((H - rho) * (H + rho) - d * d) / (R(2.0) * *r * d));
}

FN void irradiance_uv(const AtmosphereParameters* a, real r, real mu_s, real* u, real* v) {
  *u = coord_from_unit(mu_s * R(0.5) + R(0.5), a->irradiance_w);
  *v = coord_from_unit((r - a->bottom_radius) / (a->top_radius - a->bottom_radius), a->irradiance_h);
}
FN void r_mu_s_from_irradiance_uv(const AtmosphereParameters* a, real u, real v, real* r, real* mu_s) {
  const real x_mu_s = unit_from_coord(u, a->irradiance_w);
  const real x_r = unit_from_coord(v, a->irradiance_h);
  *r = a->bottom_radius + x_r * (a->top_radius - a->bottom_radius);
  *mu_s = clamp_cosine(R(2.0) * x_mu_s - R(1.0));
}

/* (r, mu, mu_s, nu) → (u_nu, u_mu_s, u_mu, u_r). The ground flag picks the half of mu:
 * rays that hit the ground map to u_mu < 0.5 (horizon at 0.5, straight down at 0), the
 * others to u_mu > 0.5 (zenith just above 0.5, horizon at 1). */
FN void scattering_uvwz(const AtmosphereParameters* a, real r, real mu, real mu_s, real nu, int hits_ground,
                        real* uvwz) {
  const real H = horizon_top(a);
  const real rho = horizon_distance(a, r);
  const int half_mu = a->mu_size / 2;
  const real u_r = coord_from_unit(rho / H, a->r_size);
  const real r_mu = r * mu;
  const real disc = r_mu * r_mu - (r - a->bottom_radius) * (r + a->bottom_radius);
  real u_mu;
  if (hits_ground) {
    const real d = -r_mu - safe_sqrt(disc);
    const real d_min = rho * rho / (r + a->bottom_radius), d_max = rho; /* d_min = r − rb */
    u_mu = R(0.5) - R(0.5) * coord_from_unit(d_max == d_min ? R(0.0) : (d - d_min) / (d_max - d_min), half_mu);
  } else {
    const real d = -r_mu + safe_sqrt(disc + H * H);
    const real d_min = a->top_radius - r, d_max = rho + H;
    u_mu = R(0.5) + R(0.5) * coord_from_unit((d - d_min) / (d_max - d_min), half_mu);
  }
  const real d_min = a->top_radius - a->bottom_radius, d_max = H;
  const real d = distance_to_top(a, a->bottom_radius, mu_s);
  const real a_s = (d - d_min) / (d_max - d_min);
  const real D = distance_to_top(a, a->bottom_radius, a->mu_s_min);
  const real A = (D - d_min) / (d_max - d_min);
  /* 0 at mu_s_min, 1 at mu_s = 1, steep around the horizon */
  const real u_mu_s = coord_from_unit(fmax(R(1.0) - a_s / A, R(0.0)) / (R(1.0) + a_s), a->mu_s_size);
  uvwz[0] = (nu + R(1.0)) * R(0.5);
  uvwz[1] = u_mu_s;
  uvwz[2] = u_mu;
  uvwz[3] = u_r;
}

/* Inverse of scattering_uvwz (nu not yet clamped to the range that mu, mu_s allow). */
FN void scattering_params_from_uvwz(const AtmosphereParameters* a, const real* uvwz, real* r, real* mu, real* mu_s,
                                    real* nu, int* hits_ground) {
  const real H = horizon_top(a);
  const int half_mu = a->mu_size / 2;
  const real rho = H * unit_from_coord(uvwz[3], a->r_size);
  *r = sqrt(rho * rho + a->bottom_radius * a->bottom_radius);
  if (uvwz[2] < R(0.5)) {
    const real d_min = rho * rho / (*r + a->bottom_radius), d_max = rho; /* d_min = r − rb */
    const real d = d_min + (d_max - d_min) * unit_from_coord(R(1.0) - R(2.0) * uvwz[2], half_mu);
    *mu = d == R(0.0) ? R(-1.0) : clamp_cosine(-(rho * rho + d * d) / (R(2.0) * *r * d));
    *hits_ground = 1;
  } else {
    const real d_min = (H - rho) * (H + rho) / (a->top_radius + *r), d_max = rho + H; /* d_min = rt − r */
    const real d = d_min + (d_max - d_min) * unit_from_coord(R(2.0) * uvwz[2] - R(1.0), half_mu);
    *mu = d == R(0.0) ? R(1.0) : clamp_cosine(((H - rho) * (H + rho) - d * d) / (R(2.0) * *r * d));
    *hits_ground = 0;
  }
  const real x_mu_s = unit_from_coord(uvwz[1], a->mu_s_size);
  const real d_min = a->top_radius - a->bottom_radius, d_max = H;
  const real D = distance_to_top(a, a->bottom_radius, a->mu_s_min);
  const real A = (D - d_min) / (d_max - d_min);
  const real a_s = (A - x_mu_s * A) / (R(1.0) + x_mu_s * A);
  const real d = d_min + fmin(a_s, A) * (d_max - d_min);
  *mu_s = d == R(0.0) ? R(1.0) : clamp_cosine((H * H - d * d) / (R(2.0) * a->bottom_radius * d));
  *nu = clamp_cosine(uvwz[0] * R(2.0) - R(1.0));
}

/* Texel (x, y, z) of the 3D scattering texture (x = nu_slice·MU_S + mu_s_index, y = mu
 * index, z = r index) → its parameters; nu is clamped to [μμ_s − √((1−μ²)(1−μ_s²)), μμ_s + √…]. */
FN void scattering_params_from_texel(const AtmosphereParameters* a, int x, int y, int z, real* r, real* mu,
                                     real* mu_s, real* nu, int* hits_ground) {
  real uvwz[4];
  uvwz[0] = a->nu_size > 1 ? (real)(x / a->mu_s_size) / (real)(a->nu_size - 1) : R(0.5);
  uvwz[1] = ((real)(x % a->mu_s_size) + R(0.5)) / (real)a->mu_s_size;
  uvwz[2] = ((real)y + R(0.5)) / (real)a->mu_size;
  uvwz[3] = ((real)z + R(0.5)) / (real)a->r_size;
  scattering_params_from_uvwz(a, uvwz, r, mu, mu_s, nu, hits_ground);
  const real s = sqrt((R(1.0) - *mu * *mu) * (R(1.0) - *mu_s * *mu_s));
  *nu = clamp_real(*nu, *mu * *mu_s - s, *mu * *mu_s + s);
}

/* ---- texture filtering (GPU semantics: texel centres, clamp to edge) ------------------- */
FN void texture_2d(GLOBAL const real* tex, int w, int h, real u, real v, real* out) {
  const real x = u * (real)w - R(0.5), y = v * (real)h - R(0.5);
  const real x0 = floor(x), y0 = floor(y);
  const real fx = x - x0, fy = y - y0;
  const int i0 = clamp_int((int)x0, 0, w - 1), i1 = clamp_int((int)x0 + 1, 0, w - 1);
  const int j0 = clamp_int((int)y0, 0, h - 1), j1 = clamp_int((int)y0 + 1, 0, h - 1);
  GLOBAL const real* t00 = tex + (j0 * w + i0) * NCH;
  GLOBAL const real* t10 = tex + (j0 * w + i1) * NCH;
  GLOBAL const real* t01 = tex + (j1 * w + i0) * NCH;
  GLOBAL const real* t11 = tex + (j1 * w + i1) * NCH;
  for (int c = 0; c < NCH; ++c)
    out[c] = (R(1.0) - fy) * ((R(1.0) - fx) * t00[c] + fx * t10[c]) + fy * ((R(1.0) - fx) * t01[c] + fx * t11[c]);
}

/* Trilinear lookup at (u, v, w) in a [d][h][wd] texture. */
FN void texture_3d(GLOBAL const real* tex, int wd, int h, int d, real u, real v, real w, real* out) {
  const real x = u * (real)wd - R(0.5), y = v * (real)h - R(0.5), z = w * (real)d - R(0.5);
  const real x0 = floor(x), y0 = floor(y), z0 = floor(z);
  const real fx = x - x0, fy = y - y0, fz = z - z0;
  const int i0 = clamp_int((int)x0, 0, wd - 1), i1 = clamp_int((int)x0 + 1, 0, wd - 1);
  const int j0 = clamp_int((int)y0, 0, h - 1), j1 = clamp_int((int)y0 + 1, 0, h - 1);
  const int k0 = clamp_int((int)z0, 0, d - 1), k1 = clamp_int((int)z0 + 1, 0, d - 1);
  const int plane = wd * h;
  GLOBAL const real* p000 = tex + (k0 * plane + j0 * wd + i0) * NCH;
  GLOBAL const real* p100 = tex + (k0 * plane + j0 * wd + i1) * NCH;
  GLOBAL const real* p010 = tex + (k0 * plane + j1 * wd + i0) * NCH;
  GLOBAL const real* p110 = tex + (k0 * plane + j1 * wd + i1) * NCH;
  GLOBAL const real* p001 = tex + (k1 * plane + j0 * wd + i0) * NCH;
  GLOBAL const real* p101 = tex + (k1 * plane + j0 * wd + i1) * NCH;
  GLOBAL const real* p011 = tex + (k1 * plane + j1 * wd + i0) * NCH;
  GLOBAL const real* p111 = tex + (k1 * plane + j1 * wd + i1) * NCH;
  for (int c = 0; c < NCH; ++c) {
    const real lo = (R(1.0) - fy) * ((R(1.0) - fx) * p000[c] + fx * p100[c]) +
                    fy * ((R(1.0) - fx) * p010[c] + fx * p110[c]);
    const real hi = (R(1.0) - fy) * ((R(1.0) - fx) * p001[c] + fx * p101[c]) +
                    fy * ((R(1.0) - fx) * p011[c] + fx * p111[c]);
    out[c] = (R(1.0) - fz) * lo + fz * hi;
  }
}

/* ---- transmittance lookups ----------------------------------------------------------- */
FN void transmittance_to_top(const AtmosphereParameters* a, GLOBAL const real* T, real r, real mu, real* out) {
  real u, v;
  transmittance_uv(a, r, mu, &u, &v);
  texture_2d(T, a->transmittance_w, a->transmittance_h, u, v, out);
}
/* T to the top from the fixed end of the segments that transmittance_along_from() measures:
 * T(r, −mu) for rays that hit the ground, T(r, mu) otherwise. */
FN void transmittance_fixed_end(const AtmosphereParameters* a, GLOBAL const real* T, real r, real mu, int hits_ground,
                                real* out) {
  transmittance_to_top(a, T, r, hits_ground ? -mu : mu, out);
}
/* T between (r, mu) and the point at distance d along the ray, from two lookups; rays that
 * hit the ground use the reversed (upward) segments so that no lookup crosses the ground.
 * fixed: transmittance_fixed_end(r, mu), which loops over d compute once. */
FN void transmittance_along_from(const AtmosphereParameters* a, GLOBAL const real* T, real r, real mu, real d,
                                 int hits_ground, const real* fixed, real* out) {
  const real r_d = clamp_radius(a, radius_along(r, mu, d));
  const real mu_d = clamp_cosine((r * mu + d) / r_d);
  real moving[NCH];
  transmittance_to_top(a, T, r_d, hits_ground ? -mu_d : mu_d, moving);
  for (int c = 0; c < NCH; ++c) {
    const real num = hits_ground ? moving[c] : fixed[c], den = hits_ground ? fixed[c] : moving[c];
    out[c] = den > R(0.0) ? fmin(num / den, R(1.0)) : R(0.0);
  }
}
FN void transmittance_along(const AtmosphereParameters* a, GLOBAL const real* T, real r, real mu, real d,
                            int hits_ground, real* out) {
  real fixed[NCH];
  transmittance_fixed_end(a, T, r, mu, hits_ground, fixed);
  transmittance_along_from(a, T, r, mu, d, hits_ground, fixed, out);
}
/* T to the sun times the visible fraction of the sun disc above the horizon (smoothstep). */
FN void transmittance_to_sun(const AtmosphereParameters* a, GLOBAL const real* T, real r, real mu_s, real* out) {
  const real sin_h = a->bottom_radius / r;
  const real cos_h = -sqrt(fmax(R(1.0) - sin_h * sin_h, R(0.0)));
  const real alpha = a->sun_angular_radius;
  const real visible = smooth_step(-sin_h * alpha, sin_h * alpha, mu_s - cos_h);
  transmittance_to_top(a, T, r, mu_s, out);
  for (int c = 0; c < NCH; ++c) out[c] *= visible;
}

/* ---- phase functions (sr⁻¹) ---------------------------------------------------------- */
FN real rayleigh_phase(real nu) { return R(3.0) / (R(16.0) * ATM_PI) * (R(1.0) + nu * nu); }
FN real mie_phase(real g, real nu) {
  const real k = R(3.0) / (R(8.0) * ATM_PI) * (R(1.0) - g * g) / (R(2.0) + g * g);
  const real x = R(1.0) + g * g - R(2.0) * g * nu;
  return k * (R(1.0) + nu * nu) / (x * sqrt(x));
}

/* ---- single scattering (paper Eq. 8–9; no phase function) ----------------------------- */
FN void single_scattering(const AtmosphereParameters* a, GLOBAL const real* T, real r, real mu, real mu_s, real nu,
                          int hits_ground, real* rayleigh, real* mie) {
  const real dx = distance_to_nearest_boundary(a, r, mu, hits_ground) / (real)SCATTERING_STEPS;
  real sum_r[NCH], sum_m[NCH], t_view[NCH], t_sun[NCH], t_fixed[NCH];
  for (int c = 0; c < NCH; ++c) sum_r[c] = sum_m[c] = R(0.0);
  transmittance_fixed_end(a, T, r, mu, hits_ground, t_fixed);
  for (int i = 0; i <= SCATTERING_STEPS; ++i) {
    const real d_i = (real)i * dx;
    const real r_d = clamp_radius(a, radius_along(r, mu, d_i));
    const real mu_s_d = clamp_cosine((r * mu_s + d_i * nu) / r_d);
    transmittance_along_from(a, T, r, mu, d_i, hits_ground, t_fixed, t_view);
    transmittance_to_sun(a, T, r_d, mu_s_d, t_sun);
    const real w = (i == 0 || i == SCATTERING_STEPS) ? R(0.5) : R(1.0);
    const real rho_r = profile_density(&a->rayleigh_density, r_d - a->bottom_radius) * w;
    const real rho_m = profile_density(&a->mie_density, r_d - a->bottom_radius) * w;
    for (int c = 0; c < NCH; ++c) {
      const real t = t_view[c] * t_sun[c];
      sum_r[c] += t * rho_r;
      sum_m[c] += t * rho_m;
    }
  }
  for (int c = 0; c < NCH; ++c) {
    rayleigh[c] = sum_r[c] * dx * a->solar_irradiance[c] * a->rayleigh_scattering[c];
    mie[c] = sum_m[c] * dx * a->solar_irradiance[c] * a->mie_scattering[c];
  }
}

/* ---- scattering lookups -------------------------------------------------------------- */
/* Values of the NU slices of a scattering texture at fixed (u_mu_s, u_mu, u_r): slice s is
 * the trilinear lookup at x = (s + u_mu_s)/NU. Since u_mu_s keeps half a texel from both
 * ends, the filter never mixes two slices. */
FN void scattering_slices(const AtmosphereParameters* a, GLOBAL const real* tex, real u_mu_s, real u_mu, real u_r,
                          real* slices) {
  const int wd = a->nu_size * a->mu_s_size;
  for (int s = 0; s < a->nu_size; ++s)
    texture_3d(tex, wd, a->mu_size, a->r_size, ((real)s + u_mu_s) / (real)a->nu_size, u_mu, u_r, slices + s * NCH);
}
/* Linear interpolation between the two slices around nu (corner-sampled, divisor NU − 1). */
FN void lerp_slices(const AtmosphereParameters* a, const real* slices, real nu, real* out) {
  const real x = (clamp_cosine(nu) + R(1.0)) * R(0.5) * (real)(a->nu_size - 1);
  const real x0 = floor(x);
  const real f = x - x0;
  const int s0 = clamp_int((int)x0, 0, a->nu_size - 1), s1 = clamp_int((int)x0 + 1, 0, a->nu_size - 1);
  for (int c = 0; c < NCH; ++c) out[c] = slices[s0 * NCH + c] * (R(1.0) - f) + slices[s1 * NCH + c] * f;
}
/* The reference's GetScattering: two trilinear lookups around nu. */
FN void get_scattering(const AtmosphereParameters* a, GLOBAL const real* tex, real r, real mu, real mu_s, real nu,
                       int hits_ground, real* out) {
  real uvwz[4];
  scattering_uvwz(a, r, mu, mu_s, nu, hits_ground, uvwz);
  const int wd = a->nu_size * a->mu_s_size;
  const real x = clamp_real(uvwz[0], R(0.0), R(1.0)) * (real)(a->nu_size - 1);
  const real x0 = floor(x);
  const real f = x - x0;
  real v0[NCH], v1[NCH];
  texture_3d(tex, wd, a->mu_size, a->r_size, (x0 + uvwz[1]) / (real)a->nu_size, uvwz[2], uvwz[3], v0);
  texture_3d(tex, wd, a->mu_size, a->r_size, (x0 + R(1.0) + uvwz[1]) / (real)a->nu_size, uvwz[2], uvwz[3], v1);
  for (int c = 0; c < NCH; ++c) out[c] = v0[c] * (R(1.0) - f) + v1[c] * f;
}
FN void get_irradiance(const AtmosphereParameters* a, GLOBAL const real* E, real r, real mu_s, real* out) {
  real u, v;
  irradiance_uv(a, r, mu_s, &u, &v);
  texture_2d(E, a->irradiance_w, a->irradiance_h, u, v, out);
}

/* Radiance of order `order` − 1 arriving along a direction with cosine nu to the sun, from
 * precomputed slices: order 2 reads single Rayleigh/Mie (no phase function stored, so the
 * phase functions of nu are applied here), higher orders the previous multiple order. */
FN void incident_from_slices(const AtmosphereParameters* a, const real* slices_r, const real* slices_m, real nu,
                             int order, real* out) {
  lerp_slices(a, slices_r, nu, out);
  if (order == 2) {
    real m[NCH];
    lerp_slices(a, slices_m, nu, m);
    const real pr = rayleigh_phase(nu), pm = mie_phase(a->mie_g, nu);
    for (int c = 0; c < NCH; ++c) out[c] = out[c] * pr + m[c] * pm;
  }
}

/* ---- scattering density J_n (paper Eq. 7's integrand, 16 × 32 midpoint rule) ---------- */
/* delta_rayleigh/delta_mie: single scattering (used when order == 2); delta_multiple:
 * radiance of order n − 1 (order > 2); delta_irradiance: ground irradiance of order n − 2
 * (direct for order 2). Result per km per sr. */
FN void scattering_density(const AtmosphereParameters* a, GLOBAL const real* T, GLOBAL const real* delta_rayleigh,
                           GLOBAL const real* delta_mie, GLOBAL const real* delta_multiple,
                           GLOBAL const real* delta_irradiance, real r, real mu, real mu_s, real nu, int order,
                           real* out) {
  const real omega[3] = {sqrt(fmax(R(1.0) - mu * mu, R(0.0))), R(0.0), mu};
  const real sun_x = omega[0] == R(0.0) ? R(0.0) : (nu - mu * mu_s) / omega[0];
  const real sun_y = sqrt(fmax(R(1.0) - sun_x * sun_x - mu_s * mu_s, R(0.0)));
  const real omega_s[3] = {sun_x, sun_y, mu_s};
  const real d_angle = ATM_PI / (real)DENSITY_SPHERE_STEPS;
  const real rho_r = profile_density(&a->rayleigh_density, r - a->bottom_radius);
  const real rho_m = profile_density(&a->mie_density, r - a->bottom_radius);
  real beta_r[NCH], beta_m[NCH];
  for (int c = 0; c < NCH; ++c) {
    beta_r[c] = a->rayleigh_scattering[c] * rho_r;
    beta_m[c] = a->mie_scattering[c] * rho_m;
    out[c] = R(0.0);
  }
  GLOBAL const real* source = order == 2 ? delta_rayleigh : delta_multiple;
  real slices_r[NU_MAX * NCH], slices_m[NU_MAX * NCH];
  real uvwz[4];
  /* phi_m and 2π − phi_m share cos(phi) (so the phase functions, since omega_y = 0) and the
   * length of the ground normal: the loop visits them in pairs, sin(phi) = ±sin_phi[m]. */
  real cos_phi[DENSITY_SPHERE_STEPS], sin_phi[DENSITY_SPHERE_STEPS];
  for (int m = 0; m < DENSITY_SPHERE_STEPS; ++m) {
    const real phi = ((real)m + R(0.5)) * d_angle;
    cos_phi[m] = cos(phi);
    sin_phi[m] = sin(phi);
  }
  for (int l = 0; l < DENSITY_SPHERE_STEPS; ++l) {
    const real theta = ((real)l + R(0.5)) * d_angle;
    const real cos_theta = cos(theta), sin_theta = sin(theta);
    const int ground = ray_hits_ground(a, r, cos_theta);
    real distance_to_ground = R(0.0);
    real ground_term[NCH]; /* T to the ground × albedo / π */
    for (int c = 0; c < NCH; ++c) ground_term[c] = R(0.0);
    if (ground) {
      distance_to_ground = distance_to_bottom(a, r, cos_theta);
      transmittance_along(a, T, r, cos_theta, distance_to_ground, 1, ground_term);
      for (int c = 0; c < NCH; ++c) ground_term[c] *= a->ground_albedo[c] / ATM_PI;
    }
    /* ground normal n = r·z + distance·omega_i: |n| does not depend on phi */
    const real n_z = r + cos_theta * distance_to_ground;
    const real n_xy = sin_theta * distance_to_ground;
    const real inv_n = R(1.0) / sqrt(n_xy * n_xy + n_z * n_z);
    /* (u_mu_s, u_mu, u_r) are the same for every phi: look the slices up once per theta. */
    scattering_uvwz(a, r, cos_theta, mu_s, R(0.0), ground, uvwz);
    scattering_slices(a, source, uvwz[1], uvwz[2], uvwz[3], slices_r);
    if (order == 2) scattering_slices(a, delta_mie, uvwz[1], uvwz[2], uvwz[3], slices_m);
    const real d_omega = d_angle * d_angle * sin_theta;
    for (int m = 0; m < DENSITY_SPHERE_STEPS; ++m) {
      const real wx = cos_phi[m] * sin_theta, wy = sin_phi[m] * sin_theta;
      const real nu2 = wx * omega[0] + cos_theta * omega[2];
      const real pr = rayleigh_phase(nu2) * d_omega, pm = mie_phase(a->mie_g, nu2) * d_omega;
      real incident[NCH], pair[NCH];
      for (int c = 0; c < NCH; ++c) pair[c] = R(0.0);
      for (int side = 0; side < 2; ++side) {
        const real wy_s = side == 0 ? wy : -wy;
        incident_from_slices(a, slices_r, slices_m, wx * omega_s[0] + wy_s * omega_s[1] + cos_theta * omega_s[2],
                             order, incident);
        if (ground) {
          const real mu_g = (distance_to_ground * (wx * omega_s[0] + wy_s * omega_s[1]) + n_z * omega_s[2]) * inv_n;
          real e[NCH];
          get_irradiance(a, delta_irradiance, a->bottom_radius, mu_g, e);
          for (int c = 0; c < NCH; ++c) incident[c] += ground_term[c] * e[c];
        }
        for (int c = 0; c < NCH; ++c) pair[c] += incident[c];
      }
      for (int c = 0; c < NCH; ++c) out[c] += pair[c] * (beta_r[c] * pr + beta_m[c] * pm);
    }
  }
}

/* ---- multiple scattering of order n (paper Eq. 7, 50-interval trapezoid) --------------- */
FN void multiple_scattering(const AtmosphereParameters* a, GLOBAL const real* T, GLOBAL const real* J, real r,
                            real mu, real mu_s, real nu, int hits_ground, real* out) {
  const real dx = distance_to_nearest_boundary(a, r, mu, hits_ground) / (real)SCATTERING_STEPS;
  real j[NCH], t[NCH], t_fixed[NCH];
  for (int c = 0; c < NCH; ++c) out[c] = R(0.0);
  transmittance_fixed_end(a, T, r, mu, hits_ground, t_fixed);
  for (int i = 0; i <= SCATTERING_STEPS; ++i) {
    const real d_i = (real)i * dx;
    const real r_i = clamp_radius(a, radius_along(r, mu, d_i));
    const real mu_i = clamp_cosine((r * mu + d_i) / r_i);
    const real mu_s_i = clamp_cosine((r * mu_s + d_i * nu) / r_i);
    get_scattering(a, J, r_i, mu_i, mu_s_i, nu, hits_ground, j);
    transmittance_along_from(a, T, r, mu, d_i, hits_ground, t_fixed, t);
    const real w = ((i == 0 || i == SCATTERING_STEPS) ? R(0.5) : R(1.0)) * dx;
    for (int c = 0; c < NCH; ++c) out[c] += j[c] * t[c] * w;
  }
}

/* ---- ground irradiance ---------------------------------------------------------------- */
/* Direct sun on a horizontal surface: E_sun T(r, mu_s) × the mean cosine over the visible
 * part of the sun disc. */
FN void direct_irradiance(const AtmosphereParameters* a, GLOBAL const real* T, real r, real mu_s, real* out) {
  const real alpha = a->sun_angular_radius;
  const real cos_factor = mu_s < -alpha ? R(0.0)
                          : (mu_s > alpha ? mu_s : (mu_s + alpha) * (mu_s + alpha) / (R(4.0) * alpha));
  transmittance_to_top(a, T, r, mu_s, out);
  for (int c = 0; c < NCH; ++c) out[c] *= a->solar_irradiance[c] * cos_factor;
}
/* Sky irradiance from scattering of order `order` (≥ 1) on a horizontal surface at r:
 * ∫_hemisphere L(ω) ω_z dω, 16 × 64 midpoint rule. Every ray is looked up as not hitting
 * the ground, as the reference does. */
FN void indirect_irradiance(const AtmosphereParameters* a, GLOBAL const real* delta_rayleigh,
                            GLOBAL const real* delta_mie, GLOBAL const real* delta_multiple, real r, real mu_s,
                            int order, real* out) {
  const real d_angle = ATM_PI / (real)IRRADIANCE_HEMISPHERE_STEPS;
  const real omega_s[3] = {sqrt(fmax(R(1.0) - mu_s * mu_s, R(0.0))), R(0.0), mu_s};
  GLOBAL const real* source = order == 1 ? delta_rayleigh : delta_multiple;
  real slices_r[NU_MAX * NCH], slices_m[NU_MAX * NCH], uvwz[4], l[NCH];
  for (int c = 0; c < NCH; ++c) out[c] = R(0.0);
  for (int j = 0; j < IRRADIANCE_HEMISPHERE_STEPS / 2; ++j) {
    const real theta = ((real)j + R(0.5)) * d_angle;
    const real cos_theta = cos(theta), sin_theta = sin(theta);
    scattering_uvwz(a, r, cos_theta, mu_s, R(0.0), 0, uvwz);
    scattering_slices(a, source, uvwz[1], uvwz[2], uvwz[3], slices_r);
    if (order == 1) scattering_slices(a, delta_mie, uvwz[1], uvwz[2], uvwz[3], slices_m);
    const real w = d_angle * d_angle * sin_theta * cos_theta;
    for (int i = 0; i < 2 * IRRADIANCE_HEMISPHERE_STEPS; ++i) {
      const real phi = ((real)i + R(0.5)) * d_angle;
      const real omega[3] = {cos(phi) * sin_theta, sin(phi) * sin_theta, cos_theta};
      /* incident_from_slices applies the phase functions when its `order` argument is 2 */
      incident_from_slices(a, slices_r, slices_m, dot3(omega, omega_s), order + 1, l);
      for (int c = 0; c < NCH; ++c) out[c] += l[c] * w;
    }
  }
}

/* ---- rendering from the final textures (the reference's GetSkyRadiance & co.) ----------
 * scattering: single Rayleigh + Σ multiple / P_R (no phase); single_mie: single Mie. */
FN void combined_scattering(const AtmosphereParameters* a, GLOBAL const real* S, GLOBAL const real* M, real r,
                            real mu, real mu_s, real nu, int hits_ground, real* scattering, real* single_mie) {
  get_scattering(a, S, r, mu, mu_s, nu, hits_ground, scattering);
  get_scattering(a, M, r, mu, mu_s, nu, hits_ground, single_mie);
}

/* Sky radiance seen from `camera` (km, planet centre at the origin) along the unit vector
 * `view`, sun along the unit vector `sun`; also the transmittance to the top (0 for rays
 * that hit the ground). Light shafts: `shadow_length` km of the ray nearest the camera
 * are left out. */
FN void sky_radiance(const AtmosphereParameters* a, GLOBAL const real* T, GLOBAL const real* S, GLOBAL const real* M,
                     const real* camera_in, const real* view, real shadow_length, const real* sun, real* radiance,
                     real* transmittance) {
  real camera[3] = {camera_in[0], camera_in[1], camera_in[2]};
  real r = sqrt(dot3(camera, camera));
  real rmu = dot3(camera, view);
  const real d_top = -rmu - sqrt(rmu * rmu - r * r + a->top_radius * a->top_radius);
  if (d_top > R(0.0)) {
    for (int k = 0; k < 3; ++k) camera[k] += view[k] * d_top;
    r = a->top_radius;
    rmu += d_top;
  } else if (r > a->top_radius) {
    for (int c = 0; c < NCH; ++c) {
      transmittance[c] = R(1.0);
      radiance[c] = R(0.0);
    }
    return;
  }
  const real mu = rmu / r, mu_s = dot3(camera, sun) / r, nu = dot3(view, sun);
  const int ground = ray_hits_ground(a, r, mu);
  if (ground) {
    for (int c = 0; c < NCH; ++c) transmittance[c] = R(0.0);
  } else {
    transmittance_to_top(a, T, r, mu, transmittance);
  }
  real s[NCH], m[NCH];
  if (shadow_length == R(0.0)) {
    combined_scattering(a, S, M, r, mu, mu_s, nu, ground, s, m);
  } else {
    const real d = shadow_length;
    const real r_p = clamp_radius(a, radius_along(r, mu, d));
    combined_scattering(a, S, M, r_p, (r * mu + d) / r_p, (r * mu_s + d * nu) / r_p, nu, ground, s, m);
    real t[NCH];
    transmittance_along(a, T, r, mu, shadow_length, ground, t);
    for (int c = 0; c < NCH; ++c) {
      s[c] *= t[c];
      m[c] *= t[c];
    }
  }
  const real pr = rayleigh_phase(nu), pm = mie_phase(a->mie_g, nu);
  for (int c = 0; c < NCH; ++c) radiance[c] = s[c] * pr + m[c] * pm;
}

/* Sky radiance between `camera` and `point` (both inside or on the atmosphere, km). */
FN void sky_radiance_to_point(const AtmosphereParameters* a, GLOBAL const real* T, GLOBAL const real* S,
                              GLOBAL const real* M, const real* camera_in, const real* point, real shadow_length,
                              const real* sun, real* radiance, real* transmittance) {
  real camera[3] = {camera_in[0], camera_in[1], camera_in[2]};
  real view[3] = {point[0] - camera[0], point[1] - camera[1], point[2] - camera[2]};
  const real len = sqrt(dot3(view, view));
  for (int k = 0; k < 3; ++k) view[k] /= len;
  real r = sqrt(dot3(camera, camera));
  real rmu = dot3(camera, view);
  const real d_top = -rmu - sqrt(rmu * rmu - r * r + a->top_radius * a->top_radius);
  if (d_top > R(0.0)) {
    for (int k = 0; k < 3; ++k) camera[k] += view[k] * d_top;
    r = a->top_radius;
    rmu += d_top;
  }
  const real mu = rmu / r, mu_s = dot3(camera, sun) / r, nu = dot3(view, sun);
  const real to_point[3] = {point[0] - camera[0], point[1] - camera[1], point[2] - camera[2]};
  real d = sqrt(dot3(to_point, to_point));
  const int ground = ray_hits_ground(a, r, mu);
  transmittance_along(a, T, r, mu, d, ground, transmittance);
  real s[NCH], m[NCH], s_p[NCH], m_p[NCH], shadow_t[NCH];
  combined_scattering(a, S, M, r, mu, mu_s, nu, ground, s, m);
  d = fmax(d - shadow_length, R(0.0));
  const real r_p = clamp_radius(a, radius_along(r, mu, d));
  combined_scattering(a, S, M, r_p, (r * mu + d) / r_p, (r * mu_s + d * nu) / r_p, nu, ground, s_p, m_p);
  if (shadow_length > R(0.0)) {
    transmittance_along(a, T, r, mu, d, ground, shadow_t);
  } else {
    for (int c = 0; c < NCH; ++c) shadow_t[c] = transmittance[c];
  }
  /* the reference fades single Mie out as the sun sets, to hide artefacts */
  const real fade = smooth_step(R(0.0), R(0.01), mu_s);
  const real pr = rayleigh_phase(nu), pm = mie_phase(a->mie_g, nu);
  for (int c = 0; c < NCH; ++c) {
    const real sc = s[c] - shadow_t[c] * s_p[c];
    const real mc = (m[c] - shadow_t[c] * m_p[c]) * fade;
    radiance[c] = sc * pr + mc * pm;
  }
}

/* Sun and sky irradiance on a surface at `point` with unit `normal`; returns the sun part
 * in sun_irradiance and the sky part (from the irradiance texture, scaled by the fraction
 * of the sky the tilted surface sees) in sky_irradiance. */
FN void sun_and_sky_irradiance(const AtmosphereParameters* a, GLOBAL const real* T, GLOBAL const real* E,
                               const real* point, const real* normal, const real* sun, real* sun_irradiance,
                               real* sky_irradiance) {
  const real r = sqrt(dot3(point, point));
  const real mu_s = dot3(point, sun) / r;
  get_irradiance(a, E, r, mu_s, sky_irradiance);
  const real tilt = (R(1.0) + dot3(normal, point) / r) * R(0.5);
  for (int c = 0; c < NCH; ++c) sky_irradiance[c] *= tilt;
  transmittance_to_sun(a, T, r, mu_s, sun_irradiance);
  const real cos_n = fmax(dot3(normal, sun), R(0.0));
  for (int c = 0; c < NCH; ++c) sun_irradiance[c] *= a->solar_irradiance[c] * cos_n;
}
