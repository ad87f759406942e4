#include "kinds/atmosphere/truth/scene_check.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <stdexcept>

#include "core/colour_space.hpp"
#include "core/hash.hpp"
#include "core/spectral_data.hpp"
#include "core/text.hpp"
#include "core/version.hpp"
#include "kinds/atmosphere/bake/bake.hpp"
#include "kinds/atmosphere/model/model.hpp"

namespace specbake::atmosphere {


using nlohmann::json;

namespace {

// The truth's walks (scene_truth_options). Points that still miss the target (in twilight, where
// the light scattered more than once into the Earth's shadow comes through long grazing sun
// rays, a walk's relative standard deviation reaches ~10–20 even with the tracer's twilight
// estimate, ~40 without it) are counted in the record, whose standard errors say how far the
// figures there are resolved.
constexpr long long kFirstPaths = 1024;
// The walk cap per point and channel at the default relative_se (1 %): it stands for a walk
// whose relative standard deviation is ~1.8; a finer target raises it by (1 %/relative_se)²,
// so that the same points, not more, stop at it, up to kMaxPathsEver.
constexpr long long kMaxPaths = 1LL << 15;
constexpr double kMaxPathsAt = 0.01;
constexpr long long kMaxPathsEver = 1LL << 22;
// Points whose sun is below kDeepTwilightSunDeg (−6°, where civil twilight ends and the sky is
// 10⁻³–10⁻⁵ of the day's) ask kDeepTwilightSeFactor × relative_se of the truth, with a cap that
// stands for a walk whose relative standard deviation is 3× the daylight cap's (~5.4; the
// −12…0° scene's noisiest points measured 5.3 in X, Y or Z): there the light comes through rare
// paths and a walk's relative standard deviation is 2–5 against ~1 in daylight, so 1 % would
// take up to 9× the walks of 2 %. Measured on the 2-core CPU, default Earth at 16 wavelengths,
// sun −12…0°, cameras 0–2 km, 128 points, relative_se 1 % (both traces): every point at 1 %
// with the daylight cap, 51 s, 46 points at the cap, the deep points' X, Y, Z se up to 2.9 %;
// factor 1.5 (this), 40 s, none at the cap, at most 1.5 %, truth se p99 1.2 CIEDE2000; factor
// 2, 26 s, at most 2.0 %, se p99 1.5.
constexpr double kDeepTwilightSeFactor = 1.5;
constexpr double kDeepTwilightCapFactor = 9.0;
// The events budget per point and channel: the walk cap times this many scattering events per
// walk (the default Earth's walks take ~2 on average, so it binds only where walks are long: an
// optically thick atmosphere, whose walks take up to TRUTH_MAX_EVENTS; there it bounds the
// check's cost at the price of its precision, which the record and the warnings report).
constexpr double kEventsPerWalk = 8.0;
// The spectral reference of rgb bakes: 48 bins of 9.79 nm over 360–830 nm (the spectral mode's
// default), integrated with the CIE 1931 functions as a spectral bake does.
constexpr int kReferenceWavelengths = 48;
constexpr std::uint64_t kSpectralSeedOffset = 0x9e3779b97f4a7c15ULL;
constexpr std::uint64_t kHeldOutSeedStride = 0xbf58476d1ce4e5b9ULL;  // seed + first * stride
constexpr double kMidGrey = 0.18;
constexpr double kRelativeFloor = 1e-3;
// A truth whose p99 standard error (CIEDE2000) is more than this share of the reported p99
// error cannot resolve it: the record and the run say so.
constexpr double kNoisyTruthShare = 0.5;

Vec3 times(const Vec3& v, const std::array<double, 3>& k) { return {v[0] * k[0], v[1] * k[1], v[2] * k[2]}; }

const Mat3& to_xyz() {
  static const Mat3 M = srgb_to_xyz();
  return M;
}

std::vector<Vec3> rows_of(const std::vector<double>& v) {
  std::vector<Vec3> out(v.size() / 3);
  for (std::size_t p = 0; p < out.size(); ++p) out[p] = {v[3 * p], v[3 * p + 1], v[3 * p + 2]};
  return out;
}

}  // namespace

json summary_json(const ErrorSummary& s) {
  return {{"max", s.max}, {"p99", s.p99}, {"median", s.median}, {"mean", s.mean}, {"count", s.count}};
}

namespace {

// Channel c's relative errors and the displayed-colour ΔE of one part.
struct Part {
  std::string name;
  std::array<ErrorSummary, 3> relative{}, dark_relative{};  // over the lit points, the dark ones
  bool has_relative = true;
  std::vector<double> de;                // every point
  ErrorSummary de_summary, dark_summary;  // over the lit points, the dark ones
};

// The worst channel's p99 relative error of a part (0 without per-channel errors).
double worst_relative_p99(const Part& part) {
  double w = 0.0;
  for (const ErrorSummary& r : part.relative) w = std::max(w, r.p99);
  return w;
}

// The points a part's figures cover: the lit ones (the reference's luminance at least
// kDarkLuminance) or the dark ones, reported apart.
std::vector<double> select_points(const std::vector<double>& v, const std::vector<char>& dark, bool want_dark) {
  std::vector<double> out;
  for (std::size_t p = 0; p < v.size(); ++p)
    if ((dark[p] != 0) == want_dark) out.push_back(v[p]);
  return out;
}

// A part's errors at every point (the exposure rule of the scene: per view, or fixed at
// exposure_y), summarised over the lit points; the dark points' own figures in dark_summary.
Part make_part(std::string name, const std::vector<Vec3>* test, const std::vector<Vec3>* ref,
               const std::vector<Vec3>& shown_test, const std::vector<Vec3>& shown_ref, double exposure_y,
               const std::vector<char>& dark) {
  Part part;
  part.name = std::move(name);
  part.has_relative = test && ref;
  if (part.has_relative)
    for (int c = 0; c < 3; ++c) {
      const std::vector<double> e = relative_errors(*test, *ref, c);
      part.relative[c] = summarize_errors(select_points(e, dark, false));
      part.dark_relative[c] = summarize_errors(select_points(e, dark, true));
    }
  part.de.resize(shown_test.size());
  for (std::size_t p = 0; p < shown_test.size(); ++p) part.de[p] = displayed_de2000(shown_test[p], shown_ref[p], exposure_y);
  part.de_summary = summarize_errors(select_points(part.de, dark, false));
  part.dark_summary = summarize_errors(select_points(part.de, dark, true));
  return part;
}

json part_json(const Part& part, bool dark) {
  json j = {{"de2000", summary_json(dark ? part.dark_summary : part.de_summary)}};
  if (part.has_relative) {
    const char* names[3] = {"R", "G", "B"};
    json rel = json::object();
    for (int c = 0; c < 3; ++c) rel[names[c]] = summary_json(dark ? part.dark_relative[c] : part.relative[c]);
    j["relative"] = rel;
  }
  return j;
}

// What to raise when a part dominates.
std::string advice(const std::string& part, const AtmosphereSpec& spec, int orders_used) {
  if (part == "lut_discretisation")
    return "raise the texture sizes (sizes: scattering {r, mu, mu_s, nu}; near the horizon and in twilight mu_s "
           "and nu first; now " + std::to_string(spec.scattering_r) + "x" + std::to_string(spec.scattering_mu) + "x" +
           std::to_string(spec.scattering_mu_s) + "x" + std::to_string(spec.scattering_nu) + ")";
  if (part == "order_truncation")
    return "use orders_tail: geometric (orders >= " + std::to_string(kMinTailOrders) + "), raise orders (now " +
           std::to_string(orders_used) + "), or use orders: auto with a smaller tolerance";
  return "bake a spectrum (spectrum: {count: 16} or more) instead of rgb";
}

}  // namespace

double exposure_luminance(double ev100) { return 0.125 * std::exp2(ev100); }

double displayed_de2000(const Vec3& test, const Vec3& ref, double exposure_y) {
  const Mat3& M = to_xyz();
  auto xyz = [&](const Vec3& rgb) {
    return std::array<double, 3>{M[0] * rgb[0] + M[1] * rgb[1] + M[2] * rgb[2],
                                 M[3] * rgb[0] + M[4] * rgb[1] + M[5] * rgb[2],
                                 M[6] * rgb[0] + M[7] * rgb[1] + M[8] * rgb[2]};
  };
  static const std::array<double, 3> white = xyz({1.0, 1.0, 1.0});
  const auto x_ref = xyz(ref), x_test = xyz(test);
  const double y = exposure_y > 0.0 ? exposure_y : x_ref[1];
  if (!(y > 0.0) || !std::isfinite(y)) return std::numeric_limits<double>::quiet_NaN();
  const double k = kMidGrey / y;
  const std::array<double, 3> a{k * x_test[0], k * x_test[1], k * x_test[2]}, b{k * x_ref[0], k * x_ref[1], k * x_ref[2]};
  return ciede2000(xyz_to_lab(a, white), xyz_to_lab(b, white));
}

ErrorSummary summarize_errors(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return !std::isfinite(x); }), v.end());
  ErrorSummary s;
  s.count = v.size();
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  s.max = v.back();
  const auto rank = [&](double q) { return v[static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size()))) - 1]; };
  s.median = rank(0.5);
  s.p99 = rank(0.99);
  double sum = 0.0;
  for (double x : v) sum += x;
  s.mean = sum / static_cast<double>(v.size());
  return s;
}

