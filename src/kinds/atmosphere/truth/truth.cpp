#include "kinds/atmosphere/truth/truth.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>

#include "cl/buffers.hpp"
#include "kinds/atmosphere/model/model.hpp"
#include "kinds/atmosphere/truth/truth_reference.hpp"

namespace specbake::atmosphere {

const int kTruthMaxEvents = TRUTH_MAX_EVENTS;

// TruthOptions::NextSun is the walk's next_sun argument (path_tracer.cl).
static_assert(static_cast<int>(TruthOptions::NextSun::automatic) == TRUTH_NEXT_SUN_AUTO &&
              static_cast<int>(TruthOptions::NextSun::along_ray) == TRUTH_NEXT_SUN_LINE &&
              static_cast<int>(TruthOptions::NextSun::at_vertex) == TRUTH_NEXT_SUN_VERTEX);

// The profiles as a medium of three channels with unit coefficients (channel i: profile i —
// Rayleigh, Mie, absorption): truth_optical_lengths over its cuts gives each profile's optical
// length to TRUTH_DEPTH_ERROR of itself (the cuts are placed for each profile alone), so that
// every channel's optical depth, a positive sum of them, is as exact. Its medium table
// (medium_table(m, unit_channels())) serves the light at a vertex, order 1 by quadrature and
// the channel groups' sun tables.
Channels unit_channels() {
  Channels unit;
  unit.lambda_nm = {0.0, 0.0, 0.0};
  unit.solar_irradiance = unit.mie_scattering = unit.ground_albedo = {0.0, 0.0, 0.0};
  unit.rayleigh_scattering = {1.0, 0.0, 0.0};
  unit.mie_extinction = {0.0, 1.0, 0.0};
  unit.absorption_extinction = {0.0, 0.0, 1.0};
  return unit;
}

namespace {

using ref3::AtmosphereParameters;
using ref3::DensityProfile;

// Channel c's optical depth from the three profiles' optical lengths (Rayleigh, Mie,
// absorption: what the medium of unit_channels() measures), km⁻¹ · km.
double depth_of_lengths(const Channels& ch, std::size_t c, const double* len) {
  return ch.rayleigh_scattering[c] * len[0] + ch.mie_extinction[c] * len[1] + ch.absorption_extinction[c] * len[2];
}

constexpr int kGroup = ref3::kTruthChannels;  // channels per launch (the kernels' NCH)
constexpr int kStride = ref3::kTruthOutStride;
// The view ray's table: kSegments equal segments, split again at every altitude where a
// profile has a kink (its layer boundary, where it reaches 0 or 1), so that no segment holds
// one; each segment's optical depth by kSubSegments × 8-point Gauss–Legendre.
constexpr int kSegments = 256;
constexpr int kSubSegments = 4;
constexpr int kMaxKinkAltitudes = TRUTH_MAX_KINKS;
constexpr int kNodes = kSegments + 1 + 2 * kMaxKinkAltitudes;
// Segment probabilities mix in this much of the uniform density, so that every segment has a
// positive probability whatever the approximations of the table. Pilot walks mix in half: in
// twilight the light at a vertex grows steeply with its altitude (it sees sunlit air through
// thinner air), which β_s ρ T does not know, and the pilot must explore the whole ray.
constexpr double kUniformMix = 1e-3;
constexpr double kUniformMixPilot = 0.5;
// Learned tables (deep-twilight points, whose free paths are guided; path_tracer.cl "learned
// guides"): pilot walks per point, all channels together (at least one batch per channel); a
// point keeps its learned tables wherever the pilot predicts they cut the view ray's second
// moment below kLearnGain of the fixed table's, i.e. any gain (with 0.5 the twilight scene's
// truth learned at 4 of 128 points and took 1.1× the time for a 10 % larger mean se).
// Shallower twilight (sun −5.6…0° on Earth) does not pilot: there, asked to halve the second
// moment (learned walks reach sunlit air more often, so each costs more), the pilot kept its
// tables at 0 of the twilight scene's 124 such points, 0 of the default scene's 9 and 1 of ~170
// in −6…0° scenes of an 8–10 km camera and of Mars, while its walks took ~5 % of the default
// Earth's check. The view ray's learned bins; the share of the pilot's table kept in the
// learned one and the floor of each direction cell (defensive mixtures: a learned table starves
// no region by more than 2× and ~3× in weight, so a region the pilot missed is not made rarer
// still — with 0.2 and 0.1 the twilight scene's worst channels reached a relative se of 1.7).
constexpr double kPilotWalks = 1024;
constexpr double kLearnGain = 1.0;
constexpr int kLearnBins = 24;
constexpr double kKeepFixed = 0.5;
constexpr double kCellFloor = 0.3;
// The rest is an even mixture of two densities (channel_table): ∝ β_s ρ T (what scattering of
// any order at the vertex is weighted by) and the light's: with order 1 walked,
// ∝ (β_R ρ_R P_R(ν) + β_M ρ_M P_M(ν)) T × V T_sun, single scattering itself (in twilight only
// the part of the ray above the Earth's shadow is lit, and the first density alone would put
// most vertices in the dark; towards the sun Mie's forward peak makes the light come from the
// aerosols near the ground, where β_s ρ alone draws too few vertices); for guided points also
// ∝ β_s ρ T S̄, the light scattered once towards the vertex (what orders ≥ 2 start from).
constexpr double kSunlitShare = 0.5;
// Majorants: the exact maxima of the profiles over [h_j − δ, top] (δ = 1e-3 shell) times
// 1 + 1e-5, far above float32 rounding of the densities (6e-8 relative).
constexpr double kMajorantMargin = 1e-5;
constexpr double kShellOverlap = 1e-3;
constexpr double kGaussX[4] = {0.1834346424956498, 0.5255324099163290, 0.7966664774136267, 0.9602898564975363};
constexpr double kGaussW[4] = {0.3626837833783620, 0.3137066458778873, 0.2223810344533745, 0.1012285362903763};

double radians(double deg) { return deg * M_PI / 180.0; }

void check_options(const std::vector<TruthPoint>& points, const TruthOptions& o) {
  if (points.empty()) throw InputError(Location{{}, 0, 0, "points"}, "at least one point");
  if (o.paths < 1) throw InputError(Location{{}, 0, 0, "paths"}, "paths >= 1, got " + std::to_string(o.paths));
  if (o.paths_per_batch < 1 || o.paths_per_batch > 1 << 20)
    throw InputError(Location{{}, 0, 0, "paths_per_batch"}, "1..1048576, got " + std::to_string(o.paths_per_batch));
  if (o.orders < 0 || o.orders > 1000)
    throw InputError(Location{{}, 0, 0, "orders"}, "0 (all) or 1..1000, got " + std::to_string(o.orders));
  if (!(o.target_relative_se >= 0.0 && std::isfinite(o.target_relative_se)))
    throw InputError(Location{{}, 0, 0, "target_relative_se"}, "a fraction >= 0 (0: off)");
  if (o.paths > (1LL << 32) || (o.paths + o.paths_per_batch - 1) / o.paths_per_batch > std::numeric_limits<int>::max())
    throw InputError(Location{{}, 0, 0, "paths"}, "at most 2^32 walks per point, and 2^31 batches");
  if (o.max_paths < 1) throw InputError(Location{{}, 0, 0, "max_paths"}, "max_paths >= 1");
  if (!(o.low_sun_relative_se >= 0.0 && std::isfinite(o.low_sun_relative_se)))
    throw InputError(Location{{}, 0, 0, "low_sun_relative_se"}, "a fraction >= 0 (0: target_relative_se)");
  if (o.low_sun_max_paths < 0) throw InputError(Location{{}, 0, 0, "low_sun_max_paths"}, ">= 0 (0: max_paths)");
  if (!(o.low_sun_elevation_deg >= -90.0 && o.low_sun_elevation_deg <= 90.0))
    throw InputError(Location{{}, 0, 0, "low_sun_elevation_deg"}, "an elevation in [-90, 90]");
  if (o.split_orders < 0 || o.split_orders > 1000)
    throw InputError(Location{{}, 0, 0, "split_orders"}, "0 (none) or 1..1000, got " + std::to_string(o.split_orders));
  // the random streams count points in 32 bits; the kernels index [point][node] with int
  if (points.size() > (1u << 24)) throw InputError(Location{{}, 0, 0, "points"}, "at most 2^24 points per call");
  for (std::size_t i = 0; i < points.size(); ++i) {
    const TruthPoint& p = points[i];
    const std::string at = "points[" + std::to_string(i) + "].";
    if (!(std::isfinite(p.altitude_km) && p.altitude_km >= 0.0))
      throw InputError(Location{{}, 0, 0, at + "altitude_km"}, "a finite altitude >= 0 km");
    if (!(p.view_zenith_deg >= 0.0 && p.view_zenith_deg <= 180.0))
      throw InputError(Location{{}, 0, 0, at + "view_zenith_deg"}, "an angle in [0, 180]");
    if (!(p.sun_zenith_deg >= 0.0 && p.sun_zenith_deg <= 180.0))
      throw InputError(Location{{}, 0, 0, at + "sun_zenith_deg"}, "an angle in [0, 180]");
    if (!(std::isfinite(p.view_sun_azimuth_deg) && std::fabs(p.view_sun_azimuth_deg) <= 360.0))
      throw InputError(Location{{}, 0, 0, at + "view_sun_azimuth_deg"}, "an angle in [-360, 360]");
  }
}

// Altitudes in (0, t) where a profile has a kink or a jump: its layer boundary, and where a
// layer's a·exp(b·h) + c·h + d crosses 0 or 1 (the clamp), found on a 4096-step scan and
// refined by bisection.
std::vector<double> kink_altitudes(const AtmosphereParameters& a) {
  const double t = a.top_radius - a.bottom_radius;
  std::vector<double> out;
  for (const DensityProfile* p : {&a.rayleigh_density, &a.mie_density, &a.absorption_density}) {
    if (p->width[0] > 0.0 && p->width[0] < t) out.push_back(p->width[0]);
    for (int layer = 0; layer < 2; ++layer) {
      auto f = [&](double h) {
        return p->exp_term[layer] * std::exp(p->exp_scale[layer] * h) + p->linear_term[layer] * h +
               p->constant_term[layer];
      };
      for (double level : {0.0, 1.0}) {
        constexpr int n = 4096;
        double h0 = 0.0, f0 = f(0.0) - level;
        for (int i = 1; i <= n; ++i) {
          const double h1 = t * i / n, f1 = f(h1) - level;
          if ((f0 < 0.0) != (f1 < 0.0)) {
            double lo = h0, hi = h1;
            for (int k = 0; k < 100 && hi - lo > 1e-13 * t; ++k) {
              const double mid = 0.5 * (lo + hi);
              if (((f(mid) - level) < 0.0) == (f0 < 0.0)) lo = mid;
              else hi = mid;
            }
            const double h = 0.5 * (lo + hi);
            if (h > 0.0 && h < t) out.push_back(h);
          }
          h0 = h1;
          f0 = f1;
        }
      }
    }
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end(), [&](double x, double y) { return y - x < 1e-9 * t; }), out.end());
  if (out.size() > kMaxKinkAltitudes) {
    spdlog::warn("truth: {} kink altitudes in the density profiles; the view-ray table splits at the first {}",
                 out.size(), kMaxKinkAltitudes);
    out.resize(kMaxKinkAltitudes);
  }
  return out;
}

// Everything the walks need, for all channels; the kernels read one group of kGroup channels.
struct Prepared {
  Model model;
  Channels channels;
  std::size_t point_base = 0;  // index of the first point in the request (random streams)
  std::size_t n_points = 0, n_channels = 0;
  std::vector<double> points;    // [P][TRUTH_POINT_STRIDE]
  std::vector<double> node_t;    // [P][kNodes]
  std::vector<double> node_tau;  // [P][C][kNodes]
  std::vector<double> node_cdf;  // [P][C][kNodes]
  std::vector<double> cells;     // [P][TRUTH_GUIDE_STRIDE]: the learned first-direction cells, flag
  std::vector<char> guided_paths;  // [P]: its walks guide their free paths (truth_deep_shadow_cosine)
                                   // and, with TruthOptions::learn, it pilots for learned tables
  std::vector<std::vector<double>> medium;  // [group]: medium_table of channels 3g..3g+2
  std::vector<double> single;    // [P][C]: order 1 by quadrature (TruthOptions::Order1::quadrature), else empty
  std::vector<char> low_sun;     // [P]: its sun is below TruthOptions::low_sun_elevation_deg
};

// The view ray of point p in the frame zenith = (0, 0, 1), view in the xz plane.
void point_geometry(const AtmosphereParameters& a, const TruthPoint& p, double* row) {
  const double tv = radians(p.view_zenith_deg), ts = radians(p.sun_zenith_deg), phi = radians(p.view_sun_azimuth_deg);
  double z[3] = {0.0, 0.0, 1.0};
  const double v[3] = {std::sin(tv), 0.0, std::cos(tv)};
  const double s[3] = {std::sin(ts) * std::cos(phi), std::sin(ts) * std::sin(phi), std::cos(ts)};
  const double t = a.top_radius - a.bottom_radius;
  double h = p.altitude_km, mu = v[2];
  for (int k = 0; k < TRUTH_POINT_STRIDE; ++k) row[k] = 0.0;
  if (h >= t) {
    // enter the atmosphere as GetSkyRadiance does (or see nothing)
    const double r = a.bottom_radius + h, rmu = r * mu;
    const double disc = rmu * rmu - (r - a.top_radius) * (r + a.top_radius);
    if (rmu >= 0.0 || disc < 0.0) return;
    const double d = -rmu - std::sqrt(disc);
    for (int k = 0; k < 3; ++k) z[k] = r * z[k] + d * v[k];
    const double n = std::sqrt(ref3::dot3(z, z));
    for (double& x : z) x /= n;
    h = t;
    mu = std::clamp((rmu + d) / a.top_radius, -1.0, 1.0);
  }
  const int ground = ref3::ray_hits_ground(&a, h, mu);
  const double length = ref3::distance_to_nearest_boundary(&a, h, mu, ground);
  if (!(length > 0.0)) return;
  row[PT_H] = h;
  row[PT_MU] = mu;
  row[PT_MU_S] = std::clamp(ref3::dot3(s, z), -1.0, 1.0);
  row[PT_NU] = std::clamp(ref3::dot3(v, s), -1.0, 1.0);
  row[PT_D] = length;
  row[PT_GROUND] = ground;
  for (int k = 0; k < 3; ++k) {
    row[PT_Z + k] = z[k];
    row[PT_V + k] = v[k];
    row[PT_S + k] = s[k];
  }
  row[PT_NODES] = 2;  // refined by view_table
}

// The nodes of a view ray of length D from (h, mu): `segments` equal segments and the crossings
// of the kink altitudes (s² + 2 rμ s + (ρ² − ρ_k²) = 0), sorted, without near repeats, ending at D.
std::vector<double> view_nodes(const AtmosphereParameters& a, const std::vector<double>& kinks, double h, double mu,
                               double D, int segments = kSegments) {
  std::vector<double> t;
  for (int k = 0; k <= segments; ++k) t.push_back(D * k / segments);
  const double r_mu = (a.bottom_radius + h) * mu, rho2 = ref3::horizon_distance2(&a, h);
  for (double hk : kinks) {
    const double c0 = rho2 - ref3::horizon_distance2(&a, hk);
    const double disc = r_mu * r_mu - c0;
    if (disc < 0.0) continue;
    const double q = -(r_mu + std::copysign(std::sqrt(disc), r_mu));
    for (double s : {q, q != 0.0 ? c0 / q : 0.0})
      if (s > 0.0 && s < D) t.push_back(s);
  }
  std::sort(t.begin(), t.end());
  t.erase(std::unique(t.begin(), t.end(), [&](double x, double y) { return y - x < 1e-9 * D; }), t.end());
  t.back() = D;
  return t;
}

// A sub-segment of a view ray: its middle, its Rayleigh and Mie lengths (for the masses), the
// sun's visible fraction at the middle and the optical lengths (Rayleigh, Mie, absorption
// profiles) towards the sun from it.
struct Sub {
  double t_mid, l_r, l_m;
  double visible;
  double sun_l[3];
  double h_mid = 0.0, mu_s = 0.0;  // the middle's altitude and sun cosine
};

// The sun's cosine at distance t along the view ray of the point `row`.
double sun_cosine_along(const AtmosphereParameters& a, const double* row, double t) {
  const double r0 = a.bottom_radius + row[PT_H];
  double z[3];
  for (int k = 0; k < 3; ++k) z[k] = r0 * row[PT_Z + k] + t * row[PT_V + k];
  const double sun[3] = {row[PT_S], row[PT_S + 1], row[PT_S + 2]};
  return std::clamp(ref3::dot3(sun, z) / std::sqrt(ref3::dot3(z, z)), -1.0, 1.0);
}

// The sun's visible fraction and, with `lengths` (only order 1's share of the pdf reads them),
// the optical lengths of the ray towards it (along the horizon when the disc centre is below it,
// as the model does) from distance t_mid on the view ray of the point `row`: 8-point
// Gauss–Legendre on each side of the sun ray's tangent point (an approximation: it only shapes
// the sampling density).
void sunlit(const AtmosphereParameters& a, const double* row, double t_mid, double h_mid, bool lengths, Sub& sub) {
  const double mu_s = sun_cosine_along(a, row, t_mid);
  sub.h_mid = h_mid;
  sub.mu_s = mu_s;
  sub.visible = ref3::sun_visible_fraction(&a, h_mid, mu_s);
  sub.sun_l[0] = sub.sun_l[1] = sub.sun_l[2] = 0.0;
  if (!lengths || !(sub.visible > 0.0)) return;
  const double r = a.bottom_radius + h_mid;
  const double mu = ref3::truth_sun_ray_cosine(&a, h_mid, mu_s);
  const double d = ref3::distance_to_top(&a, h_mid, mu);
  const double s_tan = mu < 0.0 ? std::min(-r * mu, d) : 0.0;
  for (const auto& [lo, hi] : {std::pair{0.0, s_tan}, std::pair{s_tan, d}}) {
    if (!(hi > lo)) continue;
    const double c = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
    for (int i = 0; i < 4; ++i)
      for (int side = 0; side < 2; ++side) {
        double h_s, mu_s_;
        ref3::point_along(&a, h_mid, mu, side == 0 ? c - half * kGaussX[i] : c + half * kGaussX[i], 0, &h_s, &mu_s_);
        const double w = kGaussW[i] * half;
        sub.sun_l[0] += w * ref3::profile_density(&a.rayleigh_density, h_s);
        sub.sun_l[1] += w * ref3::profile_density(&a.mie_density, h_s);
        sub.sun_l[2] += w * ref3::profile_density(&a.absorption_density, h_s);
      }
  }
}

// Per segment between nodes t: the optical lengths of the three profiles, and its sub-segments
// (the sun's optical lengths from them with `sun_lengths`).
struct Segments {
  std::vector<std::array<double, 3>> lengths;
  std::vector<std::array<Sub, kSubSegments>> subs;
};
Segments view_segments(const AtmosphereParameters& a, const double* row, const std::vector<double>& t,
                       bool sun_lengths) {
  const double h = row[PT_H], mu = row[PT_MU];
  const int ground = row[PT_GROUND] != 0.0;
  const int n = static_cast<int>(t.size());
  Segments out{std::vector<std::array<double, 3>>(n - 1), std::vector<std::array<Sub, kSubSegments>>(n - 1)};
  for (int k = 0; k + 1 < n; ++k) {
    std::array<double, 3> l{0.0, 0.0, 0.0};
    const double dt = (t[k + 1] - t[k]) / kSubSegments;
    for (int j = 0; j < kSubSegments; ++j) {
      const double mid = t[k] + (j + 0.5) * dt, half = 0.5 * dt;
      Sub sub{mid, 0.0, 0.0, 0.0, {0.0, 0.0, 0.0}};
      {
        double h_mid, mu_mid;
        ref3::point_along(&a, h, mu, mid, ground, &h_mid, &mu_mid);
        sunlit(a, row, mid, h_mid, sun_lengths, sub);
      }
      for (int i = 0; i < 4; ++i)
        for (int side = 0; side < 2; ++side) {
          const double s = side == 0 ? mid - half * kGaussX[i] : mid + half * kGaussX[i];
          double h_s, mu_s;
          ref3::point_along(&a, h, mu, s, ground, &h_s, &mu_s);
          const double w = kGaussW[i] * half;
          const double rr = w * ref3::profile_density(&a.rayleigh_density, h_s);
          const double rm = w * ref3::profile_density(&a.mie_density, h_s);
          l[0] += rr;
          l[1] += rm;
          l[2] += w * ref3::profile_density(&a.absorption_density, h_s);
          sub.l_r += rr;
          sub.l_m += rm;
        }
      out.subs[k][j] = sub;
    }
    out.lengths[k] = l;
  }
  return out;
}

// log S̄ (path_tracer.cl, "the light at a vertex") of every channel at the sky table's nodes,
// [TRUTH_SKY_H · TRUTH_SKY_MU][C]: ∫_4π dω ∫ σ_s T T_sun V dt by a coarse quadrature (it only
// shapes a pdf; a factor of 2 only moves noise) whose geometry every channel shares: directions at
// kSkyOffsets about the horizon's dip (where a shadowed point sees the sunlit air) times
// kSkyAzimuths azimuths over [0, π] (the integrand is symmetric about the sun's azimuth); along
// each, kSkySteps equal steps, T by the trapezoid rule, T_sun from each profile's optical length
// towards the sun (the sun table of a medium whose three channels are the three profiles, unit
// coefficients), each step's integral as the logarithmic mean of its ends (exact for an
// exponential). A spectrum's channels are integrated at most kSkyLambdaStepNm apart (the first,
// the last and the fewest between; every rgb channel) and log S̄ of the others interpolated
// linearly in λ⁻⁴: the optical depths that darken S̄ are mostly Rayleigh's, ∝ λ⁻⁴, and the ozone
// bands are tens of nm wide (within a factor 1.17 of each channel's own integral on Earth; a pdf
// is all it shapes). 13 of 48 channels cost the table a quarter of its time.
constexpr double kSkyOffsets[] = {-0.3, -0.03, 0.0, 0.02, 0.05, 0.1, 0.25, 0.6, 1.2};
constexpr int kSkyAzimuths = 5;
constexpr int kSkySteps = 16;
constexpr double kSkyLambdaStepNm = 40.0;

}  // namespace

