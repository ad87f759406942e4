#pragma once
// A deterministic nested quadrature, in double precision, of the first two scattering orders
// of the atmosphere model (docs/atmosphere-method.md, "Path-traced truth"), written from the physics
// alone so that it can judge the path tracer where its estimators matter most: twilight, with
// the camera in the planet's shadow. It shares no code with the tracer or the bake: the
// density profiles, phase functions, optical depths, the sun's visibility, the shadow geometry
// and the rules are all its own; only the numbers describing the atmosphere (radii, profile
// layers, coefficients per wavelength, the sun's radius and irradiance) come from the caller.
//
//   L1(x, v) = Σ_j β_j ∫_0^D T(x, y) ρ_j(y) P_j(v·s) E T_sun(y) V(y) dt
//   L2(x, v) = Σ_i β_i ∫_0^D T(x, y) ρ_i(y) ∫_4π P_i(v·ω) L1(y, ω) dω dt   (a black ground)
//
// j, i ∈ {Rayleigh, Mie}; T the transmittance (Rayleigh + Mie extinction + ozone); the sun as
// the model defines it: V = the visible fraction of the disc (a smoothstep of μ_s − cos(horizon)
// over ± sin(horizon) α), T_sun the transmittance to the top towards the disc centre, or along
// the horizon while the centre is below it.
//
// Rules. Every ray (view ray, the inner rays of L1) is cut where its altitude crosses a level
// (every `level_km` and every kink of the profiles), at its tangent point, where it crosses the
// two surfaces bounding the penumbra (k = −1: V = 0, k = +1: V = 1; from
// q + √(|p|² − r_b²) = kα r_b with q = p·s: the quadrics |p|² − q² + 2kα r_b q = r_b²(1 + α²)
// on the side q ≤ kα r_b, crossed where a quadratic in the distance has its roots), and into
// pieces of at most `max_piece_km`; each piece by `nodes`-point Gauss–Legendre, the optical
// depth to every node by the same nodes' integration matrix (exact for polynomials of degree
// nodes − 1). Inner rays stop after their last sunlit piece (a ray that never leaves the shadow
// costs only its roots). The sphere at a point y: elevation e above the local horizontal,
// azimuth φ from the sun's, dω = cos e de dφ, mirror-symmetric about the sun's vertical plane
// (views in that plane only), so φ ∈ [0, π] × 2; elevation intervals graded geometrically away
// from the ground's horizon e_h = −acos(r_b/r) (the inner ray's length jumps there; the light
// into shadowed air arrives within a few degrees above it), azimuth intervals graded towards
// the sun and away from it (Mie peaks), Gauss–Legendre in each. The optical lengths towards the
// sun, a function of (h, μ), come from a table in (ρ, u): ρ = √(r² − r_b²) (the grazing
// column goes as √h near the ground, smoothly in ρ), u ∈ [0, 1] the distance to the top
// rescaled between the zenith's and the horizon's (u = 1: the grazing ray), filled by the same
// ray rule on a finer setting and read by 4 × 4-point Lagrange interpolation.
#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace twilight_quadrature {

struct Layer {
  double width = 0, exp_term = 0, exp_scale = 0, linear = 0, constant = 0;  // km, 1, km⁻¹, km⁻¹, 1
};

constexpr int kChannels = 3;
constexpr int kMaxNodes = 32;  // Gauss–Legendre nodes per ray piece, at most

struct Atmosphere {
  double rb = 0, rt = 0, alpha = 0, g = 0;  // km, km, rad, Mie asymmetry
  Layer rayleigh[2], mie[2], ozone[2];      // layer 0 below its width
  double E[kChannels]{}, beta_r[kChannels]{}, mie_s[kChannels]{}, mie_e[kChannels]{}, ozone_e[kChannels]{};
};

