#include "jobs/job.hpp"

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

std::vector<std::string> kernel_files(const std::string& kind) {
  auto files = resource_paths("kernels/common/");
  for (auto& f : resource_paths("kernels/" + kind + "/")) files.push_back(f);
  return files;
}

}  // namespace specbake
