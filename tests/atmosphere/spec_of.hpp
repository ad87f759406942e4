#pragma once
// An atmosphere job's spec from its YAML lines (those after `kind: atmosphere`, indented by four
// spaces), parsed as a config file's job is.
#include <string>

#include "kinds/atmosphere/model/spec.hpp"
#include "registry/registry.hpp"

namespace specbake::testing {

inline AtmosphereSpec spec_of(const std::string& job_yaml) {
  const Config c = parse_config("specbake: 1\njobs:\n  - name: sky\n    kind: atmosphere\n" + job_yaml, "spec_of.yaml");
  return c.jobs.at(0).as<AtmosphereSpec>();
}

}  // namespace specbake::testing
