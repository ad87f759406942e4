/* path_tracer.cl — a Monte Carlo path tracer of the atmosphere model of atmosphere.cl: the
 * ground truth the precomputed LUTs are judged by. Shared by the OpenCL kernel
 * (kernels/atmosphere/truth_kernels.cl, real = double where the device has cl_khr_fp64, else
 * float) and the C++ double reference (src/kinds/atmosphere/truth/truth_reference.hpp). Include it
 * after atmosphere.cl, whose parameter block, density profiles, phase functions, distances and
 * sun terms it uses: the tracer and the LUT kernels cannot disagree on the model.
 *
 * What is traced: what Bruneton's GetSkyRadiance(camera, view, shadow_length = 0, sun) returns,
 * i.e. the light scattered towards a camera at altitude h along the view ray (h, mu) between the
 * camera and the ground or the top of the atmosphere, all scattering orders (or orders 1..N):
 *   L(x, v) = ∫_0^D T(x, x_t) J(x_t, v) dt,
 *   J(y, v) = Σ_i β_i,s ρ_i(y) [ P_i(ν) E_sun T_sun(y) V(y) + ∫_4π P_i(v·ω) L(y, ω) dω ],
 * where L(y, ω) includes the Lambertian ground at the end of ω, radiance (a/π) E_ground, E_ground
 * being the direct sun E_sun T_sun cosine factor plus the sky. Not traced: the sun disc itself,
 * and the ground's own radiance at the end of a view ray that hits it (both are added by the
 * renderer, not stored in the scattering textures). i: Rayleigh (phase P_R), Mie (Cornette–Shanks
 * P_M with g), the ozone layer absorbs. T(x, y) = exp(−∫ σ_t), σ_t = β_R ρ_R + β_M,e ρ_M + β_A ρ_A.
 *
 * Orders as Bruneton counts them: every scattering event and every ground reflection is one
 * order; the event on the view ray is order 1 (single scattering), so sun → ground → scattering
 * → camera is order 2.
 *
 * The sun is a direction weighted by the visible fraction of its disc, as the bake does:
 * at a scattering point E_sun T_sun V with V = sun_visible_fraction() (smoothstep over the disc
 * at the horizon), T_sun the transmittance of the ray to the top towards the disc centre, or,
 * when the centre is below the horizon but part of the disc is not, of the ray grazing the
 * horizon (what the transmittance texture's clamp to its edge gives); on the ground E_sun T_sun
 * times sun_horizontal_cosine() (the mean cosine over the visible part of the disc).
 *
 * Estimator (per wavelength: each channel is an independent scalar random walk):
 *  - the view ray's vertex is sampled with a pdf proportional to (an approximation of)
 *    β_s ρ(t) T(x, x_t): the host tabulates the ray's optical depth τ at nodes (converged
 *    quadrature, nodes at every kink of the profiles) and the segment probabilities; a segment
 *    is drawn from that table and t uniformly inside it. The weight uses the exact T: τ at the
 *    segment start plus a 4-point Gauss–Legendre integral of σ_t over [t_k, t] (no kink inside);
 *  - every other free path by delta tracking against a majorant (collision pdf σ_t T, weight
 *    1/σ_t), reaching the ground with probability T; in deep twilight (truth_deep_shadow_cosine),
 *    half of them instead from a table along the ray ∝ σ_s T̂ S̄, S̄ the light
 *    scattered once towards a point (a host table over altitude and sun angle), one-sample MIS
 *    with delta tracking ("the light at a vertex" below): in the planet's shadow the light at
 *    a vertex spans orders of magnitude with its altitude, and delta tracking seldom ends where
 *    it is bright;
 *  - order 1 (the sun at the view ray's vertex): given by the host's quadrature
 *    (TRUTH_ORDER1_GIVEN, the walks then carry orders ≥ 2), or next-event estimation there
 *    (T_sun by ratio tracking, unbiased); for every later vertex, its expectation over where the free path ends, drawn
 *    on the sunlit part of the new direction's ray by the vertex before it
 *    (truth_next_sun_term: T and T_sun by ratio tracking) — in twilight a free path rarely
 *    ends in sunlit air, and the plain estimate is that rare event;
 *  - new directions: the mixture of Rayleigh (exact inversion) and Henyey–Greenstein with the
 *    same g, weighted by (β_R P_R + β_M P_M)/(β_R P_R + β_M P_HG) ∈ [0.57, 1.14] for g = 0.8;
 *    cosine-weighted after the ground (weight a);
 *  - twilight points (sun below the horizon, guided walks) may first learn from pilot walks a
 *    view-ray table and a density for their first direction ("learned guides" below);
 *  - Russian roulette on the relative throughput (all orders), or a stop after order N.
 * Majorant: σ̄ = max of σ_t over altitudes ≥ h_min (a table of TRUTH_SHELLS altitude shells
 * built by the host from the exact maxima of the profiles), h_min the lowest altitude left on
 * the remaining ray; a density above it is counted and fails the run. Ratio tracking uses
 * TRUTH_RATIO_BOOST × σ̄: its relative variance for an optical depth τ is about e^{τ/boost} − 1.
 *
 * Random numbers: Philox4x32-10 (common/philox.h), one stream per (seed, path, point,
 * channel), so a path's value depends on nothing else (batching, launch split, device count).
 *
 * Units: km, km⁻¹, radiance in the unit of solar_irradiance per sr (W m⁻² sr⁻¹ nm⁻¹).
 * Geometry: the state is the altitude h (as atmosphere.cl: never r) plus unit vectors for the
 * local zenith, the direction and the sun; positions move by ẑ' = (r ẑ + s ω)/|…|, altitudes
 * and the ray's own distances come from the altitude-based functions of atmosphere.cl.
 */
#include "common/philox.h"

#ifndef ATM_PI
#  error "include atmosphere/atmosphere.cl before path_tracer.cl"
#endif

#define TRUTH_SHELLS 256        /* the medium table's majorants: shells of thickness (rt − rb)/TRUTH_SHELLS */
#define TRUTH_MAX_KINKS 32      /* kink altitudes of the profiles the host splits tables at */
/* The medium table (host-built, one per channel group): [TRUTH_SHELLS][NCH] majorants, then
 * the number of the exact depths' cut altitudes, TRUTH_MAX_CUTS of them (ascending, km, the
 * top of the atmosphere last; truth_depth_piece_error below says how the host places them) and
 * TRUTH_MAX_CUTS Gauss–Legendre orders (5 or 8), one per piece below a cut; then the optical depth towards the sun [TRUTH_SUN_H][TRUTH_SUN_MU][NCH] at the nodes
 * of truth_sun_node (truth_sun_depth_table: it only shapes a pdf); then the log of the light
 * scattered once towards a point, [TRUTH_SKY_H][TRUTH_SKY_MU][NCH] at the nodes of
 * truth_sky_node (truth_sky_light_table: it only shapes a pdf; all 0 where no walk of the
 * trace reads it). */
#define TRUTH_DEPTH_LEVELS 4
#define TRUTH_DEPTH_MAX_LEVELS 1024
#define TRUTH_MAX_CUTS (TRUTH_DEPTH_MAX_LEVELS + TRUTH_MAX_KINKS + 1)
#define TRUTH_CUTS_AT (TRUTH_SHELLS * NCH)
#define TRUTH_SUN_H 48
#define TRUTH_SUN_MU 64
#define TRUTH_SUN_AT (TRUTH_CUTS_AT + 1 + 2 * TRUTH_MAX_CUTS)
#define TRUTH_SKY_H 16
#define TRUTH_SKY_MU 32
#define TRUTH_SKY_AT (TRUTH_SUN_AT + TRUTH_SUN_H * TRUTH_SUN_MU * NCH)
#define TRUTH_MEDIUM_SIZE (TRUTH_SKY_AT + TRUTH_SKY_H * TRUTH_SKY_MU * NCH)
/* Exact optical depths (truth_optical_depth, from the three profiles' lengths that
 * truth_optical_lengths integrates at once): the ray is cut where it crosses a cut altitude
 * (every kink of the profiles, and levels between them), so that each piece changes altitude
 * monotonically, holds no kink and is integrated by 5- or 8-point Gauss–Legendre to the
 * relative error TRUTH_DEPTH_ERROR. The host places the levels (medium_table, truth.cpp) from
 * the bottom up, each piece as long as truth_depth_piece_error allows with 8 points, at most the atmosphere's
 * thickness / TRUTH_DEPTH_LEVELS, then gives each piece 5 points where they suffice; more than TRUTH_DEPTH_MAX_LEVELS of them (raw
 * exp_scale_per_km layers much steeper than scale_height_km's least 10 m) fall back to that
 * many equal levels, a cost bound beyond which the stated error does not hold. */
#define TRUTH_DEPTH_ERROR R(4e-8)
#define TRUTH_MAX_EVENTS 1000   /* all-orders walks stop here (counted as truncated) */
#define TRUTH_RATIO_BOOST R(2.0)

/* One view point (host-built), TRUTH_POINT_STRIDE reals. */
#define PT_H 0       /* camera altitude, km (moved to the top boundary for cameras above it) */
#define PT_MU 1      /* cos view zenith there */
#define PT_MU_S 2    /* cos sun zenith there */
#define PT_NU 3      /* cos view–sun angle */
#define PT_D 4       /* length of the view ray to the ground or the top, km */
#define PT_GROUND 5  /* 1 if the view ray ends on the ground */
#define PT_Z 6       /* 3: unit local zenith */
#define PT_V 9       /* 3: unit view direction */
#define PT_S 12      /* 3: unit sun direction */
#define PT_NODES 15  /* node count of the view ray's table (0: nothing to trace) */
#define TRUTH_POINT_STRIDE 16

/* Output per (point, batch): per channel three running statistics (Welford: the batch mean
 * and the sum of squared deviations) of the walk's radiance: all of it (orders 1..max_orders,
 * or all), the part of orders 1..split_order, and the part of orders > split_order (the same
 * walks: the two parts add up to the whole, and their difference from another bake's orders
 * is measured without the noise of an independent trace); then events, truncated walks,
 * majorant violations, walks. */
#define TRUTH_STATS 3
#define TRUTH_OUT_STRIDE (2 * TRUTH_STATS * NCH + 4)

/* ---- random numbers ------------------------------------------------------------------- */
/* A 32-bit word to (0, 1), never 0 or 1 (float builds keep the top 23 bits: (2²³ − 1) + 0.5
 * is exact in float, where (2²⁴ − 1) + 0.5 would round to 2²⁴, a uniform of exactly 1). */