std::vector<double> sky_light_table(const Model& m, const Channels& all, const std::vector<double>& lengths) {
  const AtmosphereParameters a = ref3::make_parameters(m, Channels{});
  std::vector<std::size_t> picked;  // the channels integrated, in order
  for (std::size_t c = 0; c < all.size(); ++c)
    if (picked.empty() || c + 1 == all.size() ||
        std::abs(all.lambda_nm[c + 1] - all.lambda_nm[picked.back()]) > kSkyLambdaStepNm)
      picked.push_back(c);
  const Channels ch = all.subset(picked);
  const std::size_t C = ch.size();
  constexpr int E = static_cast<int>(std::size(kSkyOffsets));
  std::vector<double> out(static_cast<std::size_t>(TRUTH_SKY_H) * TRUTH_SKY_MU * C, ref3::kTruthSkyNone);
  parallel_for(static_cast<long long>(TRUTH_SKY_H) * TRUTH_SKY_MU, [&](long long node) {
    double h, mu_s;
    ref3::truth_sky_node(&a, static_cast<int>(node / TRUTH_SKY_MU), static_cast<int>(node % TRUTH_SKY_MU), &h, &mu_s);
    const double dip = -std::acos(std::min(a.bottom_radius / (a.bottom_radius + h), 1.0));
    std::array<double, E + 2> e{};
    e[0] = -0.5 * M_PI;
    for (int k = 0; k < E; ++k) e[k + 1] = std::clamp(dip + kSkyOffsets[k], -0.5 * M_PI, 0.5 * M_PI);
    e[E + 1] = 0.5 * M_PI;
    const double sun[3] = {std::sqrt(std::max(1.0 - mu_s * mu_s, 0.0)), 0.0, mu_s};
    const double r0 = a.bottom_radius + h;
    std::vector<double> total(C, 0.0), tau(C), sigma_prev(C), g_prev(C), lg_prev(C), line(C);
    for (int ie = 1; ie <= E; ++ie) {
      const double de = 0.5 * (e[ie + 1] - e[ie - 1]);  // trapezoid weight in elevation
      if (!(de > 0.0)) continue;
      const double ce = std::cos(e[ie]), se = std::sin(e[ie]);
      for (int ia = 0; ia < kSkyAzimuths; ++ia) {
        const double phi = M_PI * ia / (kSkyAzimuths - 1);
        const double dphi = (ia == 0 || ia == kSkyAzimuths - 1 ? 0.5 : 1.0) * M_PI / (kSkyAzimuths - 1);
        const double w[3] = {ce * std::cos(phi), ce * std::sin(phi), se};
        const int ground = ref3::ray_hits_ground(&a, h, se);
        const double ds = ref3::distance_to_nearest_boundary(&a, h, se, ground) / kSkySteps;
        std::fill(tau.begin(), tau.end(), 0.0);
        std::fill(line.begin(), line.end(), 0.0);
        for (int k = 0; k <= kSkySteps; ++k) {
          const double s = ds * k;
          double h_k, mu_k;
          ref3::point_along(&a, h, se, s, ground, &h_k, &mu_k);
          const double p[3] = {s * w[0], s * w[1], r0 + s * w[2]};
          const double mu_s_k = std::clamp(ref3::dot3(sun, p) / std::sqrt(ref3::dot3(p, p)), -1.0, 1.0);
          const double visible = ref3::sun_visible_fraction(&a, h_k, mu_s_k);
          const double rho_r = ref3::profile_density(&a.rayleigh_density, h_k);
          const double rho_m = ref3::profile_density(&a.mie_density, h_k);
          const double rho_a = ref3::profile_density(&a.absorption_density, h_k);
          double l[3] = {0.0, 0.0, 0.0};
          if (visible > 0.0)
            for (int i = 0; i < 3; ++i) l[i] = ref3::truth_sun_depth_table(&a, lengths.data(), i, h_k, mu_s_k);
          for (std::size_t c = 0; c < C; ++c) {
            const double s_t = ch.rayleigh_scattering[c] * rho_r + ch.mie_extinction[c] * rho_m +
                               ch.absorption_extinction[c] * rho_a;
            if (k > 0) tau[c] += 0.5 * (sigma_prev[c] + s_t) * ds;
            sigma_prev[c] = s_t;
            const double s_s = (ch.rayleigh_scattering[c] * rho_r + ch.mie_scattering[c] * rho_m) * visible;
            double g = 0.0, lg = 0.0;
            if (s_s > 0.0) {
              lg = std::log(s_s) - tau[c] - depth_of_lengths(ch, c, l);
              g = std::exp(lg);
            }
            if (k > 0) {
              const bool both = g > 0.0 && g_prev[c] > 0.0 && std::abs(lg - lg_prev[c]) > 1e-6;
              line[c] += (both ? (g - g_prev[c]) / (lg - lg_prev[c]) : 0.5 * (g + g_prev[c])) * ds;
            }
            g_prev[c] = g;
            lg_prev[c] = lg;
          }
        }
        for (std::size_t c = 0; c < C; ++c) total[c] += 2.0 * line[c] * ce * de * dphi;  // both sides
      }
    }
    for (std::size_t c = 0; c < C; ++c)
      if (total[c] > 0.0) out[node * C + c] = std::log(total[c]);
  });
  if (C == all.size()) return out;
  // the other channels: log S̄ linear in λ⁻⁴ between the integrated ones on either side (the
  // nearer one's where either has no light)
  const std::size_t N = static_cast<std::size_t>(TRUTH_SKY_H) * TRUTH_SKY_MU;
  std::vector<double> full(N * all.size());
  for (std::size_t j = 0; j < C; ++j)
    for (std::size_t n = 0; n < N; ++n) full[n * all.size() + picked[j]] = out[n * C + j];
  auto rayleigh_x = [](double lambda) { return std::pow(lambda, -4.0); };
  for (std::size_t j = 0; j + 1 < C; ++j)
    for (std::size_t c = picked[j] + 1; c < picked[j + 1]; ++c) {
      const double x0 = rayleigh_x(ch.lambda_nm[j]), x1 = rayleigh_x(ch.lambda_nm[j + 1]);
      const double x = (rayleigh_x(all.lambda_nm[c]) - x0) / (x1 - x0);
      for (std::size_t n = 0; n < N; ++n) {
        const double lo = out[n * C + j], hi = out[n * C + j + 1];
        const bool both = lo != ref3::kTruthSkyNone && hi != ref3::kTruthSkyNone;
        full[n * all.size() + c] = both ? lo + x * (hi - lo) : (x < 0.5 ? lo : hi);
      }
    }
  return full;
}

