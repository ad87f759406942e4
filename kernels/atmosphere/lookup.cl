/* lookup.cl — the geometry and texture coordinates of the atmosphere's baked textures, as
 * scalar functions of altitude, written once in the common subset of OpenCL C, C++ and GLSL.
 *
 * Compiled three ways, the same text each time:
 *   - into the bake's kernels (kernels/atmosphere/atmosphere.cl includes it; real = float),
 *   - into the C++ double reference (src/kinds/atmosphere/bake/reference.hpp) and the host's
 *     rendering functions (src/kinds/atmosphere/shader/shader_host.hpp, with render.glsl),
 *   - into the bundle's sampling.glsl, pasted verbatim after a prelude that defines real, FN,
 *     R(x), REQUIRE, fmax, fmin and fabs (src/kinds/atmosphere/shader/render.cpp, sampling_glsl).
 * Hence the subset: scalars (real, int) only, sizes passed as real (no int → real casts, which
 * C and GLSL spell differently), no pointers, structs, `const` locals (GLSL wants constant
 * initialisers for those), overloads or names GLSL reserves (half, fixed, sample, input, ...);
 * flags are int 0/1, tested with != 0.
 *
 * Geometry (Bruneton 2017, "Precomputed Atmospheric Scattering: a New Implementation", §
 * "Distance to the top/bottom atmosphere boundary", rewritten in the altitude h = r − rb):
 * rb, rt the bottom and top radii (km), h the altitude above the ground (km), mu the cosine of a
 * ray's zenith angle, mu_s the sun's, nu the cosine between view and sun. rb ≈ 6360 km has a
 * float32 spacing of 0.49 m, comparable to the altitude of the lowest texel rows, so r itself is
 * never a state variable; the cancelling combinations are written in h (atmosphere.cl's header
 * derives each):
 *   ρ² = r² − rb² = h (h + 2 rb),   rt² − r² = (t − h)(t + h + 2 rb),  t = rt − rb,
 *   distance to the ground  ρ² / (√(r²μ² − ρ²) − rμ),  to the top (μ > 0) (rt² − r²)/(√(…) + rμ).
 *
 * Texture coordinates (Bruneton 2017, § "Precomputations", the functions
 * GetTransmittanceTextureUvFromRMu, GetIrradianceTextureUvFromRMuS and
 * GetScatteringTextureUvwzFromRMuMuSNu; texel centres at (i + 0.5)/n):
 *   coord(x, n) = 0.5/n + x (1 − 1/n)
 *   transmittance  u = coord((d − d_min)/(d_max − d_min), W), d_min = rt − r, d_max = ρ + H,
 *                  v = coord(ρ/H, H_rows), H = √(rt² − rb²)
 *   irradiance     u = coord(μ_s/2 + 1/2, W), v = coord(h/t, H_rows)
 *   scattering     u_ν = (ν + 1)/2 (corner-sampled: divisor NU − 1),
 *                  u_μs = coord(max(1 − a/A, 0)/(1 + a), MU_S) with a, A the normalised
 *                  distances to the top at μ_s and at μ_s,min from the ground,
 *                  u_μ in two halves (rays that hit the ground below 0.5), u_r = coord(ρ/H, R).
 */
#include "common/real.h"

/* ---- small helpers ------------------------------------------------------------------- */
FN real clamp_real(real x, real lo, real hi) { return fmin(fmax(x, lo), hi); }
FN real clamp_cosine(real mu) { return clamp_real(mu, R(-1.0), R(1.0)); }
FN real clamp_distance(real d) { return fmax(d, R(0.0)); }
FN real safe_sqrt(real x) { return sqrt(fmax(x, R(0.0))); }
FN real smooth_step(real e0, real e1, real x) {
  real t = clamp_real((x - e0) / (e1 - e0), R(0.0), R(1.0));
  return t * t * (R(3.0) - R(2.0) * t);
}
/* num/den capped at 1, 0 where den is 0 (a transmittance ratio through an opaque segment). */
FN real ratio_or_zero(real num, real den) { return den > R(0.0) ? fmin(num / den, R(1.0)) : R(0.0); }
FN real coord_of_unit(real x, real n) { return R(0.5) / n + x * (R(1.0) - R(1.0) / n); }
/* The blend between two μ_s texels a and b at weight g of b: geometric, a (b/a)^g, where both
 * are positive and within a factor 1000 of each other, else linear. In twilight the sky falls
 * by about e per degree of sun elevation, and a linear blend of such values overstates them
 * (the chord of a convex function): by up to 2× between the default texture's μ_s texels,
 * which lie 1.5° apart there; the geometric blend is exact for an exponential. Zeros (texels
 * whose rays see no sunlit air) keep the linear blend. */