FN real philox_uniform(PhiloxStream* s) {
  const philox_u32 x = philox_next(s);
#if defined(__OPENCL_C_VERSION__) && !defined(SPECBAKE_REAL_DOUBLE)
  return ((real)(x >> 9) + R(0.5)) * R(1.1920928955078125e-7);
#else
  return ((real)x + R(0.5)) * R(2.3283064365386963e-10);
#endif
}

/* ---- small vector helpers --------------------------------------------------------------- */
FN void v3_normalize(real* v) {
  const real n = sqrt(dot3(v, v));
  v[0] /= n;
  v[1] /= n;
  v[2] /= n;
}
/* The zenith at distance s along direction w from a point at altitude h with zenith z. */
FN void truth_move_zenith(const AtmosphereParameters* a, real h, const real* z, const real* w, real s, real* out) {
  const real r = radius_of(a, h);
  for (int k = 0; k < 3; ++k) out[k] = r * z[k] + s * w[k];
  v3_normalize(out);
}
/* The unit vector at angle acos(cos_t) from n, azimuth phi (frame of Duff et al. 2017). */
FN void truth_rotate(const real* n, real cos_t, real phi, real* out) {
  const real sgn = n[2] >= R(0.0) ? R(1.0) : R(-1.0);
  const real aa = R(-1.0) / (sgn + n[2]);
  const real b = n[0] * n[1] * aa;
  const real b1[3] = {R(1.0) + sgn * n[0] * n[0] * aa, sgn * b, -sgn * n[0]};
  const real b2[3] = {b, sgn + n[1] * n[1] * aa, -n[1]};
  const real sin_t = sqrt(fmax(R(1.0) - cos_t * cos_t, R(0.0)));
  const real cp = cos(phi), sp = sin(phi);
  for (int k = 0; k < 3; ++k) out[k] = sin_t * (cp * b1[k] + sp * b2[k]) + cos_t * n[k];
  v3_normalize(out);
}

/* ---- the medium ------------------------------------------------------------------------- */
/* Scattering (Rayleigh, Mie) and extinction coefficients of channel c at altitude h, km⁻¹. */
FN void truth_coefficients(const AtmosphereParameters* a, int c, real h, real* s_r, real* s_m, real* s_t) {
  const real rho_r = profile_density(&a->rayleigh_density, h);
  const real rho_m = profile_density(&a->mie_density, h);
  const real rho_a = profile_density(&a->absorption_density, h);
  *s_r = a->rayleigh_scattering[c] * rho_r;
  *s_m = a->mie_scattering[c] * rho_m;
  *s_t = *s_r + a->mie_extinction[c] * rho_m + a->absorption_extinction[c] * rho_a;
}
FN real truth_extinction(const AtmosphereParameters* a, int c, real h) {
  real s_r, s_m, s_t;
  truth_coefficients(a, c, h, &s_r, &s_m, &s_t);
  return s_t;
}
/* The majorant of channel c for a ray whose lowest remaining altitude is h_min. */
FN real truth_majorant(const AtmosphereParameters* a, GLOBAL const real* medium, int c, real h_min) {
  const real width = thickness(a) / (real)TRUTH_SHELLS;
  const int shell = clamp_int((int)floor(h_min / width), 0, TRUTH_SHELLS - 1);
  return medium[shell * NCH + c];
}
/* The lowest altitude of the ray (h, mu) that does not hit the ground: its start if it rises,
 * else its tangent point, at r √(1 − μ²) from the centre: ρ_t² = ρ² − (rμ)². */
FN real truth_tangent_altitude(const AtmosphereParameters* a, real h, real mu) {
  if (mu >= R(0.0)) return h;
  const real r_mu = radius_of(a, h) * mu;
  return fmax(altitude_of_rho2(a, horizon_distance2(a, h) - r_mu * r_mu), R(0.0));
}

/* ∫ σ_t dt over [t0, t1] along (h, mu, hits_ground), 4-point Gauss–Legendre. The segment
 * holds no kink of the profiles and is at most 1/256 of the view ray, so the integrand is a
 * smooth exponential of scale L ≳ the segment; the rule's relative error is
 * 5.6e-10 (Δ/L)^8 ≤ 6e-7 for Δ/L ≤ 3 (Earth: Δ/L < 0.5). */
FN real truth_segment_depth(const AtmosphereParameters* a, int c, real h, real mu, int hits_ground, real t0,
                            real t1) {
  const real x[2] = {R(0.3399810435848563), R(0.8611363115940526)};
  const real w[2] = {R(0.6521451548625461), R(0.3478548451374538)};
  const real mid = R(0.5) * (t0 + t1), half_len = R(0.5) * (t1 - t0);
  real sum = R(0.0);
  for (int i = 0; i < 2; ++i)
    for (int side = 0; side < 2; ++side) {
      const real t = side == 0 ? mid - half_len * x[i] : mid + half_len * x[i];
      real h_t, mu_t;
      point_along(a, h, mu, t, hits_ground, &h_t, &mu_t);
      sum += w[i] * truth_extinction(a, c, h_t);
    }
  return sum * half_len;
}

/* ---- exact optical depth --------------------------------------------------------------------- */
/* ∫ σ_t ds over [0, s_end] of the ray (h, mu), by quadrature: the deterministic counterpart of
 * ratio tracking, for the long grazing rays of twilight whose ratio-tracking variance,
 * e^{τ/boost} − 1, is what limits the truth there. Along the ray x = s + r μ is the signed
 * distance from its point closest to the planet's centre, where r² − r_b² = ρ_t² + x² with
 * ρ_t² = ρ² − (r μ)² (altitude-based, as everywhere here). A cut altitude h_j crosses the ray
 * at x = ±√(ρ_j² − ρ_t²); between consecutive crossings (and x = 0) the altitude is monotone
 * between two consecutive cuts, with no kink inside, so Gauss–Legendre in x is accurate: the
 * integrand is a sum of exponentials in the altitude (a Gaussian in x at a tangent point) plus
 * linear and constant terms, which the rule integrates exactly.
 *
 * The error of one piece. For e^{−E u} on [0, 1] the n-point rule's relative error is at most
 * (n!)⁴ E^{2n} / ((2n+1) ((2n)!)³) · E / (1 − e^{−E}) (the rule's remainder with the 2n-th
 * derivative bounded by E^{2n}): 3.8e-8 at E = 8 for n = 8, growing as E¹⁷; 4e-8 at E = 3.3
 * for n = 5, which Earth's pieces above the aerosols meet (Rayleigh's E ≤ 1.9). Over a piece
 * between the altitudes h0 < h1 an exponential layer a e^{b h} has E = |b| (h1 − h0), and
 * its error counts in the piece's depth only by its share of σ_t there, at most its largest
 * value over the piece over the least σ_t over the piece. truth_depth_piece_error adds those
 * up for channel c: a steep layer that is a small part of σ_t (Earth's Mie aerosols above
 * ~10 km, 1e-3 of σ_t at 10 km and 1e-8 at 25 km) then spans more of its scale heights a piece
 * than one that dominates (there E ≤ 8 for 8 points, the rule every piece met when the levels
 * were equal ones 8 scale heights of the steepest layer apart). Earth: 7 pieces from the ground
 * to the top, 4 of them of 5 points (equal levels: 10 of 8); a 0.3 km haze 8 (28); errors seen
 * ≤ 4e-9 on Earth, 3e-8 on Mars (tests/atmosphere/truth_test.cpp); a 24-point twilight trace
 * 1.47× faster. */
FN real truth_gauss_relative_error(int n, real E) {
  if (!(E > R(1e-6))) return R(0.0);
  const real e2 = E * E, e4 = e2 * e2, e8 = e4 * e4;
  /* (n!)⁴ / ((2n+1) ((2n)!)³): 3.94497e-13 (n = 5), 1.69736e-23 (n = 8) */
  const real tail = n == 5 ? R(3.94497e-13) * e8 * e2 : R(1.69736e-23) * e8 * e8;
  return tail * E / (R(1.0) - exp(-E));
}
/* Where one layer a·exp(b·h) + c·h + d is stationary, a·b·exp(b·h) + c = 0, when that lies
 * inside (lo, hi) (a maximum for a < 0, a minimum for a > 0); −1 otherwise. */
FN real layer_stationary_altitude(const DensityProfile* p, int layer, real lo, real hi) {
  const real ea = p->exp_term[layer], eb = p->exp_scale[layer], lc = p->linear_term[layer];
  if (ea == R(0.0) || eb == R(0.0) || lc == R(0.0)) return R(-1.0);
  const real arg = -lc / (ea * eb);
  if (!(arg > R(0.0))) return R(-1.0);
  const real h_star = log(arg) / eb;
  return h_star > lo && h_star < hi ? h_star : R(-1.0);
}
/* The least of one layer over [lo, hi] (no kink inside, so no clamp sets in): at an end, or for
 * a > 0 (convex) possibly at its stationary altitude. */
FN real layer_min_over(const DensityProfile* p, int layer, real lo, real hi) {
  real m = fmin(layer_density(p, layer, lo), layer_density(p, layer, hi));
  const real h_star = layer_stationary_altitude(p, layer, lo, hi);
  if (p->exp_term[layer] > R(0.0) && h_star >= R(0.0)) m = fmin(m, layer_density(p, layer, h_star));
  return m;
}
/* The layer of profile p that holds the piece [h0, h1] (no kink inside: one layer). */
FN int piece_layer(const DensityProfile* p, real h0, real h1) { return R(0.5) * (h0 + h1) < p->width[0] ? 0 : 1; }
/* The estimated relative error of the n-point rule (n = 5 or 8) over a piece between the
 * altitudes h0 < h1 (no kink inside) for channel c (see above). */
FN real truth_depth_piece_error(const AtmosphereParameters* a, int c, int n, real h0, real h1) {
  const DensityProfile* profiles[3] = {&a->rayleigh_density, &a->mie_density, &a->absorption_density};
  const real beta[3] = {a->rayleigh_scattering[c], a->mie_extinction[c], a->absorption_extinction[c]};
  real sigma_min = R(0.0);
  for (int p = 0; p < 3; ++p) {
    const int l = piece_layer(profiles[p], h0, h1);
    sigma_min += beta[p] * layer_min_over(profiles[p], l, h0, h1);
  }
  real error = R(0.0);
  for (int p = 0; p < 3; ++p) {
    const DensityProfile* q = profiles[p];
    const int l = piece_layer(q, h0, h1);
    const real ea = q->exp_term[l], eb = q->exp_scale[l];
    if (ea == R(0.0) || eb == R(0.0) || beta[p] == R(0.0)) continue;
    /* a layer clamped to 0 or 1 over the piece is a constant there (the clamp's state is the
     * same all over a piece without a kink) */
    const real y = layer_density(q, l, R(0.5) * (h0 + h1));
    if (y <= R(0.0) || y >= R(1.0)) continue;
    const real term_max = fabs(ea) * exp(eb * (eb > R(0.0) ? h1 : h0));
    const real share = sigma_min > R(0.0) ? fmin(beta[p] * term_max / sigma_min, R(1.0)) : R(1.0);
    error += share * truth_gauss_relative_error(n, fabs(eb) * (h1 - h0));
  }
  return error;
}
/* The three profiles' densities (Rayleigh, Mie, absorption) at the point x of the ray whose
 * tangent point is at ρ_t², added with weight w to acc[0..2]. */