namespace {

// S̄ of channel c at (h, μ_s) from the medium tables of a trace's channel groups (path_tracer.cl,
// truth_sky_light_table), for the view-ray tables of points whose free paths are guided.
struct SkyLight {
  const AtmosphereParameters* a = nullptr;
  const std::vector<std::vector<double>>* medium = nullptr;  // [group] medium tables with the sky table
  double operator()(std::size_t c, double h, double mu_s) const {
    return ref3::truth_sky_light_table(a, (*medium)[c / kGroup].data(), static_cast<int>(c % kGroup), h, mu_s);
  }
};

// Channel c's optical depth at the nodes and its segment probabilities (a cdf): segment masses
// ≈ ∫ β_s ρ T dt and, for the light's share, ∫ β_s ρ T (V T_sun + S̄) dt — the sun scattered
// here (order 1, with the phase functions at the point's ν; only where the walks carry order 1,
// TruthOptions::Order1::walked) and the light scattered once towards here (what orders ≥ 2 start
// from: S̄ of truth_sky_light, for points whose walks guide their free paths), T at each
// sub-segment's middle with τ linear between the nodes (only the pdf depends on them), mixed
// with a uniform share. With order 1 given by the quadrature, a daylight point's table is
// β_s ρ T alone: drawing half the vertices where order 1 is bright cost its orders ≥ 2 7 %
// more walks (default scene, rgb: 950k against 883k for the same target).
void channel_table(const Channels& ch, std::size_t c, const std::vector<double>& t, const Segments& seg,
                   const SkyLight* sky, bool order1_walked, double p_r, double p_m, double* tau, double* cdf) {
  const int n = static_cast<int>(t.size());
  const double D = t.back();
  tau[0] = 0.0;
  for (int k = 0; k + 1 < n; ++k)
    tau[k + 1] = tau[k] + ch.rayleigh_scattering[c] * seg.lengths[k][0] + ch.mie_extinction[c] * seg.lengths[k][1] +
                 ch.absorption_extinction[c] * seg.lengths[k][2];
  std::vector<double> mass(n - 1, 0.0), lit(n - 1, 0.0);
  double total = 0.0, total_lit = 0.0;
  for (int k = 0; k + 1 < n; ++k) {
    const double dt = t[k + 1] - t[k];
    for (const Sub& sub : seg.subs[k]) {
      const double tau_s = tau[k] + (tau[k + 1] - tau[k]) * (sub.t_mid - t[k]) / dt;
      const double T = std::exp(-tau_s);
      const double m = (ch.rayleigh_scattering[c] * sub.l_r + ch.mie_scattering[c] * sub.l_m) * T;
      mass[k] += m;
      if (order1_walked && sub.visible > 0.0)
        lit[k] += (ch.rayleigh_scattering[c] * sub.l_r * p_r + ch.mie_scattering[c] * sub.l_m * p_m) * T * sub.visible *
                  std::exp(-(ch.rayleigh_scattering[c] * sub.sun_l[0] + ch.mie_extinction[c] * sub.sun_l[1] +
                             ch.absorption_extinction[c] * sub.sun_l[2]));
      if (sky) lit[k] += m * (*sky)(c, sub.h_mid, sub.mu_s);
    }
    total += mass[k];
    total_lit += lit[k];
  }
  const double lit_share = total_lit > 0.0 ? kSunlitShare : 0.0;
  cdf[0] = 0.0;
  for (int k = 0; k + 1 < n; ++k) {
    const double uniform = (t[k + 1] - t[k]) / D;
    const double p = total > 0.0 ? (1.0 - kUniformMix) * ((1.0 - lit_share) * mass[k] / total +
                                                          (lit_share > 0.0 ? lit_share * lit[k] / total_lit : 0.0)) +
                                       kUniformMix * uniform
                                 : uniform;
    cdf[k + 1] = cdf[k] + p;
  }
  const double norm = cdf[n - 1];
  for (int k = 1; k < n; ++k) cdf[k] /= norm;
  cdf[n - 1] = 1.0;
  for (int k = n; k < kNodes; ++k) {
    tau[k] = tau[n - 1];
    cdf[k] = 1.0;
  }
}

// Nodes, optical depth at the nodes and segment probabilities of one point's view ray, for
// every channel.
void view_table(const AtmosphereParameters& a, const Channels& ch, const std::vector<double>& kinks, const SkyLight* sky,
                bool order1_walked,
                double* row, double* node_t, double* node_tau, double* node_cdf) {
  const std::size_t C = ch.size();
  for (int k = 0; k < kNodes; ++k) node_t[k] = 0.0;
  for (std::size_t c = 0; c < C; ++c)
    for (int k = 0; k < kNodes; ++k) node_tau[c * kNodes + k] = node_cdf[c * kNodes + k] = 0.0;
  if (row[PT_NODES] == 0.0) return;
  const std::vector<double> t = view_nodes(a, kinks, row[PT_H], row[PT_MU], row[PT_D]);
  const int n = static_cast<int>(t.size());
  row[PT_NODES] = n;
  for (int k = 0; k < kNodes; ++k) node_t[k] = t[std::min(k, n - 1)];
  const Segments seg = view_segments(a, row, t, order1_walked);
  // the phase functions at the point's view–sun angle (the same all along the view ray)
  const double p_r = ref3::rayleigh_phase(row[PT_NU]), p_m = ref3::mie_phase(a.mie_g, row[PT_NU]);
  for (std::size_t c = 0; c < C; ++c)
    channel_table(ch, c, t, seg, sky, order1_walked, p_r, p_m, node_tau + c * kNodes,
                  node_cdf + c * kNodes);
}

// ---- order 1 by quadrature (TruthOptions::Order1::quadrature) ------------------------------
// Order 1 of every channel at one point, the walks' expectation of the sun term at the view
// ray's vertex (path_tracer.cl, truth_walk):
//   L₁ = ∫_0^D E_sun e^{−τ(0,t)} (β_R ρ_R(t) P_R(ν) + β_M ρ_M(t) P_M(ν)) V(t) e^{−τ_sun(t)} dt,
// with the optical depths exact (three profiles' lengths, shared by the channels) and V the sun
// disc's visible fraction. The view ray is cut into kSingleSegments equal intervals and at
// every kink crossing; each interval is bisected (4-point Gauss–Legendre on it against the same
// on its halves) until, for every channel, the halves' sum moves by at most kSingleTolerance of
// that channel's first estimate over the whole ray, in proportion to the interval's length:
// the shadow's edge (V's smoothstep over the disc) and the sun ray's tangent point passing a
// kink are what refine. Channels whose first estimate is below kSingleFloor of an unattenuated
// thin ray's order 1 are held to that floor (deep in the shadow: nothing a picture shows).
constexpr int kSingleSegments = 8;
constexpr double kSingleTolerance = 1e-6;
constexpr double kSingleFloor = 1e-12;
constexpr int kSingleMaxDepth = 24;
constexpr double kGauss4X[2] = {0.3399810435848563, 0.8611363115940526};
constexpr double kGauss4W[2] = {0.6521451548625461, 0.3478548451374538};

class SingleScattering {
 public:
  SingleScattering(const AtmosphereParameters& a, const AtmosphereParameters& unit, const double* unit_medium,
                   const Channels& ch, const double* row)
      : a_(a), unit_(unit), medium_(unit_medium), ch_(ch), row_(row), C_(ch.size()),
        p_r_(ref3::rayleigh_phase(row[PT_NU])), p_m_(ref3::mie_phase(a.mie_g, row[PT_NU])) {}

