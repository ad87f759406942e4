#pragma once
// The scene of an atmosphere job (`scene:`, AtmosphereScene) as points: the views the scene check
// path-traces and judges, and the `specbake truth` command's scene point sets.
#include <vector>

#include <nlohmann/json.hpp>

#include "kinds/atmosphere/model/spec.hpp"

namespace specbake::atmosphere {

// One view: a camera at altitude_km above the ground (above the top of the atmosphere: the
// view enters it, as GetSkyRadiance does), looking at view_zenith_deg from the local zenith,
// the sun at sun_zenith_deg, view_sun_azimuth_deg between the view's and the sun's azimuths.
struct TruthPoint {
  double altitude_km = 0.0;
  double view_zenith_deg = 0.0;
  double sun_zenith_deg = 0.0;
  double view_sun_azimuth_deg = 0.0;
};

// A deterministic low-discrepancy point set (the Halton sequence in bases 2, 3, 5, 7, from its
// second point, or from point `first` + 1): altitude uniform in [min, max], sun elevation uniform in [min, max], view directions uniform in solid angle
// over the sky (above the planet's horizon; for cameras above the atmosphere, the part of it
// that crosses the atmosphere), the ground, or all, within the view elevation range; view–sun
// azimuth uniform in its range ([0, 180] by default). InputError when the ranges leave no view direction.
enum class TruthViews { sky, ground, all };
struct TruthScene {
  double altitude_min_km = 0.0, altitude_max_km = 0.0;
  double sun_elevation_min_deg = 0.0, sun_elevation_max_deg = 90.0;
  TruthViews views = TruthViews::sky;
  int count = 256;
  int first = 0;  // index of the first Halton point: sets from disjoint ranges are independent point sets
  // View elevations above the camera's horizontal plane (not the dipped horizon) the views are
  // limited to, on top of `views` (e.g. [0, 2] for rays grazing the horizon from the ground).
  double view_elevation_min_deg = -90.0, view_elevation_max_deg = 90.0;
  double view_sun_azimuth_min_deg = 0.0, view_sun_azimuth_max_deg = 180.0;  // within [0, 180]
};
std::vector<TruthPoint> scene_points(const TruthScene& scene, const AtmosphereSpec& spec);

// The scene's point set (Halton points first + 1 ...; `first` > 0 gives an independent set).
std::vector<TruthPoint> scene_points_of(const AtmosphereSpec& spec, int first = 0);

// `views` of a scene by name (sky, ground, all), and the scene as the config normalises it and
// the record reports it.
const char* views_name(int views);
nlohmann::json scene_json(const AtmosphereScene& scene);

}  // namespace specbake::atmosphere