FN void truth_add_densities_at_x(const AtmosphereParameters* a, real rho_t2, real x, real w, real* acc) {
  const real h = altitude_of_rho2(a, rho_t2 + x * x);
  acc[0] += w * profile_density(&a->rayleigh_density, h);
  acc[1] += w * profile_density(&a->mie_density, h);
  acc[2] += w * profile_density(&a->absorption_density, h);
}
/* ∫ ρ_i dx over [x0, x1] of that ray for the three profiles (their optical lengths, km), by
 * n-point Gauss–Legendre (n = 5 or 8), added to len[0..2]. */
FN void truth_add_piece_lengths(const AtmosphereParameters* a, int n, real rho_t2, real x0, real x1, real* len) {
  const real mid = R(0.5) * (x0 + x1), half_len = R(0.5) * (x1 - x0);
  real sum[3] = {R(0.0), R(0.0), R(0.0)};
  if (n == 5) {
    const real x[2] = {R(0.5384693101056831), R(0.9061798459386640)};
    const real w[2] = {R(0.4786286704993665), R(0.2369268850561891)};
    truth_add_densities_at_x(a, rho_t2, mid, R(0.5688888888888889), sum);
    for (int i = 0; i < 2; ++i) {
      truth_add_densities_at_x(a, rho_t2, mid - half_len * x[i], w[i], sum);
      truth_add_densities_at_x(a, rho_t2, mid + half_len * x[i], w[i], sum);
    }
  } else {
    const real x[4] = {R(0.1834346424956498), R(0.5255324099163290), R(0.7966664774136268), R(0.9602898564975363)};
    const real w[4] = {R(0.3626837833783620), R(0.3137066458778874), R(0.2223810344533745), R(0.1012285362903762)};
    for (int i = 0; i < 4; ++i) {
      truth_add_densities_at_x(a, rho_t2, mid - half_len * x[i], w[i], sum);
      truth_add_densities_at_x(a, rho_t2, mid + half_len * x[i], w[i], sum);
    }
  }
  for (int i = 0; i < 3; ++i) len[i] += sum[i] * half_len;
}
/* Adds the pieces of |x| ∈ [lo, hi] cut at the crossings √(ρ_j² − ρ_t²) of the cut altitudes
 * (the integrand depends on x² only, so the descending side is integrated in |x| too). */
FN void truth_add_monotone_lengths(const AtmosphereParameters* a, GLOBAL const real* medium, real rho_t2, real lo,
                                   real hi, real* len) {
  if (!(hi > lo)) return;
  const int n_cuts = (int)medium[TRUTH_CUTS_AT];
  real prev = lo;
  int order = 8; /* the rule of the piece below the next cut crossed */
  for (int k = 0; k < n_cuts; ++k) {
    const real x2 = horizon_distance2(a, medium[TRUTH_CUTS_AT + 1 + k]) - rho_t2;
    if (!(x2 > R(0.0))) continue;
    const real x = sqrt(x2);
    if (x <= prev) continue;
    order = (int)medium[TRUTH_CUTS_AT + 1 + TRUTH_MAX_CUTS + k];
    if (x >= hi) break;
    truth_add_piece_lengths(a, order, rho_t2, prev, x, len);
    prev = x;
  }
  truth_add_piece_lengths(a, order, rho_t2, prev, hi, len);
}
/* The three profiles' optical lengths ∫ ρ_i ds (km) over [0, s_end] of the ray (h, mu), exact
 * to TRUTH_DEPTH_ERROR at the cuts of `medium` (whose piece rules hold for every channel of its
 * group: the lengths serve each of them). */
FN void truth_optical_lengths(const AtmosphereParameters* a, GLOBAL const real* medium, real h, real mu, real s_end,
                              real* len) {
  const real r_mu = radius_of(a, h) * mu;
  const real rho_t2 = horizon_distance2(a, h) - r_mu * r_mu;
  const real x0 = r_mu, x1 = r_mu + s_end;
  for (int i = 0; i < 3; ++i) len[i] = R(0.0);
  /* the descending part (x < 0), then the rising part (x > 0) */
  if (x0 < R(0.0)) truth_add_monotone_lengths(a, medium, rho_t2, fmax(-x1, R(0.0)), -x0, len);
  if (x1 > R(0.0)) truth_add_monotone_lengths(a, medium, rho_t2, fmax(x0, R(0.0)), x1, len);
}
/* Channel c's optical depth from the three profiles' optical lengths. */
FN real truth_depth_of_lengths(const AtmosphereParameters* a, int c, const real* len) {
  return a->rayleigh_scattering[c] * len[0] + a->mie_extinction[c] * len[1] + a->absorption_extinction[c] * len[2];
}
/* Channel c's optical depth ∫ σ_t ds over [0, s_end] of the ray (h, mu). */
FN real truth_optical_depth(const AtmosphereParameters* a, int c, GLOBAL const real* medium, real h, real mu,
                            real s_end) {
  real len[3];
  truth_optical_lengths(a, medium, h, mu, s_end, len);
  return truth_depth_of_lengths(a, c, len);
}

/* ---- transmittance estimates: ratio tracking ----------------------------------------------- */
/* Unbiased estimate of T over [0, s_end] of the ray (h, mu, ground): ratio tracking against
 * TRUTH_RATIO_BOOST × the majorant of the lowest altitude left on [s, s_end]. A ray that meets
 * the ground, or one that descends and ends before its tangent point, is lowest at s_end
 * (the boost's factor 2 covers that altitude's rounding); one that passes its tangent point is
 * lowest there, and rises after it. */
FN real truth_ratio_track(const AtmosphereParameters* a, int c, GLOBAL const real* medium, real h, real mu,
                          int ground, real s_end, PhiloxStream* rng, int* violations) {
  const real s_tan = (mu < R(0.0) && !ground) ? -radius_of(a, h) * mu : R(-1.0);
  real h_min;
  if (ground || (mu < R(0.0) && s_end < s_tan)) {
    real mu_end;
    point_along(a, h, mu, s_end, ground, &h_min, &mu_end);
  } else {
    h_min = truth_tangent_altitude(a, h, mu);
  }
  real s = R(0.0), t = R(1.0);
  for (;;) {
    const real majorant_s = TRUTH_RATIO_BOOST * truth_majorant(a, medium, c, h_min);
    if (!(majorant_s > R(0.0))) break;
    s += -log(philox_uniform(rng)) / majorant_s;
    if (s >= s_end) break;
    real h_s, mu_s_;
    point_along(a, h, mu, s, ground, &h_s, &mu_s_);
    const real sigma = truth_extinction(a, c, h_s);
    if (sigma * TRUTH_RATIO_BOOST > majorant_s) *violations += 1;
    t *= R(1.0) - sigma / majorant_s;
    if (!ground && s >= s_tan) h_min = h_s;
  }
  return t;
}

/* ---- free paths: delta tracking ------------------------------------------------------------ */
/* From altitude h along mu: 0 if the walk leaves through the top, 1 if it collides (distance
 * in *s, altitude in *h_s), 2 if it reaches the ground (distance in *s). */
FN int truth_free_path(const AtmosphereParameters* a, int c, GLOBAL const real* medium, real h, real mu,
                       PhiloxStream* rng, real* s_out, real* h_s_out, int* violations) {
  const int ground = ray_hits_ground(a, h, mu);
  const real d = distance_to_nearest_boundary(a, h, mu, ground);
  const real s_tan = (mu < R(0.0) && !ground) ? -radius_of(a, h) * mu : R(-1.0);
  real h_min = ground ? R(0.0) : truth_tangent_altitude(a, h, mu);
  real s = R(0.0);
  for (;;) {
    const real majorant_s = truth_majorant(a, medium, c, h_min);
    if (!(majorant_s > R(0.0))) break; /* an empty medium */
    s += -log(philox_uniform(rng)) / majorant_s;
    if (s >= d) break;
    real h_s, mu_s;
    point_along(a, h, mu, s, ground, &h_s, &mu_s);
    const real sigma = truth_extinction(a, c, h_s);
    if (sigma > majorant_s) *violations += 1;
    if (philox_uniform(rng) * majorant_s < sigma) {
      *s_out = s;
      *h_s_out = h_s;
      return 1;
    }
    if (!ground && s >= s_tan) h_min = h_s;
  }
  *s_out = d;
  *h_s_out = ground ? R(0.0) : thickness(a);
  return ground ? 2 : 0;
}

/* ---- phase functions: sampling ------------------------------------------------------------ */
FN real henyey_greenstein_phase(real g, real cos_t) {
  const real x = R(1.0) + g * g - R(2.0) * g * cos_t;
  return (R(1.0) - g * g) / (R(4.0) * ATM_PI * x * sqrt(x));
}
/* cos θ with density ∝ 1 + cos² θ: the real root of c³ + 3c = 8u − 4, c = A − 1/A. */
FN real sample_rayleigh_cosine(real u) {
  const real q = R(4.0) * u - R(2.0);
  const real A = cbrt(q + sqrt(q * q + R(1.0)));
  return clamp_cosine(A - R(1.0) / A);
}
FN real sample_henyey_greenstein_cosine(real g, real u) {
  if (fabs(g) < R(1e-3)) return R(2.0) * u - R(1.0);
  const real k = (R(1.0) - g * g) / (R(1.0) - g + R(2.0) * g * u);
  return clamp_cosine((R(1.0) + g * g - k * k) / (R(2.0) * g));
}