  // f_c(t) for every channel c.
  void integrand(double t, double* f) const {
    const double h0 = row_[PT_H], mu0 = row_[PT_MU];
    double h, mu;
    ref3::point_along(&a_, h0, mu0, t, row_[PT_GROUND] != 0.0, &h, &mu);
    const double mu_s = sun_cosine_along(a_, row_, t);
    const double visible = ref3::sun_visible_fraction(&a_, h, mu_s);
    if (!(visible > 0.0)) {
      std::fill_n(f, C_, 0.0);
      return;
    }
    const double mu_sun = ref3::truth_sun_ray_cosine(&a_, h, mu_s);
    const double d_sun = ref3::distance_to_top(&a_, h, mu_sun);
    double len[3], sun[3];  // each profile's optical length: the view ray to t, then towards the sun
    ref3::truth_optical_lengths(&unit_, medium_, h0, mu0, t, len);
    ref3::truth_optical_lengths(&unit_, medium_, h, mu_sun, d_sun, sun);
    for (int i = 0; i < 3; ++i) len[i] += sun[i];
    const double rho_r = ref3::profile_density(&a_.rayleigh_density, h);
    const double rho_m = ref3::profile_density(&a_.mie_density, h);
    for (std::size_t c = 0; c < C_; ++c) {
      const double tau = depth_of_lengths(ch_, c, len);
      f[c] = ch_.solar_irradiance[c] *
             (ch_.rayleigh_scattering[c] * rho_r * p_r_ + ch_.mie_scattering[c] * rho_m * p_m_) * visible *
             std::exp(-tau);
    }
  }
  // 4-point Gauss–Legendre over [lo, hi], every channel, into out.
  void rule(double lo, double hi, double* out) const {
    const double mid = 0.5 * (lo + hi), half = 0.5 * (hi - lo);
    std::vector<double> f(C_);
    std::fill_n(out, C_, 0.0);
    for (int i = 0; i < 2; ++i)
      for (double t : {mid - half * kGauss4X[i], mid + half * kGauss4X[i]}) {
        integrand(t, f.data());
        for (std::size_t c = 0; c < C_; ++c) out[c] += kGauss4W[i] * half * f[c];
      }
  }

  void integrate(const std::vector<double>& nodes, double* out) const {
    struct Piece {
      double lo, hi;
      int depth;
      std::vector<double> whole;
    };
    const double D = nodes.back();
    std::vector<Piece> todo;
    std::vector<double> first(C_, 0.0), tol(C_);
    for (std::size_t k = 0; k + 1 < nodes.size(); ++k) {
      Piece piece{nodes[k], nodes[k + 1], 0, std::vector<double>(C_)};
      rule(piece.lo, piece.hi, piece.whole.data());
      for (std::size_t c = 0; c < C_; ++c) first[c] += piece.whole[c];
      todo.push_back(std::move(piece));
    }
    for (std::size_t c = 0; c < C_; ++c) {
      const double thin = ch_.solar_irradiance[c] * (ch_.rayleigh_scattering[c] + ch_.mie_scattering[c]) * D / (4.0 * M_PI);
      tol[c] = kSingleTolerance * std::max(first[c], kSingleFloor * thin);
    }
    std::fill_n(out, C_, 0.0);
    std::vector<double> left(C_), right(C_);
    while (!todo.empty()) {
      Piece piece = std::move(todo.back());
      todo.pop_back();
      const double mid = 0.5 * (piece.lo + piece.hi);
      rule(piece.lo, mid, left.data());
      rule(mid, piece.hi, right.data());
      bool done = piece.depth >= kSingleMaxDepth;
      if (!done) {
        done = true;
        for (std::size_t c = 0; c < C_ && done; ++c)
          done = std::fabs(left[c] + right[c] - piece.whole[c]) <= tol[c] * (piece.hi - piece.lo) / D;
      }
      if (done) {
        for (std::size_t c = 0; c < C_; ++c) out[c] += left[c] + right[c];
        continue;
      }
      todo.push_back(Piece{piece.lo, mid, piece.depth + 1, left});
      todo.push_back(Piece{mid, piece.hi, piece.depth + 1, right});
    }
  }

 private:
  const AtmosphereParameters& a_;
  const AtmosphereParameters& unit_;
  const double* medium_;
  const Channels& ch_;
  const double* row_;
  std::size_t C_;
  double p_r_, p_m_;
};

Prepared prepare(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points, std::size_t point_base,
                 const TruthOptions& o) {
  Prepared P;
  P.point_base = point_base;
  P.model = model_of(spec);
  const Spectrum sp = spectrum_of(spec);
  P.channels = channels_at(spec, sp.lambda_nm);
  P.n_points = points.size();
  P.n_channels = P.channels.size();
  const AtmosphereParameters a = ref3::make_parameters(P.model, Channels{});
  const std::vector<double> kinks = kink_altitudes(a);
  P.points.assign(P.n_points * TRUTH_POINT_STRIDE, 0.0);
  P.node_t.assign(P.n_points * kNodes, 0.0);
  P.node_tau.assign(P.n_points * P.n_channels * kNodes, 0.0);
  P.node_cdf.assign(P.n_points * P.n_channels * kNodes, 0.0);
  P.low_sun.assign(P.n_points, 0);
  for (std::size_t i = 0; i < P.n_points; ++i) P.low_sun[i] = 90.0 - points[i].sun_zenith_deg < o.low_sun_elevation_deg;
  P.cells.assign(P.n_points * TRUTH_GUIDE_STRIDE, 0.0);
  const double reach = ref3::truth_shadow_reach_cosine(&a);
  // the kernel's rules: walks guided towards the horizon under the sun (truth_walk's use_line),
  // and, with the sun below the camera's horizon, guided free paths too (guided_paths)
  P.guided_paths.assign(P.n_points, 0);
  const double deep = ref3::truth_deep_shadow_cosine(&a);
  bool any_guided = false;
  for (std::size_t i = 0; i < P.n_points; ++i) {
    double* row = &P.points[i * TRUTH_POINT_STRIDE];
    point_geometry(a, points[i], row);
    const bool guided = o.next_sun == TruthOptions::NextSun::along_ray ||
                        (o.next_sun == TruthOptions::NextSun::automatic && row[PT_MU_S] < reach);
    P.guided_paths[i] = guided && row[PT_NODES] != 0.0 && row[PT_MU_S] < deep;
    any_guided = any_guided || P.guided_paths[i];
  }
  const bool single = o.order1 == TruthOptions::Order1::quadrature;
  const AtmosphereParameters a_unit = ref3::make_parameters(P.model, unit_channels());
  const std::vector<double> unit_medium = medium_table(P.model, unit_channels());
  const std::size_t n_groups = (P.n_channels + kGroup - 1) / kGroup;
  P.medium.resize(n_groups);
  parallel_for(static_cast<long long>(n_groups), [&](long long g) {
    const std::size_t first = static_cast<std::size_t>(g) * kGroup;
    P.medium[g] = medium_table(P.model, P.channels.slice(first, std::min<std::size_t>(kGroup, P.n_channels - first)),
                               &unit_medium);
  });
  if (any_guided) {
    const std::vector<double> sky = sky_light_table(P.model, P.channels, unit_medium);
    for (std::size_t c = 0; c < P.n_channels; ++c)
      for (int n = 0; n < TRUTH_SKY_H * TRUTH_SKY_MU; ++n)
        P.medium[c / kGroup][ref3::kTruthSkyAt + n * kGroup + c % kGroup] = sky[n * P.n_channels + c];
  }
  const SkyLight sky{&a, &P.medium};
  if (single) P.single.assign(P.n_points * P.n_channels, 0.0);
  parallel_for(static_cast<long long>(P.n_points), [&](long long i) {
    double* row = &P.points[i * TRUTH_POINT_STRIDE];
    view_table(a, P.channels, kinks, P.guided_paths[i] ? &sky : nullptr, !single, row, &P.node_t[i * kNodes],
               &P.node_tau[i * P.n_channels * kNodes], &P.node_cdf[i * P.n_channels * kNodes]);
    for (int j = 0; j <= TRUTH_GUIDE_CELLS; ++j)
      P.cells[i * TRUTH_GUIDE_STRIDE + j] = static_cast<double>(j) / TRUTH_GUIDE_CELLS;
    if (single && row[PT_NODES] != 0.0)
      SingleScattering(a, a_unit, unit_medium.data(), P.channels, row)
          .integrate(view_nodes(a, kinks, row[PT_H], row[PT_MU], row[PT_D], kSingleSegments),
                     &P.single[i * P.n_channels]);
  });
  return P;
}

}  // namespace

// The exact depths' cut altitudes of a channel group (path_tracer.cl, "exact optical depth"):
// the kinks, and levels between them from the bottom up, each piece the longest (to 1e-4 of
// its length, by bisection) whose estimated 8-point error truth_depth_piece_error is within
// TRUTH_DEPTH_ERROR for every channel, at most thickness / TRUTH_DEPTH_LEVELS; the top last.
// Then the rule of each piece (below its cut): 5 points where their estimate is within the
// bound too, else 8. More than TRUTH_DEPTH_MAX_LEVELS levels fall back to that many equal ones,
// 8 points each.
struct DepthCuts {
  std::vector<double> altitudes, points;  // ascending km; Gauss–Legendre points of the piece below
};
static DepthCuts depth_cuts(const AtmosphereParameters& a, std::size_t channels, const std::vector<double>& kinks) {
  const double t = a.top_radius - a.bottom_radius, longest = t / TRUTH_DEPTH_LEVELS;
  auto within = [&](double h0, double h1, int n) {
    for (std::size_t c = 0; c < channels; ++c)
      if (ref3::truth_depth_piece_error(&a, static_cast<int>(c), n, h0, h1) > ref3::kTruthDepthError) return false;
    return true;
  };
  std::vector<double> ends = kinks;  // where a piece must end: each kink, then the top
  ends.push_back(t);
  DepthCuts out;
  double h = 0.0;
  for (double end : ends) {
    while (end - h > 1e-9 * t) {
      double step = std::min(longest, end - h);
      if (!within(h, h + step, 8)) {
        double lo = 0.0, hi = step;  // a piece of length lo is within the bound, one of hi not
        while (hi - lo > 1e-4 * hi) {
          const double mid = 0.5 * (lo + hi);
          if (within(h, h + mid, 8)) lo = mid;
          else hi = mid;
        }
        step = std::max(lo, 1e-9 * t);
      }
      h = step >= end - h - 1e-9 * t ? end : h + step;
      out.altitudes.push_back(h);
      if (out.altitudes.size() > kinks.size() + TRUTH_DEPTH_MAX_LEVELS) {
        out.altitudes = kinks;
        for (int j = 1; j <= TRUTH_DEPTH_MAX_LEVELS; ++j) out.altitudes.push_back(t * j / TRUTH_DEPTH_MAX_LEVELS);
        std::sort(out.altitudes.begin(), out.altitudes.end());
        out.points.assign(out.altitudes.size(), 8.0);
        return out;
      }
    }
  }
  for (std::size_t k = 0; k < out.altitudes.size(); ++k)
    out.points.push_back(within(k ? out.altitudes[k - 1] : 0.0, out.altitudes[k], 5) ? 5.0 : 8.0);
  return out;
}

// The medium table of one channel group (path_tracer.cl): [TRUTH_SHELLS][kGroup] majorants,
// then the exact depths' cut altitudes' count and the cuts (depth_cuts), and the sun
// table (the sky table is left at 0: prepare() fills it where walks read it). The sun table's
// depths are exact quadratures; given the medium table of unit_channels() (`lengths`), each is
// instead the channel's coefficients times the three profiles' optical lengths at the same
// node — the same sum, each length as exact a quadrature as the group's own — so a
// 48-wavelength trace integrates its 3072 sun rays once, not once a group.
std::vector<double> medium_table(const Model& m, const Channels& group, const std::vector<double>* lengths) {
  const AtmosphereParameters a = ref3::make_parameters(m, Channels{});
  const double t = m.top_radius_km - m.bottom_radius_km, width = t / TRUTH_SHELLS;
  std::vector<double> out(ref3::kTruthMediumSize, 0.0);
  const AtmosphereParameters ag = ref3::make_parameters(m, group);
  const DepthCuts cuts = depth_cuts(ag, group.size(), kink_altitudes(a));
  out[ref3::kTruthCutsAt] = static_cast<double>(cuts.altitudes.size());
  std::copy(cuts.altitudes.begin(), cuts.altitudes.end(), out.begin() + ref3::kTruthCutsAt + 1);
  std::copy(cuts.points.begin(), cuts.points.end(), out.begin() + ref3::kTruthCutsAt + 1 + ref3::kTruthMaxCuts);
  for (int j = 0; j < TRUTH_SHELLS; ++j) {
    const double lo = std::max(0.0, (j - kShellOverlap) * width);
    const double hi = t * (1.0 + 1e-9);
    const double mr = ref3::profile_max_over(&a.rayleigh_density, lo, hi);
    const double mm = ref3::profile_max_over(&a.mie_density, lo, hi);
    const double ma = ref3::profile_max_over(&a.absorption_density, lo, hi);
    for (std::size_t c = 0; c < group.size(); ++c)
      out[j * kGroup + c] = (group.rayleigh_scattering[c] * mr + group.mie_extinction[c] * mm +
                             group.absorption_extinction[c] * ma) *
                            (1.0 + kMajorantMargin);
  }
  // the optical depth towards the sun at the sun table's nodes: each channel's sum of the three
  // profiles' optical lengths there, read from `lengths` or integrated exactly (over the cuts
  // above, which truth_optical_lengths reads)
  for (int n = 0; n < TRUTH_SUN_H * TRUTH_SUN_MU; ++n) {
    double own[3];
    const double* l = own;
    if (lengths) {
      l = &(*lengths)[ref3::kTruthSunAt + n * kGroup];
    } else {
      double h, mu;
      ref3::truth_sun_node(&ag, n / TRUTH_SUN_MU, n % TRUTH_SUN_MU, &h, &mu);
      ref3::truth_optical_lengths(&ag, out.data(), h, mu, ref3::distance_to_top(&ag, h, mu), own);
    }
    for (std::size_t c = 0; c < group.size(); ++c)
      out[ref3::kTruthSunAt + n * kGroup + c] = depth_of_lengths(group, c, l);
  }
  return out;
}

