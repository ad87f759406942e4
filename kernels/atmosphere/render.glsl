/* render.glsl — what a renderer does with the baked atmosphere textures: the lookups of
 * Bruneton 2017 ("Precomputed Atmospheric Scattering: a New Implementation", § "Rendering":
 * GetSkyRadiance, GetSkyRadianceToPoint, GetSunAndSkyIrradiance and the texture lookups under
 * them), in the altitude-based form of lookup.cl, whose scalar functions it calls.
 *
 * Written once in the common subset of GLSL and C++: the bundle's sampling.glsl carries this
 * text verbatim (after lookup.cl and a prelude that defines real, FN, R, REQUIRE, fmax, fmin,
 * fabs, TEXTURE_RGB, TEXTURE_RGBA, OUT and INOUT; src/kinds/atmosphere/shader/render.cpp), and the host
 * compiles the same text in double with GLM's vector types and a bilinear/trilinear filter with
 * the GPU's texel-centre and clamp-to-edge rules (src/kinds/atmosphere/shader/shader_host.hpp): the previews, the scene check and the GL test's reference
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

/* Two builds of this text. Default: the RGB textures (R, G, B at three wavelengths or
 * luminance), vec3 values, scattering in the 3D or tiled 2D layout. SPECBAKE_SPECTRAL (defined
 * with SPECBAKE_WAVELENGTH_SETS by sampling_spectral.glsl, `spectrum: {store: radiance}`):
 * radiance at stored wavelengths, four per RGBA texel (a wavelength set), each set a layer of
 * 2D array textures (scattering in the tiled 2D layout: GL and Vulkan have no 3D arrays); the
 * same functions return the vec4 of the set atm.layer, and the ...AtWavelength functions at the
 * end interpolate one wavelength between sets. */
#ifdef SPECBAKE_SPECTRAL
#define SpecbakeRadiance vec4
#define SpecbakeSampler2D sampler2DArray
#define SPECBAKE_CHANNELS 4
#define SPECBAKE_FETCH(s, uv) TEXTURE_LAYER(s, uv, atm.layer)
#define SPECBAKE_SOLAR_IRRADIANCE(atm) atm.solar_irradiance[int(atm.layer)]
#ifndef SPECBAKE_SCATTERING_TILED2D
#define SPECBAKE_SCATTERING_TILED2D
#endif
#else
#define SpecbakeRadiance vec3
#define SpecbakeSampler2D sampler2D
#define SPECBAKE_CHANNELS 3
#define SPECBAKE_FETCH(s, uv) TEXTURE_RGB(s, uv)
#define SPECBAKE_SOLAR_IRRADIANCE(atm) atm.solar_irradiance
#endif

struct SpecbakeAtmosphere {
  real bottom_radius;       /* rb, km */
  real top_radius;          /* rt, km */
  real mu_s_min;            /* the scattering texture's lowest sun cosine */
  real sun_angular_radius;  /* rad */
  real mie_g;               /* Cornette–Shanks asymmetry */
#ifdef SPECBAKE_SPECTRAL
  real layer;               /* the wavelength set the lookups read: layer of the array textures */
  real lambda_first;        /* nm: stored wavelength i is lambda_first + i lambda_step, i < lambda_count */
  real lambda_step;
  real lambda_count;
  SpecbakeRadiance solar_irradiance[SPECBAKE_WAVELENGTH_SETS]; /* per set, at the top of the atmosphere */
#else
  vec3 solar_irradiance;    /* at the top of the atmosphere */
  vec3 rayleigh_scattering; /* km⁻¹ at density 1, per channel (combined textures' extrapolation) */
  vec3 mie_scattering;      /* km⁻¹ */
#endif
  real transmittance_w;
  real transmittance_h;
  real irradiance_w;
  real irradiance_h;
  real r_size;
  real mu_size;
  real mu_s_size;
  real nu_size;
  real mu_s_geometric;      /* 1: blend the two μ_s texels geometrically (mu_s_blend), 0: linearly */
};

