/* atmosphere.cl — precomputed atmospheric scattering after E. Bruneton, "Precomputed
 * Atmospheric Scattering: a New Implementation" (2017), itself an update of Bruneton &
 * Neyret, "Precomputed Atmospheric Scattering", EGSR 2008. Shared by the OpenCL kernels
 * (kernels/atmosphere/kernels.cl, real = float) and the C++ double reference
 * (src/kinds/atmosphere/bake/reference.hpp, real = double). The geometry and texture coordinates
 * are in lookup.cl, the rendering functions (GetSkyRadiance & co.) in render.glsl; both are also
 * the shipped sampling.glsl.
 *
 * Model. A spherical planet of radius rb (bottom) under an atmosphere ending at rt (top).
 * A point is described by its altitude h = r − rb above the ground (r: distance to the planet
 * centre), a view direction by mu = cos(view zenith angle), the sun by mu_s = cos(sun zenith
 * angle), and nu = cos(view-sun angle). Three constituents, each with a density profile in
 * [0, 1] (two layers: a·exp(b·h) + c·h + d, clamped to [0, 1], layer 0 below its width):
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
 *   density J_n      n_θ × 32 midpoint rule over the sphere (θ through density_theta_node: by
 *                    default 16 nodes packed towards the horizon; the reference: 16 uniform),
 *                    the view's phase weights summed to 1 per direction by default
 *                    (density_phase_norm; the reference: as the rule gives them);
 *   indirect E       16 × 64 midpoint rule over the upper hemisphere.
 * Transmittance inside every integral is read from the transmittance texture (bilinear),
 * never integrated again; the same for the scattering textures (trilinear + a lerp in ν).
 *
 * Units: lengths in km, coefficients in km⁻¹, irradiance in the unit of solar_irradiance
 * (W m⁻² nm⁻¹), radiance in that unit per sr, the density J per km.
 *
 * Texture parameterisations (the reference's, texel centres at (i + 0.5)/n; written once in
 * lookup.cl, which the shipped sampling.glsl carries too):
 *   coord(x, n) = 0.5/n + x (1 − 1/n),  unit(u, n) = (u − 0.5/n)/(1 − 1/n)
 *   transmittance [H][W]: u = coord((d − d_min)/(d_max − d_min), W), v = coord(ρ/H_, H)
 *   irradiance [H][W]:    u = coord(0.5 μ_s + 0.5, W), v = coord(h/(rt − rb), H)
 *   scattering [R][MU][NU·MU_S]: see scattering_uvwz(); ν is corner-sampled (divisor NU − 1).
 * A texture holds NCH channels per texel (wavelengths), innermost.
 *
 * Float32 and the ground. rb ≈ 6360 km has a float32 spacing of 0.49 m, comparable to the
 * altitude of the lowest texel rows (62 m) and fatal to the discriminants of rays tangent to
 * the ground, so r itself is never a state variable: every function takes the altitude h,
 * which float32 holds to 2⁻²⁴ relative, and the cancelling combinations are written in it:
 *   ρ² = r² − rb² = h (h + 2 rb),   rt² − r² = (t − h)(t + h + 2 rb)  (t = rt − rb),
 *   distance to the ground  −rμ − √(r²μ² − ρ²) = ρ² / (√(r²μ² − ρ²) − rμ),
 *   distance to the top (μ > 0) −rμ + √(r²μ² + rt² − r²) = (rt² − r²) / (√(…) + rμ),
 *   altitude after d along the ray: (d² + 2 rμ d + ρ²) / (r_d + rb), or for rays that hit the
 *   ground, measured back from the ground point: (e² + 2 s e) / (r_e + rb), s = √(r²μ² − ρ²);
 * and texel rays carry the length d that the parameterisation defines (scattering_ray_from_uv)
 * instead of recomputing it from mu, whose discriminant is 0 ± rounding on the tangent rows.
 * r = rb + h then appears only in products and ratios (rμ, (rμ + d)/r_d), where its 2⁻²⁴
 * relative rounding is harmless. All are algebraically exact rewrites of the reference's
 * formulas. Other deviations, also exact: a one-texel axis (MU/2 = 1) maps to its midpoint
 * instead of 0/0; a transmittance ratio with a zero denominator gives 0; ν entering a texture
 * lookup is clamped to [−1, 1] (it can leave it by a rounding error only).
 *
 * Loop-invariant tables (exact refactorings used by the kernels, built by the same
 * functions in the double path):
 *   ray samples [R][MU][51][RAY_STRIDE]: for each texel's (h, μ) ray and sample i, what does
 *     not depend on μ_s and ν: altitude, r/r_i and d_i/r_i (μ_s,i = (r μ_s + d_i ν)/r_i),
 *     the (u_μ, u_r) of the sample, trapezoid weight × dx, densities, transmittance;
 *   density incidence [R][MU_S][n_θ][inc_stride]: for each (h, μ_s) and incident θ, the NU
 *     ν-slices of the incoming radiance (and single Mie at order 2) and the ground geometry.
 *
 * Compile-time settings: NCH (channels), NU_MAX (largest NU the caller uses).
 */
#include "common/real.h"
#include "atmosphere/limits.h"
#include "atmosphere/lookup.cl"

#ifndef NCH
#  error "NCH (channels per texel) must be defined before including atmosphere.cl"
#endif
#ifndef NU_MAX
#  define NU_MAX ATMOSPHERE_NU_LIMIT
#endif
/* LANES: how many independent computations a work item runs side by side, as the innermost
 * loop of fixed trip count: the texels of a (μ, r) row (single and multiple scattering) and the
 * suns of a ν row (density). A CPU device's kernel compiler turns such loops into vector
 * instructions (PoCL does not vectorise across work items through these kernels' sample
 * loops); a GPU runs one texel or sun per loop step. The host sets it per device (pass.cpp's
 * `lanes`); the C++ reference, which works per texel, keeps 1. Per texel the operations and
 * their order do not depend on it. */
#ifndef LANES
#  define LANES 1
#endif
/* NOTE_TEXEL(tex, offset): every read of a texture goes through one of the four places that
 * name it (texture_2d_blend, texture_3d_column, the density's ground taps,
 * scattering_lookup_azimuthal); offset in reals
 * from the texture's start, at a texel's first channel. Nothing in a kernel; the C++
 * reference defines it to note the texels a recomputation reads, so that a self-check fetches
 * only those from the device (src/kinds/atmosphere/bake/texel_reads.hpp). */
#ifndef NOTE_TEXEL
#  define NOTE_TEXEL(tex, offset)
#endif

#define ATM_PI R(3.14159265358979323846)

/* Ray-sample table entry (see the header). */
#define RAY_H 0      /* altitude of the sample, km */
#define RAY_A 1      /* r / r_i */
#define RAY_B 2      /* d_i / r_i, km⁻¹ · km */
#define RAY_U_MU 3   /* u_mu of (h_i, mu_i) with the texel's ground flag */
#define RAY_U_R 4    /* u_r of h_i */
#define RAY_W 5      /* trapezoid weight × dx, km */
#define RAY_RHO_R 6  /* Rayleigh density at h_i */
#define RAY_RHO_M 7  /* Mie density at h_i */
#define RAY_T RAY_FIXED /* NCH values: transmittance between the texel's point and the sample */
#define RAY_STRIDE (RAY_T + NCH)

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
  real density_theta_power;         /* p of the density's θ rule (density_theta_node): 1 = uniform */
  real density_phase_norm;          /* 1: the density's phase weights sum to 1 (scattering_density); 0: as the rule gives them */
  int transmittance_w, transmittance_h;   /* mu, r */
  int irradiance_w, irradiance_h;         /* mu_s, r */
  int r_size, mu_size, mu_s_size, nu_size;
  int density_theta;                      /* θ nodes of the density's sphere rule (even) */
  int ray_simpson;                        /* the view rays' rule (ray_sample): 1 Simpson, 0 trapezoid as the
                                             reference; also keeps the int count even (no padding in double builds) */
} AtmosphereParameters;

