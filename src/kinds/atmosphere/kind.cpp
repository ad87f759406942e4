// The atmosphere kind's entry in the kind table.
#include "kinds/atmosphere/kind.hpp"

#include <algorithm>

#include "atmosphere/limits.h"
#include "kinds/atmosphere/atmosphere_job.hpp"

namespace specbake::atmosphere {

namespace {

MemoryEstimate device_memory(const AtmosphereSpec& s) {
  // One pass of w channels (channels_per_pass) keeps four 4D textures on the device (the two
  // single-scattering deltas, the multiple-scattering delta and the density), a ray-sample table
  // per (r, mu) texel row (SCATTERING_STEPS + 1 samples of RAY_FIXED + w values) and a density
  // incidence table per (r, mu_s) (DENSITY_SPHERE_STEPS directions of (2·nu + 1)·w + INC_FIXED
  // values), plus the small 2D textures.
  const std::uint64_t w = channels_per_pass(s);
  const std::uint64_t real = s.double_precision ? 8 : 4;
  const std::uint64_t texels = std::uint64_t(s.scattering_r) * s.scattering_mu * s.scattering_mu_s * s.scattering_nu;
  const std::uint64_t texture = texels * w * real;
  const std::uint64_t rays = std::uint64_t(s.scattering_r) * s.scattering_mu * (SCATTERING_STEPS + 1) * (RAY_FIXED + w) * real;
  const std::uint64_t incidence = std::uint64_t(s.scattering_r) * s.scattering_mu_s * DENSITY_SPHERE_STEPS *
                                  ((2 * s.scattering_nu + 1) * w + INC_FIXED) * real;
  return MemoryEstimate{4 * texture + rays + incidence + (std::uint64_t{1} << 24), std::max({texture, rays, incidence})};
}

}  // namespace

Kind kind() {
  Kind k = Kind::of<AtmosphereSpec>("atmosphere", "Bruneton 2017 precomputed atmospheric scattering LUTs, all orders", parse_spec, plan, bake);
  k.cost_s = [](const JobSpec& j) { return estimated_seconds(j.as<AtmosphereSpec>()); };
  k.memory = [](const JobSpec& j) { return device_memory(j.as<AtmosphereSpec>()); };
  k.programs = {kProgram};
  return k;
}

}  // namespace specbake::atmosphere
