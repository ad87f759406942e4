/* render.glsl — what a renderer does with the baked atmosphere textures: the lookups of
 * Bruneton 2017 ("Precomputed Atmospheric Scattering: a New Implementation", § "Rendering":
 * GetSkyRadiance, GetSkyRadianceToPoint, GetSunAndSkyIrradiance and the texture lookups under
 * them), in the altitude-based form of lookup.cl, whose scalar functions it calls.
 *
 * Written once in the common subset of GLSL and C++: the bundle's sampling.glsl carries this
 * text verbatim (after lookup.cl and a prelude that defines real, FN, R, REQUIRE, fmax, fmin,
 * fabs, TEXTURE_RGB, TEXTURE_RGBA, OUT and INOUT; src/kinds/atmosphere/render.cpp), and the host
 * compiles the same text in double with GLM's vector types and a bilinear/trilinear filter with
 * the GPU's texel-centre and clamp-to-edge rules (src/kinds/atmosphere/shader_host.hpp): the previews, the scene check and the GL test's reference
 * are this code. Hence: vec2/vec3, scalars as real, sizes as real, no swizzles (.x .y .z only),
 * no `const` locals, flags as int, out-parameters as OUT(type), in-out ones as INOUT(type).
 *
 * Float32 safety. A camera is given by its altitude h above the ground (km) and the unit
 * vector `up` from the planet centre through it, not by a planet-centred position: at 6360 km
 * float32 resolves 0.49 m, so |x| − rb would lose the altitude of a camera near the ground,
 * and the texture coordinates of lookup.cl are written in h for the same reason. A point seen
 * from the camera is given relative to the camera (km). Directions are unit vectors.
 *
 * Units: lengths in km; radiance and irradiance in the bundle's units (see sampling.glsl's
 * header). Textures: transmittance [u: mu, v: h], irradiance [u: mu_s, v: h] (sky part only),
 * scattering (Rayleigh + multiple, no phase) and single_mie (single Mie, no phase), each either
 * 3D (width NU·MU_S, height MU, depth R) or tiled 2D (width R·NU·MU_S, height MU).
 */

struct SpecbakeAtmosphere {
  real bottom_radius;       /* rb, km */
  real top_radius;          /* rt, km */
  real mu_s_min;            /* the scattering texture's lowest sun cosine */
  real sun_angular_radius;  /* rad */
  real mie_g;               /* Cornette–Shanks asymmetry */
  vec3 solar_irradiance;    /* at the top of the atmosphere */
  vec3 rayleigh_scattering; /* km⁻¹ at density 1, per channel (combined textures' extrapolation) */
  vec3 mie_scattering;      /* km⁻¹ */
  real transmittance_w;
  real transmittance_h;
  real irradiance_w;
  real irradiance_h;
  real r_size;
  real mu_size;
  real mu_s_size;
  real nu_size;
};

/* ---- texture lookups ------------------------------------------------------------------- */
vec3 GetTransmittanceToTopAtmosphereBoundary(SpecbakeAtmosphere atm, sampler2D transmittance_texture, real h, real mu) {
  vec2 uv = vec2(transmittance_u_at(atm.bottom_radius, atm.top_radius, h, mu, atm.transmittance_w),
                 transmittance_v_at(atm.bottom_radius, atm.top_radius, h, atm.transmittance_h));
  return TEXTURE_RGB(transmittance_texture, uv);
}
/* Transmittance between altitude h and the point a distance d along mu, from two lookups; rays
 * that meet the ground use the reversed (upward) segments so that no lookup crosses it. */
vec3 GetTransmittance(SpecbakeAtmosphere atm, sampler2D transmittance_texture, real h, real mu, real d, int meets_ground) {
  real h_d = altitude_along_ray(atm.bottom_radius, atm.top_radius, h, mu, d, meets_ground);
  real mu_d = cosine_along_ray(atm.bottom_radius, h, mu, d, meets_ground, h_d);
  vec3 start_end = GetTransmittanceToTopAtmosphereBoundary(atm, transmittance_texture, h, meets_ground != 0 ? -mu : mu);
  vec3 far_end = GetTransmittanceToTopAtmosphereBoundary(atm, transmittance_texture, h_d, meets_ground != 0 ? -mu_d : mu_d);
  vec3 num = meets_ground != 0 ? far_end : start_end;
  vec3 den = meets_ground != 0 ? start_end : far_end;
  return vec3(ratio_or_zero(num.x, den.x), ratio_or_zero(num.y, den.y), ratio_or_zero(num.z, den.z));
}
/* Transmittance to the sun times the fraction of its disc above the horizon. */
vec3 GetTransmittanceToSun(SpecbakeAtmosphere atm, sampler2D transmittance_texture, real h, real mu_s) {
  return GetTransmittanceToTopAtmosphereBoundary(atm, transmittance_texture, h, mu_s) *
         sun_visible_at(atm.bottom_radius, atm.sun_angular_radius, h, mu_s);
}
/* The sky part of the irradiance on a horizontal surface at altitude h. */
vec3 GetIrradiance(SpecbakeAtmosphere atm, sampler2D irradiance_texture, real h, real mu_s) {
  vec2 uv = vec2(irradiance_u_at(mu_s, atm.irradiance_w),
                 irradiance_v_at(atm.bottom_radius, atm.top_radius, h, atm.irradiance_h));
  return TEXTURE_RGB(irradiance_texture, uv);
}
/* The scattering textures' coordinates of (h, mu, mu_s, nu): x the continuous nu slice in
 * [0, NU − 1] (corner-sampled), then u_mu_s, u_mu and u_r (lookup.cl). */
