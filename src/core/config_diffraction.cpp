#include "core/yaml_at.hpp"

namespace specbake::config_detail {

DiffractionSpec parse_diffraction(const At& job, nlohmann::json&, Inputs&) {
  job.child("kind").fail("job kind 'diffraction' is not available in this version of specbake");
}

}  // namespace specbake::config_detail
