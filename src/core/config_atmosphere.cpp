#include "core/yaml_at.hpp"

namespace specbake::config_detail {

AtmosphereSpec parse_atmosphere(const At& job, nlohmann::json&, Inputs&) {
  job.child("kind").fail("job kind 'atmosphere' is not available in this version of specbake");
}

}  // namespace specbake::config_detail