namespace {

// The [P][kGroup][kNodes] slice of a [P][C][kNodes] table for channels first..first+count.
std::vector<double> group_slice(const std::vector<double>& v, std::size_t n_points, std::size_t n_channels,
                                std::size_t first, std::size_t count) {
  std::vector<double> out(n_points * kGroup * kNodes, 0.0);
  for (std::size_t p = 0; p < n_points; ++p)
    for (std::size_t c = 0; c < count; ++c)
      std::copy_n(&v[(p * n_channels + first + c) * kNodes], kNodes, &out[(p * kGroup + c) * kNodes]);
  for (std::size_t p = 0; p < n_points; ++p)  // unused channels: a valid table (never read)
    for (std::size_t c = count; c < kGroup; ++c)
      for (int k = 0; k < kNodes; ++k) out[(p * kGroup + c) * kNodes + k] = 1.0;
  return out;
}

// Running statistics of one (point, channel): walks, mean, sum of squared deviations; batches
// merge by the pairwise update of Chan, Golub and LeVeque.
struct Stat {
  double n = 0.0, mean = 0.0, m2 = 0.0;
  void merge(double nb, double mean_b, double m2_b) {
    const double total = n + nb, delta = mean_b - mean;
    mean += delta * nb / total;
    m2 += m2_b + delta * delta * n * nb / total;
    n = total;
  }
  double se() const { return n > 1.0 ? std::sqrt(std::max(m2, 0.0) / (n - 1.0) / n) : 0.0; }
};

// Runs, for every point p and channel c of one channel group, count[p][c] batches from batch
// base[p][c] (both [P][kGroup]; stride ≥ every count); returns [P][stride][kStride]. A pilot
// launch (TRUTH_MODE_PILOT) also fills *pilot with
// [P][stride][paths_per_batch][kGroup][TRUTH_PILOT_STRIDE]; learn() replaces the view-ray
// tables and first-direction cells that later TRUTH_MODE_LEARNED launches read.
class Engine {
 public:
  virtual ~Engine() = default;
  virtual std::vector<double> run(std::size_t group, const std::vector<int>& base, const std::vector<int>& count,
                                  int stride, int mode, std::vector<double>* pilot) = 0;
  virtual void learn(const Prepared& learned) = 0;
};

struct Group {
  std::size_t first = 0, count = 0;
  Channels channels;
  AtmosphereParameters a{};
  std::vector<double> tau, cdf, medium;
};
std::vector<Group> groups_of(const Prepared& P) {
  std::vector<Group> out;
  for (std::size_t first = 0; first < P.n_channels; first += kGroup) {
    Group g;
    g.first = first;
    g.count = std::min<std::size_t>(kGroup, P.n_channels - first);
    g.channels = P.channels.slice(first, g.count);
    g.a = ref3::make_parameters(P.model, g.channels);
    g.tau = group_slice(P.node_tau, P.n_points, P.n_channels, first, g.count);
    g.cdf = group_slice(P.node_cdf, P.n_points, P.n_channels, first, g.count);
    g.medium = P.medium[first / kGroup];
    out.push_back(std::move(g));
  }
  return out;
}

// The random streams' seed: pilot walks draw from their own family (the high word flipped).
philox_u32 seed_high(const TruthOptions& o, int mode) {
  const auto hi = static_cast<philox_u32>(o.seed >> 32);
  return mode == TRUTH_MODE_PILOT ? hi ^ 0x9e3779b9u : hi;
}
int order1_arg(const TruthOptions& o) {
  return o.order1 == TruthOptions::Order1::quadrature ? TRUTH_ORDER1_GIVEN : TRUTH_ORDER1_WALKED;
}
std::size_t pilot_size(std::size_t points, int stride, int paths_per_batch) {
  return points * static_cast<std::size_t>(stride) * static_cast<std::size_t>(paths_per_batch) * kGroup *
         TRUTH_PILOT_STRIDE;
}

class HostEngine final : public Engine {
 public:
  HostEngine(const Prepared& P, const TruthOptions& o) : P_(P), o_(o), groups_(groups_of(P)), cells_(P.cells) {}
  std::vector<double> run(std::size_t gi, const std::vector<int>& base, const std::vector<int>& count, int stride,
                          int mode, std::vector<double>* pilot) override {
    const Group& g = groups_[gi];
    std::vector<double> out(P_.n_points * stride * kStride, 0.0);
    const std::size_t item_pilot = static_cast<std::size_t>(o_.paths_per_batch) * kGroup * TRUTH_PILOT_STRIDE;
    if (mode == TRUTH_MODE_PILOT) pilot->assign(pilot_size(P_.n_points, stride, o_.paths_per_batch), 0.0);
    parallel_for(static_cast<long long>(P_.n_points) * stride, [&](long long id) {
      const int p = static_cast<int>(id / stride), j = static_cast<int>(id % stride);
      if (std::none_of(&count[p * kGroup], &count[p * kGroup] + kGroup, [&](int n) { return j < n; })) return;
      ref3::truth_trace_item(&g.a, P_.points.data(), P_.node_t.data(), g.tau.data(), g.cdf.data(), g.medium.data(),
                             kNodes, p, static_cast<int>(P_.point_base), j, &base[p * kGroup], &count[p * kGroup],
                             o_.paths_per_batch, o_.orders,
                             o_.split_orders, static_cast<int>(o_.next_sun), order1_arg(o_),
                             static_cast<philox_u32>(o_.seed & 0xffffffffu),
                             seed_high(o_, mode), static_cast<int>(g.first), static_cast<int>(g.count), cells_.data(),
                             mode, &out[id * kStride],
                             mode == TRUTH_MODE_PILOT ? &(*pilot)[static_cast<std::size_t>(id) * item_pilot] : nullptr);
    });
    return out;
  }
  void learn(const Prepared& learned) override {
    for (Group& g : groups_) g.cdf = group_slice(learned.node_cdf, learned.n_points, learned.n_channels, g.first, g.count);
    cells_ = learned.cells;
  }

 private:
  const Prepared& P_;
  const TruthOptions& o_;
  std::vector<Group> groups_;
  std::vector<double> cells_;
};

class DeviceEngine final : public Engine {
 public:
  DeviceEngine(cl_util::Device& dev, const Prepared& P, const TruthOptions& o)
      : dev_(dev), P_(P), o_(o), groups_(groups_of(P)) {
    program_ = dev.build(kTruthProgram, std::string("-DNCH=") + std::to_string(kGroup) + " " + dev.real_options());
    points_ = cl_util::upload_real(dev, P.points);
    node_t_ = cl_util::upload_real(dev, P.node_t);
    cells_ = cl_util::upload_real(dev, P.cells);
    for (const Group& g : groups_) {
      GroupBuffers b;
      b.block = ref3::parameter_block(g.a, dev.info().fp64);
      b.tau = cl_util::upload_real(dev, g.tau);
      b.cdf = cl_util::upload_real(dev, g.cdf);
      b.medium = cl_util::upload_real(dev, g.medium);
      buffers_.push_back(std::move(b));
    }
  }
  std::vector<double> run(std::size_t gi, const std::vector<int>& base, const std::vector<int>& count, int stride,
                          int mode, std::vector<double>* pilot) override {
    const Group& g = groups_[gi];
    GroupBuffers& b = buffers_[gi];
    const std::size_t n_out = P_.n_points * stride * kStride;
    const std::size_t n_pilot = mode == TRUTH_MODE_PILOT ? pilot_size(P_.n_points, stride, o_.paths_per_batch) : 1;
    return cl_util::checked("truth_trace", [&] {
      const cl::Buffer base_buf(dev_.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, base.size() * sizeof(int),
                                const_cast<int*>(base.data()));
      const cl::Buffer count_buf(dev_.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, count.size() * sizeof(int),
                                 const_cast<int*>(count.data()));
      cl::Buffer out_buf = cl_util::device_real(dev_, n_out);
      cl::Buffer pilot_buf = cl_util::device_real(dev_, n_pilot);
      cl::Kernel k(program_, "truth_trace");
      cl_uint i = 0;
      k.setArg(i++, b.block.size(), b.block.data());
      k.setArg(i++, points_);
      k.setArg(i++, node_t_);
      k.setArg(i++, b.tau);
      k.setArg(i++, b.cdf);
      k.setArg(i++, b.medium);
      k.setArg(i++, static_cast<cl_int>(P_.n_points));
      k.setArg(i++, static_cast<cl_int>(P_.point_base));
      k.setArg(i++, static_cast<cl_int>(kNodes));
      k.setArg(i++, base_buf);
      k.setArg(i++, count_buf);
      k.setArg(i++, static_cast<cl_int>(stride));
      k.setArg(i++, static_cast<cl_int>(o_.paths_per_batch));
      k.setArg(i++, static_cast<cl_int>(o_.orders));
      k.setArg(i++, static_cast<cl_int>(o_.split_orders));
      k.setArg(i++, static_cast<cl_int>(o_.next_sun));
      k.setArg(i++, static_cast<cl_int>(order1_arg(o_)));
      k.setArg(i++, static_cast<cl_uint>(o_.seed & 0xffffffffu));
      k.setArg(i++, static_cast<cl_uint>(seed_high(o_, mode)));
      k.setArg(i++, static_cast<cl_int>(g.first));
      k.setArg(i++, static_cast<cl_int>(g.count));
      k.setArg(i++, cells_);
      k.setArg(i++, static_cast<cl_int>(mode));
      k.setArg(i++, out_buf);
      k.setArg(i++, pilot_buf);
      // On a CPU one work item a group: PoCL's own choice (the largest divisor of the launch) made
      // a launch of a few hundred walks one group, run by one thread, and the walks' costs differ
      // by orders of magnitude between points, so groups of one balance best (2 cores, the same
      // bytes: twilight 24 points 14.7 -> 7.6 s, daylight 128 points 7.9 -> 6.9 s; groups of 4
      // and 16: 7.1 and 7.2 s). On a GPU the driver chooses.
      cl_util::run_1d(dev_, k, P_.n_points * static_cast<std::size_t>(stride), dev_.info().type == "cpu" ? 1 : 0);
      if (mode == TRUTH_MODE_PILOT) *pilot = cl_util::download_real(dev_, pilot_buf, n_pilot);
      return cl_util::download_real(dev_, out_buf, n_out);
    });
  }
  void learn(const Prepared& learned) override {
    cells_ = cl_util::upload_real(dev_, learned.cells);
    for (std::size_t gi = 0; gi < groups_.size(); ++gi) {
      groups_[gi].cdf = group_slice(learned.node_cdf, learned.n_points, learned.n_channels, groups_[gi].first,
                                    groups_[gi].count);
      buffers_[gi].cdf = cl_util::upload_real(dev_, groups_[gi].cdf);
    }
  }

