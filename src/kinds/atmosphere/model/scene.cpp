#include "kinds/atmosphere/model/scene.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/errors.hpp"

namespace specbake::atmosphere {

using nlohmann::json;

std::vector<TruthPoint> scene_points(const TruthScene& s, const AtmosphereSpec& spec) {
  const Location at{{}, 0, 0, "scene"};
  if (!(s.altitude_min_km >= 0.0 && s.altitude_max_km >= s.altitude_min_km && std::isfinite(s.altitude_max_km)))
    throw InputError(at, "0 <= altitude min <= altitude max (km)");
  if (!(s.sun_elevation_min_deg >= -90.0 && s.sun_elevation_max_deg <= 90.0 &&
        s.sun_elevation_max_deg >= s.sun_elevation_min_deg))
    throw InputError(at, "-90 <= sun elevation min <= sun elevation max <= 90 (degrees)");
  if (!(s.view_elevation_min_deg >= -90.0 && s.view_elevation_max_deg <= 90.0 &&
        s.view_elevation_min_deg <= s.view_elevation_max_deg))
    throw InputError(at, "-90 <= view elevation min <= view elevation max <= 90 (degrees)");
  if (!(s.view_sun_azimuth_min_deg >= 0.0 && s.view_sun_azimuth_max_deg <= 180.0 &&
        s.view_sun_azimuth_min_deg <= s.view_sun_azimuth_max_deg))
    throw InputError(at, "0 <= view-sun azimuth min <= max <= 180 (degrees)");
  if (s.count < 1 || s.first < 0) throw InputError(at, "a point count >= 1 and a first index >= 0");
  // Halton: coordinate k of point i is the radical inverse of i + 1 in the k-th prime base
  auto radical_inverse = [](int i, int base) {
    double f = 1.0, r = 0.0;
    for (; i > 0; i /= base) {
      f /= base;
      r += f * (i % base);
    }
    return r;
  };
  const int bases[4] = {2, 3, 5, 7};
  const double rb = spec.bottom_radius_km, rt = spec.top_radius_km;
  std::vector<TruthPoint> out;
  for (int i = 0; i < s.count; ++i) {
    double u[4];
    for (int k = 0; k < 4; ++k) u[k] = radical_inverse(s.first + i + 1, bases[k]);
    TruthPoint p;
    p.altitude_km = s.altitude_min_km + u[0] * (s.altitude_max_km - s.altitude_min_km);
    p.sun_zenith_deg = 90.0 - (s.sun_elevation_min_deg + u[1] * (s.sun_elevation_max_deg - s.sun_elevation_min_deg));
    const double r = rb + p.altitude_km;
    const double mu_horizon = -std::sqrt(std::max(0.0, 1.0 - (rb / r) * (rb / r)));
    const double mu_sky_max = r >= rt ? -std::sqrt(std::max(0.0, 1.0 - (rt / r) * (rt / r))) : 1.0;
    double lo = -1.0, hi = mu_sky_max;
    if (s.views == TruthViews::sky) lo = mu_horizon;
    if (s.views == TruthViews::ground) hi = mu_horizon;
    lo = std::max(lo, std::sin(s.view_elevation_min_deg * M_PI / 180.0));
    hi = std::min(hi, std::sin(s.view_elevation_max_deg * M_PI / 180.0));
    if (!(lo <= hi))
      throw InputError(at, "view directions in both the views (" +
                               std::string(s.views == TruthViews::sky ? "sky" : s.views == TruthViews::ground ? "ground" : "all") +
                               ") and the view elevation range from a camera at " + std::to_string(p.altitude_km) +
                               " km");
    const double mu = hi - u[2] * (hi - lo);
    p.view_zenith_deg = std::acos(std::clamp(mu, -1.0, 1.0)) * 180.0 / M_PI;
    p.view_sun_azimuth_deg = s.view_sun_azimuth_min_deg + u[3] * (s.view_sun_azimuth_max_deg - s.view_sun_azimuth_min_deg);
    out.push_back(p);
  }
  return out;
}

std::vector<TruthPoint> scene_points_of(const AtmosphereSpec& spec, int first) {
  const AtmosphereScene& sc = spec.scene;
  TruthScene scene;
  scene.altitude_min_km = sc.camera_altitude_min_km;
  scene.altitude_max_km = sc.camera_altitude_max_km;
  scene.sun_elevation_min_deg = sc.sun_elevation_min_deg;
  scene.sun_elevation_max_deg = sc.sun_elevation_max_deg;
  scene.views = sc.views == 0 ? TruthViews::sky : sc.views == 1 ? TruthViews::ground : TruthViews::all;
  scene.view_elevation_min_deg = sc.view_elevation_min_deg;
  scene.view_elevation_max_deg = sc.view_elevation_max_deg;
  scene.view_sun_azimuth_min_deg = sc.view_sun_azimuth_min_deg;
  scene.view_sun_azimuth_max_deg = sc.view_sun_azimuth_max_deg;
  scene.count = sc.points;
  scene.first = first;
  return scene_points(scene, spec);
}

const char* views_name(int v) { return v == 0 ? "sky" : v == 1 ? "ground" : "all"; }

json scene_json(const AtmosphereScene& sc) {
  if (!sc.check) return "none";
  json j = {{"camera_altitude_km", {sc.camera_altitude_min_km, sc.camera_altitude_max_km}},
            {"sun_elevation_deg", {sc.sun_elevation_min_deg, sc.sun_elevation_max_deg}},
            {"views", views_name(sc.views)},
            {"view_elevation_deg", {sc.view_elevation_min_deg, sc.view_elevation_max_deg}},
            {"view_sun_azimuth_deg", {sc.view_sun_azimuth_min_deg, sc.view_sun_azimuth_max_deg}},
            {"points", sc.points},
            {"relative_se", sc.relative_se},
            {"seed", sc.seed}};
  if (sc.tolerance_de2000) j["tolerance_de2000"] = *sc.tolerance_de2000;
  if (sc.tolerance_relative) j["tolerance_relative"] = *sc.tolerance_relative;
  j["exposure"] = sc.exposure_ev100 ? json{{"ev100", *sc.exposure_ev100}} : json("per-view");
  return j;
}

}  // namespace specbake::atmosphere