std::vector<double> relative_errors(const std::vector<Vec3>& test, const std::vector<Vec3>& ref, int c) {
  double top = 0.0;
  for (const Vec3& r : ref) top = std::max(top, std::fabs(r[c]));
  const double floor = kRelativeFloor * top;
  std::vector<double> out(ref.size());
  for (std::size_t p = 0; p < ref.size(); ++p) {
    const double d = std::max(std::fabs(ref[p][c]), floor);
    out[p] = d > 0.0 ? std::fabs(test[p][c] - ref[p][c]) / d : (test[p][c] != 0.0 ? 1.0 : 0.0);
  }
  return out;
}

namespace {
// kMaxPaths × k (1 %/target)², rounded, at most kMaxPathsEver.
long long walks_for(double k, double target) {
  const double f = k * (kMaxPathsAt / target) * (kMaxPathsAt / target);
  return static_cast<long long>(std::min(static_cast<double>(kMaxPathsEver), std::round(kMaxPaths * f)));
}
double deep_twilight_relative_se(double relative_se) { return kDeepTwilightSeFactor * relative_se; }
}  // namespace

long long scene_walk_cap(double relative_se) { return walks_for(1.0, std::min(relative_se, kMaxPathsAt)); }

long long deep_twilight_walk_cap(double relative_se) {
  return std::max(scene_walk_cap(relative_se),
                  walks_for(kDeepTwilightCapFactor, deep_twilight_relative_se(relative_se)));
}

// The relative standard errors a trace's precision target is set on, [point][3]: a spectral
// trace's X, Y and Z (its channels independent: var = Σ w² se²), an rgb trace's three channels;
// NaN where the value is not positive (summaries leave those out).
std::vector<double> target_relative_se(const AtmosphereSpec& traced, const TruthResult& r) {
  std::vector<double> out;
  const double none = std::numeric_limits<double>::quiet_NaN();
  if (!traced.spectral) {
    for (std::size_t p = 0; p < r.points; ++p)
      for (std::size_t c = 0; c < r.channels; ++c) out.push_back(r.L(p, c) > 0.0 ? r.se(p, c) / r.L(p, c) : none);
    return out;
  }
  const TruthBundleValues xyz = weighted_sums(r, spectrum_of(traced).to_xyz);
  for (std::size_t i = 0; i < xyz.radiance.size(); ++i)
    out.push_back(xyz.radiance[i] > 0.0 ? xyz.standard_error[i] / xyz.radiance[i] : none);
  return out;
}

// Summaries of [point][3] values by the points' sun elevation: below kDeepTwilightSunDeg (−6°)
// and from it up (the bands the truth's precision is asked for apart); a band without points is
// left out.
json by_sun_band(const std::vector<double>& per_point_rows, const std::vector<TruthPoint>& points) {
  std::vector<double> below, above;
  for (std::size_t p = 0; p < points.size() && 3 * p + 2 < per_point_rows.size(); ++p)
    for (int row = 0; row < 3; ++row)
      (90.0 - points[p].sun_zenith_deg < kDeepTwilightSunDeg ? below : above).push_back(per_point_rows[3 * p + row]);
  json j = json::object();
  if (!below.empty()) j["sun_below_-6_deg"] = summary_json(summarize_errors(below));
  if (!above.empty()) j["sun_from_-6_deg"] = summary_json(summarize_errors(above));
  return j;
}

TruthOptions scene_truth_options(const AtmosphereSpec& traced, std::uint64_t seed) {
  TruthOptions o;
  const long long cap = scene_walk_cap(traced.scene.relative_se);
  o.paths = kFirstPaths;
  o.max_paths = cap;
  o.max_events_per_point = kEventsPerWalk * static_cast<double>(cap);
  o.target_relative_se = traced.scene.relative_se;
  o.low_sun_elevation_deg = kDeepTwilightSunDeg;
  o.low_sun_relative_se = deep_twilight_relative_se(traced.scene.relative_se);
  const long long low_sun_cap = deep_twilight_walk_cap(traced.scene.relative_se);
  o.low_sun_max_paths = low_sun_cap;
  o.seed = seed;
  if (traced.spectral) {
    const Spectrum sp = spectrum_of(traced);
    const long long n = static_cast<long long>(sp.lambda_nm.size());
    o.paths = std::max<long long>(64, kFirstPaths * 3 / n);
    o.max_paths = std::max<long long>(o.paths, cap * 3 / n);
    o.low_sun_max_paths = std::max<long long>(o.paths, low_sun_cap * 3 / n);
    o.max_events_per_point = kEventsPerWalk * static_cast<double>(o.max_paths);
    o.target_weights = sp.to_xyz;  // the precision target: X, Y, Z
  }
  return o;
}