 private:
  struct GroupBuffers {
    std::vector<unsigned char> block;
    cl::Buffer tau, cdf, medium;
  };
  cl_util::Device& dev_;
  const Prepared& P_;
  const TruthOptions& o_;
  std::vector<Group> groups_;
  std::vector<GroupBuffers> buffers_;
  cl::Program program_;
  cl::Buffer points_, node_t_, cells_;
};

constexpr int kMaxRounds = 4;           // the first `paths`, then up to 3 top-ups towards the target
constexpr double kTopUpMargin = 1.1;    // a top-up asks for 10 % more walks than the estimate
constexpr long long kLaunchWalks = 1LL << 16;  // walks per point and launch (progress, short launches)
constexpr long long kLaunchItems = 1LL << 20;  // work items (batches) per launch: bounds the output buffer
// Scattering events per launch (all points, one channel group), once the first batch of each
// point has said how many events its walks take: launches of seconds, not hours, in an
// optically thick atmosphere (progress, and an interrupt, between launches).
constexpr double kLaunchEvents = 4e6;
constexpr double kChunkTableBytes = 64e6;      // view-ray tables of one chunk of points (all channels)

// What the walks of all chunks add up to.
struct Totals {
  double events = 0.0;
  long long walks = 0, truncated = 0, violations = 0;
  double tables_s = 0.0, pilot_s = 0.0;  // host tables and device set-up; the learned tables' pilots
};

// One twilight point's pilot walks: per channel, per walk, its record (path_tracer.cl).
struct PilotWalks {
  std::vector<std::vector<std::array<double, TRUTH_PILOT_STRIDE>>> channel;  // [C][walks]
};

// A second-moment histogram over n bins pooled over the channels: bin(record) (< 0: skip) and
// moment(record) per walk, each channel's histogram normalised to sum 1 before they are added,
// so that every channel has the same say whatever its radiance.
template <class Bin, class Moment>
std::vector<double> pooled_second_moments(const PilotWalks& w, int n, const Bin& bin, const Moment& moment) {
  std::vector<double> pooled(n, 0.0), own(n);
  for (const auto& walks : w.channel) {
    std::fill(own.begin(), own.end(), 0.0);
    double sum = 0.0;
    for (const auto& rec : walks) {
      const int b = bin(rec);
      if (b < 0) continue;
      own[b] += moment(rec);
      sum += moment(rec);
    }
    if (sum > 0.0)
      for (int b = 0; b < n; ++b) pooled[b] += own[b] / sum;
  }
  return pooled;
}

// The learned view-ray tables: the fixed table's segments grouped into kLearnBins bins of equal
// mass (averaged over the channels), each bin's mass ∝ √(its second moment, each channel's
// histogram normalised to 1 and then summed: every channel has the same say, whatever its
// radiance) — the variance-optimal allocation for a pdf that is the fixed one reweighted per bin
// (for a pdf q·c_k on bin k, Σ_k S_k / c_k with S_k = ∫_k f²/q is least at c_k Q_k ∝ √(S_k Q_k),
// Q_k = 1/kLearnBins here) — mixed with kKeepFixed of the pilot's table.
void learn_view_table(const PilotWalks& w, int n, double* cdf_all, std::size_t C) {
  std::vector<double> mean_mass(n - 1, 0.0);
  for (std::size_t c = 0; c < C; ++c)
    for (int k = 0; k + 1 < n; ++k) mean_mass[k] += (cdf_all[c * kNodes + k + 1] - cdf_all[c * kNodes + k]) / C;
  std::vector<int> bin_of(n - 1, 0);
  double below = 0.0;
  for (int k = 0; k + 1 < n; ++k) {
    bin_of[k] = std::min(kLearnBins - 1, static_cast<int>((below + 0.5 * mean_mass[k]) * kLearnBins));
    below += mean_mass[k];
  }
  const std::vector<double> second = pooled_second_moments(
      w, kLearnBins,
      [&](const auto& rec) {
        const int seg = static_cast<int>(rec[0]);
        return seg < 0 || seg + 1 >= n ? -1 : bin_of[seg];
      },
      [](const auto& rec) { return rec[4] * rec[4]; });
  std::vector<double> bin_mass(kLearnBins, 0.0);
  double total = 0.0;
  for (int b = 0; b < kLearnBins; ++b) total += bin_mass[b] = std::sqrt(second[b]);
  if (!(total > 0.0)) return;
  for (std::size_t c = 0; c < C; ++c) {
    double* cdf = cdf_all + c * kNodes;
    std::vector<double> fixed(n - 1), fixed_bin(kLearnBins, 0.0);
    for (int k = 0; k + 1 < n; ++k) fixed_bin[bin_of[k]] += fixed[k] = cdf[k + 1] - cdf[k];
    double acc = 0.0;
    for (int k = 0; k + 1 < n; ++k) {
      const int b = bin_of[k];
      const double learned = fixed_bin[b] > 0.0 ? bin_mass[b] / total * fixed[k] / fixed_bin[b] : 0.0;
      acc += (1.0 - kKeepFixed) * learned + kKeepFixed * fixed[k];
      cdf[k + 1] = acc;
    }
    for (int k = 1; k < n; ++k) cdf[k] /= acc;
    cdf[n - 1] = 1.0;
  }
}

// The learned first-direction cells: mass ∝ √(∫_cell F_u² du), from the pilot's values beyond
// order 1 (Y² · q_u estimates it, q_u = the pilot's pdf over the guide's g; pooled over the
// channels as above), with a floor of kCellFloor of the uniform table.
void learn_cells(const PilotWalks& w, double* cells) {
  std::vector<double> second = pooled_second_moments(
      w, TRUTH_GUIDE_CELLS, [](const auto& rec) { return rec[1] < 0.0 ? -1 : ref3::truth_guide_cell(rec[1], rec[2]); },
      [](const auto& rec) { return rec[5] * rec[5] * rec[3]; });
  double total = 0.0;
  for (double& x : second) total += x = std::sqrt(x);
  cells[0] = 0.0;
  for (int j = 0; j < TRUTH_GUIDE_CELLS; ++j) {
    const double learned = total > 0.0 ? second[j] / total : 1.0 / TRUTH_GUIDE_CELLS;
    cells[j + 1] = cells[j] + (1.0 - kCellFloor) * learned + kCellFloor / TRUTH_GUIDE_CELLS;
  }
  for (int j = 1; j <= TRUTH_GUIDE_CELLS; ++j) cells[j] /= cells[TRUTH_GUIDE_CELLS];
}

// The pilot's view-ray table of point p: the fixed one mixed half and half with the uniform
// density (node_t: the segments' lengths).
void explore_table(const Prepared& P, std::size_t p, double* cdf_all) {
  const int n = static_cast<int>(P.points[p * TRUTH_POINT_STRIDE + PT_NODES]);
  const double* t = &P.node_t[p * kNodes];
  for (std::size_t c = 0; c < P.n_channels; ++c) {
    double* cdf = cdf_all + c * kNodes;
    double acc = 0.0, prev = 0.0;
    for (int k = 0; k + 1 < n; ++k) {
      const double fixed = cdf[k + 1] - prev;
      prev = cdf[k + 1];
      acc += (1.0 - kUniformMixPilot) * fixed + kUniformMixPilot * (t[k + 1] - t[k]) / t[n - 1];
      cdf[k + 1] = acc;
    }
    for (int k = 1; k < n; ++k) cdf[k] /= acc;
    cdf[n - 1] = 1.0;
  }
}

// The second moment of the view-ray part of the estimate with table `to` over that with table
// `from`, predicted from the pilot's walks (drawn with table `pilot`): for piecewise-constant
// tables over the same segments, E_pilot[Y² q_pilot / q] is the second moment with q; each
// channel's Y² normalised to sum 1, as the learning pools them.
double predicted_ratio(const PilotWalks& w, int n, const double* pilot, const double* from, const double* to) {
  double num = 0.0, den = 0.0;
  auto mass = [](const double* cdf, int seg) { return cdf[seg + 1] - cdf[seg]; };
  for (std::size_t c = 0; c < w.channel.size(); ++c) {
    double sum = 0.0;
    for (const auto& rec : w.channel[c]) sum += rec[4] * rec[4];
    if (!(sum > 0.0)) continue;
    const double *q_p = pilot + c * kNodes, *q_f = from + c * kNodes, *q_t = to + c * kNodes;
    for (const auto& rec : w.channel[c]) {
      const int seg = static_cast<int>(rec[0]);
      if (seg < 0 || seg + 1 >= n || rec[4] == 0.0) continue;
      const double y2 = rec[4] * rec[4] / sum, qp = mass(q_p, seg);
      if (mass(q_t, seg) > 0.0) num += y2 * qp / mass(q_t, seg);
      if (mass(q_f, seg) > 0.0) den += y2 * qp / mass(q_f, seg);
    }
  }
  return den > 0.0 ? num / den : 1.0;
}

// Pilot walks for the points whose free paths are guided (deep twilight; TruthOptions::learn),
// then their learned tables in the engine where the pilot predicts a gain (kLearnGain). The
// pilot's walks only shape the tables: they are not part of the estimate (their streams are
// their own).
void learn_tables(Engine& engine, const Prepared& P, const TruthOptions& o, Totals& totals) {
  bool any = false;
  for (char t : P.guided_paths) any = any || t;
  if (!o.learn || !any) return;
  Prepared tables;
  tables.n_points = P.n_points;
  tables.n_channels = P.n_channels;
  tables.node_cdf = P.node_cdf;
  tables.cells = P.cells;
  for (std::size_t p = 0; p < P.n_points; ++p)
    if (P.guided_paths[p]) explore_table(P, p, &tables.node_cdf[p * P.n_channels * kNodes]);
  engine.learn(tables);
  const std::size_t n_groups = (P.n_channels + kGroup - 1) / kGroup;
  const int batches = std::max(1, static_cast<int>(std::ceil(kPilotWalks / static_cast<double>(P.n_channels) /
                                                             o.paths_per_batch)));
  std::vector<int> base(P.n_points * kGroup, 0), count(P.n_points * kGroup, 0);
  for (std::size_t p = 0; p < P.n_points; ++p)
    if (P.guided_paths[p]) std::fill_n(&count[p * kGroup], kGroup, batches);
  std::vector<PilotWalks> walks(P.n_points);
  for (auto& w : walks) w.channel.resize(P.n_channels);
  std::vector<double> pilot;
  for (std::size_t g = 0; g < n_groups; ++g) {
    const std::size_t first = g * kGroup, n_ch = std::min<std::size_t>(kGroup, P.n_channels - first);
    const std::vector<double> out = engine.run(g, base, count, batches, TRUTH_MODE_PILOT, &pilot);
    for (std::size_t p = 0; p < P.n_points; ++p)
      for (int j = 0; j < count[p * kGroup]; ++j) {
        const double* item = &out[(p * batches + j) * kStride];
        totals.events += item[2 * TRUTH_STATS * kGroup];
        totals.walks += o.paths_per_batch * static_cast<long long>(n_ch);
        totals.truncated += static_cast<long long>(item[2 * TRUTH_STATS * kGroup + 1]);
        totals.violations += static_cast<long long>(item[2 * TRUTH_STATS * kGroup + 2]);
        const double* rec = &pilot[(p * batches + j) * o.paths_per_batch * kGroup * TRUTH_PILOT_STRIDE];
        for (int i = 0; i < o.paths_per_batch; ++i)
          for (std::size_t c = 0; c < n_ch; ++c) {
            std::array<double, TRUTH_PILOT_STRIDE> r{};
            std::copy_n(rec + (i * kGroup + c) * TRUTH_PILOT_STRIDE, TRUTH_PILOT_STRIDE, r.begin());
            walks[p].channel[first + c].push_back(r);
          }
      }
  }
  Prepared learned = tables;
  std::vector<char> keep(P.n_points, 0);
  parallel_for(static_cast<long long>(P.n_points), [&](long long p) {
    const std::size_t at = p * P.n_channels * kNodes, size = P.n_channels * kNodes;
    double* cdf = &learned.node_cdf[at];
    if (P.guided_paths[p]) {
      const PilotWalks& w = walks[p];
      const int n = static_cast<int>(P.points[p * TRUTH_POINT_STRIDE + PT_NODES]);
      learn_view_table(w, n, cdf, P.n_channels);
      keep[p] = predicted_ratio(w, n, &tables.node_cdf[at], &P.node_cdf[at], cdf) < kLearnGain;
      if (keep[p]) {
        learn_cells(w, &learned.cells[p * TRUTH_GUIDE_STRIDE]);
        learned.cells[p * TRUTH_GUIDE_STRIDE + TRUTH_GUIDE_CELLS + 1] = 1.0;
      }
    }
    if (!keep[p]) std::copy_n(&P.node_cdf[at], size, cdf);  // the fixed table
  });
  long long kept = 0;
  for (char k : keep) kept += k;
  spdlog::debug("truth: {} of {} points learned their tables", kept, P.n_points);
  engine.learn(learned);
}

// After the first batch of every (point, channel): the batches per launch, from the events a
// walk took (kLaunchEvents), and with an events budget each point's cap on the batches of one
// channel.
void size_launches(const Prepared& P, const TruthOptions& o, const std::vector<double>& events,
                   long long& launch_batches, std::vector<long long>& cap) {
  const double low_sun_budget = o.low_sun_max_paths > 0 ? static_cast<double>(o.low_sun_max_paths) /
                                                              static_cast<double>(std::max(o.max_paths, o.paths))
                                                        : 1.0;
  const double ppb = o.paths_per_batch;
  double per_batch = 0.0;  // events of one batch of every point, one channel group
  for (std::size_t p = 0; p < P.n_points; ++p) {
    const double per_walk = events[p] / (ppb * static_cast<double>(P.n_channels));
    per_batch += per_walk * ppb * std::min<std::size_t>(kGroup, P.n_channels);
    if (o.max_events_per_point > 0.0) {
      const double events_budget = o.max_events_per_point * (P.low_sun[p] ? low_sun_budget : 1.0);
      const auto budget = static_cast<long long>(events_budget / (std::max(per_walk, 1.0) * ppb));
      cap[p] = std::max<long long>(1, std::min(cap[p], budget));
    }
  }
  if (per_batch > 0.0)
    launch_batches = std::max<long long>(1, std::min(launch_batches, static_cast<long long>(kLaunchEvents / per_batch)));
}

// The share of a weighted target's walks every weighted channel keeps at least (of the mean
// over them), whatever its first walks said of its variance: a channel whose first batch
// happened to see none of its rare paths still gets walks to show them.
constexpr double kAllocationFloor = 0.1;

// The walks (not batches) each channel of point p needs for its share of the precision target,
// from the walks so far (stat n, mean, se per channel); 0 for channels that need no more.
//  - no weights: every channel on its own, n (se / (target L))², the walks that bring its se to
//    the target;
//  - weights (rows Σ_c w_rc L_c, e.g. CIE X, Y, Z over a spectrum): for each row that misses the
//    target, the allocation with the fewest walks whose weighted sum has the target's variance V
//    (Neyman's: n_c = (Σ_k |w_rk| σ_k) |w_rc| σ_c / V, σ the per-walk standard deviation), each
//    channel at least kAllocationFloor of the row's mean; the channel's need is the largest over
//    the rows. Channels whose walks mean little to the colour (the spectrum's ends) then take a
//    few of them instead of as many as the brightest.
template <class StatOf>
std::vector<double> walks_needed(const TruthOptions& o, double target, std::size_t C, const StatOf& stat) {
  std::vector<double> need(C, 0.0);
  if (o.target_weights.empty()) {
    for (std::size_t c = 0; c < C; ++c) {
      const double L = std::fabs(stat(c).mean), se = stat(c).se();
      if (L > 0.0 && se > target * L) need[c] = stat(c).n * (se / (target * L)) * (se / (target * L)) * kTopUpMargin;
    }
    return need;
  }
  std::vector<double> sigma(C);  // per-walk standard deviation of each channel
  for (std::size_t c = 0; c < C; ++c) sigma[c] = stat(c).se() * std::sqrt(stat(c).n);
  const std::size_t rows = o.target_weights.size() / C;
  for (std::size_t row = 0; row < rows; ++row) {
    const double* w = &o.target_weights[row * C];
    double L = 0.0, var = 0.0, sum = 0.0;  // the row's value, its variance, Σ |w| σ
    std::size_t weighted = 0;
    for (std::size_t c = 0; c < C; ++c) {
      const Stat& s = stat(c);
      L += w[c] * s.mean;
      var += w[c] * w[c] * s.se() * s.se();
      sum += std::fabs(w[c]) * sigma[c];
      weighted += w[c] != 0.0;
    }
    const double V = (target * L) * (target * L);
    if (!(V > 0.0) || !(var > V) || !(sum > 0.0)) continue;
    std::vector<double> n(C, 0.0);
    double mean = 0.0;
    for (std::size_t c = 0; c < C; ++c) {
      n[c] = sum * std::fabs(w[c]) * sigma[c] / V * kTopUpMargin;
      mean += n[c] / static_cast<double>(weighted);
    }
    for (std::size_t c = 0; c < C; ++c)
      if (w[c] != 0.0) need[c] = std::max(need[c], std::max(n[c], kAllocationFloor * mean));
  }
  return need;
}

// Traces one chunk of points into r (rows point_base ... of radiance, se, paths). Every
// (point, channel) walks its own number of batches: the first `paths`, then top-ups to its
// share of the precision target (walks_needed), each channel at most the point's cap (no
// weights), or all of them together at most cap × channels (weights: the budget the target's
// allocation shares out).
void trace_chunk(Engine& engine, const Prepared& P, const TruthOptions& o, TruthResult& r, Totals& totals,
                 const std::function<void(double)>& progress) {
  const std::size_t C = P.n_channels, n_groups = (C + kGroup - 1) / kGroup;
  const long long ppb = o.paths_per_batch;
  // per point: its walk cap in batches, and its precision target (TruthOptions::low_sun_*)
  auto batches_of = [&](long long walks) {
    const long long w = std::min<long long>(std::max(walks, o.paths), 1LL << 32);
    return std::min<long long>((w + ppb - 1) / ppb, std::numeric_limits<int>::max());
  };
  const long long max_batches = batches_of(o.max_paths);
  const long long low_sun_batches = o.low_sun_max_paths > 0 ? batches_of(o.low_sun_max_paths) : max_batches;
  const double low_sun_target = o.low_sun_relative_se > 0.0 ? o.low_sun_relative_se : o.target_relative_se;
  const long long stream_batches = std::min<long long>((1LL << 32) / ppb, std::numeric_limits<int>::max());
  const bool weighted = !o.target_weights.empty();
  // per (point, channel): batches traced, batches wanted
  std::vector<long long> done(P.n_points * C, 0), want(P.n_points * C, std::min(max_batches, (o.paths + ppb - 1) / ppb));
  constexpr int kStats = TRUTH_STATS;  // whole walk, orders 1..split, orders above split
  std::vector<Stat> stats(P.n_points * C * kStats);
  auto stat = [&](std::size_t p, std::size_t c, int k = 0) -> Stat& { return stats[(p * C + c) * kStats + k]; };
  // the estimate: the walks' mean, plus order 1 where the quadrature gives it (the whole and the
  // orders up to the split; its error is far below any walk's)
  auto estimate = [&](std::size_t p, std::size_t c, int k = 0) {
    Stat s = stat(p, c, k);
    if (k < 2 && !P.single.empty()) s.mean += P.single[p * C + c];
    return s;
  };
  long long launch_batches =
      std::max<long long>(1, std::min<long long>(kLaunchWalks / ppb, kLaunchItems / static_cast<long long>(P.n_points)));
  std::vector<long long> cap(P.n_points);  // per point and channel: its walk cap's batches, or the events budget's
  for (std::size_t p = 0; p < P.n_points; ++p) cap[p] = P.low_sun[p] ? low_sun_batches : max_batches;
  std::vector<char> clipped(P.n_points, 0);             // a top-up was cut by the cap
  std::vector<double> events(P.n_points, 0.0);          // per point, all its channels
  bool probed = false;  // the first launch traces one batch per (point, channel): its events per walk
  // The batches point p's channels need for their share of its precision target by the walks so
  // far (walks_needed), each channel within the point's cap (no weights) or all of them within its
  // budget (weights: shared in the allocation's proportions over what is still to trace); *clip:
  // the cap or budget cut them.
  auto plan_of = [&](std::size_t p, bool& clip) {
    const double target = P.low_sun[p] ? low_sun_target : o.target_relative_se;
    const std::vector<double> need = walks_needed(o, target, C, [&](std::size_t c) { return estimate(p, c); });
    std::vector<long long> w(C);
    long long total = 0, traced = 0;
    for (std::size_t c = 0; c < C; ++c) {
      w[c] = std::max(done[p * C + c], static_cast<long long>(std::ceil(need[c] / static_cast<double>(ppb))));
      total += w[c];
      traced += done[p * C + c];
    }
    clip = false;
    if (!weighted) {
      for (std::size_t c = 0; c < C; ++c)
        if (w[c] > cap[p]) {
          w[c] = std::max(done[p * C + c], cap[p]);
          clip = true;
        }
    } else if (const long long budget = cap[p] * static_cast<long long>(C); total > budget) {
      const double share =
          static_cast<double>(std::max<long long>(budget - traced, 0)) / static_cast<double>(total - traced);
      for (std::size_t c = 0; c < C; ++c)
        w[c] = done[p * C + c] + static_cast<long long>(std::floor(share * static_cast<double>(w[c] - done[p * C + c])));
      clip = true;
    }
    for (std::size_t c = 0; c < C; ++c) w[c] = std::min(w[c], stream_batches);
    return w;
  };
  // Progress: the walks traced over those the target will ask for, each (point, channel) at the
  // larger of its plan so far and what its walks so far say the top-ups will ask (plan_of), each
  // batch weighted by its point's events a batch (a twilight walk costs many daylight ones): the
  // first batches of a scene whose points then walk to their cap are not most of its work.
  std::vector<long long> expected(P.n_points * C, 0);
  const auto pilot_start = std::chrono::steady_clock::now();
  learn_tables(engine, P, o, totals);
  totals.pilot_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - pilot_start).count();
  for (int round = 0; round < kMaxRounds; ++round) {
    for (;;) {
      std::vector<long long> count(P.n_points * C);
      bool any = false;
      for (std::size_t i = 0; i < count.size(); ++i) {
        count[i] = std::max<long long>(0, std::min(want[i] - done[i], probed ? launch_batches : 1LL));
        any = any || count[i] > 0;
      }
      if (!any) break;
      for (std::size_t g = 0; g < n_groups; ++g) {
        const std::size_t first = g * kGroup, n_ch = std::min<std::size_t>(kGroup, C - first);
        std::vector<int> base(P.n_points * kGroup, 0), n(P.n_points * kGroup, 0), most(P.n_points, 0);
        int stride = 0;
        for (std::size_t p = 0; p < P.n_points; ++p)
          for (std::size_t c = 0; c < n_ch; ++c) {
            base[p * kGroup + c] = static_cast<int>(done[p * C + first + c]);
            n[p * kGroup + c] = static_cast<int>(count[p * C + first + c]);
            most[p] = std::max(most[p], n[p * kGroup + c]);
            stride = std::max(stride, most[p]);
          }
        if (stride == 0) continue;
        const std::vector<double> out = engine.run(g, base, n, stride, TRUTH_MODE_LEARNED, nullptr);
        for (std::size_t p = 0; p < P.n_points; ++p)
          for (int j = 0; j < most[p]; ++j) {
            const double* item = &out[(p * stride + j) * kStride];
            for (std::size_t c = 0; c < n_ch; ++c) {
              if (j >= n[p * kGroup + c]) continue;
              for (int k = 0; k < kStats; ++k)
                stat(p, first + c, k).merge(static_cast<double>(ppb), item[2 * (kStats * c + k)],
                                            item[2 * (kStats * c + k) + 1]);
            }
            totals.events += item[2 * kStats * kGroup];
            events[p] += item[2 * kStats * kGroup];
            totals.truncated += static_cast<long long>(item[2 * kStats * kGroup + 1]);
            totals.violations += static_cast<long long>(item[2 * kStats * kGroup + 2]);
          }
      }
      for (std::size_t i = 0; i < done.size(); ++i) done[i] += count[i];
      if (!probed) {
        probed = true;
        size_launches(P, o, events, launch_batches, cap);
        for (std::size_t i = 0; i < want.size(); ++i) want[i] = std::max(done[i], std::min(want[i], cap[i / C]));
        if (o.target_relative_se > 0.0)
          for (std::size_t p = 0; p < P.n_points; ++p) {
            bool clip = false;
            const std::vector<long long> w = plan_of(p, clip);
            std::copy(w.begin(), w.end(), expected.begin() + static_cast<std::ptrdiff_t>(p * C));
          }
      }
      if (progress) {
        double traced = 0.0, total = 0.0;
        for (std::size_t p = 0; p < P.n_points; ++p) {
          long long batches = 0;
          for (std::size_t c = 0; c < C; ++c) batches += done[p * C + c];
          const double cost = batches > 0 ? std::max(events[p] / static_cast<double>(batches), 1.0) : 1.0;
          for (std::size_t c = 0; c < C; ++c) {
            traced += cost * static_cast<double>(done[p * C + c]);
            total += cost * static_cast<double>(std::max(want[p * C + c], expected[p * C + c]));
          }
        }
        progress(total > 0.0 ? traced / total : 1.0);
      }
    }
    if (!(o.target_relative_se > 0.0)) break;
    bool more = false;
    for (std::size_t p = 0; p < P.n_points; ++p) {
      bool clip = false;
      const std::vector<long long> w = plan_of(p, clip);
      clipped[p] = clipped[p] || clip;
      for (std::size_t c = 0; c < C; ++c) {
        if (w[c] > want[p * C + c]) {
          want[p * C + c] = w[c];
          more = true;
        }
        expected[p * C + c] = want[p * C + c];
      }
    }
    if (!more) break;
  }
  for (std::size_t p = 0; p < P.n_points; ++p) {
    const std::size_t row = P.point_base + p;
    long long most = 0, traced = 0;
    for (std::size_t c = 0; c < C; ++c) {
      most = std::max(most, done[p * C + c]);
      traced += done[p * C + c];
    }
    r.paths[row] = most * ppb;
    r.at_cap[row] = clipped[p] || (weighted ? traced >= cap[p] * static_cast<long long>(C) : most >= cap[p]);
    totals.walks += traced * ppb;
    for (std::size_t c = 0; c < C; ++c) {
      const std::size_t i = row * C + c;
      r.channel_paths[i] = done[p * C + c] * ppb;
      r.radiance[i] = estimate(p, c).mean;
      r.standard_error[i] = stat(p, c).se();
      if (o.split_orders > 0) {
        r.radiance_low[i] = estimate(p, c, 1).mean;
        r.standard_error_low[i] = stat(p, c, 1).se();
        r.radiance_high[i] = stat(p, c, 2).mean;
        r.standard_error_high[i] = stat(p, c, 2).se();
      }
    }
  }
}

