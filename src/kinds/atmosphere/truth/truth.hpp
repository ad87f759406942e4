#pragma once
// The path-traced ground truth of an atmosphere bake: Monte Carlo estimates, with standard
// errors, of what GetSkyRadiance returns from the baked LUTs (the light scattered into a view
// ray, all orders or orders 1..N; not the sun disc, not the ground's own radiance at the end
// of the ray), computed from the same model (kernels/atmosphere/path_tracer.cl, which uses
// atmosphere.cl's parameter block, profiles, phase functions and sun terms) without any table
// of the bake. See docs/atmosphere-method.md, "Path-traced truth".
//
// Library entry points (the `specbake truth` command, the `scene:` block and the manifest
// block are built on these):
//   read_truth_points / parse_truth_points   POINTS.csv → points (InputError at file:line:column)
//   scene_points (model/scene.hpp)            a scene description → a low-discrepancy point set
//   trace_truth                               points → radiance and standard error per channel
//   trace_truth_reference                     the same walks in C++ double on the host (tests)
//   to_bundle_units                           per wavelength → what the bundle stores (R, G, B)
//   load_bundle_luts / lut_sky_radiance       a bundle's textures → GetSkyRadiance at the points
//   truth_result_csv / truth_points_csv       RESULT.csv / POINTS.csv text
#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "cl/device.hpp"
#include "core/config.hpp"
#include "job/kind.hpp"
#include "kinds/atmosphere/model/scene.hpp"
#include "kinds/atmosphere/shader/render.hpp"

