// The dispersion kind's entry in the kind table.
#include "kinds/dispersion/kind.hpp"

#include "kinds/dispersion/dispersion_job.hpp"

namespace specbake::dispersion {

Kind kind() {
  Kind k = Kind::of<DispersionSpec>("dispersion", "spectral integration matrices K_n, CMF weights and IOR tables for real-time dispersion", parse_spec, plan, bake);
  // Measured on PoCL (2 cores): fixed samples ~0.1 s, samples: auto ~1 s.
  k.cost_s = [](const JobSpec& j) { return j.as<DispersionSpec>().samples ? 0.1 : 1.0; };
  // N <= 4096 samples and a prism picture of a few thousand pixels: kilobytes.
  k.memory = [](const JobSpec&) {
    return MemoryEstimate{std::uint64_t{1} << 22, std::uint64_t{1} << 20, std::uint64_t{1} << 26};
  };
  k.programs = {kProgram};
  k.truth_records = {"prism_de2000"};
  k.describe = [](const nlohmann::json& p) {
    std::string s = std::to_string(p.value("samples", 0)) + " samples" + (p.contains("samples_auto") ? " (auto)" : "") +
                    ", " + p.value("sampling", "?");
    if (p.contains("range_nm") && p["range_nm"].size() == 2)
      s += ", " + nlohmann::json(p["range_nm"][0]).dump() + "-" + nlohmann::json(p["range_nm"][1]).dump() + " nm";
    return s;
  };
  return k;
}

}  // namespace specbake::dispersion