AtmosphereSpec spectral_reference_of(const AtmosphereSpec& spec) {
  AtmosphereSpec ss = spec;
  ss.spectral = true;
  ss.min_nm = 360.0;
  ss.max_nm = 830.0;
  ss.count = kReferenceWavelengths;
  return ss;
}

bool is_spectral_reference(const AtmosphereSpec& spec) {
  return spec.spectral && spec.count == kReferenceWavelengths && spec.min_nm == 360.0 && spec.max_nm == 830.0;
}

namespace {
// The points' and the tracer's part of a truth key: the same for every trace at those points.
std::string points_code_key(const std::vector<TruthPoint>& points, cl_util::Device& dev) {
  return "/points " + sha256_hex(truth_points_csv(points)) + truth_code_key(dev);
}
std::string truth_key_at(const AtmosphereSpec& traced, const std::string& what, const TruthOptions& o,
                         const std::string& points_code) {
  const json p = parameters_json(traced);
  return "atmosphere.truth/" + what + "/" + p["atmosphere"].dump() + p["channels"].dump() + "/walks " +
         truth_options_json(o).dump() + points_code;
}
}  // namespace

std::string truth_key(const AtmosphereSpec& traced, const std::string& what, const TruthOptions& o,
                      const std::vector<TruthPoint>& points, cl_util::Device& dev) {
  return truth_key_at(traced, what, o, points_code_key(points, dev));
}

std::string truth_code_key(cl_util::Device& dev) {
  return "/program " + sha256_hex(expanded_program(kTruthProgram)) + "/host " + kHostSources + "/device " +
         device_identity(dev.info()).dump() + "/version " + kVersion;
}

double walk_events_estimate(const AtmosphereSpec& spec) {
  // f(τ) = 1.57 + 1.59 τ + 0.20 τ² (τ: the vertical scattering depth averaged over the bake's
  // wavelengths; ~τ² once light diffuses), saturating at ~450 (walks stop at 1000 events, and
  // Russian roulette ends many before): the mean events a walk took at the default scene's
  // points for the Earth (τ 0.14: 1.8), its Rayleigh ×10 (1.4: 4.3), ×100 (14: 57) and ×1000
  // (140: 399).
  const double tau = vertical_scattering_depth(spec, spectrum_of(spec).lambda_nm);
  const double f = 1.57 + 1.59 * tau + 0.20 * tau * tau;
  return std::min(static_cast<double>(kTruthMaxEvents), 1.0 / (1.0 / f + 1.0 / 450.0));
}

double truth_seconds(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points, bool with_reference,
                     double walk_share, bool deep_twilight_rule) {
  // Measured on the 2-core CPU (PoCL, an Intel Xeon), default Earth, relative_se 1 %, both
  // traces (the bake's wavelengths and the 48-wavelength reference; rgb and 16-wavelength bakes
  // cost about the same, as a spectrum's walks go where its colour's variance is), seconds per
  // point by the point's sun: high (0.016), low (0.035: below acos(r_b/r_t) + α, where each
  // vertex's sun term is taken along its ray with exact optical depths), below the horizon
  // (0.148: learned tables) and below kDeepTwilightSunDeg (0.70: most points at the walk cap, whose
  // walks guide their free paths, path_tracer.cl truth_guided_free_path). Each band traced on its
  // own (32 points, cameras 0–2 km, sky views; sun 20…60°, 2…8°, −6…0°, −12…−6°) gave 0.019,
  // 0.044, 0.185 and 0.70 s a point (e70933c: the exact depths' cuts by each layer's share, the
  // sun's transmittance from its table with an exact correction); whole scenes, traced at once as
  // the check does, ~0.8 of that below the horizon's band: the default scene's job 10.3 s cold
  // (these constants: 12), the sun −12…0° scene of 128 points at 16 wavelengths 64 s (59); the
  // bands' jobs within 0.9–1.25 of the measured. With order 1 by quadrature (the walks carry
  // orders ≥ 2) the same bands gave 0.017, 0.038, 0.113 and 0.60 s a point (rgb, 1981dc9): the
  // constants below scaled by those ratios.
  // With deep_twilight_rule the points below −6° ask 1.5 × relative_se (kDeepTwilightSeFactor) and
  // may take more walks (deep_twilight_walk_cap): the −12…0° scene above then took 40 s, the
  // −6…0° points at the constant here and the deeper ones 0.52 s a point.
  constexpr double kHighSun = 0.0145, kLowSun = 0.030, kBelowHorizon = 0.090, kEarthEvents = 1.8;
  const double deep_twilight_s = deep_twilight_rule ? 0.52 : 0.60;
  // Longer walks also need more of them (their radiance is noisier): Rayleigh ×10, 4.3 events a
  // walk, took 1.23 s a point against the Earth's 0.164 over the same scene: (4.3/1.8)^2.3.
  constexpr double kLongerWalks = 2.3;
  const double deg = 180.0 / M_PI;
  const double low_sun = (std::acos(spec.bottom_radius_km / spec.top_radius_km) + spec.sun_angular_radius_rad) * deg;
  const double finer = (kMaxPathsAt / spec.scene.relative_se) * (kMaxPathsAt / spec.scene.relative_se);
  const double e = walk_events_estimate(spec);
  // What bounds a point: per channel its walk cap W, or the events budget kEventsPerWalk · W,
  // but at least one batch of 64 walks (which measures the events). An event's seconds grow with
  // the walk's length (delta tracking through denser air): 5.0 µs at 57 events a walk, 56 µs at
  // 399 (Rayleigh ×100 and ×1000, every point at the budget); ~2.0 µs in the Earth's twilight walks
  // (exact sun optical depths at every vertex; below −6° most points at the cap: 0.70 s a point).
  const double event_s = std::max(2.0e-6, 5.0e-6 * std::pow(e / 57.0, 1.26));
  auto bounded = [&](const AtmosphereSpec& traced, bool deep) {
    const TruthOptions o = scene_truth_options(traced, 0);
    const double cap = static_cast<double>(o.max_paths);
    const double w = deep ? static_cast<double>(o.low_sun_max_paths) : cap;
    const double channels = traced.spectral ? static_cast<double>(spectrum_of(traced).lambda_nm.size()) : 3.0;
    return channels * std::max(64.0 * e, std::min(w * e, o.max_events_per_point * w / cap)) * event_s;
  };
  auto bound_of = [&](bool deep) {
    return walk_share *
           (bounded(spec, deep) + (with_reference ? bounded(spectral_reference_of(spec), deep) : 0.0));
  };
  const double bound = bound_of(false), deep_bound = deep_twilight_rule ? bound_of(true) : bound;
  const double traces = (with_reference ? 1.0 : 0.5) * walk_share;  // the per-point figures above hold both traces
  double s = 0.0;
  for (const TruthPoint& p : points) {
    const double sun = 90.0 - p.sun_zenith_deg;
    const double walks = sun >= low_sun ? kHighSun
                         : sun >= 0.0   ? kLowSun
                         : sun >= kDeepTwilightSunDeg ? kBelowHorizon
                                                      : deep_twilight_s;
    s += std::min(traces * walks * finer * std::pow(std::max(1.0, e / kEarthEvents), kLongerWalks),
                  sun < kDeepTwilightSunDeg ? deep_bound : bound);
  }
  return s;
}

