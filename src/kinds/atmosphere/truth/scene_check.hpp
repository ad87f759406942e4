#pragma once
// The scene check of an atmosphere bake: the error a user sees in their own scene. After the
// LUTs are baked, the points of the config's `scene:` (a low-discrepancy set of cameras, sun
// elevations and view directions) are path-traced (truth.hpp) and compared with what a shader
// computes from the baked textures (GetSkyRadiance, lut_sky_radiance). The error is split
// into its causes:
//   lut_discretisation  LUT vs the truth with the bake's own orders (texture sizes, the bake's
//                       quadratures and parameterisation)
//   order_truncation    the truth with the bake's orders vs all orders (same walks)
//   spectral_sampling   the bake's wavelengths (rgb: 680/550/440 nm displayed with Bruneton's
//                       radiance-to-luminance factors; spectral: its bins) vs a 48-wavelength
//                       spectrum over 360–830 nm integrated with the CIE 1931 functions (not
//                       for bakes of exactly that spectrum)
//   total               what the user sees: the LUT vs the all-orders truth (per channel, at the
//                       bake's wavelengths) and vs the 48-wavelength truth (displayed colour)
// each per channel (relative radiance) and in displayed colour (CIEDE2000 after a per-view
// exposure), with the truth's own Monte Carlo standard error. docs/atmosphere.md, "The scene
// check".
#include <array>
#include <optional>
#include <string>
#include <vector>

#include "cl/device.hpp"
#include "job/kind.hpp"
#include "kinds/atmosphere/truth/truth.hpp"