vec4 SpecbakeScatteringUvwz(SpecbakeAtmosphere atm, real h, real mu, real mu_s, real nu, int meets_ground) {
  return vec4(clamp_real(scattering_u_nu_at(nu), R(0.0), R(1.0)) * (atm.nu_size - R(1.0)),
              scattering_u_mu_s_at(atm.bottom_radius, atm.top_radius, mu_s, atm.mu_s_min, atm.mu_s_size),
              scattering_u_mu_at(atm.bottom_radius, atm.top_radius, h, mu, meets_ground, atm.mu_size),
              scattering_u_r_at(atm.bottom_radius, atm.top_radius, h, atm.r_size));
}
/* The 3D layout: two trilinear lookups around nu (corner-sampled, divisor NU − 1); u_mu_s keeps
 * half a texel from each slice's edges, so the filter never mixes two nu slices. */
vec3 GetScattering3D(SpecbakeAtmosphere atm, sampler3D scattering_texture, real h, real mu, real mu_s, real nu,
                     int meets_ground) {
  vec4 uvwz = SpecbakeScatteringUvwz(atm, h, mu, mu_s, nu, meets_ground);
  real u_mu_s = uvwz.y;
  real u_mu = uvwz.z;
  real u_r = uvwz.w;
  real x = uvwz.x;
  real x0 = floor(x);
  real f = x - x0;
  vec3 v0 = TEXTURE_RGB(scattering_texture, vec3((x0 + u_mu_s) / atm.nu_size, u_mu, u_r));
  vec3 v1 = TEXTURE_RGB(scattering_texture, vec3((x0 + R(1.0) + u_mu_s) / atm.nu_size, u_mu, u_r));
  return v0 * (R(1.0) - f) + v1 * f;
}
/* The tiled 2D layout (column = r_index·NU·MU_S + nu_slice·MU_S + mu_s_index): bilinear
 * filtering covers mu_s and mu; r and nu are interpolated here, from 4 fetches. */
vec3 GetScatteringTiled2D(SpecbakeAtmosphere atm, sampler2D scattering_texture, real h, real mu, real mu_s, real nu,
                          int meets_ground) {
  vec4 uvwz = SpecbakeScatteringUvwz(atm, h, mu, mu_s, nu, meets_ground);
  real u_mu_s = uvwz.y;
  real u_mu = uvwz.z;
  real u_r = uvwz.w;
  real x = uvwz.x;
  real s0 = floor(x);
  real f = x - s0;
  real s1 = fmin(s0 + R(1.0), atm.nu_size - R(1.0));
  real z = u_r * atm.r_size - R(0.5);
  real k0f = floor(z);
  real g = z - k0f;
  real k0 = clamp_real(k0f, R(0.0), atm.r_size - R(1.0));
  real k1 = clamp_real(k0f + R(1.0), R(0.0), atm.r_size - R(1.0));
  real tiles = atm.r_size * atm.nu_size;
  vec3 a00 = TEXTURE_RGB(scattering_texture, vec2((k0 * atm.nu_size + s0 + u_mu_s) / tiles, u_mu));
  vec3 a01 = TEXTURE_RGB(scattering_texture, vec2((k0 * atm.nu_size + s1 + u_mu_s) / tiles, u_mu));
  vec3 a10 = TEXTURE_RGB(scattering_texture, vec2((k1 * atm.nu_size + s0 + u_mu_s) / tiles, u_mu));
  vec3 a11 = TEXTURE_RGB(scattering_texture, vec2((k1 * atm.nu_size + s1 + u_mu_s) / tiles, u_mu));
  return (a00 * (R(1.0) - f) + a01 * f) * (R(1.0) - g) + (a10 * (R(1.0) - f) + a11 * f) * g;
}

/* The 3D layout of `ktx2: {scattering: rgba-combined}` (scattering.ktx2): RGB the scattering
 * texture, alpha single Mie's red channel; returns the scattering and rebuilds single Mie in
 * `single_mie` (extrapolated_single_mie, lookup.cl). Two RGBA lookups around nu, as GetScattering3D. */