double check_seconds(const AtmosphereSpec& spec) {
  if (!spec.scene.check) return 0.0;
  return truth_seconds(spec, scene_points_of(spec), !is_spectral_reference(spec), 1.0);
}


namespace {

// The traces a check judges by: the bake's wavelengths (all orders, split at the bake's) and,
// unless the bake is it, the spectral reference (48 wavelengths over 360–830 nm); their walks
// and the keys they are kept under: the model and wavelengths, the scene (less its tolerances,
// which judge the truth but do not change it) and its point set, the walks' options (the split
// among them), the tracer's program and host code, the device and the tool.
struct SceneTracePlan {
  TruthOptions o, so;      // the bake's trace, the reference's
  bool reference = false;  // the spectral reference is traced
  std::string bake_key, reference_key;
  std::string bake_what, points_code;  // the bake key's parts besides the spec and o (truth_key_at)
};

SceneTracePlan plan_traces(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points, int orders_used,
                           int first, std::uint64_t seed, cl_util::Device& dev) {
  json scene = scene_json(spec.scene);
  if (scene.is_object()) {
    scene.erase("tolerance_de2000");
    scene.erase("tolerance_relative");
  }
  const std::string what = "/" + scene.dump() + "/first " + std::to_string(first);
  SceneTracePlan t;
  t.o = scene_truth_options(spec, seed);
  // a bake with a geometric tail (orders_tail) stands for every order: its truth is split where
  // orders: auto stops at the latest, so its tail's error counts as lut_discretisation
  t.o.split_orders = takes_geometric_tail(spec) ? kMaxAutoOrders : orders_used;
  t.bake_what = "bake" + what;
  t.points_code = points_code_key(points, dev);
  t.bake_key = truth_key_at(spec, t.bake_what, t.o, t.points_code);
  t.reference = !is_spectral_reference(spec);
  // the same sky as the reference spectrum (independent streams: another seed)
  const AtmosphereSpec ss = spectral_reference_of(spec);
  t.so = scene_truth_options(ss, seed + kSpectralSeedOffset);
  t.reference_key = truth_key_at(ss, "reference" + what, t.so, t.points_code);
  return t;
}

struct SceneTraces {
  TruthOptions o, so;       // their walks
  bool reference = false;   // the spectral reference was traced
  std::shared_ptr<const TruthResult> bake, spectral = std::make_shared<const TruthResult>();
};

// The scene's traces, each kept in `keep` under its plan's key.
SceneTraces trace_scene(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points, int orders_used,
                        int first, std::uint64_t seed, cl_util::Device& dev, const Progress& progress, Memo& keep,
                        bool bake_wavelengths = true) {
  const SceneTracePlan plan = plan_traces(spec, points, orders_used, first, seed, dev);
  auto report = [&](double from, double to) {
    return [&, from, to](std::string_view, double f) { progress("scene check", from + (to - from) * f); };
  };
  // the trace of `at` under key k, or the one an earlier run kept
  auto trace_at = [&](const AtmosphereSpec& traced, const std::vector<TruthPoint>& at, const std::string& k,
                      const TruthOptions& o, double from, double to) {
    return keep.kept<TruthResult>(
        k, [&] { return trace_truth(traced, dev, at, o, report(from, to)); }, truth_result_bytes,
        [&](const std::string& bytes) {
          TruthResult r = truth_result_from_bytes(bytes);
          r.reused = ResultStore::name_of(k);
          spdlog::info("atmosphere: scene check: the path-traced truth at {} ({} points) reused from {} (kept by an "
                       "earlier run)",
                       traced.spectral ? std::to_string(traced.count) + " wavelengths" : std::string("rgb"), at.size(),
                       (keep.store->dir() / r.reused).string());
          return r;
        });
  };

  // A point set whose parts were each traced as a point set of their own — the settings search
  // judges [0, 2n) and then holds out [2n, 3n) as sets of their own, and a second round judges
  // [0, 3n) — is assembled from those traces (each part with its own seed, as check_scene gave
  // it; where one part is not kept, that part alone is traced) rather than traced again. The
  // splits tried: halves, thirds (either way) and quarters (either way).
  const std::size_t n = points.size();
  const std::uint64_t base_seed = seed - static_cast<std::uint64_t>(first) * kHeldOutSeedStride;
  const bool parts_apply = n >= 2 && static_cast<int>(n) == spec.scene.points;
  struct Piece {
    AtmosphereSpec spec;
    std::vector<TruthPoint> points;
    SceneTracePlan plan;
  };
  // the two parts [first, first + j) and [first + j, first + n), planned on first use
  std::map<std::size_t, std::array<Piece, 2>> splits;
  const auto split_at = [&](std::size_t j) -> const std::array<Piece, 2>& {
    auto it = splits.find(j);
    if (it != splits.end()) return it->second;
    auto part = [&](std::size_t from, std::size_t to) {
      Piece pt;
      pt.spec = spec;
      pt.spec.scene.points = static_cast<int>(to - from);
      pt.points.assign(points.begin() + from, points.begin() + to);
      const int at = first + static_cast<int>(from);
      const std::uint64_t at_seed = base_seed + static_cast<std::uint64_t>(at) * kHeldOutSeedStride;
      pt.plan = plan_traces(pt.spec, pt.points, orders_used, at, at_seed, dev);
      return pt;
    };
    return splits.emplace(j, std::array<Piece, 2>{part(0, j), part(j, n)}).first->second;
  };
  std::vector<std::size_t> candidates;
  for (const auto& [num, den] : {std::pair{1, 2}, {2, 3}, {1, 3}, {3, 4}, {1, 4}})
    if (n % den == 0) candidates.push_back(n / den * num);
  const auto traced = [&](const AtmosphereSpec& traced_spec, bool reference, const std::string& key,
                          const TruthOptions& o, double from, double to) -> std::shared_ptr<const TruthResult> {
    if (parts_apply && !keep.has(key))  // a whole trace kept earlier is read as it is
      for (std::size_t j : candidates) {
        const std::array<Piece, 2>& ps = split_at(j);
        const SceneTracePlan &p0 = ps[0].plan, &p1 = ps[1].plan;
        const std::string& k0 = reference ? p0.reference_key : p0.bake_key;
        const std::string& k1 = reference ? p1.reference_key : p1.bake_key;
        if (!keep.has(k0) && !keep.has(k1)) continue;
        const double mid = from + (to - from) * static_cast<double>(j) / static_cast<double>(n);
        const auto a = trace_at(reference ? spectral_reference_of(ps[0].spec) : ps[0].spec, ps[0].points, k0,
                                reference ? p0.so : p0.o, from, mid);
        const auto b = trace_at(reference ? spectral_reference_of(ps[1].spec) : ps[1].spec, ps[1].points, k1,
                                reference ? p1.so : p1.o, mid, to);
        spdlog::trace("atmosphere: scene check: the truth at {} points assembled from the traces of [{}, {}) and [{}, {})",
                      n, first, first + j, first + j, first + n);
        return std::make_shared<const TruthResult>(joined(*a, *b));
      }
    return trace_at(traced_spec, points, key, o, from, to);
  };

  SceneTraces t;
  t.o = plan.o;
  t.so = plan.so;
  t.reference = plan.reference;
  // the progress at which the bake's trace ends (judge_scene traces the reference alone)
  const double split = !bake_wavelengths ? 0.0 : t.reference ? 0.5 : 0.9;
  if (bake_wavelengths) t.bake = traced(spec, false, plan.bake_key, t.o, 0.0, split);
  if (t.reference) t.spectral = traced(spectral_reference_of(spec), true, plan.reference_key, t.so, split, 1.0);
  return t;
}

// Per point, R, G, B: the truth and the LUT in the bundle's units, and the colours displayed
// (linear sRGB luminance); the points darker than kDarkLuminance.
struct SceneValues {
  std::string units;                           // the bundle's
  std::vector<Vec3> t_all, t_low, se_all, lut;  // all orders, the bake's orders, all orders' se, the LUT
  std::vector<Vec3> s_all, s_se;               // the spectral reference and its se (when traced)
  std::array<double, 3> k{}, k683{};           // radiance → luminance: the bake's, the reference's
  std::vector<Vec3> shown_lut, shown_low, shown_all, shown_ref;
  std::vector<char> dark;
  long long n_dark = 0;
};

SceneValues scene_values(const AtmosphereSpec& spec, const Luts& luts, const std::vector<TruthPoint>& points,
                         const SceneTraces& tr) {
  SceneValues v;
  const std::size_t n = points.size();
  const TruthBundleValues all = to_bundle_units(spec, *tr.bake), low = to_bundle_units(spec, tr.bake->low_part());
  v.units = all.units;
  v.t_all = rows_of(all.radiance);
  v.t_low = rows_of(low.radiance);
  v.se_all = rows_of(all.standard_error);
  v.lut = lut_sky_radiance(luts, points);
  if (tr.reference) {
    const TruthBundleValues s = to_bundle_units(spectral_reference_of(spec), *tr.spectral);
    v.s_all = rows_of(s.radiance);
    v.s_se = rows_of(s.standard_error);
  }
  // displayed colours (linear sRGB luminance)
  v.k = spectrum_of(spec).sky_radiance_to_luminance;
  v.k683 = {kMaxLuminousEfficacy, kMaxLuminousEfficacy, kMaxLuminousEfficacy};
  v.shown_lut.resize(n);
  v.shown_low.resize(n);
  v.shown_all.resize(n);
  v.shown_ref.resize(n);
  for (std::size_t p = 0; p < n; ++p) {
    v.shown_lut[p] = times(v.lut[p], v.k);
    v.shown_low[p] = times(v.t_low[p], v.k);
    v.shown_all[p] = times(v.t_all[p], v.k);
    v.shown_ref[p] = tr.reference ? times(v.s_all[p], v.k683) : v.shown_all[p];
  }
  // Views whose reference is darker than kDarkLuminance are reported apart, with their own figures.
  v.dark.resize(n);
  for (std::size_t p = 0; p < n; ++p) v.dark[p] = !(srgb_luminance(v.shown_ref[p]) >= kDarkLuminance);
  v.n_dark = std::count(v.dark.begin(), v.dark.end(), 1);
  return v;
}

// The error's parts: total, lut_discretisation, order_truncation and (with the reference)
// spectral_sampling, under one exposure rule.
std::vector<Part> scene_parts(const SceneValues& v, bool reference, double exposure_y) {
  std::vector<Part> parts;
  parts.push_back(make_part("total", &v.lut, &v.t_all, v.shown_lut, v.shown_ref, exposure_y, v.dark));
  parts.push_back(make_part("lut_discretisation", &v.lut, &v.t_low, v.shown_lut, v.shown_low, exposure_y, v.dark));
  parts.push_back(make_part("order_truncation", &v.t_low, &v.t_all, v.shown_low, v.shown_all, exposure_y, v.dark));
  if (reference)
    parts.push_back(make_part("spectral_sampling", nullptr, nullptr, v.shown_all, v.shown_ref, exposure_y, v.dark));
  return parts;
}

// A point's truth se in ΔE: the displayed colour moved by one se (radiance se times the
// luminance factor k) in each channel in turn, the ΔEs combined in quadrature.
double se_de2000(const Vec3& shown, const Vec3& se, const std::array<double, 3>& k, double exposure_y) {
  double q = 0.0;
  for (int c = 0; c < 3; ++c) {
    Vec3 moved = shown;
    moved[c] += se[c] * k[c];
    const double d = displayed_de2000(moved, shown, exposure_y);
    if (std::isfinite(d)) q += d * d;
  }
  return std::sqrt(q);
}

// The truth's own standard error: relative per channel, and in ΔE as the colour moved by one se
// in each channel in turn, combined in quadrature; the points that stopped at the walk cap.
struct TruthNoise {
  std::vector<double> se_rel, de_se;  // de_se: every point
  std::vector<double> se_target, se_target_reference;  // target_relative_se of the traces
  long long below_target = 0;
  ErrorSummary se_de, se_rel_summary;  // se_de over the lit points
};

TruthNoise truth_noise(const AtmosphereSpec& spec, const SceneValues& v, const SceneTraces& tr, double exposure_y) {
  TruthNoise t;
  const std::size_t n = v.t_all.size();
  t.de_se.resize(n);
  const std::vector<Vec3>& ref_se = tr.reference ? v.s_se : v.se_all;
  const std::array<double, 3>& k_ref = tr.reference ? v.k683 : v.k;
  for (std::size_t p = 0; p < n; ++p) {
    for (int c = 0; c < 3; ++c)
      if (v.t_all[p][c] > 0.0) t.se_rel.push_back(v.se_all[p][c] / v.t_all[p][c]);
    t.de_se[p] = se_de2000(v.shown_ref[p], ref_se[p], k_ref, exposure_y);
  }
  for (std::size_t p = 0; p < n; ++p)
    if (tr.bake->at_cap[p] || (tr.reference && tr.spectral->at_cap[p]))
      ++t.below_target;
  t.se_de = summarize_errors(select_points(t.de_se, v.dark, false));
  t.se_rel_summary = summarize_errors(t.se_rel);
  t.se_target = target_relative_se(spec, *tr.bake);
  if (tr.reference) t.se_target_reference = target_relative_se(spectral_reference_of(spec), *tr.spectral);
  return t;
}

// The record's details: the scene, its point set, the exposure, the parts (lit and dark points),
// the truth's standard error and summaries.
json check_details(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points, int orders_used,
                   double exposure_y, const SceneValues& v,
                   const SceneTraces& tr, const std::vector<Part>& parts, const TruthNoise& noise) {
  const AtmosphereScene& sc = spec.scene;
  json details = {
      {"scene", scene_json(sc)},
      {"point_set", "Halton (bases 2, 3, 5, 7) from its second point: altitude and sun elevation uniform in their "
                    "ranges, view directions uniform in solid angle within the view elevations, view-sun azimuth "
                    "uniform in its range"},
      {"orders_baked", orders_used},
      {"orders_tail", takes_geometric_tail(spec) ? "geometric" : "none"},
      {"orders_note", "the walks are split at the bake's order count (for spectral bakes in several passes with "
                      "orders: auto, the largest of the passes'; a pass that stopped earlier then counts its "
                      "missing orders as lut_discretisation); with orders_tail: geometric, at orders: auto's "
                      "cap, the tail's error then in lut_discretisation"},
      {"points_without_light", std::count_if(v.shown_ref.begin(), v.shown_ref.end(),
                                             [](const Vec3& c) { return !(srgb_luminance(c) > 0.0); })},
      {"exposure", sc.exposure_ev100
                       ? "fixed, EV100 " + format_g(*sc.exposure_ev100) + ": luminance " +
                             format_g(exposure_y) + " cd/m^2 brought to 0.18 in every view, both colours scaled alike, "
                             "for every part and the truth's se; CIE L*a*b* against D65 (Y = 1), no gamut clipping, "
                             "no tone curve"
                       : "per view: the reference's luminance Y brought to 0.18 (a renderer's auto exposure), both "
                         "colours scaled alike, for every part and the truth's se; CIE L*a*b* against D65 (Y = 1), no "
                         "gamut clipping, no tone curve"},
      {"dark_points", {{"threshold_cd_m2", kDarkLuminance},
                       {"count", v.n_dark},
                       {"note", "views whose reference luminance is below the threshold: not in parts or "
                                "standard_error, their own figures here"},
                       {"parts", json::object()},
                       {"standard_error_de2000", summary_json(summarize_errors(select_points(noise.de_se, v.dark, true)))}}},
      {"relative_error", "|test - reference| / max(|reference|, 1e-3 x the channel's maximum over the points), "
                         "per channel in the bundle's units"},
      {"parts", json::object()},
      {"standard_error", {{"relative", summary_json(summarize_errors(noise.se_rel))},
                          {"target_channels", summary_json(summarize_errors(noise.se_target))},
                          {"target_channels_by_sun", by_sun_band(noise.se_target, points)},
                          {"target_channels_note",
                           spec.spectral ? "relative se of the trace's CIE X, Y, Z (what relative_se targets)"
                                         : "relative se of the trace's three channels (what relative_se targets)"},
                          {"de2000", summary_json(noise.se_de)},
                          {"target_relative", sc.relative_se},
                          {"target_relative_sun_below_-6_deg", deep_twilight_relative_se(sc.relative_se)},
                          {"points_at_max_paths", noise.below_target}}},  // reached the cap, met or not
      {"truth", tr.bake->summary()}};
  for (const Part& part : parts) {
    details["parts"][part.name] = part_json(part, false);
    if (v.n_dark > 0) details["dark_points"]["parts"][part.name] = part_json(part, true);
  }
  details["parts"]["total"]["note"] = tr.reference ? "the LUT against the all-orders truth at the bake's wavelengths; "
                                                     "de2000 against the 48-wavelength spectral truth (what the sky "
                                                     "looks like)"
                                                   : "the LUT against the all-orders truth at the bake's wavelengths "
                                                     "(the bake's are the 48 of the spectral reference)";
  if (tr.reference) {
    details["spectral_truth"] = tr.spectral->summary();
    details["standard_error"]["reference_xyz_relative"] = summary_json(summarize_errors(noise.se_target_reference));
    details["standard_error"]["reference_xyz_relative_by_sun"] = by_sun_band(noise.se_target_reference, points);
  }
  return details;
}

// scene_check.csv: per point the truth (all orders, its se, the bake's orders), the LUT, the
// spectral reference, and the CIEDE2000 of each part and of the truth's se.
OutputFile points_csv(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points, const SceneValues& v,
                      bool reference, const std::vector<Part>& parts, const TruthNoise& noise) {
  const std::size_t n = points.size();
  std::string csv = std::string(kTruthPointsHeader) +
                    ",L_R,L_G,L_B,se_R,se_G,se_B,L_orders_R,L_orders_G,L_orders_B,lut_R,lut_G,lut_B";
  if (reference) csv += ",spectral_R,spectral_G,spectral_B";
  csv += ",de2000";
  for (std::size_t i = 1; i < parts.size(); ++i) csv += ",de2000_" + parts[i].name;
  csv += ",de2000_se\n";
  for (std::size_t p = 0; p < n; ++p) {
    const TruthPoint& q = points[p];
    // the point's coordinates to 9 digits, as the values: a point read back from here is the
    // point traced (at 4 digits a deep-twilight view moved its sky by up to 4 %: it falls by
    // e per degree of sun)
    std::string row = format_g(q.altitude_km, 9) + "," + format_g(q.view_zenith_deg, 9) + "," +
                      format_g(q.sun_zenith_deg, 9) + "," + format_g(q.view_sun_azimuth_deg, 9);
    char b[64];
    auto add = [&](double x) {
      std::snprintf(b, sizeof b, ",%.9g", x);
      row += b;
    };
    for (const auto* c : {&v.t_all, &v.se_all, &v.t_low, &v.lut})
      for (int ch = 0; ch < 3; ++ch) add((*c)[p][ch]);
    if (reference)
      for (int ch = 0; ch < 3; ++ch) add(v.s_all[p][ch]);
    for (const Part& part : parts) add(part.de[p]);
    add(noise.de_se[p]);
    csv += row + "\n";
  }
  return {"scene_check.csv", csv, "", {static_cast<std::int64_t>(n)}, "CSV, one row per scene point",
          v.units + (reference && !spec.spectral ? "; spectral_* columns: linear sRGB luminance / 683" : ""),
          "the scene check per point: the truth (all orders, its se, the bake's orders), the LUT's "
          "GetSkyRadiance, and the CIEDE2000 of each part (docs/atmosphere.md, \"The scene check\")"};
}

// What the truth cannot resolve, said in the record and the run summary.
std::vector<std::string> check_warnings(const AtmosphereScene& sc, bool deep_twilight, std::size_t n, bool dark_scene,
                                        const Part& total, const TruthNoise& noise, const std::string& walk_cap,
                                        long long n_dark) {
  std::vector<std::string> out;
  if (!dark_scene && noise.se_de.p99 > kNoisyTruthShare * total.de_summary.p99)
    out.push_back("scene check: the truth's own p99 standard error (" + format_g(noise.se_de.p99) +
                  " CIEDE2000) is more than half the reported p99 error (" + format_g(total.de_summary.p99) +
                  "): the figure is mostly the truth's noise; lower scene.relative_se (now " +
                  format_g(sc.relative_se) + ")");
  if (noise.below_target > 0)
    out.push_back("scene check: " + std::to_string(noise.below_target) + " of the " + std::to_string(n) +
                  " points stopped at the truth's walk cap (" + walk_cap +
                  ", fewer where walks are long: " + format_g(kEventsPerWalk) +
                  " scattering events a walk on average), their standard error above the target relative_se " +
                  format_g(sc.relative_se) +
                  (deep_twilight
                       ? " (" + format_g(deep_twilight_relative_se(sc.relative_se)) + " where the sun is below " +
                             format_g(kDeepTwilightSunDeg) + " deg; "
                       : std::string(" (")) +
                  "standard_error in the record says how far)");
  if (n_dark > 0)
    out.push_back("scene check: " + std::to_string(n_dark) + " of the " + std::to_string(n) +
                  " points are darker than " + format_g(kDarkLuminance) +
                  " cd/m^2 and are reported apart (dark_points in the record)");
  return out;
}

// A scene without a lit point: the LUTs cannot be judged there.
std::string dark_scene_failure(const AtmosphereScene& sc, std::size_t n) {
  return "scene check: none of the scene's " + std::to_string(n) + " points is brighter than " +
         format_g(kDarkLuminance) + " cd/m^2 in the path-traced truth (cameras " + format_g(sc.camera_altitude_min_km) +
         "-" + format_g(sc.camera_altitude_max_km) + " km, sun " + format_g(sc.sun_elevation_min_deg) + " to " +
         format_g(sc.sun_elevation_max_deg) + " deg, " + views_name(sc.views) +
         " views), so the LUTs cannot be judged there; give the scene a sun and views that see sunlit "
         "air, or `scene: none`";
}

// A missed tolerance: the causes ranked by the judged measure (relative radiance per channel, rgb
// truth, or CIEDE2000), what to raise for the largest, and the truth's own noise.
std::string tolerance_failure(const AtmosphereSpec& spec, int orders_used, std::size_t n, bool by_radiance,
                              double value, double tolerance, const std::vector<Part>& parts, const TruthNoise& noise) {
  const AtmosphereScene& sc = spec.scene;
  auto measure = [&](const Part& part) { return by_radiance ? worst_relative_p99(part) : part.de_summary.p99; };
  const Part* worst = nullptr;
  std::string split_text;
  for (std::size_t i = 1; i < parts.size(); ++i) {
    if (by_radiance && !parts[i].has_relative) continue;  // spectral sampling has no radiance measure
    if (!worst || measure(parts[i]) > measure(*worst)) worst = &parts[i];
    split_text += (split_text.empty() ? "" : ", ") + parts[i].name + " " + format_g(measure(parts[i]));
  }
  const double se = by_radiance ? noise.se_rel_summary.p99 : noise.se_de.p99;
  return "scene check: p99 " + std::string(by_radiance ? "relative radiance error " : "CIEDE2000 ") +
         format_g(value) + " > tolerance " + format_g(tolerance) + " at the scene's " + std::to_string(n) +
         " points (cameras " + format_g(sc.camera_altitude_min_km) + "-" + format_g(sc.camera_altitude_max_km) +
         " km, sun " + format_g(sc.sun_elevation_min_deg) + " to " + format_g(sc.sun_elevation_max_deg) + " deg, " +
         views_name(sc.views) + " views). p99 by cause: " + split_text + "; the largest is " + worst->name + ": " +
         advice(worst->name, spec, orders_used) + ". The truth's own p99 standard error is " + format_g(se) +
         (tolerance <= 2.0 * se ? " - comparable with the tolerance: lower scene.relative_se (now " +
                                      format_g(sc.relative_se) + ") before trusting the split"
                                : "") +
         ". Per point: scene_check.csv of a bake without the tolerance";
}

}  // namespace