using MakeEngine = std::function<std::unique_ptr<Engine>(const Prepared&)>;

// Every point, in chunks whose view-ray tables stay within kChunkTableBytes.
TruthResult trace_all(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points, const TruthOptions& o,
                      const Progress& progress, const MakeEngine& make_engine) {
  const Spectrum sp = spectrum_of(spec);
  TruthResult r;
  r.lambda_nm = sp.lambda_nm;
  for (double l : r.lambda_nm) {
    if (!spec.spectral) {
      r.channel_names.push_back(l == kLambdaR ? "R" : (l == kLambdaG ? "G" : "B"));
    } else {
      char b[32];
      std::snprintf(b, sizeof b, "%g", l);
      r.channel_names.push_back(b);
    }
  }
  r.points = points.size();
  r.channels = r.lambda_nm.size();
  r.orders = o.orders;
  r.seed = o.seed;
  r.order1 = o.order1 == TruthOptions::Order1::quadrature ? "quadrature" : "walked";
  r.radiance.assign(r.points * r.channels, 0.0);
  r.standard_error.assign(r.points * r.channels, 0.0);
  r.paths.assign(r.points, 0);
  r.channel_paths.assign(r.points * r.channels, 0);
  r.at_cap.assign(r.points, 0);
  if (!o.target_weights.empty() && o.target_weights.size() % r.channels != 0)
    throw InputError(Location{{}, 0, 0, "target_weights"},
                     "rows of " + std::to_string(r.channels) + " weights (one per traced channel)");
  r.split_orders = o.split_orders;
  if (o.split_orders > 0)
    for (auto* v : {&r.radiance_low, &r.standard_error_low, &r.radiance_high, &r.standard_error_high})
      v->assign(r.points * r.channels, 0.0);
  const std::size_t chunk = std::max<std::size_t>(
      1, static_cast<std::size_t>(kChunkTableBytes / (static_cast<double>(r.channels) * kNodes * 2 * sizeof(double))));
  const std::size_t n_chunks = (points.size() + chunk - 1) / chunk;
  Totals totals;
  for (std::size_t k = 0; k < n_chunks; ++k) {
    const std::size_t first = k * chunk, n = std::min(chunk, points.size() - first);
    const std::vector<TruthPoint> part(points.begin() + first, points.begin() + first + n);
    const auto tables_start = std::chrono::steady_clock::now();
    const Prepared P = prepare(spec, part, first, o);
    const auto engine = make_engine(P);
    totals.tables_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - tables_start).count();
    trace_chunk(*engine, P, o, r, totals, [&](double f) {
      if (progress) progress("tracing", (static_cast<double>(k) + f) / static_cast<double>(n_chunks));
    });
  }
  r.mean_events = totals.walks > 0 ? totals.events / static_cast<double>(totals.walks) : 0.0;
  spdlog::debug("truth: tables {:.3f} s, pilot walks {:.3f} s", totals.tables_s, totals.pilot_s);
  r.truncated = totals.truncated;
  if (totals.violations > 0)
    throw JobError("truth: a density exceeded its majorant " + std::to_string(totals.violations) +
                   " times; the estimate would be biased");
  if (totals.truncated > 0)
    spdlog::warn("truth: {} walks stopped after {} events (all orders): their later orders are missing",
                 totals.truncated, TRUTH_MAX_EVENTS);
  for (std::size_t i = 0; i < r.radiance.size(); ++i)
    if (!std::isfinite(r.radiance[i]) || !std::isfinite(r.standard_error[i]))
      throw JobError("truth: non-finite radiance at point " + std::to_string(i / r.channels));
  return r;
}

}  // namespace