struct Settings {
  int nodes = 6;          // Gauss–Legendre nodes per ray piece
  double level_km = 6.0;  // altitude levels cutting the rays
  double max_piece_km = 100.0;
  int view_nodes = 4;  // the view ray's (outer) pieces
  double view_level_km = 6.0;
  int sphere_nodes = 4;              // per elevation and per azimuth interval
  double first_elevation_deg = 0.1;  // the smallest elevation interval next to the ground's horizon
  int table_h = 160, table_u = 240;  // the sun table's nodes in ρ and u
  // the same rule with half the nodes per piece and per interval (the table is the same: its
  // interpolation error is bounded apart)
  Settings halved() const {
    Settings s = *this;
    s.nodes = nodes / 2;
    s.view_nodes = view_nodes / 2;
    s.sphere_nodes = sphere_nodes / 2;
    return s;
  }
};

using V3 = std::array<double, 3>;
inline double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline V3 axpy(const V3& p, double s, const V3& w) { return {p[0] + s * w[0], p[1] + s * w[1], p[2] + s * w[2]}; }
inline V3 normalized(const V3& a) {
  const double n = std::sqrt(dot(a, a));
  return {a[0] / n, a[1] / n, a[2] / n};
}
inline V3 cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// Gauss–Legendre nodes x, weights w on [−1, 1] (Newton on the three-term recurrence), and the
// integration matrix S[i][j] = ∫_{−1}^{x_i} ℓ_j(x) dx of the Lagrange basis at those nodes
// (ℓ_j = w_j Σ_k (2k + 1)/2 P_k(x_j) P_k, ∫_{−1}^x P_k = (P_{k+1} − P_{k−1})/(2k + 1)).
struct Gauss {
  int n = 0;
  std::vector<double> x, w, S;
  explicit Gauss(int n_) : n(n_), x(n_), w(n_), S(n_ * n_) {
    auto legendre = [&](double z, std::vector<double>& P) {  // P_0 .. P_n
      P.assign(n + 1, 0.0);
      P[0] = 1.0;
      if (n >= 1) P[1] = z;
      for (int k = 2; k <= n; ++k) P[k] = ((2.0 * k - 1.0) * z * P[k - 1] - (k - 1.0) * P[k - 2]) / k;
    };
    std::vector<double> P;
    for (int i = 0; i < n; ++i) {
      double z = std::cos(M_PI * (i + 0.75) / (n + 0.5)), dp = 1.0;
      for (int it = 0; it < 100; ++it) {
        legendre(z, P);
        dp = n * (z * P[n] - P[n - 1]) / (z * z - 1.0);
        const double dz = P[n] / dp;
        z -= dz;
        if (std::fabs(dz) < 1e-16) break;
      }
      legendre(z, P);
      dp = n * (z * P[n] - P[n - 1]) / (z * z - 1.0);
      x[n - 1 - i] = z;  // ascending
      w[n - 1 - i] = 2.0 / ((1.0 - z * z) * dp * dp);
    }
    std::vector<double> Pi, Pj;
    for (int i = 0; i < n; ++i) {
      legendre(x[i], Pi);
      Pi.push_back(0.0);
      for (int j = 0; j < n; ++j) {
        legendre(x[j], Pj);
        double s = 0.5 * (x[i] + 1.0);
        for (int k = 1; k < n; ++k) s += 0.5 * Pj[k] * (Pi[k + 1] - Pi[k - 1]);
        S[i * n + j] = w[j] * s;
      }
    }
  }
};

class Quadrature {
 public:
  // table_from: take its sun table (same atmosphere and table size) instead of building one
  Quadrature(const Atmosphere& a, const Settings& s, const Quadrature* table_from = nullptr)
      : a_(a), s_(s), g_(s.nodes), gv_(s.view_nodes), gs_(s.sphere_nodes) {
    if (s.nodes > kMaxNodes || s.nodes < 1 || s.view_nodes < 1 || s.sphere_nodes < 1 || s.table_h < 4 || s.table_u < 4)
      throw std::invalid_argument("twilight_quadrature: node counts out of range");
    find_levels(s.level_km, levels_);
    find_levels(s.view_level_km, view_levels_);
    if (table_from && table_from->s_.table_h == s.table_h && table_from->s_.table_u == s.table_u)
      table_ = table_from->table_;
    else
      build_sun_table();
  }