/* ---- small helpers (the scalar geometry is in lookup.cl) ----------------------------- */
FN int clamp_int(int x, int lo, int hi) { return x < lo ? lo : (x > hi ? hi : x); }
FN real dot3(const real* a, const real* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
/* t = rt − rb: the thickness of the atmosphere. */
FN real thickness(const AtmosphereParameters* a) { return a->top_radius - a->bottom_radius; }
FN real clamp_altitude(const AtmosphereParameters* a, real h) { return clamp_real(h, R(0.0), thickness(a)); }
FN real radius_of(const AtmosphereParameters* a, real h) { return a->bottom_radius + h; }
FN real horizon_top(const AtmosphereParameters* a) { return horizon_top_of(a->bottom_radius, a->top_radius); }
FN real horizon_distance2(const AtmosphereParameters* a, real h) { return rho2_of(a->bottom_radius, h); }
FN real horizon_distance(const AtmosphereParameters* a, real h) { return safe_sqrt(horizon_distance2(a, h)); }
FN real altitude_of_rho2(const AtmosphereParameters* a, real rho2) { return altitude_of_rho2_at(a->bottom_radius, rho2); }

/* ---- distances (lookup.cl, bound to the parameters) ---------------------------------- */
FN real distance_to_top(const AtmosphereParameters* a, real h, real mu) {
  return distance_to_top_at(a->bottom_radius, a->top_radius, h, mu);
}
FN real distance_to_bottom(const AtmosphereParameters* a, real h, real mu) {
  return distance_to_ground_at(a->bottom_radius, h, mu);
}
FN int ray_hits_ground(const AtmosphereParameters* a, real h, real mu) { return ray_meets_ground(a->bottom_radius, h, mu); }
FN real distance_to_nearest_boundary(const AtmosphereParameters* a, real h, real mu, int hits_ground) {
  return hits_ground ? distance_to_bottom(a, h, mu) : distance_to_top(a, h, mu);
}
FN real altitude_along(const AtmosphereParameters* a, real h, real mu, real d) {
  return altitude_after(a->bottom_radius, h, mu, d);
}

/* ---- density profiles ---------------------------------------------------------------- */
FN real layer_density(const DensityProfile* p, int layer, real h) {
  /* a layer without an exponential term (the ozone tent) skips its exp: the same value, 0 · e^x
   * = 0 for the finite x of every altitude, at a third less of the path tracer's work */
  const real a_exp = p->exp_term[layer];
  const real y = (a_exp != R(0.0) ? a_exp * exp(p->exp_scale[layer] * h) : R(0.0)) + p->linear_term[layer] * h +
                 p->constant_term[layer];
  return clamp_real(y, R(0.0), R(1.0));
}
FN real profile_density(const DensityProfile* p, real h) {
  return layer_density(p, h < p->width[0] ? 0 : 1, h);
}

/* ---- transmittance (paper Eq. 5) ----------------------------------------------------- */
/* ∫ ρ_i dt from (h, mu) to the top boundary for the three profiles (trapezoid, 500 steps).
 * above_ground: the ray does not reach below the ground (every texel of the texture), so the
 * altitude is clamped at 0 — a tangent ray touches the ground, where rounding would otherwise
 * put a sample below it and switch density layers. Otherwise (rays through the planet, which
 * no texture uses) negative altitudes are kept, as the reference does. */
FN void optical_lengths_to_top(const AtmosphereParameters* a, real h, real mu, int above_ground, real* l_rayleigh,
                               real* l_mie, real* l_absorption) {
  const real dx = distance_to_top(a, h, mu) / (real)TRANSMITTANCE_STEPS;
  real sr = R(0.0), sm = R(0.0), sa = R(0.0);
  for (int i = 0; i <= TRANSMITTANCE_STEPS; ++i) {
    const real h_i = altitude_along(a, h, mu, (real)i * dx);
    const real y = above_ground ? fmax(h_i, R(0.0)) : h_i;
    const real w = (i == 0 || i == TRANSMITTANCE_STEPS) ? R(0.5) : R(1.0);
    sr += profile_density(&a->rayleigh_density, y) * w;
    sm += profile_density(&a->mie_density, y) * w;
    sa += profile_density(&a->absorption_density, y) * w;
  }
  *l_rayleigh = sr * dx;
  *l_mie = sm * dx;
  *l_absorption = sa * dx;
}
/* T(h, mu → top) by direct integration (above_ground: see optical_lengths_to_top). */
FN void transmittance_to_top_integral(const AtmosphereParameters* a, real h, real mu, int above_ground, real* t) {
  real lr, lm, la;
  optical_lengths_to_top(a, h, mu, above_ground, &lr, &lm, &la);
  for (int c = 0; c < NCH; ++c)
    t[c] = exp(-(a->rayleigh_scattering[c] * lr + a->mie_extinction[c] * lm + a->absorption_extinction[c] * la));
}

/* ---- texture coordinates (lookup.cl) and their inverses -------------------------------- */
FN real unit_from_coord(real u, int n) {
  return n > 1 ? (u - R(0.5) / (real)n) / (R(1.0) - R(1.0) / (real)n) : R(0.5);
}

FN void transmittance_uv(const AtmosphereParameters* a, real h, real mu, real* u, real* v) {
  *u = transmittance_u_at(a->bottom_radius, a->top_radius, h, mu, (real)a->transmittance_w);
  *v = transmittance_v_at(a->bottom_radius, a->top_radius, h, (real)a->transmittance_h);
}
FN void h_mu_from_transmittance_uv(const AtmosphereParameters* a, real u, real v, real* h, real* mu) {
  const real x_mu = unit_from_coord(u, a->transmittance_w);
  const real x_r = unit_from_coord(v, a->transmittance_h);
  const real H = horizon_top(a);
  const real rho = H * x_r;
  *h = clamp_altitude(a, altitude_of_rho2(a, rho * rho));
  const real r = radius_of(a, *h);
  /* rt − r = (H² − ρ²)/(rt + r), without cancellation */
  const real d_min = (H - rho) * (H + rho) / (a->top_radius + r), d_max = rho + H;
  const real d = d_min + x_mu * (d_max - d_min);
  *mu = d == R(0.0) ? R(1.0) : clamp_cosine(((H - rho) * (H + rho) - d * d) / (R(2.0) * r * d));
}

/* Texel id = j·W + i of the transmittance texture → its (h, mu), at the texel centre. */
FN void transmittance_texel_params(const AtmosphereParameters* a, int id, real* h, real* mu) {
  const int i = id % a->transmittance_w, j = id / a->transmittance_w;
  h_mu_from_transmittance_uv(a, ((real)i + R(0.5)) / (real)a->transmittance_w,
                             ((real)j + R(0.5)) / (real)a->transmittance_h, h, mu);
}

FN void irradiance_uv(const AtmosphereParameters* a, real h, real mu_s, real* u, real* v) {
  *u = irradiance_u_at(mu_s, (real)a->irradiance_w);
  *v = irradiance_v_at(a->bottom_radius, a->top_radius, h, (real)a->irradiance_h);
}
FN void h_mu_s_from_irradiance_uv(const AtmosphereParameters* a, real u, real v, real* h, real* mu_s) {
  const real x_mu_s = unit_from_coord(u, a->irradiance_w);
  const real x_r = unit_from_coord(v, a->irradiance_h);
  /* the top row's centre decodes to x_r = 1 only up to rounding (1 + 2⁻⁵² at 12 rows) */
  *h = clamp_altitude(a, x_r * thickness(a));
  *mu_s = clamp_cosine(R(2.0) * x_mu_s - R(1.0));
}
/* Texel id = j·W + i of the irradiance texture → its (h, mu_s), at the texel centre. */
FN void irradiance_texel_params(const AtmosphereParameters* a, int id, real* h, real* mu_s) {
  const int i = id % a->irradiance_w, j = id / a->irradiance_w;
  h_mu_s_from_irradiance_uv(a, ((real)i + R(0.5)) / (real)a->irradiance_w, ((real)j + R(0.5)) / (real)a->irradiance_h,
                            h, mu_s);
}

/* The pieces of scattering_uvwz (lookup.cl). */
FN real scattering_u_r(const AtmosphereParameters* a, real h) {
  return scattering_u_r_at(a->bottom_radius, a->top_radius, h, (real)a->r_size);
}
FN real scattering_u_mu_of_distance(const AtmosphereParameters* a, real h, real rho, real d, int hits_ground) {
  return scattering_u_mu_at_distance(a->bottom_radius, a->top_radius, h, rho, d, hits_ground, (real)a->mu_size);
}
FN real scattering_u_mu(const AtmosphereParameters* a, real h, real mu, int hits_ground) {
  return scattering_u_mu_at(a->bottom_radius, a->top_radius, h, mu, hits_ground, (real)a->mu_size);
}
FN real scattering_u_mu_s(const AtmosphereParameters* a, real mu_s) {
  return scattering_u_mu_s_at(a->bottom_radius, a->top_radius, mu_s, a->mu_s_min, (real)a->mu_s_size);
}
/* (h, mu, mu_s, nu) → (u_nu, u_mu_s, u_mu, u_r); the ground flag picks the half of mu. */
FN void scattering_uvwz(const AtmosphereParameters* a, real h, real mu, real mu_s, real nu, int hits_ground,
                        real* uvwz) {
  uvwz[0] = scattering_u_nu_at(nu);
  uvwz[1] = scattering_u_mu_s(a, mu_s);
  uvwz[2] = scattering_u_mu(a, h, mu, hits_ground);
  uvwz[3] = scattering_u_r(a, h);
}

/* The ray of texture coordinates (u_mu, u_r): altitude, mu, ground flag, and the distance d
 * to the boundary it ends on, which the parameterisation defines exactly (mu is derived from
 * d). Ray integrals start from this d rather than from the discriminant of mu: for the rows
 * of tangent rays that discriminant is 0 ± rounding, and its square root would make the
 * length uncertain by √ε relative. */
FN void scattering_ray_from_uv(const AtmosphereParameters* a, real u_mu, real u_r, real* h, real* mu, real* d,
                               int* hits_ground) {
  const real H = horizon_top(a);
  const int half_mu = a->mu_size / 2;
  const real rho = H * unit_from_coord(u_r, a->r_size);
  /* the top row's centre decodes to ρ = H (1 ± ε): t up to rounding, never above it */
  *h = clamp_altitude(a, altitude_of_rho2(a, rho * rho));
  const real r = radius_of(a, *h);
  if (u_mu < R(0.5)) {
    const real d_min = *h, d_max = rho;
    *d = d_min + (d_max - d_min) * unit_from_coord(R(1.0) - R(2.0) * u_mu, half_mu);
    *mu = *d == R(0.0) ? R(-1.0) : clamp_cosine(-(rho * rho + *d * *d) / (R(2.0) * r * *d));
    *hits_ground = 1;
  } else {
    const real d_min = (H - rho) * (H + rho) / (a->top_radius + r), d_max = rho + H; /* d_min = rt − r */
    *d = d_min + (d_max - d_min) * unit_from_coord(R(2.0) * u_mu - R(1.0), half_mu);
    *mu = *d == R(0.0) ? R(1.0) : clamp_cosine(((H - rho) * (H + rho) - *d * *d) / (R(2.0) * r * *d));
    *hits_ground = 0;
  }
}

/* Inverse of scattering_uvwz (nu not yet clamped to the range that mu, mu_s allow). */
FN void scattering_params_from_uvwz(const AtmosphereParameters* a, const real* uvwz, real* h, real* mu, real* mu_s,
                                    real* nu, int* hits_ground) {
  real d_ray;
  scattering_ray_from_uv(a, uvwz[2], uvwz[3], h, mu, &d_ray, hits_ground);
  const real H = horizon_top(a);
  const real x_mu_s = unit_from_coord(uvwz[1], a->mu_s_size);
  const real d_min = thickness(a), d_max = H;
  const real D = distance_to_top(a, R(0.0), a->mu_s_min);
  const real A = (D - d_min) / (d_max - d_min);
  const real a_s = (A - x_mu_s * A) / (R(1.0) + x_mu_s * A);
  const real d = d_min + fmin(a_s, A) * (d_max - d_min);
  *mu_s = d == R(0.0) ? R(1.0) : clamp_cosine((H * H - d * d) / (R(2.0) * a->bottom_radius * d));
  *nu = clamp_cosine(uvwz[0] * R(2.0) - R(1.0));
}
/* The ray of texel row (y, z) of the scattering texture (see scattering_ray_from_uv). */
FN void scattering_ray_of_texel(const AtmosphereParameters* a, int y, int z, real* h, real* mu, real* d,
                                int* hits_ground) {
  scattering_ray_from_uv(a, ((real)y + R(0.5)) / (real)a->mu_size, ((real)z + R(0.5)) / (real)a->r_size, h, mu, d,
                         hits_ground);
}

/* u_ν of ν slice `slice` (corner-sampled: slice / (NU − 1); 0.5 for a single slice). */
FN real scattering_u_nu_of_slice(const AtmosphereParameters* a, int slice) {
  return a->nu_size > 1 ? (real)slice / (real)(a->nu_size - 1) : R(0.5);
}
/* ν of a texel of slice `slice` whose row and column decode to (mu, mu_s): the slice's ν clamped
 * to [μμ_s − √((1−μ²)(1−μ_s²)), μμ_s + √…], the cosines a view and a sun at those zenith angles
 * can make. Every texel of a (μ, μ_s) column shares mu and mu_s. */
FN real scattering_nu_of_slice(const AtmosphereParameters* a, int slice, real mu, real mu_s) {
  const real nu = clamp_cosine(scattering_u_nu_of_slice(a, slice) * R(2.0) - R(1.0));
  const real s = sqrt((R(1.0) - mu * mu) * (R(1.0) - mu_s * mu_s));
  return clamp_real(nu, mu * mu_s - s, mu * mu_s + s);
}
/* Texel (x, y, z) of the 3D scattering texture (x = nu_slice·MU_S + mu_s_index, y = mu
 * index, z = r index) → its parameters (nu as scattering_nu_of_slice clamps it). */
FN void scattering_params_from_texel(const AtmosphereParameters* a, int x, int y, int z, real* h, real* mu,
                                     real* mu_s, real* nu, int* hits_ground) {
  real uvwz[4];
  uvwz[0] = scattering_u_nu_of_slice(a, x / a->mu_s_size);
  uvwz[1] = ((real)(x % a->mu_s_size) + R(0.5)) / (real)a->mu_s_size;
  uvwz[2] = ((real)y + R(0.5)) / (real)a->mu_size;
  uvwz[3] = ((real)z + R(0.5)) / (real)a->r_size;
  scattering_params_from_uvwz(a, uvwz, h, mu, mu_s, nu, hits_ground);
  *nu = scattering_nu_of_slice(a, x / a->mu_s_size, *mu, *mu_s);
}

/* ---- texture filtering (GPU semantics: texel centres, clamp to edge) ------------------- */
/* Bilinear filter in two parts: the taps (offsets of the four texels' channels and the
 * weights), then the blend of one channel; texture_2d does both. */
typedef struct {
  int t00, t10, t01, t11;
  real fx, fy;
} Taps2d;
FN_HOT Taps2d texture_2d_taps(int w, int h, real u, real v) {
  const real x = u * (real)w - R(0.5), y = v * (real)h - R(0.5);
  const real x0 = floor(x), y0 = floor(y);
  Taps2d t;
  t.fx = x - x0;
  t.fy = y - y0;
  const int i0 = clamp_int((int)x0, 0, w - 1), i1 = clamp_int((int)x0 + 1, 0, w - 1);
  const int j0 = clamp_int((int)y0, 0, h - 1), j1 = clamp_int((int)y0 + 1, 0, h - 1);
  t.t00 = (j0 * w + i0) * NCH;
  t.t10 = (j0 * w + i1) * NCH;
  t.t01 = (j1 * w + i0) * NCH;
  t.t11 = (j1 * w + i1) * NCH;
  return t;
}
FN_HOT real texture_2d_blend(GLOBAL const real* tex, const Taps2d* t, int c) {
  NOTE_TEXEL(tex, t->t00);
  NOTE_TEXEL(tex, t->t10);
  NOTE_TEXEL(tex, t->t01);
  NOTE_TEXEL(tex, t->t11);
  return (R(1.0) - t->fy) * ((R(1.0) - t->fx) * tex[t->t00 + c] + t->fx * tex[t->t10 + c]) +
         t->fy * ((R(1.0) - t->fx) * tex[t->t01 + c] + t->fx * tex[t->t11 + c]);
}
FN void texture_2d(GLOBAL const real* tex, int w, int h, real u, real v, real* out) {
  const Taps2d t = texture_2d_taps(w, h, u, v);
  for (int c = 0; c < NCH; ++c) out[c] = texture_2d_blend(tex, &t, c);
}

/* Trilinear lookup at (u, v, w) in a [d][h][wd] texture, in three parts: texture_3d_rows, the
 * rows along the two slower axes (v over h, w over d) and their weights, which every lookup
 * here shares between several u (the two ν slices of a scattering lookup, the NU slices of
 * scattering_slices, every texel of a row in the multiple-scattering kernel);
 * texture_3d_column, the bilinear blend of those rows at one column x; and texture_3d_at, the
 * filter along u between two columns. A caller that needs many u at the same rows can blend
 * every column once and filter along u from there (multiple_scattering_add_lanes): the same
 * operations in the same order. */
typedef struct {
  int j0, j1, k0, k1; /* rows (v) and planes (w) of the taps */
  real fy, fz;        /* weights of j1 and k1 */
} TexelRows;
FN_HOT TexelRows texture_3d_rows(int h, int d, real v, real w) {
  const real y = v * (real)h - R(0.5), z = w * (real)d - R(0.5);
  const real y0 = floor(y), z0 = floor(z);
  TexelRows r;
  r.fy = y - y0;
  r.fz = z - z0;
  r.j0 = clamp_int((int)y0, 0, h - 1);
  r.j1 = clamp_int((int)y0 + 1, 0, h - 1);
  r.k0 = clamp_int((int)z0, 0, d - 1);
  r.k1 = clamp_int((int)z0 + 1, 0, d - 1);
  return r;
}
/* The two columns of a filter along u over wd texels (centres, clamp to edge), and the weight
 * of the second. */
typedef struct {
  int i0, i1;
  real fx;
} TexelColumns;
FN_HOT TexelColumns texture_columns(int wd, real u) {
  const real x = u * (real)wd - R(0.5);
  const real x0 = floor(x);
  TexelColumns c;
  c.fx = x - x0;
  c.i0 = clamp_int((int)x0, 0, wd - 1);
  c.i1 = clamp_int((int)x0 + 1, 0, wd - 1);
  return c;
}
/* Column i of the rows r: the bilinear blend over (v, w) of its four taps. */
FN_HOT void texture_3d_column(GLOBAL const real* tex, int wd, int h, const TexelRows* r, int i, real* out) {
  const int plane = wd * h;
  GLOBAL const real* p00 = tex + (r->k0 * plane + r->j0 * wd + i) * NCH;
  GLOBAL const real* p10 = tex + (r->k0 * plane + r->j1 * wd + i) * NCH;
  GLOBAL const real* p01 = tex + (r->k1 * plane + r->j0 * wd + i) * NCH;
  GLOBAL const real* p11 = tex + (r->k1 * plane + r->j1 * wd + i) * NCH;
  NOTE_TEXEL(tex, p00 - tex);
  NOTE_TEXEL(tex, p10 - tex);
  NOTE_TEXEL(tex, p01 - tex);
  NOTE_TEXEL(tex, p11 - tex);
  const real fy = r->fy, fz = r->fz;
  for (int c = 0; c < NCH; ++c)
    out[c] = (R(1.0) - fz) * ((R(1.0) - fy) * p00[c] + fy * p10[c]) + fz * ((R(1.0) - fy) * p01[c] + fy * p11[c]);
}
FN_HOT void texture_3d_at(GLOBAL const real* tex, int wd, int h, const TexelRows* r, real u, real* out) {
  const TexelColumns x = texture_columns(wd, u);
  real c0[NCH], c1[NCH];
  texture_3d_column(tex, wd, h, r, x.i0, c0);
  texture_3d_column(tex, wd, h, r, x.i1, c1);
  for (int c = 0; c < NCH; ++c) out[c] = (R(1.0) - x.fx) * c0[c] + x.fx * c1[c];
}

/* ---- transmittance lookups ----------------------------------------------------------- */
FN void transmittance_to_top(const AtmosphereParameters* a, GLOBAL const real* T, real h, real mu, real* out) {
  real u, v;
  transmittance_uv(a, h, mu, &u, &v);
  texture_2d(T, a->transmittance_w, a->transmittance_h, u, v, out);
}
/* T to the top from the fixed end of the segments that transmittance_along_from() measures:
 * T(h, −mu) for rays that hit the ground, T(h, mu) otherwise. */
FN void transmittance_fixed_end(const AtmosphereParameters* a, GLOBAL const real* T, real h, real mu, int hits_ground,
                                real* out) {
  transmittance_to_top(a, T, h, hits_ground ? -mu : mu, out);
}
/* T between a ray's origin and its point at (h_d, mu_d), from two lookups; rays that hit the
 * ground use the reversed (upward) segments so that no lookup crosses the ground.
 * fixed: transmittance_fixed_end() of the origin. */
FN void transmittance_ratio(const AtmosphereParameters* a, GLOBAL const real* T, real h_d, real mu_d, int hits_ground,
                            const real* fixed, real* out) {
  real moving[NCH];
  transmittance_to_top(a, T, h_d, hits_ground ? -mu_d : mu_d, moving);
  for (int c = 0; c < NCH; ++c) {
    out[c] = hits_ground ? ratio_or_zero(moving[c], fixed[c]) : ratio_or_zero(fixed[c], moving[c]);
  }
}
/* The point at distance d along (h, mu): altitude and mu there (lookup.cl). */
FN void point_along(const AtmosphereParameters* a, real h, real mu, real d, int hits_ground, real* h_d, real* mu_d) {
  *h_d = altitude_along_ray(a->bottom_radius, a->top_radius, h, mu, d, hits_ground);
  *mu_d = cosine_along_ray(a->bottom_radius, h, mu, d, hits_ground, *h_d);
}
/* T between (h, mu) and the point at distance d along the ray. */
FN void transmittance_along_from(const AtmosphereParameters* a, GLOBAL const real* T, real h, real mu, real d,
                                 int hits_ground, const real* fixed, real* out) {
  real h_d, mu_d;
  point_along(a, h, mu, d, hits_ground, &h_d, &mu_d);
  transmittance_ratio(a, T, h_d, mu_d, hits_ground, fixed, out);
}
FN void transmittance_along(const AtmosphereParameters* a, GLOBAL const real* T, real h, real mu, real d,
                            int hits_ground, real* out) {
  real fixed[NCH];
  transmittance_fixed_end(a, T, h, mu, hits_ground, fixed);
  transmittance_along_from(a, T, h, mu, d, hits_ground, fixed, out);
}
/* The visible fraction of the sun disc above the horizon at altitude h (lookup.cl). */
FN real sun_visible_fraction(const AtmosphereParameters* a, real h, real mu_s) {
  return sun_visible_at(a->bottom_radius, a->sun_angular_radius, h, mu_s);
}

/* ---- scattering lookups -------------------------------------------------------------- */
/* The two ν slices around u_nu (corner-sampled, divisor NU − 1): the first and the weight of
 * the second. */
FN_HOT real scattering_nu_slice(const AtmosphereParameters* a, real u_nu, real* f) {
  const real x = clamp_real(u_nu, R(0.0), R(1.0)) * (real)(a->nu_size - 1);
  const real x0 = floor(x);
  *f = x - x0;
  return x0;
}
/* Where a scattering lookup at (u_nu, u_mu_s) reads along the texture's x = ν·MU_S + μ_s axis:
 * the columns of its two ν slices (s0 around (x0 + u_mu_s)/NU, s1 one slice on) and the
 * weight f of the second slice; scattering_blend filters four columns' values with them. */
typedef struct {
  TexelColumns s0, s1;
  real f;
} ScatteringColumns;
FN_HOT ScatteringColumns scattering_columns(const AtmosphereParameters* a, real u_nu, real u_mu_s) {
  const int wd = a->nu_size * a->mu_s_size;
  ScatteringColumns x;
  const real x0 = scattering_nu_slice(a, u_nu, &x.f);
  x.s0 = texture_columns(wd, (x0 + u_mu_s) / (real)a->nu_size);
  x.s1 = texture_columns(wd, (x0 + R(1.0) + u_mu_s) / (real)a->nu_size);
  return x;
}
/* One channel of the lookup from its columns' values (s0.i0, s0.i1, s1.i0, s1.i1) and weights
 * (s0.fx, s1.fx, f), trilinear as the reference. (The shipped lookups can blend μ_s
 * geometrically, render.glsl; here a pow per blend in the multiple scattering's inner loop
 * made a bake ~5× slower on a CPU, docs/atmosphere-method.md "Twilight"; the sky-view table's
 * reads of the summed densities blend so, scattering_lookup_azimuthal.) */
FN_HOT real scattering_blend(real fx0, real fx1, real f, real c00, real c01, real c10, real c11) {
  const real v0 = (R(1.0) - fx0) * c00 + fx0 * c01;
  const real v1 = (R(1.0) - fx1) * c10 + fx1 * c11;
  return v0 * (R(1.0) - f) + v1 * f;
}
/* mu_s_blend, linear where a and b lie within 2 % of each other: there the chord exceeds the
 * geometric blend by at most g (1 − g) ε² / 2 ≤ 5e-5 of the value (ε = 0.02), below float's
 * accumulation error over a ray, and no logarithm is spent (16 wavelengths, the twilight scene's
 * table: 3.3× the linear reads' time with the shortcut, 3.6× without; 6× joining each ν slice
 * geometrically first, 27× with a pow per slice). */
FN_HOT real mu_s_blend_near(real a, real b, real g) {
  if (fabs(b - a) <= R(0.02) * fmin(a, b)) return a + (b - a) * g;
  const int geo = a > R(0.0) && b > R(0.0) && fmin(a, b) > R(1e-3) * fmax(a, b);
  return geo ? a * exp2(g * log2(b / a)) : a + (b - a) * g;
}
/* The reference's GetScattering from its texture coordinates: two trilinear lookups around nu. */
FN_HOT void scattering_lookup(const AtmosphereParameters* a, GLOBAL const real* tex, const real* uvwz, real* out) {
  const int wd = a->nu_size * a->mu_s_size;
  const ScatteringColumns x = scattering_columns(a, uvwz[0], uvwz[1]);
  const TexelRows rows = texture_3d_rows(a->mu_size, a->r_size, uvwz[2], uvwz[3]);
  real c00[NCH], c01[NCH], c10[NCH], c11[NCH];
  texture_3d_column(tex, wd, a->mu_size, &rows, x.s0.i0, c00);
  texture_3d_column(tex, wd, a->mu_size, &rows, x.s0.i1, c01);
  texture_3d_column(tex, wd, a->mu_size, &rows, x.s1.i0, c10);
  texture_3d_column(tex, wd, a->mu_size, &rows, x.s1.i1, c11);
  for (int c = 0; c < NCH; ++c) out[c] = scattering_blend(x.s0.fx, x.s1.fx, x.f, c00[c], c01[c], c10[c], c11[c]);
}
FN void get_scattering(const AtmosphereParameters* a, GLOBAL const real* tex, real h, real mu, real mu_s, real nu,
                       int hits_ground, real* out) {
  real uvwz[4];
  scattering_uvwz(a, h, mu, mu_s, nu, hits_ground, uvwz);
  scattering_lookup(a, tex, uvwz, out);
}
FN void get_irradiance(const AtmosphereParameters* a, GLOBAL const real* E, real h, real mu_s, real* out) {
  real u, v;
  irradiance_uv(a, h, mu_s, &u, &v);
  texture_2d(E, a->irradiance_w, a->irradiance_h, u, v, out);
}
/* get_irradiance at h = 0: v is the centre of row 0, so the bilinear filter is a lerp along
 * that row at x = u·W − 0.5 = (0.5 μ_s + 0.5)(W − 1): the ground irradiance at mu_s is
 * (1 − f)·E[t0 + c] + f·E[t1 + c]. */
FN void ground_irradiance_taps(const AtmosphereParameters* a, real mu_s, int* t0, int* t1, real* f) {
  const int w = a->irradiance_w;
  const real x = (mu_s * R(0.5) + R(0.5)) * (real)(w - 1);
  const real x0 = floor(x);
  *f = x - x0;
  *t0 = clamp_int((int)x0, 0, w - 1) * NCH;
  *t1 = clamp_int((int)x0 + 1, 0, w - 1) * NCH;
}

/* Values of the NU slices of a scattering texture at fixed (u_mu_s, u_mu, u_r): slice s is
 * the trilinear lookup at x = (s + u_mu_s)/NU. Since u_mu_s keeps half a texel from both
 * ends, the filter never mixes two slices. */
FN void scattering_slices(const AtmosphereParameters* a, GLOBAL const real* tex, real u_mu_s, real u_mu, real u_r,
                          real* slices) {
  const int wd = a->nu_size * a->mu_s_size;
  const TexelRows rows = texture_3d_rows(a->mu_size, a->r_size, u_mu, u_r);
  for (int s = 0; s < a->nu_size; ++s)
    texture_3d_at(tex, wd, a->mu_size, &rows, ((real)s + u_mu_s) / (real)a->nu_size, slices + s * NCH);
}
/* The two slices around nu and the weight of the second (corner-sampled, divisor NU − 1):
 * the value at nu is slice s0 × (1 − f) + slice s1 × f. */
FN real slice_position(const AtmosphereParameters* a, real nu) {
  return (clamp_cosine(nu) + R(1.0)) * R(0.5) * (real)(a->nu_size - 1);
}
FN void slice_weights(const AtmosphereParameters* a, real nu, int* s0, int* s1, real* f) {
  const real x = slice_position(a, nu);
  const real x0 = floor(x);
  *f = x - x0;
  *s0 = clamp_int((int)x0, 0, a->nu_size - 1);
  *s1 = clamp_int((int)x0 + 1, 0, a->nu_size - 1);
}
/* The same weights as a function of x = slice_position(ν), for slice s: 1 − |x − s|, or 0 (also
 * for a NaN x). A compare and select rather than fmax, whose NaN rules cost three more vector
 * instructions; the same values (x − s and s − x are exact negatives, so the earlier
 * fmax(x − s, s − x) was |x − s| too). */
FN real hat(real x, int s) {
  const real w = R(1.0) - fabs(x - (real)s);
  return w > R(0.0) ? w : R(0.0);
}
/* The slice count as a compile-time constant in the kernels (built with NU_MAX = NU), so that
 * loops over every slice have a fixed trip count; the C++ reference reads it. */
#ifdef __OPENCL_C_VERSION__
#  define NU_SLICES(a) NU_MAX
#else
#  define NU_SLICES(a) ((a)->nu_size)
#endif
FN void lerp_slices(const AtmosphereParameters* a, const real* slices, real nu, real* out) {
  int s0, s1;
  real f;
  slice_weights(a, nu, &s0, &s1, &f);
  for (int c = 0; c < NCH; ++c) out[c] = slices[s0 * NCH + c] * (R(1.0) - f) + slices[s1 * NCH + c] * f;
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

/* ---- ray samples (single and multiple scattering, 50 intervals: Simpson or trapezoid) - */
/* Entry i of the ray-sample table of the ray (h, mu, hits_ground) of length d_b (to the
 * nearest boundary): dx = d_b / 50, fixed = transmittance_fixed_end(h, mu, hits_ground).
 * Samples are placed by their distance to the ray's end, e = (50 − i) dx, which also gives
 * their own distance to the boundary (for u_mu) without a discriminant. */
FN void ray_sample(const AtmosphereParameters* a, GLOBAL const real* T, real h, real mu, int hits_ground, real d_b,
                   const real* fixed, int i, real* s) {
  const real dx = d_b / (real)SCATTERING_STEPS;
  const real d_i = (real)i * dx, e = (real)(SCATTERING_STEPS - i) * dx;
  const real r = radius_of(a, h);
  real h_i, mu_i;
  if (hits_ground) {
    /* r_g μ_g at the ground point, (ρ² − d_b²)/(2 d_b): 0 for the tangent row, exactly */
    const real rho = horizon_distance(a, h);
    const real up = d_b > R(0.0) ? (rho - d_b) * (rho + d_b) / (R(2.0) * d_b) : R(0.0);
    h_i = clamp_altitude(a, altitude_of_rho2(a, e * (e + R(2.0) * fmax(up, R(0.0)))));
    mu_i = clamp_cosine(-(fmax(up, R(0.0)) + e) / radius_of(a, h_i));
  } else {
    h_i = clamp_altitude(a, altitude_along(a, h, mu, d_i));
    mu_i = clamp_cosine((r * mu + d_i) / radius_of(a, h_i));
  }
  const real r_i = radius_of(a, h_i);
  s[RAY_H] = h_i;
  s[RAY_A] = r / r_i;
  s[RAY_B] = d_i / r_i;
  s[RAY_U_MU] = scattering_u_mu_of_distance(a, h_i, horizon_distance(a, h_i), e, hits_ground);
  s[RAY_U_R] = scattering_u_r(a, h_i);
  /* composite Simpson (SCATTERING_STEPS even): weights 1, 4, 2, …, 4, 1 over 3; or the
   * reference's trapezoid. Simpson's error on the Mie layer's e^{−h/H} along a steep ray is
   * ~(dx/H)⁴/180 against the trapezoid's (dx/H)²/12 (8 % at dx = H = 1.2 km) */
  s[RAY_W] = (a->ray_simpson ? ((i == 0 || i == SCATTERING_STEPS) ? R(1.0) / R(3.0)
                                                                   : ((i & 1) ? R(4.0) / R(3.0) : R(2.0) / R(3.0)))
                             : ((i == 0 || i == SCATTERING_STEPS) ? R(0.5) : R(1.0))) *
             dx;
  s[RAY_RHO_R] = profile_density(&a->rayleigh_density, h_i);
  s[RAY_RHO_M] = profile_density(&a->mie_density, h_i);
  transmittance_ratio(a, T, h_i, mu_i, hits_ground, fixed, s + RAY_T);
}
/* mu_s at a sample: (r mu_s + d_i nu) / r_i. */
FN real ray_sample_mu_s(const real* s, real mu_s, real nu) { return clamp_cosine(s[RAY_A] * mu_s + s[RAY_B] * nu); }

/* ---- single scattering (paper Eq. 8–9; no phase function) ----------------------------- */
/* The sun seen from ray sample s by the texel (mu_s, nu): the transmittance lookup's taps, and
 * the sun disc's visible fraction (T to the sun is visible × the taps' blend). */
FN_HOT Taps2d sun_taps_at_sample(const AtmosphereParameters* a, const real* s, real mu_s, real nu, real* visible) {
  const real mu_s_i = ray_sample_mu_s(s, mu_s, nu);
  real u, v;
  *visible = sun_visible_fraction(a, s[RAY_H], mu_s_i);
  transmittance_uv(a, s[RAY_H], mu_s_i, &u, &v);
  return texture_2d_taps(a->transmittance_w, a->transmittance_h, u, v);
}
/* Sample s's terms of single_scattering()'s sums, per channel: T to the sample × T to the sun ×
 * the densities × the trapezoid weight. */
FN_HOT void single_scattering_terms(GLOBAL const real* T, const real* s, const Taps2d* sun, real visible, real* sum_r,
                                    real* sum_m) {
  const real wr = s[RAY_RHO_R] * s[RAY_W], wm = s[RAY_RHO_M] * s[RAY_W];
  for (int c = 0; c < NCH; ++c) {
    real t_sun = texture_2d_blend(T, sun, c);
    t_sun *= visible;
    const real t = s[RAY_T + c] * t_sun;
    sum_r[c] += t * wr;
    sum_m[c] += t * wm;
  }
}
/* One sample's contribution to the sums of single_scattering(). */
FN void single_scattering_add(const AtmosphereParameters* a, GLOBAL const real* T, const real* s, real mu_s, real nu,
                              real* sum_r, real* sum_m) {
  real visible;
  const Taps2d sun = sun_taps_at_sample(a, s, mu_s, nu, &visible);
  single_scattering_terms(T, s, &sun, visible, sum_r, sum_m);
}
/* single_scattering_add for LANES texels of one (μ, r) row (lane k: mu_s[k], nu[k]; sums
 * [k·NCH + c]): the sun's taps across the lanes (vector instructions on a CPU), then each
 * lane's terms over its channels. */
FN_HOT void single_scattering_add_lanes(const AtmosphereParameters* a, GLOBAL const real* T, const real* s,
                                        const real* mu_s, const real* nu, real* sum_r, real* sum_m) {
  Taps2d sun[LANES];
  real visible[LANES];
  for (int k = 0; k < LANES; ++k) sun[k] = sun_taps_at_sample(a, s, mu_s[k], nu[k], &visible[k]);
  for (int k = 0; k < LANES; ++k) single_scattering_terms(T, s, &sun[k], visible[k], sum_r + k * NCH, sum_m + k * NCH);
}
FN void single_scattering_finish(const AtmosphereParameters* a, const real* sum_r, const real* sum_m, real* rayleigh,
                                 real* mie) {
  for (int c = 0; c < NCH; ++c) {
    rayleigh[c] = sum_r[c] * a->solar_irradiance[c] * a->rayleigh_scattering[c];
    mie[c] = sum_m[c] * a->solar_irradiance[c] * a->mie_scattering[c];
  }
}
/* Single scattering along the ray (h, mu) of length d_b to its boundary. */
FN void single_scattering_ray(const AtmosphereParameters* a, GLOBAL const real* T, real h, real mu, real d_b,
                              int hits_ground, real mu_s, real nu, real* rayleigh, real* mie) {
  real sum_r[NCH], sum_m[NCH], fixed[NCH], s[RAY_STRIDE];
  for (int c = 0; c < NCH; ++c) sum_r[c] = sum_m[c] = R(0.0);
  transmittance_fixed_end(a, T, h, mu, hits_ground, fixed);
  for (int i = 0; i <= SCATTERING_STEPS; ++i) {
    ray_sample(a, T, h, mu, hits_ground, d_b, fixed, i, s);
    single_scattering_add(a, T, s, mu_s, nu, sum_r, sum_m);
  }
  single_scattering_finish(a, sum_r, sum_m, rayleigh, mie);
}
FN void single_scattering(const AtmosphereParameters* a, GLOBAL const real* T, real h, real mu, real mu_s, real nu,
                          int hits_ground, real* rayleigh, real* mie) {
  single_scattering_ray(a, T, h, mu, distance_to_nearest_boundary(a, h, mu, hits_ground), hits_ground, mu_s, nu,
                        rayleigh, mie);
}

/* ---- multiple scattering of order n (paper Eq. 7, 50-interval trapezoid) --------------- */
FN_HOT void multiple_scattering_add(const AtmosphereParameters* a, GLOBAL const real* J, const real* s, real mu_s, real nu,
                                real* out) {
  real uvwz[4], j[NCH];
  uvwz[0] = scattering_u_nu_at(nu);
  uvwz[1] = scattering_u_mu_s(a, ray_sample_mu_s(s, mu_s, nu));
  uvwz[2] = s[RAY_U_MU];
  uvwz[3] = s[RAY_U_R];
  scattering_lookup(a, J, uvwz, j);
  for (int c = 0; c < NCH; ++c) out[c] += j[c] * s[RAY_T + c] * s[RAY_W];
}
/* multiple_scattering_add for LANES texels of one (μ, r) row (lane k: mu_s[k], nu[k];
 * out[k·NCH + c]), with J's columns blended at the sample's (u_mu, u_r) rows
 * (texture_3d_column of texture_3d_rows(s[RAY_U_MU], s[RAY_U_R]) for every column i, in
 * columns[i·NCH + c]): every texel of a row shares its ray samples, so the kernel blends the
 * columns once per sample. The lookup's columns across the lanes (vector instructions on a
 * CPU), then each lane's blend over its channels: per lane, scattering_lookup's operations. */
FN_HOT void multiple_scattering_add_lanes(const AtmosphereParameters* a, LOCAL const real* columns, const real* s,
                                          const real* mu_s, const real* nu, real* out) {
  /* the columns' offsets and weights as one array per field (an array of the structs keeps
   * the compiler from vectorising the lanes: 1.4× the kernel's time) */
  int i00[LANES], i01[LANES], i10[LANES], i11[LANES];
  real fx0[LANES], fx1[LANES], f[LANES];
  for (int k = 0; k < LANES; ++k) {
    const ScatteringColumns x =
        scattering_columns(a, scattering_u_nu_at(nu[k]), scattering_u_mu_s(a, ray_sample_mu_s(s, mu_s[k], nu[k])));
    i00[k] = x.s0.i0 * NCH;
    i01[k] = x.s0.i1 * NCH;
    i10[k] = x.s1.i0 * NCH;
    i11[k] = x.s1.i1 * NCH;
    fx0[k] = x.s0.fx;
    fx1[k] = x.s1.fx;
    f[k] = x.f;
  }
  for (int k = 0; k < LANES; ++k)
    for (int c = 0; c < NCH; ++c) {
      const real j = scattering_blend(fx0[k], fx1[k], f[k], columns[i00[k] + c], columns[i01[k] + c],
                                      columns[i10[k] + c], columns[i11[k] + c]);
      out[k * NCH + c] += j * s[RAY_T + c] * s[RAY_W];
    }
}
/* J (or any scattering-layout texture) at a ray sample, the view–sun azimuth kept across the
 * texel rows it blends. The reference's lookup blends its (μ, r) rows at one ν; near the zenith
 * a row's μ differs from the sample's, and the same ν there is another azimuth: at the ground
 * Bruneton's μ rows are the zenith, then ~28° (Mars) or ~35° (Earth) from it, and a row at μ_q
 * allows only ν ∈ μ_q μ_s ± √((1−μ_q²)(1−μ_s²)), holding the clamped slices' values beyond. For an
 * air whose multiple scattering follows a forward phase (dust, g 0.7) that mixed views towards
 * the sun with views across it: order 2 of near-zenith views came out 0.7× the truth towards the
 * sun (docs/atmosphere-method.md, "Near the zenith: the azimuth of a J read"). Here each row q
 * (μ_q, from corner_mu) is read at its own ν_q = μ_q μ_s + cos φ √((1 − μ_q²)(1 − μ_s²)), with
 * cos φ the sample's (ν − μ μ_s)/√((1 − μ²)(1 − μ_s²)), between the two slices around ν_q weighted
 * by the slices' own ν as the bake clamped them (as scattering_nu_of_slice); at μ or μ_s = ±1 (no
 * azimuth) every row takes ν. The same 16 texels as scattering_lookup; μ_s joined linearly or
 * (geometric: the two ν-blended μ_s columns, one logarithm per channel) by mu_s_blend_near. uvwz as scattering_uvwz; mu, sin_mu = √(1 − μ²), mu_s: the
 * sample's; corner_mu, corner_sin: the rows' μ and √(1 − μ²) (sky_view_ray_sample). */
FN_HOT void scattering_lookup_azimuthal(const AtmosphereParameters* a, GLOBAL const real* tex, const real* uvwz,
                                        const real* corner_mu, const real* corner_sin, real mu, real sin_mu, real mu_s,
                                        real nu, int geometric, real* out) {
  const int wd = a->nu_size * a->mu_s_size, plane = wd * a->mu_size;
  const TexelRows rows = texture_3d_rows(a->mu_size, a->r_size, uvwz[2], uvwz[3]);
  const TexelColumns xs = texture_columns(a->mu_s_size, uvwz[1]);
  const real sin_s = sqrt(fmax(R(1.0) - mu_s * mu_s, R(0.0)));
  const real s_view = sin_mu * sin_s;
  const int azimuthal = s_view > R(1e-6);
  const real cos_phi = azimuthal ? clamp_real((nu - mu * mu_s) / s_view, R(-1.0), R(1.0)) : R(0.0);
  real col0[NCH], col1[NCH]; /* the two μ_s columns, each blended over rows and slices */
  for (int c = 0; c < NCH; ++c) col0[c] = col1[c] = R(0.0);
  for (int q = 0; q < 4; ++q) {
    const int j = (q & 1) ? rows.j1 : rows.j0, k = (q & 2) ? rows.k1 : rows.k0;
    const real w = ((q & 1) ? rows.fy : R(1.0) - rows.fy) * ((q & 2) ? rows.fz : R(1.0) - rows.fz);
    const real centre = corner_mu[q] * mu_s, spread = corner_sin[q] * sin_s;
    const real nu_q = azimuthal ? clamp_cosine(centre + cos_phi * spread) : nu;
    /* the slices around ν_q, weighted by their ν as the bake took them (as
     * scattering_nu_of_slice: clamped to [centre − spread, centre + spread]) */
    real f_slice;
    const int s0 = (int)scattering_nu_slice(a, scattering_u_nu_at(nu_q), &f_slice);
    const int s1 = clamp_int(s0 + 1, 0, a->nu_size - 1);
    const real n0 = fmax(scattering_u_nu_of_slice(a, s0) * R(2.0) - R(1.0), centre - spread);
    const real n1 = fmin(scattering_u_nu_of_slice(a, s1) * R(2.0) - R(1.0), centre + spread);
    const real f = n1 > n0 ? clamp_real((nu_q - n0) / (n1 - n0), R(0.0), R(1.0)) : R(0.0);
    GLOBAL const real* row = tex + (k * plane + j * wd) * NCH;
    GLOBAL const real* t00 = row + (s0 * a->mu_s_size + xs.i0) * NCH;
    GLOBAL const real* t01 = row + (s0 * a->mu_s_size + xs.i1) * NCH;
    GLOBAL const real* t10 = row + (s1 * a->mu_s_size + xs.i0) * NCH;
    GLOBAL const real* t11 = row + (s1 * a->mu_s_size + xs.i1) * NCH;
    NOTE_TEXEL(tex, t00 - tex);
    NOTE_TEXEL(tex, t01 - tex);
    NOTE_TEXEL(tex, t10 - tex);
    NOTE_TEXEL(tex, t11 - tex);
    const real w0 = w * (R(1.0) - f), w1 = w * f;
    for (int c = 0; c < NCH; ++c) {
      col0[c] += w0 * t00[c] + w1 * t10[c];
      col1[c] += w0 * t01[c] + w1 * t11[c];
    }
  }
  for (int c = 0; c < NCH; ++c)
    out[c] = geometric ? mu_s_blend_near(col0[c], col1[c], xs.fx) : (R(1.0) - xs.fx) * col0[c] + xs.fx * col1[c];
}
/* Multiple scattering along the ray (h, mu) of length d_b to its boundary. */
FN void multiple_scattering_ray(const AtmosphereParameters* a, GLOBAL const real* T, GLOBAL const real* J, real h,
                                real mu, real d_b, int hits_ground, real mu_s, real nu, real* out) {
  real fixed[NCH], s[RAY_STRIDE];
  for (int c = 0; c < NCH; ++c) out[c] = R(0.0);
  transmittance_fixed_end(a, T, h, mu, hits_ground, fixed);
  for (int i = 0; i <= SCATTERING_STEPS; ++i) {
    ray_sample(a, T, h, mu, hits_ground, d_b, fixed, i, s);
    multiple_scattering_add(a, J, s, mu_s, nu, out);
  }
}

/* ---- the sky-view table (lookup.cl, "The sky-view table") ----------------------------------
 * Texel id of a table of n_az × n_view × (n_sun · n_h) texels over altitudes grid[0..1] (km) and
 * sun elevations grid[2..3] (rad): its camera altitude h, view cosine mu, sun cosine mu_s, ν and
 * whether the view meets the ground (the half of the view axis it is in). */
FN real sky_view_node(int i, int n) { return n > 1 ? (real)i / (real)(n - 1) : R(0.0); }
/* The ray of altitude node i_h and view node i_v: its altitude, cosine and half (meets the ground). */
FN void sky_view_ray(const AtmosphereParameters* a, const real* grid, int n_h, int n_view, int i_h, int i_v, real* h,
                     real* mu, int* ground) {
  const int half_view = n_view / 2;
  *h = clamp_altitude(a, grid[0] + (grid[1] - grid[0]) * sky_view_node(i_h, n_h));
  const real theta_h = sky_view_horizon_zenith(a->bottom_radius, *h);
  real theta;
  if (i_v < half_view) {
    const real x = sky_view_node(half_view - 1 - i_v, half_view);
    theta = theta_h + (ATM_PI - theta_h) * x * x;
    *ground = 1;
  } else {
    const real x = sky_view_node(i_v - half_view, half_view);
    theta = theta_h * (R(1.0) - x * x);
    *ground = 0;
  }
  *mu = clamp_cosine(cos(theta));
}
/* The sun of sun node i_s and azimuth node i_az seen along a ray of cosine mu: μ_s and ν. */
FN void sky_view_sun(const real* grid, int n_sun, int n_az, int i_s, int i_az, real mu, real* mu_s, real* nu) {
  const real e = grid[2] + (grid[3] - grid[2]) * sky_view_node(i_s, n_sun);
  const real phi = ATM_PI * sky_view_node(i_az, n_az);
  *mu_s = clamp_cosine(sin(e));
  *nu = clamp_cosine(mu * *mu_s + safe_sqrt(R(1.0) - mu * mu) * cos(e) * cos(phi));
}
FN void sky_view_texel_params(const AtmosphereParameters* a, const real* grid, int n_h, int n_sun, int n_view,
                              int n_az, int id, real* h, real* mu, real* mu_s, real* nu, int* ground) {
  const int i_az = id % n_az, i_v = (id / n_az) % n_view, k = id / (n_az * n_view);
  sky_view_ray(a, grid, n_h, n_view, k % n_h, i_v, h, mu, ground);
  sky_view_sun(grid, n_sun, n_az, k / n_h, i_az, *mu, mu_s, nu);
}
/* A sky-view ray sample: ray_sample's entries, then the sample's own μ and √(1 − μ²)
 * (SKY_RAY_MU, SKY_RAY_SIN) and those of the four texel rows its J read blends
 * (SKY_RAY_CORNER_MU, SKY_RAY_CORNER_SIN: rows j0/j1 × planes k0/k1 of texture_3d_rows,
 * scattering_lookup_azimuthal's corners), which every sun and azimuth of the ray shares. */
#define SKY_RAY_MU RAY_STRIDE
#define SKY_RAY_SIN (RAY_STRIDE + 1)
#define SKY_RAY_CORNER_MU (RAY_STRIDE + 2)
#define SKY_RAY_CORNER_SIN (RAY_STRIDE + 6)
#define SKY_RAY_EXTRA 10 /* entries after the transmittances */
#define SKY_RAY_STRIDE (RAY_STRIDE + SKY_RAY_EXTRA)
FN void sky_view_ray_sample(const AtmosphereParameters* a, GLOBAL const real* T, real h, real mu, int hits_ground,
                            real d_b, const real* fixed, int i, real* s) {
  ray_sample(a, T, h, mu, hits_ground, d_b, fixed, i, s);
  real h_i, d_i;
  int ground_i;
  scattering_ray_from_uv(a, s[RAY_U_MU], s[RAY_U_R], &h_i, &s[SKY_RAY_MU], &d_i, &ground_i);
  s[SKY_RAY_SIN] = sqrt(fmax(R(1.0) - s[SKY_RAY_MU] * s[SKY_RAY_MU], R(0.0)));
  const TexelRows rows = texture_3d_rows(a->mu_size, a->r_size, s[RAY_U_MU], s[RAY_U_R]);
  for (int q = 0; q < 4; ++q) {
    const int j = (q & 1) ? rows.j1 : rows.j0, k = (q & 2) ? rows.k1 : rows.k0;
    real h_q, mu_q, d_q;
    int ground_q;
    scattering_ray_of_texel(a, j, k, &h_q, &mu_q, &d_q, &ground_q);
    s[SKY_RAY_CORNER_MU + q] = mu_q;
    s[SKY_RAY_CORNER_SIN + q] = sqrt(fmax(R(1.0) - mu_q * mu_q, R(0.0)));
  }
}
/* Adds sky-view sample s's single scattering (sum_r, sum_m) and, orders_above_one ≠ 0, its
 * J_sum term (ms) for the sun (mu_s, nu) of the ray's origin. */
FN void sky_view_add_sample(const AtmosphereParameters* a, GLOBAL const real* T, GLOBAL const real* J_sum,
                            int orders_above_one, int mu_s_geometric, const real* s, real mu_s, real nu, real* sum_r,
                            real* sum_m, real* ms) {
  single_scattering_add(a, T, s, mu_s, nu, sum_r, sum_m);
  if (orders_above_one == 0) return;
  const real mu_s_i = ray_sample_mu_s(s, mu_s, nu);
  real uvwz[4], j[NCH];
  uvwz[0] = scattering_u_nu_at(nu);
  uvwz[1] = scattering_u_mu_s(a, mu_s_i);
  uvwz[2] = s[RAY_U_MU];
  uvwz[3] = s[RAY_U_R];
  scattering_lookup_azimuthal(a, J_sum, uvwz, s + SKY_RAY_CORNER_MU, s + SKY_RAY_CORNER_SIN, s[SKY_RAY_MU],
                              s[SKY_RAY_SIN], mu_s_i, nu, mu_s_geometric, j);
  for (int c = 0; c < NCH; ++c) ms[c] += j[c] * s[RAY_T + c] * s[RAY_W];
}
FN void sky_view_finish(const AtmosphereParameters* a, const real* sum_r, const real* sum_m, const real* ms, real nu,
                        real* out) {
  real ray[NCH], mie[NCH];
  single_scattering_finish(a, sum_r, sum_m, ray, mie);
  const real p = rayleigh_phase(nu);
  for (int c = 0; c < NCH; ++c) {
    out[c] = ray[c] * p + ms[c];
    out[NCH + c] = mie[c];
  }
}
/* Its values: out[c] = single Rayleigh × P_R(ν) + Σ_{n≥2} L_n, out[NCH + c] = single Mie (no
 * phase), integrated along the texel's exact ray with the 4D texture's own rules
 * (single_scattering_ray's samples and sums; J read by scattering_lookup_azimuthal); J_sum = Σ_{n≥2}
 * J_n in the scattering texture's layout (L is linear in J: the sum of each order's integral).
 * orders_above_one 0: single scattering only (J_sum unread). mu_s_geometric 1
 * (SkyView::geometric_density: a scene in deep twilight with `quadrature: {mu_s_blend:
 * geometric}`, the default): J_sum's two μ_s texels joined by mu_s_blend, as the shipped lookups
 * join theirs (scattering_lookup_azimuthal): in deep twilight J falls by about e per degree of the
 * local sun and the ray's far points see the sun lower than the camera does, so a linear blend
 * reads the table's densities too bright (docs/atmosphere-method.md, "Deep twilight: the
 * sky-view table's density reads"). */
FN void sky_view_texel(const AtmosphereParameters* a, GLOBAL const real* T, GLOBAL const real* J_sum,
                       int orders_above_one, int mu_s_geometric, const real* grid, int n_h, int n_sun, int n_view,
                       int n_az, int id, real* out) {
  real h, mu, mu_s, nu, fixed[NCH], s[SKY_RAY_STRIDE], sum_r[NCH], sum_m[NCH], ms[NCH];
  int ground;
  sky_view_texel_params(a, grid, n_h, n_sun, n_view, n_az, id, &h, &mu, &mu_s, &nu, &ground);
  const real d = distance_to_nearest_boundary(a, h, mu, ground);
  transmittance_fixed_end(a, T, h, mu, ground, fixed);
  for (int c = 0; c < NCH; ++c) sum_r[c] = sum_m[c] = ms[c] = R(0.0);
  for (int i = 0; i <= SCATTERING_STEPS; ++i) {
    sky_view_ray_sample(a, T, h, mu, ground, d, fixed, i, s);
    sky_view_add_sample(a, T, J_sum, orders_above_one, mu_s_geometric, s, mu_s, nu, sum_r, sum_m, ms);
  }
  sky_view_finish(a, sum_r, sum_m, ms, nu, out);
}

/* sky_view_texel from its ray's samples (sky_view_ray_sample of the texel's (altitude, view) ray,
 * shared by every sun and azimuth of that ray; sample i at samples[i · SKY_RAY_STRIDE]): the
 * same sums. */
FN void sky_view_texel_from_samples(const AtmosphereParameters* a, GLOBAL const real* T, GLOBAL const real* J_sum,
                                    int orders_above_one, int mu_s_geometric, GLOBAL const real* samples, real mu_s,
                                    real nu, real* out) {
  real sum_r[NCH], sum_m[NCH], ms[NCH], s[SKY_RAY_STRIDE];
  for (int c = 0; c < NCH; ++c) sum_r[c] = sum_m[c] = ms[c] = R(0.0);
  for (int i = 0; i <= SCATTERING_STEPS; ++i) {
    for (int k = 0; k < SKY_RAY_STRIDE; ++k) s[k] = samples[i * SKY_RAY_STRIDE + k];
    sky_view_add_sample(a, T, J_sum, orders_above_one, mu_s_geometric, s, mu_s, nu, sum_r, sum_m, ms);
  }
  sky_view_finish(a, sum_r, sum_m, ms, nu, out);
}

/* ---- scattering density J_n (paper Eq. 7's integrand, 16 × 32 midpoint rule) ---------- */
/* Entry of the density-incidence table: what the 32 φ of incident direction θ_l share at
 * (h, mu_s): the ν-slices of the incoming radiance, and the ground seen along θ_l. */
FN int incidence_stride(const AtmosphereParameters* a) { return 2 * a->nu_size * NCH + NCH + INC_FIXED; }
#define INC_SOURCE(a) 0                                     /* NU × NCH: order − 1 (Rayleigh at order 2) */
#define INC_MIE(a) ((a)->nu_size * NCH)                     /* NU × NCH: single Mie (order 2 only) */
#define INC_GROUND_TERM(a) (2 * (a)->nu_size * NCH)         /* NCH: T to the ground × albedo / π */
#define INC_GROUND(a) (INC_GROUND_TERM(a) + NCH)            /* 1 if the direction hits the ground */
#define INC_DISTANCE(a) (INC_GROUND(a) + 1)                 /* distance to the ground, km */
#define INC_NZ(a) (INC_GROUND(a) + 2)                       /* ground normal r + cos θ · distance */
#define INC_INV_N(a) (INC_GROUND(a) + 3)                    /* 1 / |ground normal| (does not depend on φ) */
#define INC_COS(a) (INC_GROUND(a) + 4)
#define INC_SIN(a) (INC_GROUND(a) + 5)
#define INC_MAX (2 * NU_MAX * NCH + NCH + INC_FIXED)

/* Node l of the density's θ rule and its width dθ: the midpoint rule in y ∈ (−1, 1), n =
 * a->density_theta equal steps, of θ(y) = π/2 (1 + sgn(y) |y|^p), dθ = (π/2) p |y|^(p−1) dy.
 * p = 1 is the reference's uniform rule, θ_l = (l + ½) π/n. p > 1 packs the nodes towards the
 * horizon (θ = π/2), where the incoming light changes fastest: the limb, the ground's horizon
 * just below it, and in twilight the only light there is — single scattering from sunlit air
 * hundreds of km away, arriving within a few degrees of the horizontal. n is even, so y = 0
 * falls between nodes and each half is a smooth midpoint rule (second order in 1/n). */
FN void density_theta_node(const AtmosphereParameters* a, int l, real* theta, real* d_theta) {
  const real n = (real)a->density_theta;
  const real y = ((real)(2 * l + 1) - n) / n;
  const real p = a->density_theta_power;
  const real ay = fabs(y);
  const real stretch = pow(ay, p - R(1.0));
  *theta = R(0.5) * ATM_PI * (R(1.0) + (y < R(0.0) ? -ay : ay) * stretch);
  *d_theta = ATM_PI * p * stretch / n;
}

/* delta_rayleigh/delta_mie: single scattering (used when order == 2); delta_multiple:
 * radiance of order n − 1 (order > 2). */
FN void density_incidence(const AtmosphereParameters* a, GLOBAL const real* T, GLOBAL const real* delta_rayleigh,
                          GLOBAL const real* delta_mie, GLOBAL const real* delta_multiple, real h, real mu_s,
                          int order, int l, real* e) {
  real theta, d_theta;
  density_theta_node(a, l, &theta, &d_theta);
  const real cos_theta = cos(theta), sin_theta = sin(theta);
  const int ground = ray_hits_ground(a, h, cos_theta);
  real distance = R(0.0);
  for (int c = 0; c < NCH; ++c) e[INC_GROUND_TERM(a) + c] = R(0.0);
  if (ground) {
    distance = distance_to_bottom(a, h, cos_theta);
    transmittance_along(a, T, h, cos_theta, distance, 1, e + INC_GROUND_TERM(a));
    for (int c = 0; c < NCH; ++c) e[INC_GROUND_TERM(a) + c] *= a->ground_albedo[c] / ATM_PI;
  }
  /* ground normal n = r·z + distance·omega_i */
  const real n_z = radius_of(a, h) + cos_theta * distance;
  const real n_xy = sin_theta * distance;
  e[INC_GROUND(a)] = ground ? R(1.0) : R(0.0);
  e[INC_DISTANCE(a)] = distance;
  e[INC_NZ(a)] = n_z;
  e[INC_INV_N(a)] = R(1.0) / sqrt(n_xy * n_xy + n_z * n_z);
  e[INC_COS(a)] = cos_theta;
  e[INC_SIN(a)] = sin_theta;
  real uvwz[4];
  scattering_uvwz(a, h, cos_theta, mu_s, R(0.0), ground, uvwz);
  scattering_slices(a, order == 2 ? delta_rayleigh : delta_multiple, uvwz[1], uvwz[2], uvwz[3], e + INC_SOURCE(a));
  if (order == 2) scattering_slices(a, delta_mie, uvwz[1], uvwz[2], uvwz[3], e + INC_MIE(a));
}

/* The density rule's weights of the view's phase functions for a view of cosine mu,
 * q_X = Σ_{θ,φ} P_X(ω·ω_i) dω (X = R, M; 1 for the exact integral), returned as the factors
 * the density multiplies them by: 1/q_X with density_phase_norm, else 1. Normalised, each phase
 * function's weights sum to 1 and the density scatters exactly β_s ρ of a uniform light (energy
 * conservation, whatever the rule). As the rule gives them, the 16-node horizon rule's sums are
 * 1.007–1.011 (Rayleigh), 1.003–1.094 (Mie, g 0.7) and 0.97–1.17 (g 0.8), worst towards the
 * nadir and the zenith, where its θ nodes are widest: each order scatters that much more, or
 * less, light than it received — for dust a baked sky a few % too bright
 * (docs/atmosphere-method.md, "The density's phase weights"). The same for every texel of a
 * (μ, r) row: the bake tabulates them per row (density_phase_table). */
FN void density_phase_factors(const AtmosphereParameters* a, real mu, real* f_r, real* f_m) {
  *f_r = *f_m = R(1.0);
  if (a->density_phase_norm == R(0.0)) return;
  const real omega_x = sqrt(fmax(R(1.0) - mu * mu, R(0.0)));
  const real d_angle = ATM_PI / (real)DENSITY_SPHERE_STEPS;
  real q_r = R(0.0), q_m = R(0.0);
  for (int l = 0; l < a->density_theta; ++l) {
    real theta_l, d_theta;
    density_theta_node(a, l, &theta_l, &d_theta);
    const real cos_theta = cos(theta_l), sin_theta = sin(theta_l);
    const real d_omega = R(2.0) * d_theta * d_angle * sin_theta; /* φ and 2π − φ */
    for (int m = 0; m < DENSITY_SPHERE_STEPS; ++m) {
      const real nu2 = cos(((real)m + R(0.5)) * d_angle) * sin_theta * omega_x + cos_theta * mu;
      q_r += rayleigh_phase(nu2) * d_omega;
      q_m += mie_phase(a->mie_g, nu2) * d_omega;
    }
  }
  *f_r = R(1.0) / q_r;
  *f_m = R(1.0) / q_m;
}

/* J_n at (h, mu, mu_s) and `count` values nu[k] (a texel row of the ν axis) from the n_θ
 * incidence entries of (h, mu_s) and the ground irradiance of order n − 2 (direct for order
 * 2); out[k·NCH + c], per km per sr.
 *
 * The sum is arranged so that the work per incident direction does not grow with the channel
 * count (the same quadrature, the same terms, summed in another order). For direction ω_i =
 * (θ_l, φ_m) and the sun of nu[k], the sky's light is linear between the NU stored slices:
 * I(ν_i) = Σ_s hat_s(ν_i) I_s (slice_weights), and the light scattered towards the view is
 * (β_R ρ_R P_R(ω·ω_i) + β_M ρ_M P_M(ω·ω_i)) dω. So each θ_l reduces to channel-independent
 * weights over the 32 φ,
 *   A_X[s] = Σ_φ P_X(ω·ω_i) hat_s(ν_i) dω        (X = R, M: the view's phase function),
 * and J gains Σ_s I_s[c] (β_R[c] A_R[s] + β_M[c] A_M[s]). At order 2 the light is single
 * scattering stored without its phase function, so the weights also carry P_R(ν_i) (for the
 * Rayleigh slices) or P_M(ν_i) (Mie): four arrays. The ground's light, T·albedo/π times the
 * ground irradiance at the ground normal's μ_s, is added per direction. The view's phase
 * functions, which do not depend on ν, are computed once per θ_l for the whole row, times
 * norm_r and norm_m (density_phase_factors).
 *
 * The row's suns are the innermost loop, in lanes of LANES (a fixed trip count; lanes past
 * `count` get a sun at ν = μ μ_s and are discarded), inside the loop over θ: each θ's incidence
 * entry and view phase functions serve every chunk of lanes. Each sun's sums run over (θ, φ)
 * in the same order as one sun at a time would, so the lane width does not change a result. */
FN void scattering_density(const AtmosphereParameters* a, GLOBAL const real* incidence,
                           GLOBAL const real* delta_irradiance, real h, real mu, real mu_s, const real* nu, int count,
                           int order, real norm_r, real norm_m, real* out) {
  const real omega_x = sqrt(fmax(R(1.0) - mu * mu, R(0.0)));
  const real d_angle = ATM_PI / (real)DENSITY_SPHERE_STEPS;
  const real rho_r = profile_density(&a->rayleigh_density, h);
  const real rho_m = profile_density(&a->mie_density, h);
  real beta_r[NCH], beta_m[NCH];
  for (int c = 0; c < NCH; ++c) {
    beta_r[c] = a->rayleigh_scattering[c] * rho_r;
    beta_m[c] = a->mie_scattering[c] * rho_m;
  }
  for (int k = 0; k < count * NCH; ++k) out[k] = R(0.0);
  /* phi_m and 2π − phi_m share cos(phi) (so the view's phase functions, since omega_y = 0)
   * and the length of the ground normal: the loop visits them in pairs, sin(phi) = ±sin_phi[m]. */
  real cos_phi[DENSITY_SPHERE_STEPS], sin_phi[DENSITY_SPHERE_STEPS];
  for (int m = 0; m < DENSITY_SPHERE_STEPS; ++m) {
    const real phi = ((real)m + R(0.5)) * d_angle;
    cos_phi[m] = cos(phi);
    sin_phi[m] = sin(phi);
  }
  const int single = order == 2;
  const int stride = incidence_stride(a);
  real e[INC_MAX];
  /* per φ of the current θ: the view's phase functions × dω, and the direction's x and y */
  real view_r[DENSITY_SPHERE_STEPS], view_m[DENSITY_SPHERE_STEPS], wx[DENSITY_SPHERE_STEPS], wy[DENSITY_SPHERE_STEPS];
  real scatter[DENSITY_SPHERE_STEPS * NCH]; /* β_R[c] view_r + β_M[c] view_m: the ground's light */
  /* per lane: the sun's x and y in the view's frame; A_R, A_M of the source slices, then
   * (order 2) of the Mie slices, [s][lane]; the ground's light [lane][c] */
  real sun_x[LANES], sun_y[LANES], nu_i[LANES], f[LANES];
  /* per (φ, side) of the current θ, [2 m + side][lane]: the slice position of ν_i, and at order
   * 2 its phase functions */
  real x[2 * DENSITY_SPHERE_STEPS * LANES], p_r[2 * DENSITY_SPHERE_STEPS * LANES], p_m[2 * DENSITY_SPHERE_STEPS * LANES];
  int t0[LANES], t1[LANES]; /* the ground irradiance's taps */
  real a_r[NU_MAX * LANES], a_m[NU_MAX * LANES];
  real a_r_mie[NU_MAX * LANES], a_m_mie[NU_MAX * LANES];
  real ground_light[NCH * LANES];
  for (int l = 0; l < a->density_theta; ++l) {
    for (int k = 0; k < stride; ++k) e[k] = incidence[l * stride + k];
    const int ground = e[INC_GROUND(a)] != R(0.0);
    const real cos_theta = e[INC_COS(a)], sin_theta = e[INC_SIN(a)];
    const real distance = e[INC_DISTANCE(a)], n_z = e[INC_NZ(a)], inv_n = e[INC_INV_N(a)];
    real theta_l, d_theta;
    density_theta_node(a, l, &theta_l, &d_theta);
    const real d_omega = d_theta * d_angle * sin_theta;
    /* the sun's cosine to the ground normal n = r·z + distance·ω_i is (distance·ν_i + (n_z −
     * distance·cos θ)·μ_s)/|n|, affine in ν_i */
    const real ground_slope = distance * inv_n, ground_offset = (n_z - distance * cos_theta) * mu_s * inv_n;
    for (int m = 0; m < DENSITY_SPHERE_STEPS; ++m) {
      wx[m] = cos_phi[m] * sin_theta;
      wy[m] = sin_phi[m] * sin_theta;
      const real nu2 = wx[m] * omega_x + cos_theta * mu;
      view_r[m] = rayleigh_phase(nu2) * d_omega * norm_r;
      view_m[m] = mie_phase(a->mie_g, nu2) * d_omega * norm_m;
      for (int c = 0; c < NCH; ++c) scatter[m * NCH + c] = beta_r[c] * view_r[m] + beta_m[c] * view_m[m];
    }
    for (int k0 = 0; k0 < count; k0 += LANES) {
      for (int k = 0; k < LANES; ++k) {
        const real nu_k = k0 + k < count ? nu[k0 + k] : mu * mu_s;
        sun_x[k] = omega_x == R(0.0) ? R(0.0) : (nu_k - mu * mu_s) / omega_x;
        sun_y[k] = sqrt(fmax(R(1.0) - sun_x[k] * sun_x[k] - mu_s * mu_s, R(0.0)));
      }
      for (int i = 0; i < NCH * LANES; ++i) ground_light[i] = R(0.0);
      real x_lo[LANES], x_hi[LANES]; /* each lane's range of x over (φ, side) */
      for (int k = 0; k < LANES; ++k) {
        x_lo[k] = (real)(NU_SLICES(a) - 1);
        x_hi[k] = R(0.0);
      }
      for (int m = 0; m < DENSITY_SPHERE_STEPS; ++m) {
        for (int side = 0; side < 2; ++side) {
          const real wy_s = side == 0 ? wy[m] : -wy[m];
          const int ms = (2 * m + side) * LANES;
          for (int k = 0; k < LANES; ++k) {
            nu_i[k] = wx[m] * sun_x[k] + cos_theta * mu_s + wy_s * sun_y[k];
            x[ms + k] = slice_position(a, nu_i[k]);
            x_lo[k] = fmin(x_lo[k], x[ms + k]);
            x_hi[k] = fmax(x_hi[k], x[ms + k]);
          }
          if (single)
            for (int k = 0; k < LANES; ++k) {
              p_r[ms + k] = rayleigh_phase(nu_i[k]);
              p_m[ms + k] = mie_phase(a->mie_g, nu_i[k]);
            }
          if (ground) {
            /* the ground irradiance's taps across the lanes, then each lane's channels */
            for (int k = 0; k < LANES; ++k)
              ground_irradiance_taps(a, ground_slope * nu_i[k] + ground_offset, &t0[k], &t1[k], &f[k]);
            for (int k = 0; k < LANES; ++k) {
              NOTE_TEXEL(delta_irradiance, t0[k]);
              NOTE_TEXEL(delta_irradiance, t1[k]);
            }
            for (int k = 0; k < LANES; ++k)
              for (int c = 0; c < NCH; ++c)
                ground_light[k * NCH + c] += scatter[m * NCH + c] * ((R(1.0) - f[k]) * delta_irradiance[t0[k] + c] +
                                                                      f[k] * delta_irradiance[t1[k] + c]);
          }
        }
      }
      /* The weights slice by slice, slice_weights as a hat function of x (zero away from the two
       * slices around it: fixed-length loops across the lanes, without indexing by x). A
       * slice's sums over (φ, side) stay in registers across that loop, in the order (m, side).
       * ν_i spans cos θ μ_s ± sin θ |sun_xy| over φ, so near the poles of θ a few slices hold
       * every x: the slices outside [floor(min x), floor(max x) + 1] have hat weight 0 for every
       * x: neither loop below visits them. */
      real lo = x_lo[0], hi = x_hi[0];
      for (int k = 1; k < LANES; ++k) {
        lo = fmin(lo, x_lo[k]);
        hi = fmax(hi, x_hi[k]);
      }
      const int s_lo = clamp_int((int)floor(lo), 0, NU_SLICES(a) - 1);
      const int s_hi = clamp_int((int)floor(hi) + 1, 0, NU_SLICES(a) - 1);
      for (int s = s_lo; s <= s_hi; ++s) {
        real sr[LANES], sm[LANES], srm[LANES], smm[LANES];
        for (int k = 0; k < LANES; ++k) sr[k] = sm[k] = srm[k] = smm[k] = R(0.0);
        if (single) {
          for (int ms = 0; ms < 2 * DENSITY_SPHERE_STEPS; ++ms)
            for (int k = 0; k < LANES; ++k) {
              const int i = ms * LANES + k;
              const real w = hat(x[i], s);
              sr[k] += view_r[ms / 2] * p_r[i] * w;
              sm[k] += view_m[ms / 2] * p_r[i] * w;
              srm[k] += view_r[ms / 2] * p_m[i] * w;
              smm[k] += view_m[ms / 2] * p_m[i] * w;
            }
        } else {
          for (int ms = 0; ms < 2 * DENSITY_SPHERE_STEPS; ++ms)
            for (int k = 0; k < LANES; ++k) {
              const real w = hat(x[ms * LANES + k], s);
              sr[k] += view_r[ms / 2] * w;
              sm[k] += view_m[ms / 2] * w;
            }
        }
        for (int k = 0; k < LANES; ++k) {
          a_r[s * LANES + k] = sr[k];
          a_m[s * LANES + k] = sm[k];
          a_r_mie[s * LANES + k] = srm[k];
          a_m_mie[s * LANES + k] = smm[k];
        }
      }
      for (int k = 0; k < LANES && k0 + k < count; ++k) {
        real* const j = out + (k0 + k) * NCH;
        for (int s = s_lo; s <= s_hi; ++s) {
          const real* const source = e + INC_SOURCE(a) + s * NCH;
          const real ar = a_r[s * LANES + k], am = a_m[s * LANES + k];
          for (int c = 0; c < NCH; ++c) j[c] += source[c] * (beta_r[c] * ar + beta_m[c] * am);
          if (single) {
            const real* const mie = e + INC_MIE(a) + s * NCH;
            const real arm = a_r_mie[s * LANES + k], amm = a_m_mie[s * LANES + k];
            for (int c = 0; c < NCH; ++c) j[c] += mie[c] * (beta_r[c] * arm + beta_m[c] * amm);
          }
        }
        if (ground)
          for (int c = 0; c < NCH; ++c) j[c] += e[INC_GROUND_TERM(a) + c] * ground_light[k * NCH + c];
      }
    }
  }
}

/* ---- the orders beyond the last (`orders_tail: geometric`) -------------------------- */
/* The density of every order from n on, J_{≥n} = Σ_{k≥0} J_{n+k}, from the last two densities
 * at one texel and channel, as a geometric series: each order beyond n is taken to be ρ times
 * the one before, ρ = J_n / J_{n−1} (this texel's own ratio), so J_{≥n} = J_n / (1 − ρ).
 * Successive orders tend to a fixed ratio at every texel — the light settles into the scattering
 * operator's leading eigenfunction, ~0.5 per order in the default Earth's blue by order 5 — and
 * the texel's ratio keeps what a global one loses: in the planet's shadow every order is a
 * larger fraction of the one before than in daylight. ρ is clamped to [0, TAIL_RATIO_MAX]
 * (no tail where J_{n−1} ≤ 0): a ratio near 1 is an optically thick medium, whose orders a
 * series started this early cannot stand for (`orders: auto` there). J per km. */
#define TAIL_RATIO_MAX R(0.9)
FN real geometric_tail(real j, real j_prev) {
  const real rho = j_prev > R(0.0) ? fmin(fmax(j / j_prev, R(0.0)), TAIL_RATIO_MAX) : R(0.0);
  return j / (R(1.0) - rho);
}

/* ---- ground irradiance ---------------------------------------------------------------- */
/* The mean cosine of the sun on a horizontal surface over the visible part of its disc
 * (the reference's approximation near the horizon). */
FN real sun_horizontal_cosine(const AtmosphereParameters* a, real mu_s) {
  const real alpha = a->sun_angular_radius;
  return mu_s < -alpha ? R(0.0) : (mu_s > alpha ? mu_s : (mu_s + alpha) * (mu_s + alpha) / (R(4.0) * alpha));
}
/* Direct sun on a horizontal surface: E_sun T(h, mu_s) × the mean cosine over the visible
 * part of the sun disc. */
FN void direct_irradiance(const AtmosphereParameters* a, GLOBAL const real* T, real h, real mu_s, real* out) {
  const real cos_factor = sun_horizontal_cosine(a, mu_s);
  transmittance_to_top(a, T, h, mu_s, out);
  for (int c = 0; c < NCH; ++c) out[c] *= a->solar_irradiance[c] * cos_factor;
}
/* Sky irradiance from scattering of order `order` (≥ 1) on a horizontal surface at h:
 * ∫_hemisphere L(ω) ω_z dω, 16 × 64 midpoint rule. Every ray is looked up as not hitting
 * the ground, as the reference does. */
FN void indirect_irradiance(const AtmosphereParameters* a, GLOBAL const real* delta_rayleigh,
                            GLOBAL const real* delta_mie, GLOBAL const real* delta_multiple, real h, real mu_s,
                            int order, real* out) {
  const real d_angle = ATM_PI / (real)IRRADIANCE_HEMISPHERE_STEPS;
  const real omega_s[3] = {sqrt(fmax(R(1.0) - mu_s * mu_s, R(0.0))), R(0.0), mu_s};
  GLOBAL const real* source = order == 1 ? delta_rayleigh : delta_multiple;
  real slices_r[NU_MAX * NCH], slices_m[NU_MAX * NCH], uvwz[4], l[NCH];
  for (int c = 0; c < NCH; ++c) out[c] = R(0.0);
  for (int j = 0; j < IRRADIANCE_HEMISPHERE_STEPS / 2; ++j) {
    const real theta = ((real)j + R(0.5)) * d_angle;
    const real cos_theta = cos(theta), sin_theta = sin(theta);
    scattering_uvwz(a, h, cos_theta, mu_s, R(0.0), 0, uvwz);
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