/* ---- the next order's sun term along a new direction ---------------------------------------- */
/* From a vertex at altitude h (unit zenith z) that sends the walk along the unit direction w,
 * the expected sun term of the next vertex, over where the free path would end:
 *   ∫_0^D T(0, s) [σ_R(s) P_R(ν) + σ_M,s(s) P_M(ν)] E_sun T_sun(s) V(s) ds
 *     + [the ray meets the ground] T(0, D) (a/π) E_sun T_sun(ground) cos_factor(ground),
 * ν = w·sun (the same all along the ray). One point s is drawn on the part of the ray that sees
 * the sun, with a pdf tabulated at TRUTH_LINE_SEGMENTS + 1 equal nodes, linear between them:
 * TRUTH_LINE_F_SHARE ∝ σ_s T̂ and the rest ∝ σ_s T̂ T̂_sun V (T̂ by the trapezoid rule, T̂_sun from
 * the medium table's sun depths, truth_sun_depth_table: they only shape the pdf; the second
 * part follows the light, the first keeps the pdf from trusting it alone); T and T_sun are
 * exact (twilight) or ratio-tracking estimates, so the estimate is unbiased whatever the table.
 * At sun −4…−11° the pdf's mismatch was most of a twilight walk's variance: with an even split
 * and a one-scale-height Chapman guess for T̂_sun, uniform inside segments, the line's
 * variance (weighted over the directions drawn) was 4–10× what this pdf leaves
 * (docs/atmosphere-method.md "Twilight").
 * A segment is left out only when V = 0 at both its ends: {V = 0} = {p·sun ≤ −√(r² − r_b²) −
 * r_b α} is convex (ρ² + 2 r_b α q ≤ r_b²(1 + α²), q = −p·sun ≥ r_b α, ρ the distance from the
 * shadow's axis), so such a segment is dark all along. In twilight most vertices lie in the planet's shadow and a free path rarely ends in
 * sunlit air: this draws the point there (the plain estimate — the sun at the free path's end —
 * had 5–20× the variance per walk at views with the sun 3°–6° below the horizon,
 * docs/atmosphere-method.md "Twilight"). */
#define TRUTH_LINE_SEGMENTS 8
#define TRUTH_LINE_F_SHARE R(0.1) /* the pdf's part that does not follow the sun (defensive) */
/* Which estimate of the sun at vertices after the first (a walk argument): the expectation
 * along the ray (truth_next_sun_term), the sun at the free path's end (plain next-event
 * estimation), or the first where the planet's shadow can matter (AUTO). Both are unbiased;
 * the rule only moves cost and noise. */
#define TRUTH_NEXT_SUN_AUTO 0
#define TRUTH_NEXT_SUN_LINE 1
#define TRUTH_NEXT_SUN_VERTEX 2
/* AUTO: the line estimate for points whose sun is lower than sin(acos(r_b/r_t) + α) in
 * cosine: for a higher sun no air within the top of the atmosphere's horizon distance from the
 * camera (great-circle angle acos(r_b/r_t), ~9° on Earth) lies in the shadow, and the plain
 * estimate, which costs less, is as good. */
FN real truth_shadow_reach_cosine(const AtmosphereParameters* a) {
  const real k = a->bottom_radius / a->top_radius, alpha = a->sun_angular_radius;
  return sqrt(fmax(R(1.0) - k * k, R(0.0))) * cos(alpha) + k * sin(alpha);
}
/* The sun-depth table's node (i, j): altitude h = (rt − rb) (i / (TRUTH_SUN_H − 1))², sun cosine
 * μ = μ_h + (1 − μ_h) (j / (TRUTH_SUN_MU − 1))² with μ_h = −√(r² − r_b²)/r the horizon's (nodes
 * crowd at the ground and at the grazing ray, where the depth changes fastest). */
FN void truth_sun_node(const AtmosphereParameters* a, int i, int j, real* h, real* mu) {
  const real x = (real)i / (real)(TRUTH_SUN_H - 1), y = (real)j / (real)(TRUTH_SUN_MU - 1);
  *h = (a->top_radius - a->bottom_radius) * x * x;
  const real mu_h = -horizon_distance(a, *h) / radius_of(a, *h);
  *mu = mu_h + (R(1.0) - mu_h) * y * y;
}
/* Channel c of a [rows][cols][NCH] node table at fractional node coordinates (x, y) ∈
 * [0, rows − 1] × [0, cols − 1], bilinearly (the sun and sky tables of the medium). */
FN real truth_table_bilinear(GLOBAL const real* T, int rows, int cols, int c, real x, real y) {
  const int i = (int)fmin(floor(x), (real)(rows - 2)), j = (int)fmin(floor(y), (real)(cols - 2));
  const real fx = x - (real)i, fy = y - (real)j;
  GLOBAL const real* n = T + (i * cols + j) * NCH + c;
  return (R(1.0) - fx) * ((R(1.0) - fy) * n[0] + fy * n[NCH]) + fx * ((R(1.0) - fy) * n[cols * NCH] + fy * n[(cols + 1) * NCH]);
}
/* The optical depth towards the sun from altitude h (sun cosine mu_s; along the horizon when
 * the disc centre is below it, as truth_sun_transmittance), interpolated bilinearly in the
 * nodes' coordinates from the table the host fills with exact depths (truth_optical_lengths).
 * Only to shape a pdf: the walks' transmittances are never read from it. */
FN real truth_sun_depth_table(const AtmosphereParameters* a, GLOBAL const real* medium, int c, real h, real mu_s) {
  const real t = a->top_radius - a->bottom_radius;
  const real hh = fmin(fmax(h, R(0.0)), t);
  const real mu_h = -horizon_distance(a, hh) / radius_of(a, hh);
  const real u = fmin(fmax((mu_s - mu_h) / (R(1.0) - mu_h), R(0.0)), R(1.0));
  const real x = sqrt(hh / t) * (real)(TRUTH_SUN_H - 1), y = sqrt(u) * (real)(TRUTH_SUN_MU - 1);
  return truth_table_bilinear(medium + TRUTH_SUN_AT, TRUTH_SUN_H, TRUTH_SUN_MU, c, x, y);
}
/* T_sun from altitude h with sun cosine mu_s (visible fraction not included): along mu_s, or
 * along the horizon when the disc centre is below it. Ratio tracking, or where `exact` (twilight
 * walks) the sun table's T̂ = e^{−τ̂} corrected by the exact depth with probability
 * TRUTH_SUN_EXACT_SHARE = q: T̂ + [u < q] (T − T̂) / q, whose expectation is T for any q > 0
 * and whose variance, (1/q − 1)(T − T̂)², is small beside a walk's own where T̂ is close (the
 * table's |τ̂ − τ| ≤ 0.02 + 0.008 τ, tests/atmosphere/truth_test.cpp: a few % of T; a twilight
 * walk's radiance varies by a factor of ~3 between walks). So 3 of 4 sun transmittances, a third
 * of a twilight walk's exact depths, cost a table read. */
#define TRUTH_SUN_EXACT_SHARE R(0.25)
/* t_hat, an approximation of T over [0, s_end] of the ray (h, mu), corrected by the exact depth
 * with probability TRUTH_SUN_EXACT_SHARE = q: t_hat + [u < q] (T − t_hat) / q, expectation T. */
FN real truth_corrected_transmittance(const AtmosphereParameters* a, int c, GLOBAL const real* medium, real h,
                                      real mu, real s_end, real t_hat, PhiloxStream* rng) {
  if (philox_uniform(rng) >= TRUTH_SUN_EXACT_SHARE) return t_hat;
  const real t = exp(-truth_optical_depth(a, c, medium, h, mu, s_end));
  return t_hat + (t - t_hat) / TRUTH_SUN_EXACT_SHARE;
}
/* The cosine of the ray T_sun is taken along: the disc centre's, or the horizon's when the
 * centre is below it (what the transmittance texture's clamp to its edge gives). */
FN real truth_sun_ray_cosine(const AtmosphereParameters* a, real h, real mu_s) {
  return fmax(mu_s, -horizon_distance(a, h) / radius_of(a, h));
}
FN real truth_sun_transmittance(const AtmosphereParameters* a, int c, GLOBAL const real* medium, real h, real mu_s,
                                int exact, PhiloxStream* rng, int* violations) {
  const real mu = truth_sun_ray_cosine(a, h, mu_s);
  if (!exact) return truth_ratio_track(a, c, medium, h, mu, 0, distance_to_top(a, h, mu), rng, violations);
  return truth_corrected_transmittance(a, c, medium, h, mu, distance_to_top(a, h, mu),
                                       exp(-truth_sun_depth_table(a, medium, c, h, mu_s)), rng);
}
/* T over [0, s_end] of the line estimate's ray (h, mu, ground), whose trapezoid rule at the
 * line's nodes gave the depth tau_hat: by ratio tracking, or where `exact` (the walks of points
 * whose sun is low: their grazing rays have optical depths of several, where ratio tracking's
 * relative variance e^{τ/boost} − 1 dominated the truth's noise) with the sun's correction,
 * T̂ + [u < q] (T − T̂) / q, T̂ = e^{−tau_hat}, T exact (truth_optical_depth): its expectation is
 * T whatever T̂, and its variance (1/q − 1)(T − T̂)² is small beside a walk's own: at most
 * 0.08 T² on the rays of test TruthTracking.LineViewTransmittanceKeepsItsExpectationWhatever
 * ItsTrapezoid (Earth; Mars 0.02), against ~1–2 for a twilight walk. The exact depth it spares
 * on 3 of 4 line estimates (~40 Gauss–Legendre points over the cut pieces, against the line's
 * 9 nodes) was most of such an estimate's cost. */
FN real truth_view_transmittance(const AtmosphereParameters* a, int c, GLOBAL const real* medium, real h, real mu,
                                 int ground, real s_end, real tau_hat, int exact, PhiloxStream* rng,
                                 int* violations) {
  if (!exact) return truth_ratio_track(a, c, medium, h, mu, ground, s_end, rng, violations);
  return truth_corrected_transmittance(a, c, medium, h, mu, s_end, exp(-tau_hat), rng);
}

/* ---- the light at a vertex: where twilight free paths should end ---------------------------- */
/* S̄(h, μ_s) = ∫_4π L₁(y, ω) dω, L₁(y, ω) = ∫ σ_s T T_sun V dt along ω: the light scattered once
 * (isotropic phase: it only shapes a pdf) that reaches a point at altitude h whose sun cosine is
 * μ_s. In the planet's shadow it spans orders of magnitude: a shadowed point 40 km up sees the
 * sunlit air through thin air, one 5 km up through hundreds of km of dense air, and a point
 * farther towards the terminator sees it nearer. A free path drawn by delta tracking (∝ σ_t T)
 * seldom ends where S̄ is large, and those rare ends carried most of a deep-twilight walk's
 * variance (ground camera, sun −11°, 440 nm: 0.1 % of the walks held 76 % of the second moment,
 * each one a vertex 35–50 km up); truth_guided_free_path draws half of them ∝ σ_s T̂ S̄ instead,
 * and the view ray's table of such points weights its segments by it too (truth.cpp). The host
 * fills the table by a coarse quadrature (truth.cpp, sky_light_table: a factor of 2 only moves
 * noise). Nodes: altitude (rt − rb) (i / (TRUTH_SKY_H − 1))², μ_s uniform on
 * [TRUTH_SKY_MU_MIN, 1] (clamped below: S̄ is negligible there); stored as log S̄
 * (TRUTH_SKY_NONE for none), interpolated bilinearly in the log (exact for exponential
 * variation). */