  // ---- the model's pieces ----------------------------------------------------------------
  static double density(const Layer* l, double h) {
    const Layer& y = h < l[0].width ? l[0] : l[1];
    return std::clamp(y.exp_term * std::exp(y.exp_scale * h) + y.linear * h + y.constant, 0.0, 1.0);
  }
  static double rayleigh_phase(double c) { return 3.0 / (16.0 * M_PI) * (1.0 + c * c); }
  double mie_phase(double c) const {  // Cornette–Shanks
    const double g = a_.g, k = 3.0 / (8.0 * M_PI) * (1.0 - g * g) / (2.0 + g * g);
    return k * (1.0 + c * c) / std::pow(1.0 + g * g - 2.0 * g * c, 1.5);
  }
  // the visible fraction of the sun's disc at p (smoothstep over the disc at the horizon)
  double visible(const V3& p, const V3& sun) const {
    const double r = std::sqrt(dot(p, p)), mu_s = dot(p, sun) / r;
    const double cos_h = -std::sqrt(std::max(r * r - a_.rb * a_.rb, 0.0)) / r, sin_h = a_.rb / r;
    const double t = std::clamp((mu_s - cos_h + sin_h * a_.alpha) / (2.0 * sin_h * a_.alpha), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
  }

  // Optical lengths (∫ρ_R, ∫ρ_M, ∫ρ_ozone ds, km) from altitude h along cos μ to the top, by
  // the ray rule with the given levels (find_levels) and nodes (no shadow): the exact values the table holds.
  std::array<double, 3> lengths_to_top(double h, double mu, const std::vector<double>& levels, const Gauss& g) const {
    const double r = a_.rb + h;
    const V3 p{0, 0, r}, w{std::sqrt(std::max(1 - mu * mu, 0.0)), 0, mu};
    const double b = r * mu, c_perp = r * r - b * b;
    const double L = -b + std::sqrt(std::max(a_.rt * a_.rt - c_perp, 0.0));
    std::vector<double> cuts{0.0, L};
    add_level_cuts(levels, b, c_perp, L, cuts);
    finish_cuts(cuts, L, 10.0);
    std::array<double, 3> out{};
    for (std::size_t k = 0; k + 1 < cuts.size(); ++k) {
      const double mid = 0.5 * (cuts[k] + cuts[k + 1]), half = 0.5 * (cuts[k + 1] - cuts[k]);
      for (int i = 0; i < g.n; ++i) {
        const V3 q = axpy(p, mid + half * g.x[i], w);
        const double hh = std::max(std::sqrt(dot(q, q)) - a_.rb, 0.0);
        out[0] += g.w[i] * half * density(a_.rayleigh, hh);
        out[1] += g.w[i] * half * density(a_.mie, hh);
        out[2] += g.w[i] * half * density(a_.ozone, hh);
      }
    }
    return out;
  }
  // The sun's optical depth per channel at p (cos of the sun's zenith mu_s there), through the
  // table; along the horizon when the disc centre is below it.
  void sun_depth(double h, double mu_s, double* tau) const {
    const std::array<double, 3> l = table_lookup(h, mu_s);
    for (int c = 0; c < kChannels; ++c) tau[c] = a_.beta_r[c] * l[0] + a_.mie_e[c] * l[1] + a_.ozone_e[c] * l[2];
  }
  std::array<double, 3> table_lookup(double h, double mu_s) const {
    h = std::clamp(h, 0.0, a_.rt - a_.rb);
    const double u = u_of(h, mu_s), r = a_.rb + h;
    const double rho = std::sqrt(std::max(r * r - a_.rb * a_.rb, 0.0)), H = std::sqrt(a_.rt * a_.rt - a_.rb * a_.rb);
    const double fh = rho / H * (s_.table_h - 1), fu = u * (s_.table_u - 1);
    int ih = std::clamp(static_cast<int>(std::floor(fh)) - 1, 0, s_.table_h - 4);
    int iu = std::clamp(static_cast<int>(std::floor(fu)) - 1, 0, s_.table_u - 4);
    double wh[4], wu[4];
    lagrange4(fh - ih, wh);
    lagrange4(fu - iu, wu);
    std::array<double, 3> out{};
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        const double* t = &table_[3 * ((ih + a) * s_.table_u + iu + b)];
        const double ww = wh[a] * wu[b];
        for (int k = 0; k < 3; ++k) out[k] += ww * t[k];
      }
    return out;
  }