namespace specbake::atmosphere {

// The displayed colour's difference: both colours are linear sRGB luminances (cd m⁻²: the
// bundle's values times the radiance-to-luminance factors), taken to CIE XYZ, scaled by one
// exposure that brings the reference's luminance Y to 0.18 (mid grey, the per-view auto
// exposure of a renderer), then CIE L*a*b* against D65 (Y = 1) and CIEDE2000. No clipping to
// the sRGB gamut and no tone curve: the difference is the sky's, not a display's. With
// exposure_y > 0 the exposure brings that luminance to 0.18 instead (a fixed exposure, the same
// for every view: scene_exposure_y); NaN when the luminance brought to 0.18 is not > 0.
double displayed_de2000(const Vec3& test_luminance_rgb, const Vec3& reference_luminance_rgb, double exposure_y = 0.0);
// The luminance (cd m⁻²) a fixed exposure of `ev100` brings to mid grey: 0.125 · 2^EV100, the
// reflected-light meter's calibration (K = 12.5 cd m⁻² s, ISO 100).
double exposure_luminance(double ev100);
// Views darker than this (cd m⁻², the reference's luminance) are reported apart by the scene
// check, with their own figures: below the darkest night sky a display shows.
inline constexpr double kDarkLuminance = 1e-4;

// max, median and 99th percentile (nearest rank) and mean of the finite values; count of them.
struct ErrorSummary {
  double max = 0.0, median = 0.0, p99 = 0.0, mean = 0.0;
  std::size_t count = 0;
};
ErrorSummary summarize_errors(std::vector<double> values);
// {max, p99, median, mean, count}
nlohmann::json summary_json(const ErrorSummary& s);

// Per point relative errors |test − ref| / max(|ref|, 1e-3 · max_points |ref|) of one channel
// (1 where that denominator is 0 and test is not: a channel the truth has no light in).
std::vector<double> relative_errors(const std::vector<Vec3>& test, const std::vector<Vec3>& ref, int channel);

// The displayed colours (linear sRGB luminance) a judged check compared at each of its points,
// the points reported apart (dark) and the exposure rule: what the settings search models.
struct JudgedColours {
  std::vector<Vec3> shown_lut, shown_ref;
  std::vector<char> dark;
  double exposure_y = 0.0;
  // Per point, the CIEDE2000 of `shown` against shown_ref under the check's exposure (NaN at the
  // dark points, which the judged value leaves out).
  std::vector<double> errors(const std::vector<Vec3>& shown) const;
  // The judged value of `shown`: the p99 of errors(shown) over the lit points, as the check's.
  double p99(const std::vector<Vec3>& shown) const;
};

struct SceneCheck {
  Accuracy record;           // "vs_path_traced", judged against the scene's tolerance when it has one
  OutputFile points_csv;     // scene_check.csv: per point the truth, the LUT and every error
  std::string failure;       // non-empty when the tolerance is missed: what dominates, what to raise
  std::vector<std::string> warnings;  // what the truth cannot resolve (also in the record's details)
  JudgedColours colours;     // the colours its value judged (total: the LUT against the reference)
  double seconds = 0.0;
};



// The walks of a check's trace of `traced` (the bake's spec, or the spectral reference of an
// rgb bake): 1024 per point and channel first, then top-ups until the standard error is the
// scene's relative_se of the radiance — each channel of an rgb trace on its own, at most
// scene_walk_cap walks; each of X, Y, Z of a spectrum of n wavelengths, which start from 3/n of
// the walks each and are topped up where the colour's variance is (truth.cpp, walks_needed),
// at most 3 · cap walks a point over all of them.
TruthOptions scene_truth_options(const AtmosphereSpec& traced, std::uint64_t seed);
// The walk cap per point and channel for a scene's relative_se: 32768 at 1 % (and above), times
// (1 %/relative_se)² below it — a walk noisier than ~1.8 relative standard deviation stops at
// the cap whatever the target — at most 2²².
long long scene_walk_cap(double relative_se);
// The same for points whose sun is below kDeepTwilightSunDeg, which ask 1.5 × relative_se
// (scene_check.cpp, kDeepTwilightSeFactor) and may take more walks for it: a cap standing for a
// walk of relative standard deviation ~5.4 at that target, never below scene_walk_cap.
long long deep_twilight_walk_cap(double relative_se);
// The spectral reference of an rgb bake: the same atmosphere at 48 wavelengths over 360–830 nm.
AtmosphereSpec spectral_reference_of(const AtmosphereSpec& spec);

// What a kept truth's key carries besides its inputs: the tracer's expanded program, the host
// sources, the device and the tool's version.
std::string truth_code_key(cl_util::Device& dev);
// The key a trace of `points` is kept under: `what` it is (and whatever else the caller's
// result depends on), the model and wavelengths of `traced`, every walk option, the points and
// truth_code_key.
std::string truth_key(const AtmosphereSpec& traced, const std::string& what, const TruthOptions& o,
                      const std::vector<TruthPoint>& points, cl_util::Device& dev);
// Whether `spec` is the spectral reference itself (48 wavelengths over 360–830 nm): its check
// traces no second spectrum.
bool is_spectral_reference(const AtmosphereSpec& spec);

// What the scene check of `spec` costs when its truth is traced (not kept): wall seconds on the
// 2-core CPU through PoCL, a model like bake_seconds (docs/atmosphere.md, "The scene check",
// "Cost"). Per point of the scene, the seconds its walks took on the default Earth in its sun
// band (daylight, low sun, below the horizon: the twilight estimators cost more per walk and
// more walks stop at the cap), times the events a walk takes in this atmosphere against the
// Earth's (walks_events_per_walk), at most the events budget's seconds; 0 without a check.
double check_seconds(const AtmosphereSpec& spec);
// Whether the traces check_scene(spec, …, orders_used, …) judges by are kept in `memo` (this
// process) or its store (an earlier run; by file name, not read): the check then costs ~0 s.
// Without orders_used (orders: auto), whether such traces are kept at any order count. For the
// job's progress shares and estimates, not for correctness.
bool scene_truth_kept(const AtmosphereSpec& spec, std::optional<int> orders_used, cl_util::Device& dev,
                      const Memo& memo);
// The same model for any points: the bake's wavelengths traced (and the spectral reference with
// `with_reference`), with `walk_share` of the scene check's walks and caps; deep_twilight_rule:
// the points below −6° at the check's own target and cap for them (scene_truth_options), else at
// relative_se and the daylight cap like the rest.
double truth_seconds(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points, bool with_reference,
                     double walk_share, bool deep_twilight_rule = true);
// The truth's scattering events per walk, estimated from the atmosphere's vertical scattering
// optical depth at the bake's wavelengths (a fit to measured walks: ~1.8 for the Earth, ~60 at
// 100× its Rayleigh), at most the tracer's limit of 1000.
double walk_events_estimate(const AtmosphereSpec& spec);

// Traces the scene of `spec` and judges `luts` (baked with `orders_used` orders) against it.
// `first` > 0 judges an independent point set of the same scene (scene_points_of; the walks
// then use other random streams too). With `memo`, the traces are kept there and reused by
// checks of the same atmosphere, wavelengths, scene, point set and order split (the truth does
// not depend on texture sizes).
SceneCheck check_scene(const AtmosphereSpec& spec, const Luts& luts, int orders_used, cl_util::Device& dev,
                       const Progress& progress, Memo* memo = nullptr, int first = 0);

// Whether judge_scene can judge `spec`: a CIEDE2000 tolerance (the displayed colour against the
// 48-wavelength reference; a bake of exactly that spectrum is judged against the same trace as
// any other bake of its atmosphere).
bool judged_by_reference_alone(const AtmosphereSpec& spec);
// The check's judged value alone, for the settings search's tries: the p99 CIEDE2000 of the LUT
// against the spectral reference — the same number check_scene reports as `total` — from the
// reference's trace only (the truth at the bake's own wavelengths, which only the parts need, is
// not traced). The record holds the value, the truth's standard error in CIEDE2000 and the dark
// points; no parts, no per-point file. Requires judged_by_reference_alone(spec).
SceneCheck judge_scene(const AtmosphereSpec& spec, const Luts& luts, cl_util::Device& dev, const Progress& progress,
                       Memo* memo = nullptr, int first = 0);

// The 48-wavelength reference's own p99 standard error in CIEDE2000 over the lit points of the
// point set judge_scene(spec, …, first) judges (traced as judge_scene traces it, and kept in
// `memo` for it): what a judged value cannot resolve. Requires judged_by_reference_alone(spec).
double reference_se_p99(const AtmosphereSpec& spec, cl_util::Device& dev, const Progress& progress, Memo* memo = nullptr,
                        int first = 0);

}  // namespace specbake::atmosphere