/* ---- texture lookups ------------------------------------------------------------------- */
SpecbakeRadiance GetTransmittanceToTopAtmosphereBoundary(SpecbakeAtmosphere atm, SpecbakeSampler2D transmittance_texture,
                                                        real h, real mu) {
  vec2 uv = vec2(transmittance_u_at(atm.bottom_radius, atm.top_radius, h, mu, atm.transmittance_w),
                 transmittance_v_at(atm.bottom_radius, atm.top_radius, h, atm.transmittance_h));
  return SPECBAKE_FETCH(transmittance_texture, uv);
}
/* Transmittance between altitude h and the point a distance d along mu, from two lookups; rays
 * that meet the ground use the reversed (upward) segments so that no lookup crosses it. */
SpecbakeRadiance GetTransmittance(SpecbakeAtmosphere atm, SpecbakeSampler2D transmittance_texture, real h, real mu, real d,
                                  int meets_ground) {
  real h_d = altitude_along_ray(atm.bottom_radius, atm.top_radius, h, mu, d, meets_ground);
  real mu_d = cosine_along_ray(atm.bottom_radius, h, mu, d, meets_ground, h_d);
  SpecbakeRadiance start_end =
      GetTransmittanceToTopAtmosphereBoundary(atm, transmittance_texture, h, meets_ground != 0 ? -mu : mu);
  SpecbakeRadiance far_end =
      GetTransmittanceToTopAtmosphereBoundary(atm, transmittance_texture, h_d, meets_ground != 0 ? -mu_d : mu_d);
  SpecbakeRadiance num = meets_ground != 0 ? far_end : start_end;
  SpecbakeRadiance den = meets_ground != 0 ? start_end : far_end;
  SpecbakeRadiance ratio = num;
  for (int c = 0; c < SPECBAKE_CHANNELS; ++c) ratio[c] = ratio_or_zero(num[c], den[c]);
  return ratio;
}
/* Transmittance to the sun times the fraction of its disc above the horizon. */
SpecbakeRadiance GetTransmittanceToSun(SpecbakeAtmosphere atm, SpecbakeSampler2D transmittance_texture, real h,
                                       real mu_s) {
  return GetTransmittanceToTopAtmosphereBoundary(atm, transmittance_texture, h, mu_s) *
         sun_visible_at(atm.bottom_radius, atm.sun_angular_radius, h, mu_s);
}
/* The sky part of the irradiance on a horizontal surface at altitude h. */
SpecbakeRadiance GetIrradiance(SpecbakeAtmosphere atm, SpecbakeSampler2D irradiance_texture, real h, real mu_s) {
  vec2 uv = vec2(irradiance_u_at(mu_s, atm.irradiance_w),
                 irradiance_v_at(atm.bottom_radius, atm.top_radius, h, atm.irradiance_h));
  return SPECBAKE_FETCH(irradiance_texture, uv);
}
/* The scattering textures' coordinates of (h, mu, mu_s, nu): x the continuous nu slice in
 * [0, NU − 1] (corner-sampled), then u_mu_s, u_mu and u_r (lookup.cl). */
vec4 SpecbakeScatteringUvwz(SpecbakeAtmosphere atm, real h, real mu, real mu_s, real nu, int meets_ground) {
  return vec4(clamp_real(scattering_u_nu_at(nu), R(0.0), R(1.0)) * (atm.nu_size - R(1.0)),
              scattering_u_mu_s_at(atm.bottom_radius, atm.top_radius, mu_s, atm.mu_s_min, atm.mu_s_size),
              scattering_u_mu_at(atm.bottom_radius, atm.top_radius, h, mu, meets_ground, atm.mu_size),
              scattering_u_r_at(atm.bottom_radius, atm.top_radius, h, atm.r_size));
}
/* The μ_s texel columns around u_mu_s (texel centres, clamped) and the weight g of the second:
 * with mu_s_geometric a lookup fetches both at their centres (the filter then blends μ and r
 * only) and joins them by mu_s_blend; else one fetch at u_mu_s lets the filter blend μ_s too. */