  // ---- single scattering along a ray ------------------------------------------------------
  // ∫_0^L T(p, p + sω) ρ_j T_sun V ds for j = Rayleigh (A[c][0]) and Mie (A[c][1]) per channel,
  // L the distance to the ground or the top. Returns false (A = 0) if no point of the ray sees
  // any of the sun.
  bool single(const V3& p, const V3& w, const V3& sun, double A[kChannels][2]) const {
    return single_rule(p, w, sun, A, g_, levels_, s_.max_piece_km);
  }

  // ---- orders 1 and 2 at a view ------------------------------------------------------------
  // Camera at altitude h (inside the atmosphere), view zenith angle, sun zenith angle, the sun's
  // azimuth from the view's 0 or 180° (the mirror symmetry needs the view in the sun's plane).
  struct Result {
    double L1[kChannels]{}, L2[kChannels]{};
  };
  Result orders_1_2(double h, double view_zenith, double sun_zenith, double azimuth) const {
    if (std::fabs(std::sin(azimuth)) > 1e-12)
      throw std::invalid_argument(
          "twilight_quadrature: the view must lie in the sun's vertical plane (azimuth 0 or 180°)");
    const V3 x{0, 0, a_.rb + h}, v{std::sin(view_zenith), 0, std::cos(view_zenith)};
    const V3 sun{std::sin(sun_zenith) * std::cos(azimuth), std::sin(sun_zenith) * std::sin(azimuth),
                 std::cos(sun_zenith)};
    Result out;
    const double nu = dot(v, sun);
    {  // order 1: the view ray's single scattering, on the inner rule
      double A[kChannels][2];
      single(x, v, sun, A);
      for (int c = 0; c < kChannels; ++c)
        out.L1[c] = a_.E[c] * (a_.beta_r[c] * rayleigh_phase(nu) * A[c][0] + a_.mie_s[c] * mie_phase(nu) * A[c][1]);
    }
    // order 2: the view ray (outer rule), the sphere at each of its nodes
    const double b = dot(x, v), c_perp = dot(x, x) - b * b;
    const bool ground = b < 0 && c_perp < a_.rb * a_.rb;
    const double D = ground ? -b - std::sqrt(a_.rb * a_.rb - c_perp) : -b + std::sqrt(a_.rt * a_.rt - c_perp);
    std::vector<double> cuts{0.0, D};
    add_level_cuts(view_levels_, b, c_perp, D, cuts);
    add_shadow_cuts(x, v, sun, D, cuts);
    finish_cuts(cuts, D, s_.max_piece_km);
    double tau0[kChannels]{};
    std::vector<double> sig(gv_.n * kChannels), rho_r(gv_.n), rho_m(gv_.n);
    for (std::size_t k = 0; k + 1 < cuts.size(); ++k) {
      const double mid = 0.5 * (cuts[k] + cuts[k + 1]), half = 0.5 * (cuts[k + 1] - cuts[k]);
      for (int i = 0; i < gv_.n; ++i) {
        const V3 y = axpy(x, mid + half * gv_.x[i], v);
        const double hy = std::sqrt(dot(y, y)) - a_.rb;
        rho_r[i] = density(a_.rayleigh, hy);
        rho_m[i] = density(a_.mie, hy);
        const double rho_o = density(a_.ozone, hy);
        for (int c = 0; c < kChannels; ++c)
          sig[i * kChannels + c] = a_.beta_r[c] * rho_r[i] + a_.mie_e[c] * rho_m[i] + a_.ozone_e[c] * rho_o;
      }
      for (int i = 0; i < gv_.n; ++i) {
        const V3 y = axpy(x, mid + half * gv_.x[i], v);
        double J[kChannels][2];
        sphere(y, v, sun, J);
        for (int c = 0; c < kChannels; ++c) {
          double tau = tau0[c];
          for (int j = 0; j < gv_.n; ++j) tau += half * gv_.S[i * gv_.n + j] * sig[j * kChannels + c];
          out.L2[c] +=
              gv_.w[i] * half * std::exp(-tau) * (a_.beta_r[c] * rho_r[i] * J[c][0] + a_.mie_s[c] * rho_m[i] * J[c][1]);
        }
      }
      for (int c = 0; c < kChannels; ++c)
        for (int j = 0; j < gv_.n; ++j) tau0[c] += half * gv_.w[j] * sig[j * kChannels + c];
    }
    return out;
  }

