#pragma once
#include "jobs/job.hpp"

namespace specbake::diffraction {

nlohmann::json plan(const DiffractionSpec& spec, JobContext& ctx);
BakeResult bake(const DiffractionSpec& spec, JobContext& ctx);

}  // namespace specbake::diffraction