FN real mu_s_blend(real a, real b, real g) {
  return (a > R(0.0) && b > R(0.0) && fmin(a, b) > R(1e-3) * fmax(a, b)) ? a * pow(b / a, g) : a + (b - a) * g;
}

/* ---- geometry in the altitude h ------------------------------------------------------ */
/* H = √(rt² − rb²): the distance to the top boundary along the horizon at the ground. */
FN real horizon_top_of(real rb, real rt) { return sqrt((rt - rb) * (rt + rb)); }
/* ρ² = r² − rb² = h (h + 2 rb); ρ is the distance to the horizon from altitude h. */
FN real rho2_of(real rb, real h) { return h * (h + R(2.0) * rb); }
/* rt² − r² = (t − h)(t + h + 2 rb). */
FN real top_gap2_of(real rb, real rt, real h) { return (rt - rb - h) * (rt - rb + h + R(2.0) * rb); }
/* The altitude of the point at r_d² − rb² = rho2 (rho2 may be negative: below the ground). */
FN real altitude_of_rho2_at(real rb, real rho2) { return rho2 / (sqrt(fmax(rho2 + rb * rb, R(0.0))) + rb); }
/* Distance from altitude h (≤ t) along mu to the top boundary. */
FN real distance_to_top_at(real rb, real rt, real h, real mu) {
  real r_mu = (rb + h) * mu;
  real gap2 = top_gap2_of(rb, rt, h);
  real s = safe_sqrt(r_mu * r_mu + gap2);
  return clamp_distance(mu > R(0.0) ? gap2 / (s + r_mu) : s - r_mu);
}
/* Distance from altitude h ≥ 0 along mu to the ground (meaningful when the ray hits it). */
FN real distance_to_ground_at(real rb, real h, real mu) {
  real r_mu = (rb + h) * mu;
  real rho2 = rho2_of(rb, h);
  real den = safe_sqrt(r_mu * r_mu - rho2) - r_mu;
  return den > R(0.0) ? clamp_distance(rho2 / den) : R(0.0);
}
/* 1 when the ray from altitude h along mu meets the ground, else 0. */
FN int ray_meets_ground(real rb, real h, real mu) {
  real r_mu = (rb + h) * mu;
  return (mu < R(0.0) && r_mu * r_mu - rho2_of(rb, h) >= R(0.0)) ? 1 : 0;
}
/* Altitude after travelling d along (h, mu): |x + d ω| − rb, without cancellation. */
FN real altitude_after(real rb, real h, real mu, real d) {
  return altitude_of_rho2_at(rb, d * d + R(2.0) * (rb + h) * mu * d + rho2_of(rb, h));
}
/* The point a distance e before the ground along a ray (h, mu) that hits it, measured back from
 * the ground point where the reversed ray rises with r_g μ_g = s = √(r²μ² − ρ²):
 * ρ_e² = e² + 2 s e (no cancellation near the ground), r_e μ_e = −(s + e).
 * Its altitude (unclamped), and its mu given that altitude: */
FN real altitude_before_ground(real rb, real h, real mu, real e) {
  real r_mu = (rb + h) * mu;
  real s = safe_sqrt(r_mu * r_mu - rho2_of(rb, h));
  return altitude_of_rho2_at(rb, e * (e + R(2.0) * s));
}
FN real cosine_before_ground(real rb, real h, real mu, real e, real h_e) {
  real r_mu = (rb + h) * mu;
  real s = safe_sqrt(r_mu * r_mu - rho2_of(rb, h));
  return clamp_cosine(-(s + e) / (rb + h_e));
}
/* The point at distance d along the ray (h, mu): its altitude (clamped to [0, t]) and its mu.
 * Rays that meet the ground are measured back from the ground point (the two functions above),
 * the others forward (altitude_after). */