  // J[c][i] = ∫_4π P_i(v·ω) L1(y, ω) dω, i = Rayleigh, Mie.
  void sphere(const V3& y, const V3& v, const V3& sun, double J[kChannels][2]) const {
    for (int c = 0; c < kChannels; ++c) J[c][0] = J[c][1] = 0.0;
    const V3 z = normalized(y);
    V3 t1{sun[0] - dot(sun, z) * z[0], sun[1] - dot(sun, z) * z[1], sun[2] - dot(sun, z) * z[2]};
    if (!(dot(t1, t1) > 1e-12)) throw std::invalid_argument("twilight_quadrature: the sun at the zenith or nadir");
    t1 = normalized(t1);
    const V3 t2 = cross(z, t1);
    const double r = std::sqrt(dot(y, y));
    const double e_h = -std::acos(std::min(a_.rb / r, 1.0));
    // elevation intervals: geometric from the horizon up and down
    std::vector<double> ecuts{e_h};
    for (double d = s_.first_elevation_deg * M_PI / 180; e_h + d < M_PI / 2; d *= 2) ecuts.push_back(e_h + d);
    ecuts.push_back(M_PI / 2);
    for (double d = s_.first_elevation_deg * M_PI / 180; e_h - d > -M_PI / 2; d *= 2) ecuts.push_back(e_h - d);
    ecuts.push_back(-M_PI / 2);
    std::sort(ecuts.begin(), ecuts.end());
    static const double kPhi[] = {0, 2, 5, 10, 20, 35, 55, 80, 110, 140, 160, 170, 175, 178, 180};
    for (std::size_t ie = 0; ie + 1 < ecuts.size(); ++ie) {
      const double em = 0.5 * (ecuts[ie] + ecuts[ie + 1]), eh = 0.5 * (ecuts[ie + 1] - ecuts[ie]);
      if (!(eh > 0)) continue;
      for (int a = 0; a < gs_.n; ++a) {
        const double e = em + eh * gs_.x[a], we = gs_.w[a] * eh * std::cos(e);
        for (std::size_t ip = 0; ip + 1 < std::size(kPhi); ++ip) {
          const double pm = 0.5 * (kPhi[ip] + kPhi[ip + 1]) * M_PI / 180,
                       ph = 0.5 * (kPhi[ip + 1] - kPhi[ip]) * M_PI / 180;
          for (int b = 0; b < gs_.n; ++b) {
            const double phi = pm + ph * gs_.x[b], wgt = 2.0 * we * gs_.w[b] * ph;  // × 2: the mirror half
            const double ce = std::cos(e), se = std::sin(e), cp = std::cos(phi), sp = std::sin(phi);
            const V3 w{ce * (cp * t1[0] + sp * t2[0]) + se * z[0], ce * (cp * t1[1] + sp * t2[1]) + se * z[1],
                       ce * (cp * t1[2] + sp * t2[2]) + se * z[2]};
            double A[kChannels][2];
            if (!single(y, w, sun, A)) continue;
            const double cs = dot(w, sun), cv = dot(v, w);
            const double pr_s = rayleigh_phase(cs), pm_s = mie_phase(cs), pr_v = rayleigh_phase(cv),
                         pm_v = mie_phase(cv);
            for (int c = 0; c < kChannels; ++c) {
              const double L1 = a_.E[c] * (a_.beta_r[c] * pr_s * A[c][0] + a_.mie_s[c] * pm_s * A[c][1]);
              J[c][0] += wgt * pr_v * L1;
              J[c][1] += wgt * pm_v * L1;
            }
          }
        }
      }
    }
  }