vec3 SpecbakeMuSColumns(SpecbakeAtmosphere atm, real u_mu_s) {
  real xs = u_mu_s * atm.mu_s_size - R(0.5);
  real i0 = floor(xs);
  return vec3((clamp_real(i0, R(0.0), atm.mu_s_size - R(1.0)) + R(0.5)) / atm.mu_s_size,
              (clamp_real(i0 + R(1.0), R(0.0), atm.mu_s_size - R(1.0)) + R(0.5)) / atm.mu_s_size, xs - i0);
}
SpecbakeRadiance SpecbakeMuSBlend(SpecbakeRadiance a, SpecbakeRadiance b, real g) {
  SpecbakeRadiance v = a;
  for (int c = 0; c < SPECBAKE_CHANNELS; ++c) v[c] = mu_s_blend(a[c], b[c], g);
  return v;
}
#ifndef SPECBAKE_SPECTRAL
/* The 3D layout: a lookup in each of the two nu slices around nu (corner-sampled, divisor NU −
 * 1), lerped; u_mu_s keeps half a texel from each slice's edges, so the filter never mixes two
 * nu slices. */
vec3 SpecbakeScattering3DSlice(SpecbakeAtmosphere atm, sampler3D scattering_texture, real slice, real u_mu_s, real u_mu,
                               real u_r) {
  if (atm.mu_s_geometric == R(0.0))
    return TEXTURE_RGB(scattering_texture, vec3((slice + u_mu_s) / atm.nu_size, u_mu, u_r));
  vec3 m = SpecbakeMuSColumns(atm, u_mu_s);
  return SpecbakeMuSBlend(TEXTURE_RGB(scattering_texture, vec3((slice + m.x) / atm.nu_size, u_mu, u_r)),
                          TEXTURE_RGB(scattering_texture, vec3((slice + m.y) / atm.nu_size, u_mu, u_r)), m.z);
}
vec3 GetScattering3D(SpecbakeAtmosphere atm, sampler3D scattering_texture, real h, real mu, real mu_s, real nu,
                     int meets_ground) {
  vec4 uvwz = SpecbakeScatteringUvwz(atm, h, mu, mu_s, nu, meets_ground);
  real x0 = floor(uvwz.x);
  real f = uvwz.x - x0;
  vec3 v0 = SpecbakeScattering3DSlice(atm, scattering_texture, x0, uvwz.y, uvwz.z, uvwz.w);
  vec3 v1 = SpecbakeScattering3DSlice(atm, scattering_texture, x0 + R(1.0), uvwz.y, uvwz.z, uvwz.w);
  return v0 * (R(1.0) - f) + v1 * f;
}
#endif
/* The tiled 2D layout (column = r_index·NU·MU_S + nu_slice·MU_S + mu_s_index): bilinear
 * filtering covers mu and (without mu_s_geometric) mu_s; r and nu are interpolated here: per nu
 * slice, the two r tiles' fetches lerped (at the μ_s coordinate, or at each of the two μ_s
 * texel centres, then blended as the 3D layout does), then the two slices lerped. 4 fetches,
 * 8 with mu_s_geometric. */