FN real altitude_along_ray(real rb, real rt, real h, real mu, real d, int meets_ground) {
  real h_d = meets_ground != 0 ? altitude_before_ground(rb, h, mu, fmax(distance_to_ground_at(rb, h, mu) - d, R(0.0)))
                               : altitude_after(rb, h, mu, d);
  return clamp_real(h_d, R(0.0), rt - rb);
}
FN real cosine_along_ray(real rb, real h, real mu, real d, int meets_ground, real h_d) {
  return meets_ground != 0 ? cosine_before_ground(rb, h, mu, fmax(distance_to_ground_at(rb, h, mu) - d, R(0.0)), h_d)
                           : clamp_cosine(((rb + h) * mu + d) / (rb + h_d));
}
/* The visible fraction of the sun disc (angular radius alpha) above the horizon at altitude h
 * (smoothstep over the disc); the horizon's cosine −√(1 − (rb/r)²) is written −ρ/r. */
FN real sun_visible_at(real rb, real alpha, real h, real mu_s) {
  real r = rb + h;
  real sin_h = rb / r;
  real cos_h = -safe_sqrt(rho2_of(rb, h)) / r;
  return smooth_step(-sin_h * alpha, sin_h * alpha, mu_s - cos_h);
}

/* ---- phase functions (sr⁻¹), Bruneton 2017 § "Rayleigh / Mie" ------------------------ */
FN real rayleigh_phase(real nu) {
  REQUIRE(nu >= R(-1.0) && nu <= R(1.0));
  return R(3.0) / (R(16.0) * R(3.14159265358979323846)) * (R(1.0) + nu * nu);
}
/* Cornette–Shanks with asymmetry g. */
FN real mie_phase(real g, real nu) {
  REQUIRE(g > R(-1.0) && g < R(1.0));
  REQUIRE(nu >= R(-1.0) && nu <= R(1.0));
  real k = R(3.0) / (R(8.0) * R(3.14159265358979323846)) * (R(1.0) - g * g) / (R(2.0) + g * g);
  real x = R(1.0) + g * g - R(2.0) * g * nu;
  return k * (R(1.0) + nu * nu) / (x * sqrt(x));
}

/* Single Mie scattering of channel c rebuilt from a combined texel (Bruneton 2017, § "Combined
 * scattering textures", GetExtrapolatedSingleMieScattering): the scattering texture's channel
 * s_c and red s_r, the single Mie red m_r held in its alpha, and the Rayleigh and Mie scattering
 * coefficients of red and of channel c. Exact where single Mie and single Rayleigh have the same
 * spectral shape as their coefficients; the bake measures what it costs (rgba-combined). */
FN real extrapolated_single_mie(real s_c, real s_r, real m_r, real beta_rayleigh_r, real beta_mie_r,
                                real beta_rayleigh_c, real beta_mie_c) {
  return s_r > R(0.0) && beta_mie_r > R(0.0) && beta_rayleigh_c > R(0.0)
             ? s_c * m_r / s_r * (beta_rayleigh_r / beta_mie_r) * (beta_mie_c / beta_rayleigh_c)
             : R(0.0);
}

/* ---- texture coordinates ------------------------------------------------------------- */
/* Transmittance texture of w × rows texels (u: mu, v: altitude). */
FN real transmittance_u_at(real rb, real rt, real h, real mu, real w) {
  REQUIRE(h >= R(0.0) && h <= rt - rb);
  REQUIRE(mu >= R(-1.0) && mu <= R(1.0));
  real d = distance_to_top_at(rb, rt, h, mu);
  real d_min = rt - rb - h, d_max = safe_sqrt(rho2_of(rb, h)) + horizon_top_of(rb, rt);
  return coord_of_unit((d - d_min) / (d_max - d_min), w);
}
FN real transmittance_v_at(real rb, real rt, real h, real rows) {
  return coord_of_unit(safe_sqrt(rho2_of(rb, h)) / horizon_top_of(rb, rt), rows);
}
/* Irradiance texture of w × rows texels (u: mu_s, v: altitude). */
FN real irradiance_u_at(real mu_s, real w) {
  REQUIRE(mu_s >= R(-1.0) && mu_s <= R(1.0));
  return coord_of_unit(mu_s * R(0.5) + R(0.5), w);
}
FN real irradiance_v_at(real rb, real rt, real h, real rows) {
  REQUIRE(h >= R(0.0) && h <= rt - rb);
  return coord_of_unit(h / (rt - rb), rows);
}
/* Scattering texture, R × MU × (NU·MU_S) texels. u_r of altitude h: */
FN real scattering_u_r_at(real rb, real rt, real h, real n_r) {
  return coord_of_unit(safe_sqrt(rho2_of(rb, h)) / horizon_top_of(rb, rt), n_r);
}
/* u_mu of a ray at altitude h, with horizon distance rho, that reaches its boundary after d:
 * rays that meet the ground map below 0.5 (horizon at 0.5, straight down at 0), the others
 * above (zenith just above 0.5, horizon at 1). n_mu is even; each half has n_mu/2 texels. */