  const Settings& settings() const { return s_; }
  void levels(double step_km, std::vector<double>& out) const { find_levels(step_km, out); }
  const Atmosphere& atmosphere() const { return a_; }

 private:
  // levels: every step_km from 0 to the top, and every kink of the three profiles (layer
  // boundaries; where a layer's value crosses its clamp to [0, 1], found by scanning each
  // layer at 1 m and bisecting)
  void find_levels(double step_km, std::vector<double>& out) const {
    const double top = a_.rt - a_.rb;
    out.clear();
    for (double h = step_km; h < top - 1e-9; h += step_km) out.push_back(h);
    for (const Layer* prof : {a_.rayleigh, a_.mie, a_.ozone}) {
      if (prof[0].width > 0 && prof[0].width < top) out.push_back(prof[0].width);
      for (int l = 0; l < 2; ++l) {
        auto raw = [&](double h) {
          return prof[l].exp_term * std::exp(prof[l].exp_scale * h) + prof[l].linear * h + prof[l].constant;
        };
        const double lo = l == 0 ? 0.0 : std::max(prof[0].width, 0.0), hi = l == 0 ? std::min(prof[0].width, top) : top;
        for (double bound : {0.0, 1.0}) {
          const int n = static_cast<int>((hi - lo) / 1e-3);
          for (int i = 0; i < n; ++i) {
            double h0 = lo + (hi - lo) * i / n, h1 = lo + (hi - lo) * (i + 1) / n;
            if ((raw(h0) - bound) * (raw(h1) - bound) < 0) {
              for (int it = 0; it < 60; ++it) {
                const double hm = 0.5 * (h0 + h1);
                ((raw(h0) - bound) * (raw(hm) - bound) <= 0 ? h1 : h0) = hm;
              }
              out.push_back(0.5 * (h0 + h1));
            }
          }
        }
      }
    }
    std::sort(out.begin(), out.end());
  }
  // a ray p + sω with b = p·ω, c_perp = |p|² − b²: where it crosses the levels' spheres in (0, L)
  void add_level_cuts(const std::vector<double>& levels, double b, double c_perp, double L,
                      std::vector<double>& cuts) const {
    if (b < 0 && -b < L) cuts.push_back(-b);  // tangent point
    for (double lev : levels) {
      const double R = a_.rb + lev, d2 = R * R - c_perp;
      if (!(d2 > 0)) continue;
      const double d = std::sqrt(d2);
      for (double s : {-b - d, -b + d})
        if (s > 0 && s < L) cuts.push_back(s);
    }
  }
  // where the ray crosses the penumbra's two bounding surfaces (k = −1: V = 0, k = +1: V = 1)
  void add_shadow_cuts(const V3& p, const V3& w, const V3& sun, double L, std::vector<double>& cuts) const {
    const double a0 = dot(w, sun), b0 = dot(p, sun), b = dot(p, w), r2 = dot(p, p), rb = a_.rb, al = a_.alpha;
    for (int k : {-1, 1}) {
      const double A = 1.0 - a0 * a0, B = b - b0 * a0 + k * al * rb * a0;
      const double C = r2 - b0 * b0 + 2.0 * k * al * rb * b0 - rb * rb * (1.0 + al * al);
      double roots[2];
      int n = 0;
      if (A > 1e-15) {
        const double disc = B * B - A * C;
        if (disc >= 0) {
          const double sq = std::sqrt(disc), q = -(B + (B >= 0 ? sq : -sq));  // stable roots
          roots[n++] = q / A;
          if (q != 0) roots[n++] = C / q;
        }
      } else if (B != 0) {
        roots[n++] = -C / (2.0 * B);
      }
      for (int i = 0; i < n; ++i) {
        const double s = roots[i];
        if (s > 0 && s < L && b0 + s * a0 <= k * al * rb + 1e-9) cuts.push_back(s);
      }
    }
  }
  // sort, drop duplicates, split pieces longer than max_piece
  static void finish_cuts(std::vector<double>& cuts, double L, double max_piece) {
    std::sort(cuts.begin(), cuts.end());
    thread_local std::vector<double> out;
    out.assign(1, cuts[0]);
    for (std::size_t k = 1; k < cuts.size(); ++k) {
      const double len = cuts[k] - out.back();
      if (!(len > 1e-9 * std::max(1.0, L))) continue;
      const int n = static_cast<int>(std::ceil(len / max_piece));
      const double start = out.back();
      for (int i = 1; i <= n; ++i) out.push_back(i == n ? cuts[k] : start + len * i / n);
    }
    cuts.swap(out);
  }

