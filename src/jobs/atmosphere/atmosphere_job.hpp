#pragma once
#include "jobs/job.hpp"

namespace specbake::atmosphere {

nlohmann::json plan(const AtmosphereSpec& spec, JobContext& ctx);
BakeResult bake(const AtmosphereSpec& spec, JobContext& ctx);

}  // namespace specbake::atmosphere