vec3 GetCombinedScattering3D(SpecbakeAtmosphere atm, sampler3D combined_texture, real h, real mu, real mu_s, real nu,
                             int meets_ground, OUT(vec3) single_mie) {
  vec4 uvwz = SpecbakeScatteringUvwz(atm, h, mu, mu_s, nu, meets_ground);
  real u_mu_s = uvwz.y;
  real u_mu = uvwz.z;
  real u_r = uvwz.w;
  real x = uvwz.x;
  real x0 = floor(x);
  real f = x - x0;
  vec4 v0 = TEXTURE_RGBA(combined_texture, vec3((x0 + u_mu_s) / atm.nu_size, u_mu, u_r));
  vec4 v1 = TEXTURE_RGBA(combined_texture, vec3((x0 + R(1.0) + u_mu_s) / atm.nu_size, u_mu, u_r));
  vec4 c = v0 * (R(1.0) - f) + v1 * f;
  vec3 b_r = atm.rayleigh_scattering;
  vec3 b_m = atm.mie_scattering;
  single_mie = vec3(extrapolated_single_mie(c.x, c.x, c.w, b_r.x, b_m.x, b_r.x, b_m.x),
                    extrapolated_single_mie(c.y, c.x, c.w, b_r.x, b_m.x, b_r.y, b_m.y),
                    extrapolated_single_mie(c.z, c.x, c.w, b_r.x, b_m.x, b_r.z, b_m.z));
  return vec3(c.x, c.y, c.z);
}

/* GetScattering is the layout the includer picks: tiled 2D where SPECBAKE_SCATTERING_TILED2D is
 * defined, else 3D. */
#ifdef SPECBAKE_SCATTERING_TILED2D
#define SpecbakeScatteringSampler sampler2D
#define GetScattering GetScatteringTiled2D
#else
#define SpecbakeScatteringSampler sampler3D
#define GetScattering GetScattering3D
#endif

/* ---- rendering ------------------------------------------------------------------------- */
/* The camera at altitude h looking along `view`, as the functions below start: a camera in space
 * moves along `view` to where the ray enters the top (up and h follow it, d_top is the distance
 * moved, else 0). r is the camera's radius and mu the ray's cosine there; h is clamped to
 * [0, t] after mu is taken. Returns 0 for a camera in space whose ray misses the atmosphere. */
int SpecbakeEnterAtmosphere(SpecbakeAtmosphere atm, INOUT(vec3) up, INOUT(real) h, vec3 view, OUT(real) r,
                            OUT(real) mu, OUT(real) d_top) {
  real rb = atm.bottom_radius;
  real t = atm.top_radius - rb;
  r = rb + h;
  real r_mu = r * dot(up, view);
  real disc = r_mu * r_mu + top_gap2_of(rb, atm.top_radius, h);
  d_top = disc >= R(0.0) ? -r_mu - sqrt(disc) : R(-1.0);
  if (d_top > R(0.0)) {
    up = normalize(up * r + view * d_top);
    r_mu = -sqrt(disc);  /* = r_mu + d_top, without the cancellation near the limb */
    r = atm.top_radius;
    h = t;
  } else {
    d_top = R(0.0);
    if (h > t) return 0;
  }
  mu = clamp_cosine(r_mu / r);
  h = clamp_real(h, R(0.0), t);
  return 1;
}
/* The scattering and (in single_mie) single Mie lookups at the point a distance d along the ray
 * that starts at altitude h, radius r, with cosines mu, mu_s and nu. */
vec3 SpecbakeScatteringAlong(SpecbakeAtmosphere atm, SpecbakeScatteringSampler scattering_texture,
                             SpecbakeScatteringSampler single_mie_scattering_texture, real h, real r, real mu,
                             real mu_s, real nu, real d, int ground, OUT(vec3) single_mie) {
  real h_p = clamp_real(altitude_after(atm.bottom_radius, h, mu, d), R(0.0), atm.top_radius - atm.bottom_radius);
  real r_p = atm.bottom_radius + h_p;
  real mu_p = clamp_cosine((r * mu + d) / r_p);
  real mu_s_p = clamp_cosine((r * mu_s + d * nu) / r_p);
  single_mie = GetScattering(atm, single_mie_scattering_texture, h_p, mu_p, mu_s_p, nu, ground);
  return GetScattering(atm, scattering_texture, h_p, mu_p, mu_s_p, nu, ground);
}

/* Sky radiance seen by a camera at altitude h (above the top: a camera in space) along the unit
 * vector `view`, sun along the unit vector `sun`; `transmittance` to the top of the atmosphere
 * (0 for rays that meet the ground, 1 for rays from space that miss the atmosphere). Light
 * shafts: `shadow_length` km of the ray nearest the camera are left out. */