#define TRUTH_SKY_MU_MIN R(-0.5)
#define TRUTH_SKY_NONE R(-700.0)
FN void truth_sky_node(const AtmosphereParameters* a, int i, int j, real* h, real* mu_s) {
  const real x = (real)i / (real)(TRUTH_SKY_H - 1);
  *h = thickness(a) * x * x;
  *mu_s = TRUTH_SKY_MU_MIN + (R(1.0) - TRUTH_SKY_MU_MIN) * (real)j / (real)(TRUTH_SKY_MU - 1);
}
/* S̄ at (h, μ_s) from the table (bilinear in log S̄; μ_s clamped to the table's range). */
FN real truth_sky_light_table(const AtmosphereParameters* a, GLOBAL const real* medium, int c, real h, real mu_s) {
  const real t = thickness(a);
  const real x = sqrt(fmin(fmax(h, R(0.0)), t) / t) * (real)(TRUTH_SKY_H - 1);
  const real y = fmin(fmax((mu_s - TRUTH_SKY_MU_MIN) / (R(1.0) - TRUTH_SKY_MU_MIN), R(0.0)), R(1.0)) *
                 (real)(TRUTH_SKY_MU - 1);
  return exp(truth_table_bilinear(medium + TRUTH_SKY_AT, TRUTH_SKY_H, TRUTH_SKY_MU, c, x, y));
}

/* The table along a ray that truth_next_sun_term builds anyway, for the free path that follows on
 * the same ray (truth_guided_free_path): TRUTH_LINE_SEGMENTS equal segments of [0, d], q at their
 * nodes ∝ σ_s T̂ S̄, and Σ of the segments' trapezoid masses — left 0 (delta tracking alone) where
 * S̄ grows along the ray by less than TRUTH_FREE_PATH_GAIN over its start's (the table would buy
 * little for its exact T; 2, 4 and 16 gave the same variance × time on deep-twilight views). */
#define TRUTH_FREE_PATH_GAIN R(4.0)
typedef struct {
  real q[TRUTH_LINE_SEGMENTS + 1];
  real sum, ds;
} TruthRayTable;

/* The sun term of the next vertex along the ray (h, w) in expectation (above); with guided != 0
 * also fills *table for the free path on the same ray (S̄ read at the same nodes). */
FN real truth_next_sun_term(const AtmosphereParameters* a, int c, GLOBAL const real* medium, real h, const real* z,
                            const real* w, const real* sun, int exact, int guided, TruthRayTable* table,
                            PhiloxStream* rng, int* violations) {
  const real mu = clamp_cosine(dot3(w, z));
  const int ground = ray_hits_ground(a, h, mu);
  const real d = distance_to_nearest_boundary(a, h, mu, ground);
  const real nu = clamp_cosine(dot3(w, sun));
  const real r0 = radius_of(a, h);
  const real e_sun = a->solar_irradiance[c];
  const real ds = d / (real)TRUTH_LINE_SEGMENTS;
  /* the table: σ_s T̂ and V at the nodes, then the segments' masses */
  real f[TRUTH_LINE_SEGMENTS + 1], g[TRUTH_LINE_SEGMENTS + 1], mass[TRUTH_LINE_SEGMENTS], sky[TRUTH_LINE_SEGMENTS + 1];
  real tau_k[TRUTH_LINE_SEGMENTS + 1];
  int lit[TRUTH_LINE_SEGMENTS + 1];
  real tau = R(0.0), sigma_prev = R(0.0);
  for (int k = 0; k <= TRUTH_LINE_SEGMENTS; ++k) {
    const real s = ds * (real)k;
    real h_k, mu_k, p[3];
    point_along(a, h, mu, s, ground, &h_k, &mu_k);
    for (int i = 0; i < 3; ++i) p[i] = r0 * z[i] + s * w[i];
    const real mu_s_k = clamp_cosine(dot3(sun, p) / sqrt(dot3(p, p)));
    const real visible = sun_visible_fraction(a, h_k, mu_s_k);
    lit[k] = visible > R(0.0);
    real s_r, s_m, s_t;
    truth_coefficients(a, c, h_k, &s_r, &s_m, &s_t);
    if (k > 0) tau += R(0.5) * (sigma_prev + s_t) * ds;
    sigma_prev = s_t;
    tau_k[k] = tau;
    f[k] = (s_r + s_m) * exp(-tau);
    g[k] = lit[k] ? f[k] * visible * exp(-truth_sun_depth_table(a, medium, c, h_k, mu_s_k)) : R(0.0);
    if (guided) {
      sky[k] = truth_sky_light_table(a, medium, c, h_k, mu_s_k);
      table->q[k] = f[k] * sky[k];
    }
  }
  if (guided) {
    table->ds = ds;
    table->sum = R(0.0);
    real sky_max = R(0.0);
    for (int k = 0; k < TRUTH_LINE_SEGMENTS; ++k) table->sum += R(0.5) * (table->q[k] + table->q[k + 1]);
    for (int k = 1; k <= TRUTH_LINE_SEGMENTS; ++k) sky_max = fmax(sky_max, sky[k]);
    if (!(sky_max > TRUTH_FREE_PATH_GAIN * sky[0])) table->sum = R(0.0);
  }
  real total_f = R(0.0), total_g = R(0.0);
  int lit_segments = 0;
  for (int k = 0; k < TRUTH_LINE_SEGMENTS; ++k) {
    const int on = lit[k] || lit[k + 1];
    lit_segments += on;
    if (!on) continue;
    total_f += R(0.5) * (f[k] + f[k + 1]);
    total_g += R(0.5) * (g[k] + g[k + 1]);
  }
  real value = R(0.0);
  if (lit_segments > 0) {
    /* the pdf's two parts at the nodes (q, each part normalised over the lit segments), and a
     * floor of 1e-3 / lit segments (~0.1–0.2 % of the draws in all) so that no lit segment has
     * probability 0 (T̂ may underflow far along a long ray) */
    real sum = R(0.0), q[TRUTH_LINE_SEGMENTS + 1];
    for (int k = 0; k <= TRUTH_LINE_SEGMENTS; ++k)
      q[k] = (total_f > R(0.0) ? TRUTH_LINE_F_SHARE * f[k] / total_f : R(0.0)) +
             (total_g > R(0.0) ? (R(1.0) - TRUTH_LINE_F_SHARE) * g[k] / total_g : R(0.0));
    const real floor_k = R(1e-3) / (real)lit_segments;
    for (int k = 0; k < TRUTH_LINE_SEGMENTS; ++k) {
      mass[k] = R(0.0);
      if (!(lit[k] || lit[k + 1])) continue;
      mass[k] = R(0.5) * (q[k] + q[k + 1]) + floor_k;
      sum += mass[k];
    }
    const real u = philox_uniform(rng) * sum;
    int k = 0;
    real below = R(0.0);
    while (k < TRUTH_LINE_SEGMENTS - 1 && (mass[k] == R(0.0) || below + mass[k] <= u)) {
      below += mass[k];
      ++k;
    }
    /* inside the segment: density floor + q_k (1 − x) + q_{k+1} x over x ∈ [0, 1] (the
     * trapezoid's own shape), one uniform picking the part and the place */
    const real qa = q[k], qb = q[k + 1];
    const real v = philox_uniform(rng) * mass[k];
    real x;
    if (v < floor_k) {
      x = v / floor_k;
    } else {
      const real uu = (v - floor_k) / (R(0.5) * (qa + qb)); /* CDF (qa x + (qb − qa) x²/2) / ((qa + qb)/2) */
      x = uu * (qa + qb) / (qa + sqrt(fmax(qa * qa + (qb - qa) * uu * (qa + qb), R(0.0))));
    }
    x = fmin(fmax(x, R(0.0)), R(1.0));
    const real s = ds * ((real)k + x);
    const real pdf = (floor_k + qa * (R(1.0) - x) + qb * x) / (sum * ds);
    real h_s, mu_dummy, p[3];
    point_along(a, h, mu, s, ground, &h_s, &mu_dummy);
    for (int i = 0; i < 3; ++i) p[i] = r0 * z[i] + s * w[i];
    const real mu_s = clamp_cosine(dot3(sun, p) / sqrt(dot3(p, p)));
    const real visible = sun_visible_fraction(a, h_s, mu_s);
    real s_r, s_m, s_t;
    truth_coefficients(a, c, h_s, &s_r, &s_m, &s_t);
    if (visible > R(0.0) && s_r + s_m > R(0.0) && pdf > R(0.0)) {
      const real tau_hat = tau_k[k] + x * (tau_k[k + 1] - tau_k[k]);
      const real t_view = truth_view_transmittance(a, c, medium, h, mu, ground, s, tau_hat, exact, rng, violations);
      const real t_sun = truth_sun_transmittance(a, c, medium, h_s, mu_s, exact, rng, violations);
      value += t_view * (s_r * rayleigh_phase(nu) + s_m * mie_phase(a->mie_g, nu)) * e_sun * t_sun * visible / pdf;
    }
  }
  if (ground && a->ground_albedo[c] > R(0.0)) {
    real p[3];
    for (int i = 0; i < 3; ++i) p[i] = r0 * z[i] + d * w[i];
    const real mu_s = clamp_cosine(dot3(sun, p) / sqrt(dot3(p, p)));
    const real cos_factor = sun_horizontal_cosine(a, mu_s);
    if (cos_factor > R(0.0)) {
      const real t_view =
          truth_view_transmittance(a, c, medium, h, mu, 1, d, tau_k[TRUTH_LINE_SEGMENTS], exact, rng, violations);
      const real t_sun = truth_sun_transmittance(a, c, medium, R(0.0), mu_s, exact, rng, violations);
      value += t_view * a->ground_albedo[c] / ATM_PI * e_sun * t_sun * cos_factor;
    }
  }
  return value;
}

