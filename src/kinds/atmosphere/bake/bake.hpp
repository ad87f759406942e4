#pragma once
// The bake: every pass of a spec on the device (or the double reference on the host), summed
// into the final R, G, B textures (Luts) with what the manifest reports of them; the bake's
// parameters and its predicted time.
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "cl/device.hpp"
#include "job/kind.hpp"
#include "kinds/atmosphere/bake/pass.hpp"
#include "kinds/atmosphere/model/spec.hpp"
#include "kinds/atmosphere/shader/render.hpp"

namespace specbake::atmosphere {

// The resolved model and wavelengths (the manifest's parameters): atmosphere, channels, ...
nlohmann::json parameters_json(const AtmosphereSpec& spec);

// The sizes the bundle stores: the baked ones, with half the μ_s texels (n / 2) and ν slices
// ((n + 1) / 2: every other one of an odd count) where the spec stores half
// (AtmosphereSpec::store_half_mu_s, store_half_nu; the bake resamples them, store_sun_axes).
Sizes stored_sizes(const AtmosphereSpec& spec);
// The scattering and single Mie textures of `luts` resampled to `mu_s` texels along μ_s, then to
// `nu` slices along ν: each stored texel is the lookup of the baked texture at its own μ_s and ν
// (the two baked texels around its texture coordinate, blended as the shader blends them: μ_s as
// the model reads it, ν linearly); luts.model.sizes follows.
void store_sun_axes(Luts& luts, int mu_s, int nu);

// Channels per pass: 3 (R, G, B) for rgb; for spectral bakes the smallest of kPassWidths that
// holds every wavelength, else the widest (then ⌈n / 16⌉ passes). A pass's geometry (ray
// tables, incidence directions, phase functions, texture coordinates) does not depend on its
// channel count, so one wide pass costs much less than several narrow ones.
int channels_per_pass(const AtmosphereSpec& spec);

// `spectrum: {store: radiance}`: the interpolation between stored wavelengths is measured against
// one more pass at up to kInterpolationTests wavelengths halfway between stored ones
// (interpolation_test_wavelengths, atmosphere_job.hpp).
inline constexpr int kInterpolationTests = 8;

// Wall seconds of one bake without its scene check (truth/scene_check.hpp, check_seconds) and
// search on a 2-core CPU device (PoCL), from a cost model calibrated on the bundled configs: per
// order and pass, a geometry part and a per-channel part, both proportional to the scattering
// texels and growing with the density's θ nodes, small terms for the transmittance and
// irradiance texels (from a default bake's stage times), and `store: radiance`'s interpolation
// pass. `orders: auto` is costed at 10 orders.
double bake_seconds(const AtmosphereSpec& spec);
// The part of bake_seconds that is set-up, files and previews.
double bake_files_seconds(const AtmosphereSpec& spec);

// A stage whose outputs held values that are not finite (NaN or ±inf): the bake stops there.
struct NonFiniteStage {
  std::string stage;
  int order = 0, pass = 0;
  long long values = 0;
};
// The LUTs of a bake (final textures in R,G,B), with what the manifest reports about them.
struct Baked {
  Luts luts;
  Spectrum spectrum;
  int orders_used = 0;
  bool converged = true;
  nlohmann::json orders;       // per order: max/mean of what it adds to scattering and irradiance
  nlohmann::json passes;       // wavelengths of each pass, orders used
  nlohmann::json self_checks;  // device vs double reference, per stage
  double self_check_worst = 0.0;
  // `spectrum: {store: radiance}`: the radiance at every wavelength (else empty)
  SpectralLuts radiance;
  // Seconds per stage summed over passes ("total" by stage name, "per_order" by order), each
  // {"device_s", "host_s", "wall_s"} as cl_util::StageSeconds defines them.
  nlohmann::json timings;
};
// Runs every pass on the device (self_check_texels > 0: recompute that many texels of each
// stage in double from the device's own inputs).
Baked bake_luts(const AtmosphereSpec& spec, cl_util::Device& dev, const Progress& progress,
                int self_check_texels = 0);
// The error that stops a bake at a stage that wrote values that are not finite.
JobError non_finite_error(const NonFiniteStage& f);
// The self-checks' verdict: the accuracy record, or a JobError naming the stage that differs
// from the double reference beyond the tolerance.
Accuracy judge_self_checks(const Baked& b);
// The same bake on the host in double (small sizes: tests).
Baked bake_luts_reference(const AtmosphereSpec& spec);

// Channels [first, first + count) of a pass's textures ([texels][width]) into the spectral store
// (`store: radiance`): set g / 4, channel g % 4 of wavelength g; scattering and single Mie from the
// 3D texel order [r][mu][x] to the tiled 2D one [mu][r][x].
void keep_radiance(SpectralLuts& L, const Sizes& s, int first, int count, int width, const PassResult& r);

}  // namespace specbake::atmosphere