vec3 GetSkyRadiance(SpecbakeAtmosphere atm, sampler2D transmittance_texture,
                    SpecbakeScatteringSampler scattering_texture, SpecbakeScatteringSampler single_mie_scattering_texture,
                    vec3 up, real h, vec3 view, real shadow_length, vec3 sun, OUT(vec3) transmittance) {
  real r;
  real mu;
  real d_top;
  if (SpecbakeEnterAtmosphere(atm, up, h, view, r, mu, d_top) == 0) {
    transmittance = vec3(R(1.0));
    return vec3(R(0.0));
  }
  real mu_s = clamp_cosine(dot(up, sun));
  real nu = clamp_cosine(dot(view, sun));
  int ground = ray_meets_ground(atm.bottom_radius, h, mu);
  transmittance = ground != 0 ? vec3(R(0.0)) : GetTransmittanceToTopAtmosphereBoundary(atm, transmittance_texture, h, mu);
  vec3 s;
  vec3 m;
  if (shadow_length == R(0.0)) {
    s = GetScattering(atm, scattering_texture, h, mu, mu_s, nu, ground);
    m = GetScattering(atm, single_mie_scattering_texture, h, mu, mu_s, nu, ground);
  } else {
    vec3 t_shadow = GetTransmittance(atm, transmittance_texture, h, mu, shadow_length, ground);
    s = SpecbakeScatteringAlong(atm, scattering_texture, single_mie_scattering_texture, h, r, mu, mu_s, nu,
                                shadow_length, ground, m) * t_shadow;
    m = m * t_shadow;
  }
  return s * rayleigh_phase(nu) + m * mie_phase(atm.mie_g, nu);
}

/* Sky radiance between a camera at altitude h and a point `to_point` km away from it (both in
 * or on the atmosphere), and the transmittance between them. Single Mie fades out as the sun
 * sets, as in the reference, to hide its artefacts there. */
vec3 GetSkyRadianceToPoint(SpecbakeAtmosphere atm, sampler2D transmittance_texture,
                           SpecbakeScatteringSampler scattering_texture,
                           SpecbakeScatteringSampler single_mie_scattering_texture, vec3 up, real h, vec3 to_point,
                           real shadow_length, vec3 sun, OUT(vec3) transmittance) {
  real d = length(to_point);
  vec3 view = to_point / d;
  real r;
  real mu;
  real d_top;
  if (SpecbakeEnterAtmosphere(atm, up, h, view, r, mu, d_top) == 0) {  /* from space, past the atmosphere */
    transmittance = vec3(R(1.0));
    return vec3(R(0.0));
  }
  d = fmax(d - d_top, R(0.0));
  real mu_s = clamp_cosine(dot(up, sun));
  real nu = clamp_cosine(dot(view, sun));
  int ground = ray_meets_ground(atm.bottom_radius, h, mu);
  transmittance = GetTransmittance(atm, transmittance_texture, h, mu, d, ground);
  vec3 s = GetScattering(atm, scattering_texture, h, mu, mu_s, nu, ground);
  vec3 m = GetScattering(atm, single_mie_scattering_texture, h, mu, mu_s, nu, ground);
  d = fmax(d - shadow_length, R(0.0));
  vec3 m_p;
  vec3 s_p = SpecbakeScatteringAlong(atm, scattering_texture, single_mie_scattering_texture, h, r, mu, mu_s, nu, d,
                                     ground, m_p);
  vec3 t_shadow = shadow_length > R(0.0) ? GetTransmittance(atm, transmittance_texture, h, mu, d, ground) : transmittance;
  real fade = smooth_step(R(0.0), R(0.01), mu_s);
  s = s - t_shadow * s_p;
  m = (m - t_shadow * m_p) * fade;
  return s * rayleigh_phase(nu) + m * mie_phase(atm.mie_g, nu);
}

/* Sun and sky irradiance on a surface at altitude h (up: the local vertical) with unit `normal`:
 * returns the sun's part; `sky_irradiance` gets the sky's, from the irradiance texture scaled by
 * the fraction of the sky the tilted surface sees. */
vec3 GetSunAndSkyIrradiance(SpecbakeAtmosphere atm, sampler2D transmittance_texture, sampler2D irradiance_texture,
                            vec3 up, real h, vec3 normal, vec3 sun, OUT(vec3) sky_irradiance) {
  h = clamp_real(h, R(0.0), atm.top_radius - atm.bottom_radius);
  real mu_s = clamp_cosine(dot(up, sun));
  sky_irradiance = GetIrradiance(atm, irradiance_texture, h, mu_s) * ((R(1.0) + dot(normal, up)) * R(0.5));
  return atm.solar_irradiance * GetTransmittanceToSun(atm, transmittance_texture, h, mu_s) *
         fmax(dot(normal, sun), R(0.0));
}