/* ---- free paths of twilight walks ---------------------------------------------------------- */
/* A free path from the ray's start along (h, mu) drawn from the mixture (1 − β) delta tracking +
 * β q, q the table of truth_next_sun_term along the same ray (∝ σ_s T̂ S̄, linear in each
 * segment; β = TRUTH_FREE_PATH_SHARE): one-sample MIS with the balance heuristic. Returns what
 * truth_free_path returns; *factor multiplies the walk's weight so that, with the 1/σ_t the
 * walk applies at a collision as for delta tracking, the weight carries T(s)/pdf(s), pdf(s) =
 * (1 − β) σ_t T + β q(s) (T exact, truth_optical_depth); at the ground, whose mass only delta
 * tracking draws (T(d)), 1/(1 − β). Unbiased whatever q is: the delta-tracking part reaches
 * every point and the ground. β 0.3, 0.5, 0.7: variance × time 1.5 : 1 : 1 on deep-twilight views. */
#define TRUTH_FREE_PATH_SHARE R(0.5)
/* Which points guide their free paths: those whose sun is lower than the dip of the horizon
 * seen from half the atmosphere's thickness (Earth: 5.6° below the horizon), so that the air
 * above the camera is in the planet's shadow up to at least that height and its light comes
 * from far away. Higher, sunlit air is common along every ray and the guide buys nothing for
 * its cost (sun −6…0°, 16 views: the same variance for ~1.2× the time; −9…−6°: 2–12× less). */
FN real truth_deep_shadow_cosine(const AtmosphereParameters* a) {
  const real k = a->bottom_radius / (R(0.5) * (a->bottom_radius + a->top_radius));
  return -sqrt(fmax(R(1.0) - k * k, R(0.0)));
}
FN int truth_guided_free_path(const AtmosphereParameters* a, int c, GLOBAL const real* medium, real h, real mu,
                              const TruthRayTable* table, PhiloxStream* rng, real* s_out, real* h_s_out,
                              real* factor, int* violations) {
  if (!(table->sum > R(0.0))) {
    *factor = R(1.0);
    return truth_free_path(a, c, medium, h, mu, rng, s_out, h_s_out, violations);
  }
  const int ground = ray_hits_ground(a, h, mu);
  const real beta = TRUTH_FREE_PATH_SHARE;
  int what = 1;
  if (philox_uniform(rng) >= beta) {
    what = truth_free_path(a, c, medium, h, mu, rng, s_out, h_s_out, violations);
    if (what != 1) {
      *factor = R(1.0) / (R(1.0) - beta);
      return what;
    }
  } else {
    /* a segment by its trapezoid mass, then x ∈ [0, 1] from the density ∝ q_k (1 − x) + q_{k+1} x */
    const real u = philox_uniform(rng) * table->sum;
    int k = 0;
    real below = R(0.0);
    for (; k < TRUTH_LINE_SEGMENTS - 1; ++k) {
      const real m = R(0.5) * (table->q[k] + table->q[k + 1]);
      if (m > R(0.0) && below + m > u) break;
      below += m;
    }
    const real qa = table->q[k], qb = table->q[k + 1], uu = philox_uniform(rng);
    const real x = fmin(fmax(uu * (qa + qb) / (qa + sqrt(fmax(qa * qa + (qb - qa) * uu * (qa + qb), R(0.0)))), R(0.0)),
                        R(1.0));
    real mu_dummy;
    *s_out = table->ds * ((real)k + x);
    point_along(a, h, mu, *s_out, ground, h_s_out, &mu_dummy);
  }
  const real s = *s_out;
  const int k = clamp_int((int)floor(s / table->ds), 0, TRUTH_LINE_SEGMENTS - 1);
  const real x = fmin(fmax(s / table->ds - (real)k, R(0.0)), R(1.0));
  const real q_s = beta > R(0.0) ? (table->q[k] * (R(1.0) - x) + table->q[k + 1] * x) / (table->sum * table->ds) : R(0.0);
  const real T = exp(-truth_optical_depth(a, c, medium, h, mu, s));
  const real sigma = truth_extinction(a, c, *h_s_out) * T;
  const real pdf = (R(1.0) - beta) * sigma + beta * q_s;
  *factor = pdf > R(0.0) ? sigma / pdf : R(0.0);
  return what;
}

/* ---- guided directions (twilight walks) ------------------------------------------------------ */
/* With the sun below the horizon, the light reaching shadowed air comes from sunlit air
 * hundreds of km towards the sun, within a few degrees of the local horizontal; the phase
 * function sends ~3 % of its directions there. Twilight walks draw their direction after a
 * scattering event from the mixture (1 − β) phase + β guide (one-sample MIS, balance
 * heuristic: weight f / mixture pdf, unbiased since the phase part is positive everywhere it
 * is), the guide being a product, over the local frame (zenith z, azimuth 0 towards the sun),
 * of a wrapped Cauchy azimuth (concentration TRUTH_GUIDE_RHO) and a Cauchy elevation about
 * truth_guide_centre, just above the horizon's dip (scale TRUTH_GUIDE_WIDTH) truncated to
 * [−π/2, π/2]; pdf per sr p_φ p_e / cos e.
 * The scale is TRUTH_GUIDE_WIDTH where free paths are guided (deep twilight) and
 * TRUTH_GUIDE_WIDTH_SHALLOW at the other points that guide (sun from −5.6° to ~8°). There the
 * walks' largest sun terms come from vertices 5–45 km up in the shadow looking 0–12° above the
 * local horizontal towards the sun (ν 0.75–0.99), above the narrow guide's band: with 0.1
 * instead of 0.05, blue's variance per walk ×0.75–0.94 at five such ground views (50 000–100 000
 * walks), red's up to ×1.5 (which the 1024-walk floor hides: red is at 0.2–0.4 % there); with
 * the sun at −9° and −11° every channel ×1.3–1.7, so deep twilight keeps 0.05. */
#define TRUTH_GUIDE_SHARE R(0.5)
#define TRUTH_GUIDE_RHO R(0.5)
#define TRUTH_GUIDE_WIDTH R(0.05)
#define TRUTH_GUIDE_WIDTH_SHALLOW R(0.1)
/* The horizontal unit vectors t1 (towards the sun's azimuth) and t2 = z × t1. */
FN void truth_guide_frame(const real* z, const real* sun, real* t1, real* t2) {
  const real sz = dot3(sun, z);
  for (int k = 0; k < 3; ++k) t1[k] = sun[k] - sz * z[k];
  real n = dot3(t1, t1);
  if (!(n > R(1e-20))) { /* the sun at the zenith or nadir: any horizontal direction */
    const real e[3] = {fabs(z[0]) < R(0.9) ? R(1.0) : R(0.0), fabs(z[0]) < R(0.9) ? R(0.0) : R(1.0), R(0.0)};
    const real ez = dot3(e, z);
    for (int k = 0; k < 3; ++k) t1[k] = e[k] - ez * z[k];
    n = dot3(t1, t1);
  }
  n = sqrt(n);
  for (int k = 0; k < 3; ++k) t1[k] /= n;
  t2[0] = z[1] * t1[2] - z[2] * t1[1];
  t2[1] = z[2] * t1[0] - z[0] * t1[2];
  t2[2] = z[0] * t1[1] - z[1] * t1[0];
}
/* The elevation the guide is centred on at altitude h: TRUTH_GUIDE_LIFT above the horizon's dip
 * −acos(r_b/r). From an elevated vertex the sunlit air is seen past the tangent point of a ray
 * that grazes the lower atmosphere towards the terminator: a band of elevations just above the
 * dip (a tangent altitude h_t is seen at √(2h/r) − √(2(h − h_t)/r) above it, ~1–3° for h_t of
 * 10–20 km), the horizontal only for a vertex on the ground. */
#define TRUTH_GUIDE_LIFT R(0.03)
FN real truth_guide_centre(const AtmosphereParameters* a, real h) {
  return TRUTH_GUIDE_LIFT - acos(fmin(a->bottom_radius / radius_of(a, h), R(1.0)));
}
/* The guide at one vertex: its frame (t1 towards the sun's azimuth, t2 = z × t1, z), and the
 * Cauchy elevation about e0 truncated to [−π/2, π/2]: u_e ↦ e0 + W tan(lo + u_e (hi − lo)). */
typedef struct {
  real z[3], t1[3], t2[3];
  real e0, lo, hi, width;
} TruthGuide;
FN void truth_guide_at(const real* z, const real* sun, real e0, real width, TruthGuide* g) {
  truth_guide_frame(z, sun, g->t1, g->t2);
  for (int k = 0; k < 3; ++k) g->z[k] = z[k];
  g->e0 = e0;
  g->width = width;
  g->lo = atan((R(-0.5) * ATM_PI - e0) / width);
  g->hi = atan((R(0.5) * ATM_PI - e0) / width);
}
FN void truth_guide_sample(const TruthGuide* g, real u_e, real u_phi, real* out) {
  const real q = (R(1.0) - TRUTH_GUIDE_RHO) / (R(1.0) + TRUTH_GUIDE_RHO);
  const real phi = R(2.0) * atan(q * tan(ATM_PI * (u_phi - R(0.5))));
  const real e = g->e0 + g->width * tan(g->lo + u_e * (g->hi - g->lo));
  const real ce = cos(e), se = sin(e), cp = cos(phi), sp = sin(phi);
  for (int k = 0; k < 3; ++k) out[k] = ce * (cp * g->t1[k] + sp * g->t2[k]) + se * g->z[k];
  v3_normalize(out);
}
FN real truth_guide_pdf(const TruthGuide* g, const real* w) {
  const real se = clamp_cosine(dot3(w, g->z));
  const real ce = sqrt(fmax(R(1.0) - se * se, R(0.0)));
  if (!(ce > R(0.0))) return R(0.0); /* the pole: a null set, any finite value */
  const real e = asin(se), phi = atan2(dot3(w, g->t2), dot3(w, g->t1));
  const real rho = TRUTH_GUIDE_RHO;
  const real p_phi = (R(1.0) - rho * rho) / (R(2.0) * ATM_PI * (R(1.0) + rho * rho - R(2.0) * rho * cos(phi)));
  const real x = (e - g->e0) / g->width;
  const real p_e = R(1.0) / ((g->hi - g->lo) * g->width * (R(1.0) + x * x));
  return p_phi * p_e / ce;
}