SceneCheck check_scene(const AtmosphereSpec& spec, const Luts& luts, int orders_used, cl_util::Device& dev,
                       const Progress& progress, Memo* memo, int first) {
  const auto t0 = std::chrono::steady_clock::now();
  const AtmosphereScene& sc = spec.scene;
  const std::vector<TruthPoint> points = scene_points_of(spec, first);
  const std::size_t n = points.size();
  // an independent point set also draws its walks from other streams
  const std::uint64_t seed = sc.seed + static_cast<std::uint64_t>(first) * kHeldOutSeedStride;
  Memo local;
  const SceneTraces tr = trace_scene(spec, points, orders_used, first, seed, dev, progress, memo ? *memo : local);
  const SceneValues v = scene_values(spec, luts, points, tr);
  // One exposure rule for every part and for the truth's se: per view, or the config's fixed one.
  const double exposure_y = sc.exposure_ev100 ? exposure_luminance(*sc.exposure_ev100) : 0.0;
  const std::vector<Part> parts = scene_parts(v, tr.reference, exposure_y);
  const TruthNoise noise = truth_noise(spec, v, tr, exposure_y);

  const Part& total = parts[0];
  const bool by_radiance = sc.tolerance_relative.has_value();
  // no lit point: nothing to judge the LUTs by (NaN fails the record)
  const bool dark_scene = total.de_summary.count == 0;
  const double value = dark_scene ? std::numeric_limits<double>::quiet_NaN()
                            : by_radiance ? worst_relative_p99(total) : total.de_summary.p99;
  const std::optional<double> tolerance = by_radiance ? sc.tolerance_relative : sc.tolerance_de2000;
  SceneCheck out;
  out.record = Accuracy::judged(
      "vs_path_traced",
      by_radiance ? "p99 over the scene's points of the relative radiance error, worst channel"
                  : "p99 over the scene's points of the CIEDE2000 of the displayed colour",
      value, tolerance, "Monte Carlo path tracing of the same model at the scene's points (all orders)",
      check_details(spec, points, orders_used, exposure_y, v, tr, parts, noise));
  out.record.unit = by_radiance ? "p99 relative" : "p99 CIEDE2000";
  out.points_csv = points_csv(spec, points, v, tr.reference, parts, noise);
  out.colours = {v.shown_lut, v.shown_ref, v.dark, exposure_y};
  // a spectral trace shares the rgb cap's work out over its wavelengths: say both
  const std::size_t wavelengths = tr.bake->lambda_nm.size();
  const std::string walk_cap =
      (spec.spectral ? std::to_string(tr.o.max_paths * static_cast<long long>(wavelengths)) + " walks a point over " +
                           std::to_string(wavelengths) + " wavelengths, the work of " +
                           std::to_string(scene_walk_cap(sc.relative_se)) + " rgb walks"
                     : std::to_string(tr.o.max_paths) + " walks a channel") +
      (reaches_deep_twilight(spec)
           ? "; " + std::to_string(deep_twilight_walk_cap(sc.relative_se)) +
                 " rgb walks' work where the sun is below " + format_g(kDeepTwilightSunDeg) + " deg"
           : std::string());
  out.warnings = check_warnings(sc, reaches_deep_twilight(spec), n, dark_scene, total, noise, walk_cap, v.n_dark);
  out.record.details["warnings"] = out.warnings;
  if (dark_scene)
    out.failure = dark_scene_failure(sc, n);
  else if (!out.record.passed)
    out.failure = tolerance_failure(spec, orders_used, n, by_radiance, value, *tolerance, parts, noise);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  spdlog::debug("atmosphere: scene check of {} points in {:.2f} s: p99 CIEDE2000 {:.3g}, max {:.3g}", n, out.seconds,
                total.de_summary.p99, total.de_summary.max);
  return out;
}

