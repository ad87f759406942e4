// The dispersion kind's entry in the kind table.
#include "kinds/dispersion/kind.hpp"

#include "kinds/dispersion/dispersion_job.hpp"

namespace specbake::dispersion {

Kind kind() {
  Kind k;
  k.name = "dispersion";
  k.summary = "spectral integration matrices K_n, CMF weights and IOR tables for real-time dispersion";
  k.parse = [](const yaml::At& job, nlohmann::json& norm, Inputs& inputs) -> std::shared_ptr<const KindSpec> {
    return std::make_shared<DispersionSpec>(parse_spec(job, norm, inputs));
  };
  k.plan = [](const JobSpec& j, JobContext& ctx) { return plan(j.as<DispersionSpec>(), ctx); };
  k.bake = [](const JobSpec& j, JobContext& ctx) { return bake(j.as<DispersionSpec>(), ctx); };
  // Measured on PoCL (2 cores): fixed samples ~0.1 s, samples: auto ~1 s.
  k.cost_s = [](const JobSpec& j) { return j.as<DispersionSpec>().samples ? 0.1 : 1.0; };
  // N <= 4096 samples and a prism picture of a few thousand pixels: kilobytes.
  k.memory = [](const JobSpec&) { return MemoryEstimate{std::uint64_t{1} << 22, std::uint64_t{1} << 20}; };
  k.programs = {kProgram};
  return k;
}

}  // namespace specbake::dispersion