TruthMemory truth_memory(std::size_t points, std::size_t channels) {
  const double per_point = static_cast<double>(channels) * kNodes * 2 * sizeof(double);
  const std::size_t chunk = std::min<std::size_t>(
      points, std::max<std::size_t>(1, static_cast<std::size_t>(kChunkTableBytes / per_point)));
  const std::uint64_t tables = static_cast<std::uint64_t>(static_cast<double>(chunk) * per_point) +
                               std::uint64_t{chunk} * (kNodes + TRUTH_POINT_STRIDE) * sizeof(double);
  const std::uint64_t items = std::min<std::uint64_t>(kLaunchItems, std::uint64_t{chunk} * static_cast<std::uint64_t>(kLaunchWalks / TruthOptions{}.paths_per_batch));
  const std::uint64_t out = items * kStride * sizeof(double);
  return {2 * tables + out, tables + out, std::max(tables / 2, out)};
}

TruthResult TruthResult::low_part() const {
  TruthResult r = *this;
  if (split_orders > 0) {
    r.radiance = radiance_low;
    r.standard_error = standard_error_low;
    r.orders = split_orders;
  }
  r.split_orders = 0;
  r.radiance_low.clear();
  r.standard_error_low.clear();
  r.radiance_high.clear();
  r.standard_error_high.clear();
  return r;
}

TruthResult joined(const TruthResult& a, const TruthResult& b) {
  if (a.channels != b.channels || a.lambda_nm != b.lambda_nm || a.orders != b.orders ||
      a.split_orders != b.split_orders)
    throw std::invalid_argument("joining truths of other channels, orders or split");
  TruthResult r = a;
  r.points = a.points + b.points;
  auto append = [](auto& to, const auto& from) { to.insert(to.end(), from.begin(), from.end()); };
  append(r.radiance, b.radiance);
  append(r.standard_error, b.standard_error);
  append(r.paths, b.paths);
  append(r.channel_paths, b.channel_paths);
  append(r.at_cap, b.at_cap);
  append(r.radiance_low, b.radiance_low);
  append(r.standard_error_low, b.standard_error_low);
  append(r.radiance_high, b.radiance_high);
  append(r.standard_error_high, b.standard_error_high);
  double walks_a = 0.0, walks_b = 0.0;
  for (long long n : a.channel_paths) walks_a += static_cast<double>(n);
  for (long long n : b.channel_paths) walks_b += static_cast<double>(n);
  if (walks_a + walks_b > 0.0) r.mean_events = (a.mean_events * walks_a + b.mean_events * walks_b) / (walks_a + walks_b);
  r.truncated = a.truncated + b.truncated;
  r.seconds = a.seconds + b.seconds;
  r.reused = !a.reused.empty() && !b.reused.empty() ? a.reused + " + " + b.reused : "";
  return r;
}

nlohmann::json TruthResult::summary() const {
  long long lo = paths.empty() ? 0 : paths[0], hi = lo, total = 0, walks = 0;
  for (long long n : paths) {
    lo = std::min(lo, n);
    hi = std::max(hi, n);
    total += n;
  }
  for (long long n : channel_paths) walks += n;
  return {{"method", std::string(order1 == "quadrature"
                                     ? "order 1 (single scattering) by adaptive Gauss-Legendre quadrature of the view "
                                       "ray with exact optical depths (relative 1e-6), orders 2 and above by "
                                     : "") +
                         "Monte Carlo path tracing (kernels/atmosphere/path_tracer.cl): view-ray vertex from the "
                         "tabulated optical depth, delta tracking, sun by next-event estimation with ratio "
                         "tracking (at vertices after the first, for points whose sun is low enough for the "
                         "planet's shadow to matter, its expectation along the ray drawn on the ray's sunlit "
                         "part; points with the sun below the horizon first trace pilot walks and keep a learned view-ray "
                         "table and first direction where the pilot predicts a gain), Philox4x32-10 streams per (seed, "
                         "path, point, channel)"},
          {"order1", order1},
          {"wavelengths_nm", lambda_nm},
          {"channels", channel_names},
          {"points", points},
          {"paths_per_point", {{"min", lo}, {"max", hi}, {"total", total}}},  // of each point's most-walked channel
          {"walks", walks},  // over every point and channel: each channel walks its own share of the target
          {"orders", orders == 0 ? nlohmann::json("all") : nlohmann::json(orders)},
          {"split_orders", split_orders == 0 ? nlohmann::json(nullptr) : nlohmann::json(split_orders)},
          {"seed", seed},
          {"mean_events_per_walk", mean_events},
          {"truncated_walks", truncated},
          {"precision", precision},
          {"device", device},
          {"seconds", seconds},
          {"reused", reused.empty() ? nlohmann::json(nullptr) : nlohmann::json(reused)},
          {"units", "W m^-2 sr^-1 nm^-1 per traced wavelength"}};
}

nlohmann::json truth_options_json(const TruthOptions& o) {
  return {{"paths", o.paths},
          {"orders", o.orders},
          {"seed", o.seed},
          {"paths_per_batch", o.paths_per_batch},
          {"target", o.target_relative_se},
          {"max_paths", o.max_paths},
          {"split", o.split_orders},
          {"weights", o.target_weights},
          {"next_sun", static_cast<int>(o.next_sun)},
          {"order1", o.order1 == TruthOptions::Order1::quadrature ? "quadrature" : "walked"},
          {"learn", o.learn},
          {"max_events_per_point", o.max_events_per_point},
          {"low_sun", {{"below_deg", o.low_sun_elevation_deg},
                       {"target", o.low_sun_relative_se},
                       {"max_paths", o.low_sun_max_paths}}}};
}

TruthResult trace_truth(const AtmosphereSpec& spec, cl_util::Device& dev, const std::vector<TruthPoint>& points,
                        const TruthOptions& o, const Progress& progress) {
  check_options(points, o);
  const auto t0 = std::chrono::steady_clock::now();
  TruthResult r = trace_all(spec, points, o, progress,
                            [&](const Prepared& P) { return std::make_unique<DeviceEngine>(dev, P, o); });
  r.precision = dev.info().fp64 ? "float64" : "float32";
  r.device = dev.description();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  spdlog::debug("truth: {} points x {} channels in {:.2f} s ({}), {:.2f} events per walk", r.points, r.channels,
                r.seconds, r.precision, r.mean_events);
  return r;
}

TruthResult trace_truth_reference(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points,
                                  const TruthOptions& o) {
  check_options(points, o);
  const auto t0 = std::chrono::steady_clock::now();
  TruthResult r =
      trace_all(spec, points, o, {}, [&](const Prepared& P) { return std::make_unique<HostEngine>(P, o); });
  r.precision = "float64";
  r.device = "host (C++ double)";
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

}  // namespace specbake::atmosphere
