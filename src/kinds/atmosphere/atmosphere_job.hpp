#pragma once
#include <optional>
// An atmosphere job: its plan, its bake (the bake, the scene check or the settings search, the
// spectral interpolation check) and its bundle's files.
#include <string>

#include "job/kind.hpp"
#include "kinds/atmosphere/bake/bake.hpp"
#include "kinds/atmosphere/model/spec.hpp"
#include "kinds/atmosphere/shader/render.hpp"
#include "kinds/atmosphere/truth/scene_check.hpp"
#include "kinds/atmosphere/truth/twilight_strip.hpp"

namespace specbake::atmosphere {

nlohmann::json plan(const AtmosphereSpec& spec, JobContext& ctx);
BakeResult bake(const AtmosphereSpec& spec, JobContext& ctx);

// Wall seconds of a job on a 2-core CPU device (PoCL): bake_seconds plus check_seconds (its truth
// traced), or for `sizes: auto` / `spectrum: auto` kTypicalTries bakes of the search's start,
// the truth traced once and at the held-out points (and the interpolation pass).
double estimated_seconds(const AtmosphereSpec& spec);
// With a search kept in ctx.memo's store (`plan` keeps the search it runs): the kept choice's
// bake_seconds, what `run` then costs; with the scene's truth kept (an earlier run of the same
// atmosphere, wavelengths and scene): the bake without tracing it (and the twilight strip's);
// nullopt when nothing kept applies.
std::optional<KeptCost> kept_estimated_seconds(const AtmosphereSpec& spec, JobContext& ctx);

// `spectrum: {store: radiance}`: what the linear interpolation between stored wavelengths of
// sampling_spectral.glsl (GetSkyRadianceAtWavelength & co.) costs. Measured at wavelengths halfway
// between stored ones (where it errs most): at most kInterpolationTests of them, spread evenly.
inline constexpr int kInterpolationGrid = 32;  // directions per fisheye axis
std::vector<double> interpolation_test_wavelengths(const std::vector<double>& stored_nm);
// Relative errors |interpolated − exact| / max(|exact|, 1e-3 · max |exact| at that wavelength) of
// the sky radiance and its transmittance (the preview fisheyes: kFisheyeViews, a kInterpolationGrid² grid of
// directions each) and of the sun and sky irradiance on the ground (each view's sun), where
// `exact` holds a bake at exactly `exact.lambda_nm`, read at its stored wavelengths.
struct InterpolationError {
  ErrorSummary radiance, transmittance, irradiance;
};
InterpolationError interpolation_error(const Model& m, const SpectralLuts& stored, const SpectralLuts& exact);

}  // namespace specbake::atmosphere
