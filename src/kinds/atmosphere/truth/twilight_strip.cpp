#include "kinds/atmosphere/truth/twilight_strip.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "core/colour_space.hpp"
#include "core/hash.hpp"
#include "io/label.hpp"
#include "io/png.hpp"
#include "kinds/atmosphere/bake/bake.hpp"
#include "kinds/atmosphere/model/model.hpp"
#include "kinds/atmosphere/truth/scene_check.hpp"
#include "kinds/atmosphere/truth/truth.hpp"

namespace specbake::atmosphere {

using nlohmann::json;

namespace {

constexpr double kLowestSunDeg = -12.0, kHighestSunDeg = 10.0, kTopViewDeg = 40.0;
constexpr int kRows = 12;
// The strip's walks: the scene check's, to this target and an eighth of its walk cap (a preview:
// its figures carry their own standard error in the record).
constexpr double kStripRelativeSe = 0.03;
constexpr long long kStripCapDivisor = 8;
// The strip's views, towards the sun from the horizon up, are the scene's hardest: their truth
// costs ~1.9× what truth_seconds' per-point model gives for a scene point of the same sun
// (measured: a sun −10…5° scene's strip traced in 17.4 s on the 2-core CPU, modelled 9.0 s).
constexpr double kStripViewsCost = 1.9;
constexpr std::uint64_t kStripSeedOffset = 0x5851f42d4c957f2dULL;
constexpr double kMidGrey = 0.18;  // the exposed luminance of a column's mean

// View elevation of row j (0 at the top): ((j' + 0.5) / rows)² of 40°, j' counted from the
// bottom — rows packed towards the horizon, where the twilight glow lies.
double row_elevation_deg(int j) {
  const double u = (kRows - 1 - j + 0.5) / kRows;
  return kTopViewDeg * u * u;
}

// CIEDE2000 → colour: black at 0, green at 1, yellow at 2, red from 5; grey where undefined.
std::array<std::uint8_t, 3> error_colour(double de) {
  if (!std::isfinite(de)) return {80, 80, 80};
  struct Stop {
    double de, r, g, b;
  };
  const Stop stops[] = {{0, 0, 0, 0}, {1, 0, 150, 0}, {2, 230, 220, 0}, {5, 220, 0, 0}};
  if (de >= 5) return {220, 0, 0};
  for (int i = 0; i < 3; ++i)
    if (de <= stops[i + 1].de) {
      const double f = (de - stops[i].de) / (stops[i + 1].de - stops[i].de);
      auto mix = [&](double a, double b) { return static_cast<std::uint8_t>(std::lround(a + (b - a) * f)); };
      return {mix(stops[i].r, stops[i + 1].r), mix(stops[i].g, stops[i + 1].g), mix(stops[i].b, stops[i + 1].b)};
    }
  return {220, 0, 0};
}

// The strip's views, [row][column] with row 0 at the top, and its lowest sun.
std::vector<TruthPoint> strip_points(const AtmosphereSpec& spec, double* lowest_out, int* columns_out) {
  const double lowest = std::max(kLowestSunDeg, std::ceil(90.0 - spec.max_sun_zenith_deg));
  const int columns = static_cast<int>(std::lround(kHighestSunDeg - lowest)) + 1;
  std::vector<TruthPoint> points;
  for (int j = 0; j < kRows; ++j)
    for (int i = 0; i < columns; ++i)
      points.push_back({spec.scene.camera_altitude_min_km, 90.0 - row_elevation_deg(j), 90.0 - (lowest + i), 0.0});
  if (lowest_out) *lowest_out = lowest;
  if (columns_out) *columns_out = columns;
  return points;
}

}  // namespace

double twilight_strip_seconds(const AtmosphereSpec& spec) {
  if (!wants_twilight_strip(spec)) return 0.0;
  return kStripViewsCost * truth_seconds(spec, strip_points(spec, nullptr, nullptr), false, 1.0 / kStripCapDivisor,
                                         false);
}

bool wants_twilight_strip(const AtmosphereSpec& spec) {
  return spec.scene.check && spec.preview_size > 0 && spec.scene.sun_elevation_min_deg < kDeepTwilightSunDeg;
}

TwilightStrip twilight_strip(const AtmosphereSpec& spec, const Luts& luts, cl_util::Device& dev, Memo& keep,
                             const Progress& progress) {
  double lowest = 0.0;
  int columns = 0;
  const std::vector<TruthPoint> points = strip_points(spec, &lowest, &columns);
  const double altitude = spec.scene.camera_altitude_min_km;

  TruthOptions o = scene_truth_options(spec, spec.scene.seed + kStripSeedOffset);
  o.target_relative_se = std::max(o.target_relative_se, kStripRelativeSe);
  const long long cap = std::max(o.paths, o.max_paths / kStripCapDivisor);
  o.max_events_per_point *= static_cast<double>(cap) / static_cast<double>(o.max_paths);  // its events a walk
  o.max_paths = cap;
  o.low_sun_relative_se = 0.0;  // one relaxed target and cap for every column, twilight or not
  o.low_sun_max_paths = 0;
  const std::string key = truth_key(spec, "twilight-strip", o, points, dev);
  const auto truth = keep.kept<TruthResult>(
      key, [&] { return trace_truth(spec, dev, points, o, progress); }, truth_result_bytes,
      [&](const std::string& bytes) { return truth_result_from_bytes(bytes); });

  // displayed colours (linear sRGB luminance), as the scene check's
  const std::array<double, 3> k = spectrum_of(spec).sky_radiance_to_luminance;
  const TruthBundleValues tv = to_bundle_units(spec, *truth);
  const std::vector<Vec3> lut = lut_sky_radiance(luts, points);
  const std::size_t n = points.size();
  std::vector<Vec3> shown_lut(n), shown_truth(n), shown_se(n);
  for (std::size_t q = 0; q < n; ++q)
    for (int c = 0; c < 3; ++c) {
      shown_lut[q][c] = lut[q][c] * k[c];
      shown_truth[q][c] = tv.radiance[3 * q + c] * k[c];
      shown_se[q][c] = tv.standard_error[3 * q + c] * k[c];
    }
  // each column exposed at its truth's mean luminance
  std::vector<double> column_y(columns, 0.0);
  for (int i = 0; i < columns; ++i) {
    for (int j = 0; j < kRows; ++j) column_y[i] += srgb_luminance(shown_truth[j * columns + i]) / kRows;
  }
  std::vector<double> de(n), de_se(n);
  for (int j = 0; j < kRows; ++j)
    for (int i = 0; i < columns; ++i) {
      const std::size_t q = static_cast<std::size_t>(j) * columns + i;
      const double y = column_y[i] > 0.0 ? column_y[i] : std::nan("");
      de[q] = displayed_de2000(shown_lut[q], shown_truth[q], y);
      Vec3 plus = shown_truth[q];
      for (int c = 0; c < 3; ++c) plus[c] += shown_se[q][c];
      de_se[q] = displayed_de2000(plus, shown_truth[q], y);  // the truth's own se, as a colour difference
    }

  // The scene's suns: columns outside them (the strip always spans −12…+10°) are hatched in every
  // panel, with a white line at the scene's edge: the bake has no sky-view table there, and the
  // record's bands say what lies inside apart (de2000_in_scene).
  const double scene_lo = spec.scene.sun_elevation_min_deg, scene_hi = spec.scene.sun_elevation_max_deg;
  auto in_scene = [&](int i) {
    const double sun = lowest + i;
    return sun >= scene_lo - 1e-9 && sun <= scene_hi + 1e-9;
  };
  int outside = 0;
  for (int i = 0; i < columns; ++i) outside += !in_scene(i);

  // the picture: three panels of columns × rows cells, labels above each and the sun's axis below
  const int size = spec.preview_size;
  const int cw = std::max(6, size / columns), ch = std::max(6, size / (2 * kRows));
  const int pw = cw * columns, ph = ch * kRows, px = label_px(pw), band = px * 2;
  Rgb8 img(pw, 3 * (ph + band) + band);
  auto put = [&](int x, int y, const std::array<std::uint8_t, 3>& c) {
    std::uint8_t* d = &img.rgb[3 * (static_cast<std::size_t>(y) * img.width + x)];
    d[0] = c[0];
    d[1] = c[1];
    d[2] = c[2];
  };
  auto toned = [&](const Vec3& shown, double y) -> std::array<std::uint8_t, 3> {
    if (!(y > 0.0)) return {0, 0, 0};
    std::array<std::uint8_t, 3> c{};
    for (int i = 0; i < 3; ++i) c[i] = srgb8(tone(static_cast<float>(shown[i] * kMidGrey / y), spec.preview_tone));
    return c;
  };
  for (int panel = 0; panel < 3; ++panel) {
    const int top = band + panel * (ph + band);
    for (int j = 0; j < kRows; ++j)
      for (int i = 0; i < columns; ++i) {
        const std::size_t q = static_cast<std::size_t>(j) * columns + i;
        const std::array<std::uint8_t, 3> c = panel == 0   ? toned(shown_lut[q], column_y[i])
                                              : panel == 1 ? toned(shown_truth[q], column_y[i])
                                                           : error_colour(de[q]);
        const bool hatched = !in_scene(i);
        for (int y = 0; y < ch; ++y)
          for (int x = 0; x < cw; ++x)
            put(i * cw + x, top + j * ch + y,
                hatched && (i * cw + x + j * ch + y) % 4 == 0 ? std::array<std::uint8_t, 3>{128, 128, 128} : c);
      }
    for (int i = 1; i < columns; ++i)  // the scene's edges: between a column in it and one outside
      if (in_scene(i) != in_scene(i - 1))
        for (int y = 0; y < ph; ++y) put(i * cw, top + y, {255, 255, 255});
  }
  const char* titles[3] = {"bake: towards the sun, 0-40 deg up",
                           outside > 0 ? "path-traced truth (hatched: suns beyond the scene)" : "path-traced truth",
                           "dE2000: 1 green, 2 yellow, 5+ red"};
  for (int panel = 0; panel < 3; ++panel) draw_label(img, 0, panel * (ph + band), {titles[panel]}, px);
  for (const double sun : {lowest, -6.0, 0.0, kHighestSunDeg})
    if (sun >= lowest) {
      char t[32];
      std::snprintf(t, sizeof t, sun == lowest ? "sun %+.0f deg" : "%+.0f", sun);
      const int x = std::clamp(static_cast<int>((sun - lowest) * cw), 0, std::max(0, pw - 4 * px));
      draw_label(img, x, 3 * (ph + band), {t}, px);
    }

  // the record: the colour difference and the truth's own per sun band
  json bands = json::array();
  const double edges[][2] = {{-12.0, -6.0}, {-6.0, 0.0}, {0.0, 10.0 + 1e-9}};
  for (const auto& e : edges) {
    std::vector<double> d, s, d_in;
    for (int j = 0; j < kRows; ++j)
      for (int i = 0; i < columns; ++i) {
        const double sun = lowest + i;
        if (sun < e[0] || sun >= e[1]) continue;
        d.push_back(de[static_cast<std::size_t>(j) * columns + i]);
        s.push_back(de_se[static_cast<std::size_t>(j) * columns + i]);
        if (in_scene(i)) d_in.push_back(d.back());
      }
    if (d.empty()) continue;
    json band = {{"sun_elevation_deg", {e[0], std::min(e[1], kHighestSunDeg)}},
                 {"de2000", summary_json(summarize_errors(d))},
                 {"truth_se_de2000", summary_json(summarize_errors(s))}};
    if (!d_in.empty()) band["de2000_in_scene"] = summary_json(summarize_errors(d_in));
    bands.push_back(band);
  }
  TwilightStrip out;
  out.record = {{"file", "preview/twilight_strip.png"},
                {"camera_altitude_km", altitude},
                {"sun_elevation_deg", {lowest, kHighestSunDeg}},
                {"view_elevation_deg", {0.0, kTopViewDeg}},
                {"view_sun_azimuth_deg", 0.0},
                {"columns", columns},
                {"scene_sun_elevation_deg", {scene_lo, scene_hi}},
                {"columns_outside_scene", outside},
                {"rows", kRows},
                {"exposure", "per sun column: the truth's mean luminance brought to 0.18"},
                {"truth", truth->summary()},
                {"bands", bands}};
  out.png = {"preview/twilight_strip.png",
             png_rgb8(img.width, img.height, img.rgb),
             "",
             {img.height, img.width, 3},
             "",
             "8-bit sRGB",
             "the twilight strip: the bake, the path-traced truth and their CIEDE2000 towards the sun, sun " +
                 std::to_string(static_cast<int>(lowest)) + "..+10 deg across (docs/atmosphere.md, \"Previews\")"};
  spdlog::debug("atmosphere: twilight strip of {} views ({} s of truth)", n, truth->seconds);
  return out;
}

}  // namespace specbake::atmosphere