/* ---- learned guides (twilight points) ------------------------------------------------------- */
/* The guide above is a map from the unit square (u_e, u_φ) to directions, with pdf g(w) for
 * uniform (u_e, u_φ). Where the light comes from is learned per point from a few pilot walks
 * (truth.cpp, learn_tables): a piecewise-constant density h over TRUTH_GUIDE_E × TRUTH_GUIDE_PHI
 * cells of (u_e, |2u_φ − 1|) (symmetric about the sun's azimuth), so the walk's first direction
 * has the pdf h(u(w)) g(w) on the guided share. h is stored as the cells' cumulative masses
 * (TRUTH_GUIDE_CELLS + 1 reals per point, the last 1), then a flag: 1 if the point learned
 * (TRUTH_GUIDE_STRIDE reals per point; a point that did not walks with the fixed guide). The
 * pilot's and the learned walks' first guide is centred above the vertex's horizon dip
 * (truth_guide_centre), so that both share one map; so is every guide at a vertex whose sun is
 * below its horizontal (elsewhere on the horizontal). That rule, against the horizontal at every
 * later vertex: all orders' variance at sun −9…−12° views ~1.3× lower, the worst view of 48 at
 * sun −6…9° at 0.028 relative se against 0.32 at the same walks; centred above the dip at every
 * vertex, the typical view there was 1.8× noisier in variance and cost 20 % more. Every cell
 * keeps a positive mass, so the learned pdf is positive wherever g is, and the one-sample
 * mixture with the phase function stays unbiased whatever was learned. The view ray's segment table is learned likewise
 * (node_cdf, host side). Walks of a pilot launch write, per walk and channel,
 * TRUTH_PILOT_STRIDE reals: the view ray's segment, the first direction's cell coordinates
 * (u_e, |2u_φ − 1|; −1 when no direction was drawn), its mixture pdf over g, the walk's value
 * and its value beyond order 1. */
#define TRUTH_GUIDE_E 16
#define TRUTH_GUIDE_PHI 8
#define TRUTH_GUIDE_CELLS (TRUTH_GUIDE_E * TRUTH_GUIDE_PHI)
#define TRUTH_GUIDE_STRIDE (TRUTH_GUIDE_CELLS + 2)
#define TRUTH_GUIDE_LEARNED_SHARE R(0.8)
#define TRUTH_PILOT_STRIDE 6
/* Order 1 (the sun scattered once on the view ray): walked (next-event estimation at the view
 * ray's vertex) or given — the host's deterministic quadrature of it (truth.cpp,
 * single_scattering), added to every walk of a traced launch (not a pilot's), the walks then
 * carrying orders ≥ 2 only: in the first minutes of twilight single scattering is most of the
 * light and most of a walk's variance (the vertex seldom falls on the ray's sunlit part). */
#define TRUTH_ORDER1_WALKED 0
#define TRUTH_ORDER1_GIVEN 1
#define TRUTH_MODE_PILOT 1   /* the pilot's tables, and the walks' pilot records */
#define TRUTH_MODE_LEARNED 2 /* each point's tables: learned where its flag says so, else fixed */
/* (u_e, |2u_φ − 1|) of the unit direction w: the inverse of truth_guide_sample. */
FN void truth_guide_coordinates(const TruthGuide* g, const real* w, real* u_e, real* u_abs) {
  const real e = asin(clamp_cosine(dot3(w, g->z)));
  const real phi = atan2(dot3(w, g->t2), dot3(w, g->t1));
  const real q = (R(1.0) - TRUTH_GUIDE_RHO) / (R(1.0) + TRUTH_GUIDE_RHO);
  *u_e = fmin(fmax((atan((e - g->e0) / g->width) - g->lo) / (g->hi - g->lo), R(0.0)), R(1.0));
  *u_abs = fmin(R(2.0) * atan(tan(R(0.5) * fabs(phi)) / q) / ATM_PI, R(1.0));
}
FN int truth_guide_cell(real u_e, real u_abs) {
  int ie = (int)(u_e * (real)TRUTH_GUIDE_E), ip = (int)(u_abs * (real)TRUTH_GUIDE_PHI);
  if (ie > TRUTH_GUIDE_E - 1) ie = TRUTH_GUIDE_E - 1;
  if (ip > TRUTH_GUIDE_PHI - 1) ip = TRUTH_GUIDE_PHI - 1;
  return ie * TRUTH_GUIDE_PHI + ip;
}
/* h(u) of a learned table (cells' cumulative masses) at the cell coordinates, per unit area. */
FN real truth_learned_density(GLOBAL const real* cells, real u_e, real u_abs) {
  const int j = truth_guide_cell(u_e, u_abs);
  return (cells[j + 1] - cells[j]) * (real)TRUTH_GUIDE_CELLS;
}
/* A direction from a learned table: a cell by its mass, a point uniform in it, a random side
 * of the sun's azimuth. */
FN void truth_learned_sample(GLOBAL const real* cells, const TruthGuide* g, real u_cell, real u1, real u2, real u_side,
                             real* out) {
  int lo = 0, hi = TRUTH_GUIDE_CELLS; /* cells[lo] ≤ u_cell < cells[hi] */
  while (hi - lo > 1) {
    const int mid = (lo + hi) / 2;
    if (cells[mid] <= u_cell) lo = mid;
    else hi = mid;
  }
  const int ie = lo / TRUTH_GUIDE_PHI, ip = lo % TRUTH_GUIDE_PHI;
  const real u_e = ((real)ie + u1) / (real)TRUTH_GUIDE_E;
  const real u_abs = ((real)ip + u2) / (real)TRUTH_GUIDE_PHI;
  truth_guide_sample(g, u_e, u_side < R(0.5) ? R(0.5) - R(0.5) * u_abs : R(0.5) + R(0.5) * u_abs, out);
}

/* ---- one walk ---------------------------------------------------------------------------- */
/* The radiance estimate of one walk for channel c of point `pt`. node_tau and node_cdf are the
 * view-ray table of this point and channel (node distances in node_t). max_orders: 0 = all.
 * *radiance_low receives the part of orders 1..split_order (split_order 0: none). Russian
 * roulette keeps every order's expectation, so both parts are unbiased; the split draws no
 * random numbers, so a walk's stream and value do not depend on it. */