FN real scattering_u_mu_at_distance(real rb, real rt, real h, real rho, real d, int meets_ground, real n_mu) {
  if (meets_ground != 0) {
    real d_min = h, d_max = rho;
    return R(0.5) - R(0.5) * coord_of_unit(d_max == d_min ? R(0.0) : (d - d_min) / (d_max - d_min), n_mu * R(0.5));
  }
  real d_min = rt - rb - h, d_max = rho + horizon_top_of(rb, rt);
  return R(0.5) + R(0.5) * coord_of_unit((d - d_min) / (d_max - d_min), n_mu * R(0.5));
}
FN real scattering_u_mu_at(real rb, real rt, real h, real mu, int meets_ground, real n_mu) {
  real d = meets_ground != 0 ? distance_to_ground_at(rb, h, mu) : distance_to_top_at(rb, rt, h, mu);
  return scattering_u_mu_at_distance(rb, rt, h, safe_sqrt(rho2_of(rb, h)), d, meets_ground, n_mu);
}
/* u_mu_s: 0 at mu_s_min, 1 at mu_s = 1, steep around the horizon. */
FN real scattering_u_mu_s_at(real rb, real rt, real mu_s, real mu_s_min, real n_mu_s) {
  REQUIRE(mu_s >= R(-1.0) && mu_s <= R(1.0));
  real d_min = rt - rb, d_max = horizon_top_of(rb, rt);
  real a_s = (distance_to_top_at(rb, rt, R(0.0), mu_s) - d_min) / (d_max - d_min);
  real a_min = (distance_to_top_at(rb, rt, R(0.0), mu_s_min) - d_min) / (d_max - d_min);
  return coord_of_unit(fmax(R(1.0) - a_s / a_min, R(0.0)) / (R(1.0) + a_s), n_mu_s);
}
FN real scattering_u_nu_at(real nu) { return (nu + R(1.0)) * R(0.5); }

/* ---- the sky-view table: the sky in the viewer's frame over a scene's range ----------------
 * Bruneton's 4D scattering texture serves every viewer, but in twilight its texels lie far
 * apart where the sky changes fastest, and each view's radiance is rebuilt from lookups of
 * densities it filtered. The sky-view table holds, for the scene's cameras and suns only, the
 * radiance of each view integrated along its exact ray by the bake (single scattering and every
 * order ≥ 2 from the summed scattering density; atmosphere.cl, sky_view_texel):
 *   sky_view      Rayleigh single × P_R(ν) + multiple scattering (no phase left to apply)
 *   sky_view_mie  single Mie without its phase (× P_M(ν) at lookup, so the forward peak stays sharp)
 * Axes, each corner-sampled (node i of n at the texel centre (i + 0.5)/n, i.e. coord_of_unit of
 * i/(n − 1)):
 *   altitude h ∈ [h_min, h_max] and sun elevation e ∈ [e_min, e_max] (rad), linear;
 *   view–sun azimuth φ ∈ [0, π] (the sky is symmetric about the sun's vertical plane), linear;
 *   view zenith θ in two halves split at the horizon's zenith angle θ_h = acos(−ρ/r) (π/2 at
 *   the ground), like the scattering texture's u_mu: rays that meet the ground map below 0.5
 *   (θ = θ_h + (π − θ_h) x², x = 0 at the horizon, 1 straight down), the others above
 *   (θ = θ_h (1 − x²), x = 0 at the horizon, 1 at the zenith), n_view/2 texels each: the
 *   nodes crowd at the horizon (spacing ∝ x), where the twilight sky changes fastest, and no
 *   lookup blends across it.
 * Layout: a 3D texture of width n_azimuth, height n_view and depth n_sun · n_altitude (sun
 * outermost): the GPU filters azimuth, view and altitude; the lookup blends two sun slices
 * itself, geometrically (mu_s_blend), as the sky falls by about e per degree of sun elevation. */
