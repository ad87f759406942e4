#include "jobs/job.hpp"

#include <algorithm>

#include "core/resources.hpp"
#include "jobs/atmosphere/atmosphere_job.hpp"
#include "jobs/diffraction/diffraction_job.hpp"
#include "jobs/dispersion/dispersion_job.hpp"

namespace specbake {

namespace {
template <class... F>
struct overloaded : F... {
  using F::operator()...;
};
}  // namespace

nlohmann::json plan_job(const JobSpec& job, JobContext& ctx) {
  return std::visit(overloaded{[&](const DispersionSpec& s) { return dispersion::plan(s, ctx); },
                               [&](const DiffractionSpec& s) { return diffraction::plan(s, ctx); },
                               [&](const AtmosphereSpec& s) { return atmosphere::plan(s, ctx); }},
                    job.spec);
}

BakeResult bake_job(const JobSpec& job, JobContext& ctx) {
  return std::visit(overloaded{[&](const DispersionSpec& s) { return dispersion::bake(s, ctx); },
                               [&](const DiffractionSpec& s) { return diffraction::bake(s, ctx); },
                               [&](const AtmosphereSpec& s) { return atmosphere::bake(s, ctx); }},
                    job.spec);
}

double estimated_cost(const JobSpec& job) {
  // Measured orders of magnitude on PoCL (2 cores): dispersion ~0.1 s (auto ~1 s),
  // diffraction ~1-10 s, atmosphere ~10-30 s.
  return std::visit(overloaded{[](const DispersionSpec& s) { return s.samples ? 0.1 : 1.0; },
                               [](const DiffractionSpec&) { return 5.0; },
                               [](const AtmosphereSpec&) { return 20.0; }},
                    job.spec);
}

MemoryEstimate estimated_device_memory(const JobSpec& job) {
  return std::visit(
      overloaded{
          [](const DispersionSpec&) {
            // N ≤ 4096 samples and a prism picture of a few thousand pixels: kilobytes.
            return MemoryEstimate{std::uint64_t{1} << 22, std::uint64_t{1} << 20};
          },
          [](const DiffractionSpec& s) {
            const std::uint64_t w = s.procedural ? s.procedural->size : (s.field ? s.field->width : 0);
            const std::uint64_t h = s.procedural ? s.procedural->size : (s.field ? s.field->height : 0);
            // Complex float fields of the heightfield's size: the term input, the FFT buffer and
            // the cropped terms (at most the full field per term, counted as two fields), plus a
            // complex double field for the exact transforms of the self-check.
            const std::uint64_t field = w * h * 8;
            return MemoryEstimate{4 * field + 2 * field, 2 * field};
          },
          [](const AtmosphereSpec& s) {
            // One pass of w channels (atmosphere::channels_per_pass) keeps four 4D textures on
            // the device (the two single-scattering deltas, the multiple-scattering delta and the
            // density), a ray-sample table per (r, mu) texel row (51 samples × (8 + w) values)
            // and a density incidence table per (r, mu_s) (16 directions × ((2·nu + 1)·w + 6)
            // values), plus the small 2D textures.
            const std::uint64_t w = atmosphere::channels_per_pass(s);
            const std::uint64_t real = s.double_precision ? 8 : 4;
            const std::uint64_t texels = std::uint64_t(s.scattering_r) * s.scattering_mu * s.scattering_mu_s * s.scattering_nu;
            const std::uint64_t texture = texels * w * real;
            const std::uint64_t rays = std::uint64_t(s.scattering_r) * s.scattering_mu * 51 * (8 + w) * real;
            const std::uint64_t incidence =
                std::uint64_t(s.scattering_r) * s.scattering_mu_s * 16 * ((2 * s.scattering_nu + 1) * w + 6) * real;
            return MemoryEstimate{4 * texture + rays + incidence + (std::uint64_t{1} << 24),
                                  std::max({texture, rays, incidence})};
          }},
      job.spec);
}

void check_device_memory(const JobSpec& job, const cl_util::DeviceInfo& di) {
  const MemoryEstimate need = estimated_device_memory(job);
  if (need.total_bytes > di.global_mem_bytes || need.largest_buffer > di.max_alloc_bytes)
    throw InputError(job.where, "job '" + job.name + "' needs about " + std::to_string(need.total_bytes >> 20) +
                                    " MiB of device memory (largest buffer " + std::to_string(need.largest_buffer >> 20) +
                                    " MiB) but " + di.name + " has " + std::to_string(di.global_mem_bytes >> 20) +
                                    " MiB (largest buffer " + std::to_string(di.max_alloc_bytes >> 20) +
                                    " MiB); expected smaller sizes");
}

std::vector<std::string> kernel_files(const std::string& kind) {
  auto files = resource_paths("kernels/common/");
  for (auto& f : resource_paths("kernels/" + kind + "/")) files.push_back(f);
  return files;
}

}  // namespace specbake