std::vector<double> JudgedColours::errors(const std::vector<Vec3>& shown) const {
  std::vector<double> e(shown.size(), std::numeric_limits<double>::quiet_NaN());
  for (std::size_t p = 0; p < shown.size() && p < shown_ref.size(); ++p)
    if (!dark[p]) e[p] = displayed_de2000(shown[p], shown_ref[p], exposure_y);
  return e;
}

double JudgedColours::p99(const std::vector<Vec3>& shown) const {
  return summarize_errors(select_points(errors(shown), dark, false)).p99;
}

bool judged_by_reference_alone(const AtmosphereSpec& spec) { return !spec.scene.tolerance_relative; }

namespace {

// The 48-wavelength reference traced at a point set (the same trace, under the same key, as
// check_scene's reference: one kept result serves both), its displayed colours, the points
// reported apart and its se in CIEDE2000 per point.
struct ReferenceAt {
  SceneTraces tr;
  std::vector<Vec3> shown_ref;
  std::vector<char> dark;
  std::vector<double> de_se;
  double exposure_y = 0.0;
};
ReferenceAt trace_reference(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points, cl_util::Device& dev,
                            const Progress& progress, Memo* memo, int first) {
  const AtmosphereScene& sc = spec.scene;
  const std::size_t n = points.size();
  const std::uint64_t seed = sc.seed + static_cast<std::uint64_t>(first) * kHeldOutSeedStride;
  Memo local;
  ReferenceAt r;
  // the reference itself is judged against the trace every other bake of its atmosphere is
  // (an rgb bake's reference: the same key)
  AtmosphereSpec judged = spec;
  if (is_spectral_reference(spec)) judged.spectral = false;
  r.tr = trace_scene(judged, points, 0, first, seed, dev, progress, memo ? *memo : local, false);
  const TruthBundleValues s = to_bundle_units(spectral_reference_of(spec), *r.tr.spectral);
  const std::vector<Vec3> s_all = rows_of(s.radiance), s_se = rows_of(s.standard_error);
  const std::array<double, 3> k683{kMaxLuminousEfficacy, kMaxLuminousEfficacy, kMaxLuminousEfficacy};
  r.exposure_y = sc.exposure_ev100 ? exposure_luminance(*sc.exposure_ev100) : 0.0;
  r.shown_ref.resize(n);
  r.dark.resize(n);
  r.de_se.resize(n);
  for (std::size_t p = 0; p < n; ++p) {
    r.shown_ref[p] = times(s_all[p], k683);
    r.dark[p] = !(srgb_luminance(r.shown_ref[p]) >= kDarkLuminance);
    r.de_se[p] = se_de2000(r.shown_ref[p], s_se[p], k683, r.exposure_y);
  }
  return r;
}

}  // namespace