  bool single_rule(const V3& p, const V3& w, const V3& sun, double A[kChannels][2], const Gauss& g,
                   const std::vector<double>& levels, double max_piece) const {
    for (int c = 0; c < kChannels; ++c) A[c][0] = A[c][1] = 0.0;
    const double b = dot(p, w), c_perp = dot(p, p) - b * b;
    const bool ground = b < 0 && c_perp < a_.rb * a_.rb;
    const double L =
        ground ? -b - std::sqrt(a_.rb * a_.rb - c_perp) : -b + std::sqrt(std::max(a_.rt * a_.rt - c_perp, 0.0));
    if (!(L > 0)) return false;
    // the penumbra's crossings first: the sunlit stretches, and the end of the last
    thread_local std::vector<double> cuts, all;
    cuts.assign({0.0, L});
    add_shadow_cuts(p, w, sun, L, cuts);
    std::sort(cuts.begin(), cuts.end());
    double lit_end = -1;
    for (std::size_t k = 0; k + 1 < cuts.size(); ++k)
      if (cuts[k + 1] > cuts[k] && visible(axpy(p, 0.5 * (cuts[k] + cuts[k + 1]), w), sun) > 0) lit_end = cuts[k + 1];
    if (lit_end < 0) return false;
    all.clear();
    for (double s : cuts)
      if (s <= lit_end) all.push_back(s);
    add_level_cuts(levels, b, c_perp, lit_end, all);
    finish_cuts(all, lit_end, max_piece);
    double tau0[kChannels]{};
    double sig[kMaxNodes * kChannels], rr[kMaxNodes], rm[kMaxNodes], hh[kMaxNodes];
    for (std::size_t k = 0; k + 1 < all.size(); ++k) {
      const double mid = 0.5 * (all[k] + all[k + 1]), half = 0.5 * (all[k + 1] - all[k]);
      for (int i = 0; i < g.n; ++i) {
        const V3 q = axpy(p, mid + half * g.x[i], w);
        hh[i] = std::max(std::sqrt(dot(q, q)) - a_.rb, 0.0);
        rr[i] = density(a_.rayleigh, hh[i]);
        rm[i] = density(a_.mie, hh[i]);
        const double ro = density(a_.ozone, hh[i]);
        for (int c = 0; c < kChannels; ++c)
          sig[i * kChannels + c] = a_.beta_r[c] * rr[i] + a_.mie_e[c] * rm[i] + a_.ozone_e[c] * ro;
      }
      if (visible(axpy(p, mid, w), sun) > 0) {  // a sunlit piece (no crossing inside: lit throughout)
        for (int i = 0; i < g.n; ++i) {
          const V3 q = axpy(p, mid + half * g.x[i], w);
          const double V = visible(q, sun);
          if (!(V > 0)) continue;
          double ts[kChannels];
          sun_depth(hh[i], dot(q, sun) / std::sqrt(dot(q, q)), ts);
          for (int c = 0; c < kChannels; ++c) {
            double tau = tau0[c] + ts[c];
            for (int j = 0; j < g.n; ++j) tau += half * g.S[i * g.n + j] * sig[j * kChannels + c];
            const double f = g.w[i] * half * std::exp(-tau) * V;
            A[c][0] += f * rr[i];
            A[c][1] += f * rm[i];
          }
        }
      }
      for (int c = 0; c < kChannels; ++c)
        for (int j = 0; j < g.n; ++j) tau0[c] += half * g.w[j] * sig[j * kChannels + c];
    }
    return true;
  }