FN real truth_walk(const AtmosphereParameters* a, int c, GLOBAL const real* pt, GLOBAL const real* node_t,
                   GLOBAL const real* node_tau, GLOBAL const real* node_cdf, GLOBAL const real* medium,
                   GLOBAL const real* cells, int mode, int max_orders, int split_order, int next_sun,
                   int order1_from, PhiloxStream* rng, real* radiance_low, real* pilot, int* events, int* truncated,
                   int* violations) {
  *radiance_low = R(0.0);
  if (mode == TRUTH_MODE_PILOT) {
    pilot[0] = pilot[1] = pilot[2] = R(-1.0);
    pilot[3] = pilot[4] = pilot[5] = R(0.0);
  }
  const int use_line = next_sun == TRUTH_NEXT_SUN_LINE ||
                       (next_sun == TRUTH_NEXT_SUN_AUTO && pt[PT_MU_S] < truth_shadow_reach_cosine(a));
  /* free paths guided towards the light (truth_guided_free_path) in deep twilight */
  const int guided_paths = use_line && pt[PT_MU_S] < truth_deep_shadow_cosine(a);
  const int n = (int)pt[PT_NODES];
  if (n < 2) return R(0.0);
  const real sun[3] = {pt[PT_S], pt[PT_S + 1], pt[PT_S + 2]};
  const real e_sun = a->solar_irradiance[c];

  /* the view ray's vertex: segment k with probability cdf[k+1] − cdf[k], t uniform in it */
  const real u = philox_uniform(rng);
  int lo = 0, hi = n - 1; /* cdf[lo] ≤ u < cdf[hi] */
  while (hi - lo > 1) {
    const int mid = (lo + hi) / 2;
    if (node_cdf[mid] <= u) lo = mid;
    else hi = mid;
  }
  const real p_k = node_cdf[lo + 1] - node_cdf[lo];
  const real t0 = node_t[lo], dt = node_t[lo + 1] - node_t[lo];
  if (!(p_k > R(0.0)) || !(dt > R(0.0))) return R(0.0);
  const real t = t0 + philox_uniform(rng) * dt;
  if (mode == TRUTH_MODE_PILOT) pilot[0] = (real)lo;
  const real h0 = pt[PT_H], mu0 = pt[PT_MU];
  const int ground0 = pt[PT_GROUND] != R(0.0);
  const real tau = node_tau[lo] + truth_segment_depth(a, c, h0, mu0, ground0, t0, t);
  real weight = exp(-tau) * dt / p_k; /* T / pdf */
  real rho = R(1.0);                  /* throughput relative to the view ray's vertex */

  real z[3] = {pt[PT_Z], pt[PT_Z + 1], pt[PT_Z + 2]};
  real w[3] = {pt[PT_V], pt[PT_V + 1], pt[PT_V + 2]};
  real h, mu_dummy;
  point_along(a, h0, mu0, t, ground0, &h, &mu_dummy);
  {
    real z1[3];
    truth_move_zenith(a, h0, z, w, t, z1);
    for (int k = 0; k < 3; ++k) z[k] = z1[k];
  }
  int on_ground = 0;
  int sun_done = 0; /* this vertex's sun term came with the previous vertex */
  real radiance = R(0.0), order1 = R(0.0);
  for (int order = 1;; ++order) {
    *events += 1;
    const real mu_s = clamp_cosine(dot3(sun, z));
    if (on_ground) {
      /* ground vertex: the sun (unless it came with the previous vertex), then a
       * cosine-weighted direction */
      const real albedo = a->ground_albedo[c];
      const real cos_factor = sun_done ? R(0.0) : sun_horizontal_cosine(a, mu_s);
      if (cos_factor > R(0.0) && albedo > R(0.0)) {
        const real t_sun = truth_sun_transmittance(a, c, medium, R(0.0), mu_s, use_line, rng, violations);
        const real add = weight * albedo / ATM_PI * e_sun * t_sun * cos_factor;
        radiance += add;
        if (order == 1) order1 += add;
        if (order <= split_order) *radiance_low += add;
      }
      if (max_orders > 0 && order >= max_orders) break;
      weight *= albedo;
      rho *= albedo;
      const real cos_t = sqrt(philox_uniform(rng));
      const real phi = R(2.0) * ATM_PI * philox_uniform(rng);
      truth_rotate(z, cos_t, phi, w);
    } else {
      /* scattering vertex: the sun (unless it came with the previous vertex), then the phase
       * function */
      real s_r, s_m, s_t;
      truth_coefficients(a, c, h, &s_r, &s_m, &s_t);
      const real nu = clamp_cosine(dot3(w, sun));
      /* order 1 given (TRUTH_ORDER1_GIVEN): the view ray's own sun term is the host's quadrature */
      const int given = order == 1 && order1_from == TRUTH_ORDER1_GIVEN;
      const real visible = sun_done || given ? R(0.0) : sun_visible_fraction(a, h, mu_s);
      if (visible > R(0.0) && s_r + s_m > R(0.0)) {
        const real t_sun = truth_sun_transmittance(a, c, medium, h, mu_s, use_line, rng, violations);
        const real add = weight * (s_r * rayleigh_phase(nu) + s_m * mie_phase(a->mie_g, nu)) * e_sun * t_sun * visible;
        radiance += add;
        if (order == 1) order1 += add;
        if (order <= split_order) *radiance_low += add;
      }
      if (max_orders > 0 && order >= max_orders) break;
      if (!(s_r + s_m > R(0.0))) break;
      const real g = a->mie_g;
      const real u_type = philox_uniform(rng), u_cos = philox_uniform(rng), u_phi = philox_uniform(rng);
      real w1[3];
      const int learned =
          mode == TRUTH_MODE_LEARNED && order == 1 && use_line && cells[TRUTH_GUIDE_CELLS + 1] != R(0.0);
      const int record = mode == TRUTH_MODE_PILOT && order == 1 && use_line;
      const real guide_share = learned ? TRUTH_GUIDE_LEARNED_SHARE : TRUTH_GUIDE_SHARE;
      TruthGuide guide;
      if (use_line)
        truth_guide_at(z, sun, learned || record || mu_s < R(0.0) ? truth_guide_centre(a, h) : R(0.0),
                       guided_paths ? TRUTH_GUIDE_WIDTH : TRUTH_GUIDE_WIDTH_SHALLOW, &guide);
      if (use_line && philox_uniform(rng) < guide_share) {
        if (learned) {
          const real u1 = philox_uniform(rng), u2 = philox_uniform(rng);
          truth_learned_sample(cells, &guide, u_type, u1, u2, u_phi, w1);
        } else {
          truth_guide_sample(&guide, u_cos, u_phi, w1);
        }
      } else {
        const real cos_t =
            u_type * (s_r + s_m) < s_r ? sample_rayleigh_cosine(u_cos) : sample_henyey_greenstein_cosine(g, u_cos);
        truth_rotate(w, cos_t, R(2.0) * ATM_PI * u_phi, w1);
      }
      /* f / pdf of the direction drawn; Russian roulette keeps following the phase function's
       * ratio alone (any survival probability keeps the estimate unbiased) */
      const real cos_t = clamp_cosine(dot3(w, w1));
      const real p_r = rayleigh_phase(cos_t);
      const real f = s_r * p_r + s_m * mie_phase(g, cos_t);
      const real pdf_phase = (s_r * p_r + s_m * henyey_greenstein_phase(g, cos_t)) / (s_r + s_m);
      real pdf = pdf_phase;
      if (use_line) {
        const real g_w = truth_guide_pdf(&guide, w1);
        real u_e = R(0.0), u_abs = R(0.0), h_u = R(1.0);
        if (learned || record) truth_guide_coordinates(&guide, w1, &u_e, &u_abs);
        if (learned) h_u = truth_learned_density(cells, u_e, u_abs);
        pdf = (R(1.0) - guide_share) * pdf_phase + guide_share * h_u * g_w;
        if (record) {
          pilot[1] = u_e;
          pilot[2] = u_abs;
          pilot[3] = g_w > R(0.0) ? pdf / g_w : R(0.0);
        }
      }
      weight *= f / pdf;
      rho *= f / ((s_r + s_m) * pdf_phase);
      for (int k = 0; k < 3; ++k) w[k] = w1[k];
    }
    /* the next vertex's sun term, in expectation over where the free path ends */
    sun_done = use_line;
    TruthRayTable ray_table;
    if (sun_done) {
      const real add = weight * truth_next_sun_term(a, c, medium, on_ground ? R(0.0) : h, z, w, sun, use_line,
                                                    guided_paths, &ray_table, rng, violations);
      radiance += add;
      if (order + 1 <= split_order) *radiance_low += add;
    }
    if (max_orders == 0 && order >= TRUTH_MAX_EVENTS) {
      *truncated += 1;
      break;
    }
    /* Russian roulette on the relative throughput. The uniform is drawn at every vertex, so
     * that a throughput within rounding of 1 (e.g. a Mie share of 1e-17 at 45 km) cannot shift
     * the stream between builds that round differently. */
    const real u_rr = philox_uniform(rng);
    if (rho < R(1.0)) {
      if (u_rr >= rho) break;
      weight /= rho;
      rho = R(1.0);
    }
    /* the next free path */
    const real mu = clamp_cosine(dot3(w, z));
    const real h_start = on_ground ? R(0.0) : h;
    real s, h_s;
    real path_factor = R(1.0);
    const int what = guided_paths ? truth_guided_free_path(a, c, medium, h_start, mu, &ray_table, rng, &s, &h_s,
                                                           &path_factor, violations)
                                  : truth_free_path(a, c, medium, h_start, mu, rng, &s, &h_s, violations);
    if (what == 0) break;
    weight *= path_factor;
    real z1[3];
    truth_move_zenith(a, h_start, z, w, s, z1);
    for (int k = 0; k < 3; ++k) z[k] = z1[k];
    if (what == 1) {
      real s_r, s_m, s_t;
      truth_coefficients(a, c, h_s, &s_r, &s_m, &s_t);
      weight /= s_t;
      rho *= (s_r + s_m) / s_t;
      h = h_s;
      on_ground = 0;
    } else {
      h = R(0.0);
      on_ground = 1;
    }
  }
  if (mode == TRUTH_MODE_PILOT) {
    pilot[4] = radiance;
    pilot[5] = radiance - order1;
  }
  return radiance;
}

/* ---- one work item: a batch of walks of one point, each channel that asks for one ---------- */
/* Point p (point point_base + p of the request, for the random streams) and the launch's j-th
 * batch of each of its channels: channel c of this group (channel channel_base + c of the
 * request) traces its batch b = batch_base[c] + j (walks b·paths_per_batch ...
 * (b + 1)·paths_per_batch − 1 of its stream) when j < batch_count[c], and nothing otherwise
 * (its statistics written as 0): each channel walks as many batches as its own precision
 * needs. Writes TRUTH_OUT_STRIDE reals at out_item: per channel (mean, m2) of the whole walk,
 * of orders 1..split_order and of the orders above it (with order 1 given, TRUTH_ORDER1_GIVEN,
 * the walks' own part: the host adds the quadrature's order 1 to the first two means). Table
 * layouts: node_t [P][nodes], node_tau and node_cdf [P][NCH][nodes], medium
 * as TRUTH_MEDIUM_SIZE describes it (majorants, then kinks), cells [P][TRUTH_GUIDE_STRIDE]
 * (read in TRUTH_MODE_LEARNED only). A pilot launch (TRUTH_MODE_PILOT) also writes each walk's
 * record at pilot_item [paths_per_batch][NCH][TRUTH_PILOT_STRIDE]. */
FN void truth_trace_item(const AtmosphereParameters* a, GLOBAL const real* points, GLOBAL const real* node_t,
                         GLOBAL const real* node_tau, GLOBAL const real* node_cdf, GLOBAL const real* medium,
                         int nodes, int p, int point_base, int j, GLOBAL const int* batch_base,
                         GLOBAL const int* batch_count, int paths_per_batch, int max_orders,
                         int split_order, int next_sun, int order1, philox_u32 seed_lo, philox_u32 seed_hi,
                         int channel_base, int channels, GLOBAL const real* cells, int mode, GLOBAL real* out_item,
                         GLOBAL real* pilot_item) {
  GLOBAL const real* pt = points + p * TRUTH_POINT_STRIDE;
  int events = 0, truncated = 0, violations = 0;
  for (int c = 0; c < NCH; ++c) {
    real mean[TRUTH_STATS] = {R(0.0), R(0.0), R(0.0)}, m2[TRUTH_STATS] = {R(0.0), R(0.0), R(0.0)};
    if (c < channels && j < batch_count[c]) {
      const int b = batch_base[c] + j;
      for (int i = 0; i < paths_per_batch; ++i) {
        PhiloxStream rng;
        philox_stream_init(&rng, seed_lo, seed_hi, (philox_u32)b * (philox_u32)paths_per_batch + (philox_u32)i,
                           (philox_u32)(point_base + p),
                           (philox_u32)(channel_base + c));
        real low, rec[TRUTH_PILOT_STRIDE];
        const real x = truth_walk(a, c, pt, node_t + p * nodes, node_tau + (p * NCH + c) * nodes,
                                  node_cdf + (p * NCH + c) * nodes, medium, cells + p * TRUTH_GUIDE_STRIDE, mode,
                                  max_orders, split_order, next_sun, order1, &rng, &low, rec, &events, &truncated, &violations);
        if (mode == TRUTH_MODE_PILOT)
          for (int k = 0; k < TRUTH_PILOT_STRIDE; ++k) pilot_item[(i * NCH + c) * TRUTH_PILOT_STRIDE + k] = rec[k];
        const real xs[TRUTH_STATS] = {x, low, x - low};
        for (int k = 0; k < TRUTH_STATS; ++k) {
          const real delta = xs[k] - mean[k];
          mean[k] += delta / (real)(i + 1);
          m2[k] += delta * (xs[k] - mean[k]);
        }
      }
    }
    for (int k = 0; k < TRUTH_STATS; ++k) {
      out_item[2 * (TRUTH_STATS * c + k)] = mean[k];
      out_item[2 * (TRUTH_STATS * c + k) + 1] = m2[k];
    }
  }
  out_item[2 * TRUTH_STATS * NCH] = (real)events;
  out_item[2 * TRUTH_STATS * NCH + 1] = (real)truncated;
  out_item[2 * TRUTH_STATS * NCH + 2] = (real)violations;
  out_item[2 * TRUTH_STATS * NCH + 3] = (real)paths_per_batch;
}

/* ---- host-side helpers (tables) ------------------------------------------------------------ */
/* The maximum of one layer a·exp(b·h) + c·h + d, clamped to [0, 1], over [lo, hi]: the clamp is
 * monotone, so it is the clamp of the unclamped maximum, which lies at an end, or for a < 0
 * (concave) possibly where a·b·exp(b·h) + c = 0. */
FN real layer_max_over(const DensityProfile* p, int layer, real lo, real hi) {
  real m = fmax(layer_density(p, layer, lo), layer_density(p, layer, hi));
  const real h_star = layer_stationary_altitude(p, layer, lo, hi);
  if (p->exp_term[layer] < R(0.0) && h_star >= R(0.0)) m = fmax(m, layer_density(p, layer, h_star));
  return m;
}
/* max of profile_density() over [lo, hi] (layer 0 below width[0], layer 1 from it). */
FN real profile_max_over(const DensityProfile* p, real lo, real hi) {
  const real w = p->width[0];
  real m = R(0.0);
  if (lo < w) m = fmax(m, layer_max_over(p, 0, lo, fmin(hi, w)));
  if (hi >= w) m = fmax(m, layer_max_over(p, 1, fmax(lo, w), hi));
  return m;
}