double reference_se_p99(const AtmosphereSpec& spec, cl_util::Device& dev, const Progress& progress, Memo* memo,
                        int first) {
  if (!judged_by_reference_alone(spec))
    throw std::logic_error("reference_se_p99: a spec judged by relative radiance");
  const ReferenceAt r = trace_reference(spec, scene_points_of(spec, first), dev, progress, memo, first);
  return summarize_errors(select_points(r.de_se, r.dark, false)).p99;
}

SceneCheck judge_scene(const AtmosphereSpec& spec, const Luts& luts, cl_util::Device& dev, const Progress& progress,
                       Memo* memo, int first) {
  if (!judged_by_reference_alone(spec))
    throw std::logic_error("judge_scene: a spec judged by relative radiance");
  const auto t0 = std::chrono::steady_clock::now();
  const AtmosphereScene& sc = spec.scene;
  const std::vector<TruthPoint> points = scene_points_of(spec, first);
  const std::size_t n = points.size();
  ReferenceAt r = trace_reference(spec, points, dev, progress, memo, first);
  const SceneTraces& tr = r.tr;
  const std::vector<Vec3> lut = lut_sky_radiance(luts, points);
  const std::array<double, 3> k = spectrum_of(spec).sky_radiance_to_luminance;
  const double exposure_y = r.exposure_y;
  const std::vector<Vec3>& shown_ref = r.shown_ref;
  const std::vector<char>& dark = r.dark;
  const std::vector<double>& de_se = r.de_se;
  std::vector<Vec3> shown_lut(n);
  for (std::size_t p = 0; p < n; ++p) shown_lut[p] = times(lut[p], k);
  const Part total = make_part("total", nullptr, nullptr, shown_lut, shown_ref, exposure_y, dark);
  const bool dark_scene = total.de_summary.count == 0;
  const double value = dark_scene ? std::numeric_limits<double>::quiet_NaN() : total.de_summary.p99;
  long long at_cap = 0;
  for (std::size_t p = 0; p < n; ++p) at_cap += tr.spectral->at_cap[p];
  const json details = {
      {"judged_only", "the p99 CIEDE2000 against the 48-wavelength reference alone (no parts: the truth at the "
                      "bake's own wavelengths is not traced)"},
      {"parts", {{"total", part_json(total, false)}}},
      {"standard_error", {{"de2000", summary_json(summarize_errors(select_points(de_se, dark, false)))},
                          {"target_relative", sc.relative_se},
                          {"target_relative_sun_below_-6_deg", deep_twilight_relative_se(sc.relative_se)},
                          {"points_at_max_paths", at_cap}}},
      {"dark_points", {{"threshold_cd_m2", kDarkLuminance}, {"count", std::count(dark.begin(), dark.end(), 1)}}}};
  SceneCheck out;
  out.colours = {shown_lut, shown_ref, dark, exposure_y};
  out.record = Accuracy::judged("vs_path_traced", "p99 over the scene's points of the CIEDE2000 of the displayed colour",
                                value, sc.tolerance_de2000, "Monte Carlo path tracing of the same model at the scene's "
                                "points (all orders, the 48-wavelength reference)", details);
  out.record.unit = "p99 CIEDE2000";
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

bool scene_truth_kept(const AtmosphereSpec& spec, std::optional<int> orders_used, cl_util::Device& dev,
                      const Memo& memo) {
  if (!spec.scene.check) return false;
  auto kept = [&](const std::string& key) { return memo.has(key); };
  const std::vector<TruthPoint> points = scene_points_of(spec);
  const SceneTracePlan plan = plan_traces(spec, points, orders_used.value_or(1), 0, spec.scene.seed, dev);
  if (plan.reference && !kept(plan.reference_key)) return false;
  if (orders_used) return kept(plan.bake_key);
  // orders: auto: the bake's trace is split at the orders the bake ends with, not known before
  // it; a trace kept at any count is the one an unchanged bake reads again
  // (the same key with only the split varied)
  for (int n = 1; n <= kMaxAutoOrders; ++n) {
    TruthOptions o = plan.o;
    o.split_orders = n;
    if (kept(truth_key_at(spec, plan.bake_what, o, plan.points_code))) return true;
  }
  return false;
}

}  // namespace specbake::atmosphere