SpecbakeRadiance SpecbakeScatteringTiledColumn(SpecbakeAtmosphere atm, SpecbakeSampler2D scattering_texture, real slice,
                                               real u_column, real u_mu, real k0, real k1, real g) {
  real tiles = atm.r_size * atm.nu_size;
  SpecbakeRadiance a = SPECBAKE_FETCH(scattering_texture, vec2((k0 * atm.nu_size + slice + u_column) / tiles, u_mu));
  SpecbakeRadiance b = SPECBAKE_FETCH(scattering_texture, vec2((k1 * atm.nu_size + slice + u_column) / tiles, u_mu));
  return a * (R(1.0) - g) + b * g;
}
SpecbakeRadiance SpecbakeScatteringTiledSlice(SpecbakeAtmosphere atm, SpecbakeSampler2D scattering_texture, real slice,
                                              real u_mu_s, real u_mu, real k0, real k1, real g) {
  if (atm.mu_s_geometric == R(0.0))
    return SpecbakeScatteringTiledColumn(atm, scattering_texture, slice, u_mu_s, u_mu, k0, k1, g);
  vec3 m = SpecbakeMuSColumns(atm, u_mu_s);
  return SpecbakeMuSBlend(SpecbakeScatteringTiledColumn(atm, scattering_texture, slice, m.x, u_mu, k0, k1, g),
                          SpecbakeScatteringTiledColumn(atm, scattering_texture, slice, m.y, u_mu, k0, k1, g), m.z);
}
SpecbakeRadiance GetScatteringTiled2D(SpecbakeAtmosphere atm, SpecbakeSampler2D scattering_texture, real h, real mu,
                                      real mu_s, real nu, int meets_ground) {
  vec4 uvwz = SpecbakeScatteringUvwz(atm, h, mu, mu_s, nu, meets_ground);
  real s0 = floor(uvwz.x);
  real f = uvwz.x - s0;
  real s1 = fmin(s0 + R(1.0), atm.nu_size - R(1.0));
  real z = uvwz.w * atm.r_size - R(0.5);
  real k0f = floor(z);
  real g = z - k0f;
  real k0 = clamp_real(k0f, R(0.0), atm.r_size - R(1.0));
  real k1 = clamp_real(k0f + R(1.0), R(0.0), atm.r_size - R(1.0));
  SpecbakeRadiance v0 = SpecbakeScatteringTiledSlice(atm, scattering_texture, s0, uvwz.y, uvwz.z, k0, k1, g);
  SpecbakeRadiance v1 = SpecbakeScatteringTiledSlice(atm, scattering_texture, s1, uvwz.y, uvwz.z, k0, k1, g);
  return v0 * (R(1.0) - f) + v1 * f;
}

#ifndef SPECBAKE_SPECTRAL
/* The 3D layout of `ktx2: {scattering: rgba-combined}` (scattering.ktx2): RGB the scattering
 * texture, alpha single Mie's red channel; returns the scattering and rebuilds single Mie in
 * `single_mie` (extrapolated_single_mie, lookup.cl). Two RGBA lookups around nu, as GetScattering3D. */
vec4 SpecbakeCombined3DSlice(SpecbakeAtmosphere atm, sampler3D combined_texture, real slice, real u_mu_s, real u_mu,
                             real u_r) {
  if (atm.mu_s_geometric == R(0.0))
    return TEXTURE_RGBA(combined_texture, vec3((slice + u_mu_s) / atm.nu_size, u_mu, u_r));
  vec3 m = SpecbakeMuSColumns(atm, u_mu_s);
  vec4 a = TEXTURE_RGBA(combined_texture, vec3((slice + m.x) / atm.nu_size, u_mu, u_r));
  vec4 b = TEXTURE_RGBA(combined_texture, vec3((slice + m.y) / atm.nu_size, u_mu, u_r));
  return vec4(mu_s_blend(a.x, b.x, m.z), mu_s_blend(a.y, b.y, m.z), mu_s_blend(a.z, b.z, m.z), mu_s_blend(a.w, b.w, m.z));
}
vec3 GetCombinedScattering3D(SpecbakeAtmosphere atm, sampler3D combined_texture, real h, real mu, real mu_s, real nu,
                             int meets_ground, OUT(vec3) single_mie) {
  vec4 uvwz = SpecbakeScatteringUvwz(atm, h, mu, mu_s, nu, meets_ground);
  real u_mu_s = uvwz.y;
  real u_mu = uvwz.z;
  real u_r = uvwz.w;
  real x = uvwz.x;
  real x0 = floor(x);
  real f = x - x0;
  vec4 v0 = SpecbakeCombined3DSlice(atm, combined_texture, x0, u_mu_s, u_mu, u_r);
  vec4 v1 = SpecbakeCombined3DSlice(atm, combined_texture, x0 + R(1.0), u_mu_s, u_mu, u_r);
  vec4 c = v0 * (R(1.0) - f) + v1 * f;
  vec3 b_r = atm.rayleigh_scattering;
  vec3 b_m = atm.mie_scattering;
  single_mie = vec3(extrapolated_single_mie(c.x, c.x, c.w, b_r.x, b_m.x, b_r.x, b_m.x),
                    extrapolated_single_mie(c.y, c.x, c.w, b_r.x, b_m.x, b_r.y, b_m.y),
                    extrapolated_single_mie(c.z, c.x, c.w, b_r.x, b_m.x, b_r.z, b_m.z));
  return vec3(c.x, c.y, c.z);
}
#endif

