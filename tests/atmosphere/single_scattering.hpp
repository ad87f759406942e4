#pragma once
// An independent single-scattering quadrature of the atmosphere model (3D vectors, composite
// Simpson), the ground truth of the path tracer's first order in tests.
#include <algorithm>
#include <array>
#include <cmath>

#include "kinds/atmosphere/model/model.hpp"
#include "kinds/atmosphere/truth/truth.hpp"
#include "kinds/atmosphere/truth/truth_reference.hpp"

namespace specbake::atmosphere::quadrature {

// ---- an independent single-scattering quadrature (3D vectors, composite Simpson) ----------
// It shares with the tracer only the model's definitions (profiles, phase functions,
// coefficients); geometry, transmittance and integration are its own.
struct Medium {
  ref3::AtmosphereParameters a;
  Channels ch;
  explicit Medium(const AtmosphereSpec& s)
      : a(ref3::make_parameters(model_of(s), channels_at(s, {kLambdaR, kLambdaG, kLambdaB}))),
        ch(channels_at(s, {kLambdaR, kLambdaG, kLambdaB})) {}
  double altitude(const double* x) const { return std::sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - a.bottom_radius; }
  double sigma_t(int c, const double* x) const {
    const double h = altitude(x);
    return ch.rayleigh_scattering[c] * ref3::profile_density(&a.rayleigh_density, h) +
           ch.mie_extinction[c] * ref3::profile_density(&a.mie_density, h) +
           ch.absorption_extinction[c] * ref3::profile_density(&a.absorption_density, h);
  }
  // distance along unit d from x to the far (exit) root of the sphere of radius R, or -1
  static double exit_sphere(const double* x, const double* d, double R) {
    const double b = x[0] * d[0] + x[1] * d[1] + x[2] * d[2], c = x[0] * x[0] + x[1] * x[1] + x[2] * x[2] - R * R;
    const double disc = b * b - c;
    return disc < 0 ? -1.0 : -b + std::sqrt(disc);
  }
  // distance to the near root ahead (entering or hitting the sphere), or -1
  static double hit_sphere(const double* x, const double* d, double R) {
    const double b = x[0] * d[0] + x[1] * d[1] + x[2] * d[2], c = x[0] * x[0] + x[1] * x[1] + x[2] * x[2] - R * R;
    const double disc = b * b - c;
    if (disc < 0) return -1.0;
    const double s = -b - std::sqrt(disc);
    return s > 0 ? s : -1.0;
  }
  // ∫ f(x + s d) ds over [0, len], composite Simpson with n (even) intervals
  template <class F>
  static double simpson(const double* x, const double* d, double len, int n, F&& f) {
    double sum = 0.0;
    for (int i = 0; i <= n; ++i) {
      const double s = len * i / n, p[3] = {x[0] + s * d[0], x[1] + s * d[1], x[2] + s * d[2]};
      sum += (i == 0 || i == n ? 1.0 : (i % 2 ? 4.0 : 2.0)) * f(p);
    }
    return sum * len / (3.0 * n);
  }
  double depth(int c, const double* x, const double* d, double len, int n) const {
    return simpson(x, d, len, n, [&](const double* p) { return sigma_t(c, p); });
  }
  // The camera, view and sun of a point (camera moved into the atmosphere), and the view
  // ray's length.
  struct Ray {
    double x[3], v[3], s[3], length;
  };
  Ray ray(const TruthPoint& p) const {
    const double tv = p.view_zenith_deg * M_PI / 180, ts = p.sun_zenith_deg * M_PI / 180,
                 az = p.view_sun_azimuth_deg * M_PI / 180;
    Ray r{{0, 0, a.bottom_radius + p.altitude_km},
          {std::sin(tv), 0, std::cos(tv)},
          {std::sin(ts) * std::cos(az), std::sin(ts) * std::sin(az), std::cos(ts)},
          0.0};
    if (p.altitude_km > a.top_radius - a.bottom_radius) {
      const double e = hit_sphere(r.x, r.v, a.top_radius);
      for (int k = 0; k < 3; ++k) r.x[k] += e * r.v[k];
    }
    const double g = hit_sphere(r.x, r.v, a.bottom_radius);
    r.length = g > 0 ? g : exit_sphere(r.x, r.v, a.top_radius);
    return r;
  }
};

// Single scattering at a point by composite Simpson: n intervals along the view ray (optical
// depth accumulated by Simpson on each interval), m along each sun ray. The sun as the model
// defines it (atmosphere.cl): weighted by the visible fraction of its disc above the local
// horizon (sun_visible_fraction), its transmittance that of the ray towards the disc centre,
// or, with the centre below the horizon, of the ray grazing the horizon in the sun's vertical
// plane. In twilight the integrand has a steep step (the disc's 0.27° at the shadow's edge):
// callers bound the rule's error by its change from n/2, m/2.
std::array<double, 3> single_scattering_quadrature(const Medium& M, const TruthPoint& p, int n, int m) {
  const Medium::Ray R = M.ray(p);
  const double nu = R.v[0] * R.s[0] + R.v[1] * R.s[1] + R.v[2] * R.s[2];
  const double rb = M.a.bottom_radius, rt = M.a.top_radius;
  std::array<double, 3> out{};
  for (int c = 0; c < 3; ++c) {
    const double pr = ref3::rayleigh_phase(nu), pm = ref3::mie_phase(M.a.mie_g, nu);
    auto f = [&](double t, double tau) {
      const double y[3] = {R.x[0] + t * R.v[0], R.x[1] + t * R.v[1], R.x[2] + t * R.v[2]};
      const double r = std::sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]), h = r - rb;
      const double mu_s = (y[0] * R.s[0] + y[1] * R.s[1] + y[2] * R.s[2]) / r;
      const double visible = ref3::sun_visible_fraction(&M.a, h, std::clamp(mu_s, -1.0, 1.0));
      if (!(visible > 0.0)) return 0.0;
      const double sr = M.ch.rayleigh_scattering[c] * ref3::profile_density(&M.a.rayleigh_density, h);
      const double sm = M.ch.mie_scattering[c] * ref3::profile_density(&M.a.mie_density, h);
      // towards the disc centre, or along the horizon below it
      const double mu_h = -std::sqrt(std::max(0.0, 1 - rb * rb / (r * r)));
      double d[3] = {R.s[0], R.s[1], R.s[2]};
      if (mu_s < mu_h) {
        double t[3] = {R.s[0] - mu_s * y[0] / r, R.s[1] - mu_s * y[1] / r, R.s[2] - mu_s * y[2] / r};
        const double tn = std::sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
        const double sin_h = std::sqrt(1 - mu_h * mu_h);
        for (int k = 0; k < 3; ++k) d[k] = sin_h * t[k] / tn + mu_h * y[k] / r;
      }
      const double t_sun = std::exp(-M.depth(c, y, d, Medium::exit_sphere(y, d, rt), m));
      return std::exp(-tau) * (sr * pr + sm * pm) * M.ch.solar_irradiance[c] * t_sun * visible;
    };
    double tau = 0.0, sum = 0.0, f0 = f(0.0, 0.0);
    const double dt = R.length / n;
    for (int i = 0; i < n; ++i) {
      const double t0 = i * dt;
      const double y0[3] = {R.x[0] + t0 * R.v[0], R.x[1] + t0 * R.v[1], R.x[2] + t0 * R.v[2]};
      const double fm = f(t0 + 0.5 * dt, tau + M.depth(c, y0, R.v, 0.5 * dt, 2));
      const double tau1 = tau + M.depth(c, y0, R.v, dt, 2);
      const double f1 = f(t0 + dt, tau1);
      sum += dt / 6.0 * (f0 + 4.0 * fm + f1);
      tau = tau1;
      f0 = f1;
    }
    out[c] = sum;
  }
  return out;
}

}  // namespace specbake::atmosphere::quadrature