  // u: the distance to the top along μ (clamped to the horizon's), rescaled between the
  // zenith's (u = 0) and the grazing ray's (u = 1)
  double u_of(double h, double mu_s) const {
    const double r = a_.rb + h, rho = std::sqrt(std::max(r * r - a_.rb * a_.rb, 0.0));
    const double H = std::sqrt(a_.rt * a_.rt - a_.rb * a_.rb);
    const double mu = std::max(mu_s, -rho / r);
    const double d = -r * mu + std::sqrt(std::max(r * r * mu * mu + a_.rt * a_.rt - r * r, 0.0));
    const double d_min = a_.rt - r, d_max = rho + H;
    return d_max > d_min ? std::clamp((d - d_min) / (d_max - d_min), 0.0, 1.0) : 0.0;
  }
  double mu_of(double h, double u) const {  // the inverse: μ of the ray of length d from radius r
    const double r = a_.rb + h, rho = std::sqrt(std::max(r * r - a_.rb * a_.rb, 0.0));
    const double H = std::sqrt(a_.rt * a_.rt - a_.rb * a_.rb);
    const double d_min = a_.rt - r, d_max = rho + H, d = d_min + u * (d_max - d_min);
    if (!(d > 0)) return 1.0;
    return std::clamp((a_.rt * a_.rt - r * r - d * d) / (2.0 * r * d), -1.0, 1.0);
  }
  static void lagrange4(double t, double* w) {  // nodes 0, 1, 2, 3
    w[0] = -(t - 1) * (t - 2) * (t - 3) / 6.0;
    w[1] = t * (t - 2) * (t - 3) / 2.0;
    w[2] = -t * (t - 1) * (t - 3) / 2.0;
    w[3] = t * (t - 1) * (t - 2) / 6.0;
  }
  void build_sun_table() {
    const Gauss fine(8);
    std::vector<double> levels;
    find_levels(1.0, levels);
    table_.assign(3 * s_.table_h * s_.table_u, 0.0);
    const double H = std::sqrt(a_.rt * a_.rt - a_.rb * a_.rb);
    for (int i = 0; i < s_.table_h; ++i) {  // rows uniform in ρ = √(r² − r_b²): the columns are smooth in ρ, not in h
      const double rho = H * i / (s_.table_h - 1), h = std::sqrt(rho * rho + a_.rb * a_.rb) - a_.rb;
      for (int j = 0; j < s_.table_u; ++j) {
        const double u = static_cast<double>(j) / (s_.table_u - 1);
        const auto l = lengths_to_top(h, mu_of(h, u), levels, fine);
        for (int k = 0; k < 3; ++k) table_[3 * (i * s_.table_u + j) + k] = l[k];
      }
    }
  }

  Atmosphere a_;
  Settings s_;
  Gauss g_, gv_, gs_;
  std::vector<double> levels_, view_levels_, table_;
};

}  // namespace twilight_quadrature