/* GetScattering is the layout the includer picks: tiled 2D where SPECBAKE_SCATTERING_TILED2D is
 * defined, else 3D. */
#ifdef SPECBAKE_SCATTERING_TILED2D
#define SpecbakeScatteringSampler SpecbakeSampler2D
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
SpecbakeRadiance SpecbakeScatteringAlong(SpecbakeAtmosphere atm, SpecbakeScatteringSampler scattering_texture,
                                         SpecbakeScatteringSampler single_mie_scattering_texture, real h, real r,
                                         real mu, real mu_s, real nu, real d, int ground,
                                         OUT(SpecbakeRadiance) single_mie) {
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
SpecbakeRadiance GetSkyRadiance(SpecbakeAtmosphere atm, SpecbakeSampler2D transmittance_texture,
                                SpecbakeScatteringSampler scattering_texture,
                                SpecbakeScatteringSampler single_mie_scattering_texture, vec3 up, real h, vec3 view,
                                real shadow_length, vec3 sun, OUT(SpecbakeRadiance) transmittance) {
  real r;
  real mu;
  real d_top;
  if (SpecbakeEnterAtmosphere(atm, up, h, view, r, mu, d_top) == 0) {
    transmittance = SpecbakeRadiance(R(1.0));
    return SpecbakeRadiance(R(0.0));
  }
  real mu_s = clamp_cosine(dot(up, sun));
  real nu = clamp_cosine(dot(view, sun));
  int ground = ray_meets_ground(atm.bottom_radius, h, mu);
  transmittance = ground != 0 ? SpecbakeRadiance(R(0.0)) : GetTransmittanceToTopAtmosphereBoundary(atm, transmittance_texture, h, mu);
  SpecbakeRadiance s;
  SpecbakeRadiance m;
  if (shadow_length == R(0.0)) {
    s = GetScattering(atm, scattering_texture, h, mu, mu_s, nu, ground);
    m = GetScattering(atm, single_mie_scattering_texture, h, mu, mu_s, nu, ground);
  } else {
    SpecbakeRadiance t_shadow = GetTransmittance(atm, transmittance_texture, h, mu, shadow_length, ground);
    s = SpecbakeScatteringAlong(atm, scattering_texture, single_mie_scattering_texture, h, r, mu, mu_s, nu,
                                shadow_length, ground, m) * t_shadow;
    m = m * t_shadow;
  }
  return s * rayleigh_phase(nu) + m * mie_phase(atm.mie_g, nu);
}

#ifndef SPECBAKE_SPECTRAL
/* ---- the sky-view table (lookup.cl, "The sky-view table"; RGB bundles that have one) ---------
 * Its range and node counts (sampling.glsl's SPECBAKE_SKY_VIEW). */
struct SpecbakeSkyView {
  real altitude_min;   /* km: the cameras it holds */
  real altitude_max;
  real sun_min;        /* rad: the sun elevations it holds */
  real sun_max;
  real altitude_size;  /* node counts */
  real sun_size;
  real view_size;
  real azimuth_size;
};
/* Sun node s of a table at (u_az, u_view) and altitude position p ∈ [0, altitude_size − 1]: the
 * depth coordinate stays inside the sun node's block of altitudes, so the filter blends
 * altitudes, never two suns. */
vec3 SpecbakeSkyViewSlice(SpecbakeSkyView sv, sampler3D table, real s, real u_az, real u_view, real p) {
  real z = (s * sv.altitude_size + p + R(0.5)) / (sv.sun_size * sv.altitude_size);
  return TEXTURE_RGB(table, vec3(u_az, u_view, z));
}
/* The table's sky radiance at altitude h (inside its range) along a ray with cosines mu, mu_s,
 * nu: Rayleigh and multiple scattering as stored, single Mie times its phase; the two sun nodes
 * around the sun blended geometrically (mu_s_blend). */
vec3 GetSkyViewScattering(SpecbakeAtmosphere atm, SpecbakeSkyView sv, sampler3D sky_view_texture,
                          sampler3D sky_view_mie_texture, real h, real mu, real mu_s, real nu, int ground) {
  real u_view = sky_view_u_view_at(atm.bottom_radius, h, mu, ground, sv.view_size);
  real u_az = sky_view_u_azimuth_at(sky_view_cos_azimuth(mu, mu_s, nu), sv.azimuth_size);
  real p = sky_view_node_position(h, sv.altitude_min, sv.altitude_max, sv.altitude_size);
  real q = sky_view_node_position(asin(mu_s), sv.sun_min, sv.sun_max, sv.sun_size);
  real s0 = floor(q);
  real s1 = fmin(s0 + R(1.0), sv.sun_size - R(1.0));
  real g = q - s0;
  vec3 l = SpecbakeMuSBlend(SpecbakeSkyViewSlice(sv, sky_view_texture, s0, u_az, u_view, p),
                            SpecbakeSkyViewSlice(sv, sky_view_texture, s1, u_az, u_view, p), g);
  vec3 m = SpecbakeMuSBlend(SpecbakeSkyViewSlice(sv, sky_view_mie_texture, s0, u_az, u_view, p),
                            SpecbakeSkyViewSlice(sv, sky_view_mie_texture, s1, u_az, u_view, p), g);
  return l + m * mie_phase(atm.mie_g, nu);
}
/* GetSkyRadiance (no light shafts) that reads the sky-view table where it holds the camera and
 * the sun — a camera inside the atmosphere at an altitude and under a sun elevation of the
 * scene's range — and the 4D textures elsewhere. */
vec3 GetSkyRadianceWithSkyView(SpecbakeAtmosphere atm, SpecbakeSkyView sv, SpecbakeSampler2D transmittance_texture,
                               SpecbakeScatteringSampler scattering_texture,
                               SpecbakeScatteringSampler single_mie_scattering_texture, sampler3D sky_view_texture,
                               sampler3D sky_view_mie_texture, vec3 up, real h, vec3 view, vec3 sun,
                               OUT(vec3) transmittance) {
  real mu_s = clamp_cosine(dot(up, sun));
  if (h > atm.top_radius - atm.bottom_radius ||
      sky_view_covers(h, asin(mu_s), sv.altitude_min, sv.altitude_max, sv.sun_min, sv.sun_max) == 0)
    return GetSkyRadiance(atm, transmittance_texture, scattering_texture, single_mie_scattering_texture, up, h, view,
                          R(0.0), sun, transmittance);
  real hc = clamp_real(h, R(0.0), atm.top_radius - atm.bottom_radius);
  real mu = clamp_cosine(dot(up, view));
  real nu = clamp_cosine(dot(view, sun));
  int ground = ray_meets_ground(atm.bottom_radius, hc, mu);
  transmittance = ground != 0 ? vec3(R(0.0)) : GetTransmittanceToTopAtmosphereBoundary(atm, transmittance_texture, hc, mu);
  return GetSkyViewScattering(atm, sv, sky_view_texture, sky_view_mie_texture, hc, mu, mu_s, nu, ground);
}
#endif

/* Sky radiance between a camera at altitude h and a point `to_point` km away from it (both in
 * or on the atmosphere), and the transmittance between them. Single Mie fades out as the sun
 * sets, as in the reference, to hide its artefacts there. */
SpecbakeRadiance GetSkyRadianceToPoint(SpecbakeAtmosphere atm, SpecbakeSampler2D transmittance_texture,
                                       SpecbakeScatteringSampler scattering_texture,
                                       SpecbakeScatteringSampler single_mie_scattering_texture, vec3 up, real h,
                                       vec3 to_point, real shadow_length, vec3 sun,
                                       OUT(SpecbakeRadiance) transmittance) {
  real d = length(to_point);
  vec3 view = to_point / d;
  real r;
  real mu;
  real d_top;
  if (SpecbakeEnterAtmosphere(atm, up, h, view, r, mu, d_top) == 0) {  /* from space, past the atmosphere */
    transmittance = SpecbakeRadiance(R(1.0));
    return SpecbakeRadiance(R(0.0));
  }
  d = fmax(d - d_top, R(0.0));
  real mu_s = clamp_cosine(dot(up, sun));
  real nu = clamp_cosine(dot(view, sun));
  int ground = ray_meets_ground(atm.bottom_radius, h, mu);
  transmittance = GetTransmittance(atm, transmittance_texture, h, mu, d, ground);
  SpecbakeRadiance s = GetScattering(atm, scattering_texture, h, mu, mu_s, nu, ground);
  SpecbakeRadiance m = GetScattering(atm, single_mie_scattering_texture, h, mu, mu_s, nu, ground);
  d = fmax(d - shadow_length, R(0.0));
  SpecbakeRadiance m_p;
  SpecbakeRadiance s_p = SpecbakeScatteringAlong(atm, scattering_texture, single_mie_scattering_texture, h, r, mu, mu_s, nu, d,
                                     ground, m_p);
  SpecbakeRadiance t_shadow = shadow_length > R(0.0) ? GetTransmittance(atm, transmittance_texture, h, mu, d, ground) : transmittance;
  real fade = smooth_step(R(0.0), R(0.01), mu_s);
  s = s - t_shadow * s_p;
  m = (m - t_shadow * m_p) * fade;
  return s * rayleigh_phase(nu) + m * mie_phase(atm.mie_g, nu);
}

/* Sun and sky irradiance on a surface at altitude h (up: the local vertical) with unit `normal`:
 * returns the sun's part; `sky_irradiance` gets the sky's, from the irradiance texture scaled by
 * the fraction of the sky the tilted surface sees. */
SpecbakeRadiance GetSunAndSkyIrradiance(SpecbakeAtmosphere atm, SpecbakeSampler2D transmittance_texture,
                                        SpecbakeSampler2D irradiance_texture, vec3 up, real h, vec3 normal, vec3 sun,
                                        OUT(SpecbakeRadiance) sky_irradiance) {
  h = clamp_real(h, R(0.0), atm.top_radius - atm.bottom_radius);
  real mu_s = clamp_cosine(dot(up, sun));
  sky_irradiance = GetIrradiance(atm, irradiance_texture, h, mu_s) * ((R(1.0) + dot(normal, up)) * R(0.5));
  return SPECBAKE_SOLAR_IRRADIANCE(atm) * GetTransmittanceToSun(atm, transmittance_texture, h, mu_s) *
         fmax(dot(normal, sun), R(0.0));
}

#ifdef SPECBAKE_SPECTRAL
/* ---- one wavelength -------------------------------------------------------------------- */
/* A spectral renderer's lookups at any wavelength lambda (nm): the functions above at the sets
 * holding the two stored wavelengths around lambda, interpolated linearly between them (outside
 * the stored range: the nearest stored wavelength). The bundle's manifest records what this
 * interpolation costs against a bake at wavelengths between the stored ones. */

/* Where lambda (nm) falls among the stored wavelengths lambda_first + i lambda_step: x, y the
 * stored indices around it (y = x at the end), z the weight of y, w 1 when y is in another set. */
vec4 SpecbakeWavelengthTaps(SpecbakeAtmosphere atm, real lambda) {
  real x = clamp_real((lambda - atm.lambda_first) / atm.lambda_step, R(0.0), atm.lambda_count - R(1.0));
  real i0 = floor(x);
  real i1 = fmin(i0 + R(1.0), atm.lambda_count - R(1.0));
  return vec4(i0, i1, x - i0, floor(i0 / R(4.0)) != floor(i1 / R(4.0)) ? R(1.0) : R(0.0));
}
/* atm reading the set (array layer) that holds stored wavelength i. */
SpecbakeAtmosphere SpecbakeAtmosphereOfWavelength(SpecbakeAtmosphere atm, real i) {
  SpecbakeAtmosphere a = atm;
  a.layer = floor(i / R(4.0));
  return a;
}
/* The value at the taps' wavelength from v0 (the set of taps.x) and v1 (the set of taps.y). */
real SpecbakeMixWavelengths(SpecbakeRadiance v0, SpecbakeRadiance v1, vec4 taps) {
  return v0[int(taps.x - R(4.0) * floor(taps.x / R(4.0)))] * (R(1.0) - taps.z) +
         v1[int(taps.y - R(4.0) * floor(taps.y / R(4.0)))] * taps.z;
}

real GetSolarIrradianceAtWavelength(SpecbakeAtmosphere atm, real lambda) {
  vec4 k = SpecbakeWavelengthTaps(atm, lambda);
  return SpecbakeMixWavelengths(atm.solar_irradiance[int(floor(k.x / R(4.0)))],
                                atm.solar_irradiance[int(floor(k.y / R(4.0)))], k);
}

real GetSkyRadianceAtWavelength(SpecbakeAtmosphere atm, SpecbakeSampler2D transmittance_texture,
                                SpecbakeSampler2D scattering_texture, SpecbakeSampler2D single_mie_scattering_texture,
                                vec3 up, real h, vec3 view, real shadow_length, vec3 sun, real lambda,
                                OUT(real) transmittance) {
  vec4 k = SpecbakeWavelengthTaps(atm, lambda);
  SpecbakeRadiance t0;
  SpecbakeRadiance l0 = GetSkyRadiance(SpecbakeAtmosphereOfWavelength(atm, k.x), transmittance_texture,
                                       scattering_texture, single_mie_scattering_texture, up, h, view, shadow_length,
                                       sun, t0);
  SpecbakeRadiance t1 = t0;
  SpecbakeRadiance l1 = l0;
  if (k.w != R(0.0))
    l1 = GetSkyRadiance(SpecbakeAtmosphereOfWavelength(atm, k.y), transmittance_texture, scattering_texture,
                        single_mie_scattering_texture, up, h, view, shadow_length, sun, t1);
  transmittance = SpecbakeMixWavelengths(t0, t1, k);
  return SpecbakeMixWavelengths(l0, l1, k);
}

real GetSkyRadianceToPointAtWavelength(SpecbakeAtmosphere atm, SpecbakeSampler2D transmittance_texture,
                                       SpecbakeSampler2D scattering_texture,
                                       SpecbakeSampler2D single_mie_scattering_texture, vec3 up, real h,
                                       vec3 to_point, real shadow_length, vec3 sun, real lambda,
                                       OUT(real) transmittance) {
  vec4 k = SpecbakeWavelengthTaps(atm, lambda);
  SpecbakeRadiance t0;
  SpecbakeRadiance l0 = GetSkyRadianceToPoint(SpecbakeAtmosphereOfWavelength(atm, k.x), transmittance_texture,
                                              scattering_texture, single_mie_scattering_texture, up, h, to_point,
                                              shadow_length, sun, t0);
  SpecbakeRadiance t1 = t0;
  SpecbakeRadiance l1 = l0;
  if (k.w != R(0.0))
    l1 = GetSkyRadianceToPoint(SpecbakeAtmosphereOfWavelength(atm, k.y), transmittance_texture, scattering_texture,
                               single_mie_scattering_texture, up, h, to_point, shadow_length, sun, t1);
  transmittance = SpecbakeMixWavelengths(t0, t1, k);
  return SpecbakeMixWavelengths(l0, l1, k);
}

real GetSunAndSkyIrradianceAtWavelength(SpecbakeAtmosphere atm, SpecbakeSampler2D transmittance_texture,
                                        SpecbakeSampler2D irradiance_texture, vec3 up, real h, vec3 normal, vec3 sun,
                                        real lambda, OUT(real) sky_irradiance) {
  vec4 k = SpecbakeWavelengthTaps(atm, lambda);
  SpecbakeRadiance e0;
  SpecbakeRadiance s0 = GetSunAndSkyIrradiance(SpecbakeAtmosphereOfWavelength(atm, k.x), transmittance_texture,
                                               irradiance_texture, up, h, normal, sun, e0);
  SpecbakeRadiance e1 = e0;
  SpecbakeRadiance s1 = s0;
  if (k.w != R(0.0))
    s1 = GetSunAndSkyIrradiance(SpecbakeAtmosphereOfWavelength(atm, k.y), transmittance_texture, irradiance_texture,
                                up, h, normal, sun, e1);
  sky_irradiance = SpecbakeMixWavelengths(e0, e1, k);
  return SpecbakeMixWavelengths(s0, s1, k);
}
#endif