FN real sky_view_horizon_zenith(real rb, real h) { return acos(clamp_cosine(-safe_sqrt(rho2_of(rb, h)) / (rb + h))); }
/* The angle θ_h − θ between the horizon and a view of cosine mu at altitude h (positive above the
 * horizon), from its sine and cosine (sin θ_h = rb/r, cos θ_h = −ρ/r) rather than as a difference
 * of two arc cosines: near the horizon, where the table's nodes crowd, that difference would carry
 * the arc cosines' absolute rounding (float32: ~1e-7 rad, and GLSL leaves acos's precision to the
 * implementation) into an angle of a few 1e-3 rad; here the rounding stays relative to the angle.
 * Written with the one-argument atan that C, OpenCL and GLSL share. */
FN real sky_view_above_horizon(real rb, real h, real mu) {
  real r = rb + h;
  real sin_h = rb / r;
  real cos_h = -safe_sqrt(rho2_of(rb, h)) / r;
  real sin_t = safe_sqrt(R(1.0) - mu * mu);
  real s = sin_h * mu - cos_h * sin_t;  /* sin(θ_h − θ) */
  real c = cos_h * mu + sin_h * sin_t;  /* cos(θ_h − θ) */
  if (c > fabs(s)) return atan(s / c);
  return (s > R(0.0) ? R(0.5) : R(-0.5)) * R(3.14159265358979323846) - atan(c / s);
}
/* Texture coordinate of the view zenith (from mu) at altitude h. */
FN real sky_view_u_view_at(real rb, real h, real mu, int meets_ground, real n_view) {
  real theta_h = sky_view_horizon_zenith(rb, h);
  real delta = sky_view_above_horizon(rb, h, clamp_cosine(mu));
  if (meets_ground != 0) {
    real x = safe_sqrt(clamp_real(-delta / (R(3.14159265358979323846) - theta_h), R(0.0), R(1.0)));
    return R(0.5) - R(0.5) * coord_of_unit(x, n_view * R(0.5));
  }
  real x = safe_sqrt(clamp_real(delta / theta_h, R(0.0), R(1.0)));
  return R(0.5) + R(0.5) * coord_of_unit(x, n_view * R(0.5));
}
/* cos φ of the view–sun azimuth from μ, μ_s and ν (1 where the view or the sun is vertical). */
FN real sky_view_cos_azimuth(real mu, real mu_s, real nu) {
  real s = safe_sqrt((R(1.0) - mu * mu) * (R(1.0) - mu_s * mu_s));
  return s > R(1e-6) ? clamp_cosine((nu - mu * mu_s) / s) : R(1.0);
}
FN real sky_view_u_azimuth_at(real cos_phi, real n_azimuth) {
  return coord_of_unit(acos(clamp_cosine(cos_phi)) / R(3.14159265358979323846), n_azimuth);
}
/* Position of x on a corner-sampled axis of n nodes over [lo, hi]: in [0, n − 1], clamped. */
FN real sky_view_node_position(real x, real lo, real hi, real n) {
  return (n > R(1.0) && hi > lo) ? clamp_real((x - lo) / (hi - lo), R(0.0), R(1.0)) * (n - R(1.0)) : R(0.0);
}
/* 1 when the table holds (h, e): the camera's altitude and the sun's elevation within its range
 * (a margin of 1e-4 of each for rounding). */
FN int sky_view_covers(real h, real e, real h_min, real h_max, real e_min, real e_max) {
  real dh = R(1e-4) * fmax(h_max - h_min, R(1e-3));
  real de = R(1e-4) * fmax(e_max - e_min, R(1e-3));
  return (h >= h_min - dh && h <= h_max + dh && e >= e_min - de && e <= e_max + de) ? 1 : 0;
}