namespace specbake::atmosphere {

namespace fs = std::filesystem;

// The tracer's OpenCL program (the atmosphere kind's programs: its expanded source enters the hash
// of every atmosphere bake).
inline constexpr const char* kTruthProgram = "kernels/atmosphere/truth_kernels.cl";
// SHA-256 of the host sources and data this kind's results depend on (src/kinds/atmosphere/,
// src/core/, data/; generated at build time by cmake/source_ids.cmake): with the programs'
// expanded sources, what identifies the code of a kept truth.
extern const char* const kHostSources;

// A walk of all orders stops after this many scattering events (path_tracer.cl, TRUTH_MAX_EVENTS).
extern const int kTruthMaxEvents;

// The POINTS.csv header, exactly.
inline constexpr const char* kTruthPointsHeader = "altitude_km,view_zenith_deg,sun_zenith_deg,view_sun_azimuth_deg";

struct TruthOptions {
  long long paths = 4096;           // walks per point and channel (rounded up to whole batches)
  int orders = 0;                   // 0: all orders (Russian roulette); N >= 1: orders 1..N only
  std::uint64_t seed = 1;           // same seed, points and options on one device: byte-identical results
  int paths_per_batch = 64;         // walks per work item (and per Welford batch); >= 1
  // > 0: after the first `paths` walks, trace more for each point (continuing its random
  // streams) until every channel's standard error is at most this fraction of its radiance,
  // or the point has max(paths, max_paths) walks. 0: exactly `paths` walks.
  double target_relative_se = 0.0;
  long long max_paths = 1LL << 22;
  // Points whose sun elevation (degrees, at the point's camera as given) is below
  // low_sun_elevation_deg ask low_sun_relative_se of their radiance instead (0: the same target)
  // and may take low_sun_max_paths walks (0: max_paths; the events budget scales with it): where
  // the light comes from rare paths a walk costs most, and a precision stated per band keeps
  // the cost where it buys the most. Default: no point is such.
  double low_sun_elevation_deg = -90.0;
  double low_sun_relative_se = 0.0;
  long long low_sun_max_paths = 0;
  // N >= 1: also estimate, from the same walks, the part of orders 1..N and the part of orders
  // above N (TruthResult::low / high). 0: no split.
  int split_orders = 0;
  // Optional [rows][channels] weights: the precision target then applies to each row's
  // weighted sum Σ_c w[row][c] L_c (e.g. CIE XYZ over a spectrum's wavelengths, whose
  // channels each need far fewer walks than the sum's precision asks of one channel) rather
  // than to every channel. Empty: every channel.
  std::vector<double> target_weights;
  // The sun term of every vertex after the view ray's (path_tracer.cl, TRUTH_NEXT_SUN_*):
  // automatic (its expectation along the ray for points whose sun is low enough for the
  // planet's shadow to matter, the plain next-event estimate at the free path's end otherwise),
  // or one of the two everywhere (tests compare them). Same expectation; other noise and cost.
  enum class NextSun { automatic = 0, along_ray = 1, at_vertex = 2 };
  NextSun next_sun = NextSun::automatic;
  // Order 1, the sun scattered once on the view ray: a deterministic quadrature on the host
  // (exact optical depths, adaptive to a relative 1e-6; no noise), the walks carrying orders ≥ 2
  // (path_tracer.cl, TRUTH_ORDER1_GIVEN), or walked like the other orders (next-event estimation
  // at the view ray's vertex; tests compare the two). Same expectation; in the first minutes of
  // twilight, where single scattering is most of the light, a fraction of the walks.
  enum class Order1 { quadrature = 0, walked = 1 };
  Order1 order1 = Order1::quadrature;
  // Twilight points (those whose walks are guided towards the sunlit air) first trace a few
  // pilot walks and learn from them where their light comes from: the view ray's segment
  // table and the first direction's cells (path_tracer.cl "learned guides"). Same
  // expectation; in deep twilight a fraction of the variance. false: the fixed tables.
  bool learn = true;
  // > 0: a point's walks stop once they would take more scattering events than this (per
  // channel; measured on the point's first batch), whatever max_paths allows: what bounds the
  // cost in an optically thick atmosphere, where a walk takes up to TRUTH_MAX_EVENTS events.
  double max_events_per_point = 0.0;
};

// Every option, as a kept trace's key carries them.
nlohmann::json truth_options_json(const TruthOptions& o);

// Radiance per point and traced channel, [point][channel] row-major.
struct TruthResult {
  std::vector<double> lambda_nm;           // the traced wavelengths (the bake's: 680/550/440 for rgb)
  std::vector<std::string> channel_names;  // "R","G","B" (rgb) or the wavelength in nm ("364.896")
  std::size_t points = 0, channels = 0;
  std::vector<double> radiance;        // W m^-2 sr^-1 nm^-1
  std::vector<double> standard_error;  // of radiance, from the per-walk sample variance
  std::vector<long long> paths;        // walks per point: those of its most-walked channel
  std::vector<long long> channel_paths;  // walks per point and channel (each walks its share of the target)
  std::vector<char> at_cap;            // per point: its walks stopped at max_paths or the events budget
  // With TruthOptions::split_orders = N: the same walks' orders 1..N (low) and orders > N
  // (high), low + high = radiance; empty otherwise.
  int split_orders = 0;
  std::vector<double> radiance_low, standard_error_low, radiance_high, standard_error_high;
  int orders = 0;                      // 0: all
  std::uint64_t seed = 0;
  double mean_events = 0.0;            // scattering events + ground hits per walk
  long long truncated = 0;             // all-orders walks stopped after 1000 events (bias; expected 0)
  std::string precision;               // "float64" or "float32" (device arithmetic)
  std::string device;                  // device description, or "host (C++ double)"
  double seconds = 0.0;                // wall time (tables and walks); 0 when reused
  std::string reused;                  // the kept entry it was read from (a file name); empty: traced now
  std::string order1 = "walked";       // how order 1 was found: "quadrature" or "walked" (TruthOptions::Order1)
  double L(std::size_t point, std::size_t channel) const { return radiance[point * channels + channel]; }
  double se(std::size_t point, std::size_t channel) const { return standard_error[point * channels + channel]; }
  // The orders-1..N part as a result of its own (radiance = low), for the same conversions.
  TruthResult low_part() const;
  // Parameters and diagnostics for a manifest or report (no values per point).
  nlohmann::json summary() const;
};

// Traces every point on the device. Throws InputError for an invalid point or option (no
// location: the caller knows where they came from), DeviceError for OpenCL failures, JobError
// when a density exceeded its majorant (a bug: the estimate would be biased).
TruthResult trace_truth(const AtmosphereSpec& spec, cl_util::Device& dev, const std::vector<TruthPoint>& points,
                        const TruthOptions& options, const Progress& progress = {});
// Bytes a trace of `points` points and `channels` channels holds at once (the largest chunk's
// view-ray tables and their per-group copies, one launch's output), on the host and on the
// device; for memory estimates before anything is allocated.
struct Model;
struct Channels;
// The tracer's medium table for one group of up to three channels (path_tracer.cl): the
// majorants per altitude shell, the cut altitudes of its exact optical depths (depth_cuts) and
// the optical depth towards the sun (the light scattered once towards a point, which twilight
// walks read, is filled in by the trace). With `lengths`, the medium table of the three profiles
// as unit channels, the sun depths are the channels' sums of those lengths instead of
// quadratures of their own.
std::vector<double> medium_table(const Model& m, const Channels& group,
                                 const std::vector<double>* lengths = nullptr);
// The profiles as three channels of unit coefficients (Rayleigh, Mie, absorption).
Channels unit_channels();
// log S̄, the light scattered once towards a point (path_tracer.cl, "the light at a vertex"), of
// every channel at the sky table's nodes, [TRUTH_SKY_H · TRUTH_SKY_MU][channel]; `lengths`: the
// medium table of unit_channels(). Only shapes the pdfs of twilight walks.
std::vector<double> sky_light_table(const Model& m, const Channels& ch, const std::vector<double>& lengths);

struct TruthMemory {
  std::uint64_t host = 0, device = 0, largest_buffer = 0;
};
TruthMemory truth_memory(std::size_t points, std::size_t channels);  // with the default paths_per_batch

// The same walks on the host in C++ double (path_tracer.cl compiled by the C++ compiler): with
// a float64 device, the same numbers up to libm rounding. Slow: for tests.
TruthResult trace_truth_reference(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points,
                                  const TruthOptions& options);

// What the bundle stores, R, G, B per point: rgb bakes the radiance at 680/550/440 nm itself;
// spectral bakes Σ_i to_rgb[c][i] L(λ_i) with the job's own weights (spectrum_of(spec).to_rgb:
// linear sRGB luminance / 683), standard errors combined as independent (each wavelength is
// traced by its own walks).
struct TruthBundleValues {
  std::vector<double> radiance, standard_error;  // [point][3]
  std::string units;
};
TruthBundleValues to_bundle_units(const AtmosphereSpec& spec, const TruthResult& r);
// Three rows Σ_i w[c·n + i] L_i per point over the result's n channels, their se from the
// channels' (independent walks: var = Σ w² se²); `units` left empty.
TruthBundleValues weighted_sums(const TruthResult& r, const std::vector<double>& weights);

// A result as bytes for a ResultStore (CBOR; every number exact; not `seconds`, so the bytes
// are the same every run), and back (throws std::exception on bytes that are not such a result).
// Two traces' results as one: a's points, then b's (the same channels, orders and split; throws
// std::invalid_argument otherwise). Walk-weighted mean events; seconds and truncated walks
// summed; seed and device are a's; `reused` names both where both were read from kept entries.
TruthResult joined(const TruthResult& a, const TruthResult& b);
std::string truth_result_bytes(const TruthResult& r);
TruthResult truth_result_from_bytes(const std::string& bytes);

// POINTS.csv: the header kTruthPointsHeader, then one point per line (4 numbers). Blank lines
// only at the end. altitude >= 0; zenith angles in [0, 180]; azimuth in [-360, 360].
std::vector<TruthPoint> read_truth_points(const fs::path& file);  // IoError if unreadable
std::vector<TruthPoint> parse_truth_points(const std::string& text, const fs::path& file_for_messages);
std::string truth_points_csv(const std::vector<TruthPoint>& points);

// RESULT.csv: the four point columns, then L_<c>,se_<c> per traced channel; for spectral
// results also L_R,se_R,L_G,se_G,L_B,se_B in the bundle's units; with `lut` (one R,G,B per
// point, in the bundle's units), lut_R,lut_G,lut_B.
std::string truth_result_csv(const AtmosphereSpec& spec, const std::vector<TruthPoint>& points, const TruthResult& r,
                             const std::vector<Vec3>* lut = nullptr);
void write_text_file(const fs::path& file, const std::string& text);  // IoError on failure


// The final textures of a bundle (rgb or spectral; 3D layout), with the geometry from its
// manifest. IoError for unreadable files, InputError (naming the manifest) for a bundle that
// is not an atmosphere bundle with scattering.bin and single_mie_scattering.bin.
Luts load_bundle_luts(const fs::path& bundle_dir);
// GetSkyRadiance (separate single-Mie texture, no shadow length) at each point, R, G, B in
// the bundle's units, through Renderer::sky_radiance.
std::vector<Vec3> lut_sky_radiance(const Luts& luts, const std::vector<TruthPoint>& points);

}  // namespace specbake::atmosphere
