#pragma once
#include "job/kind.hpp"
#include "kinds/diffraction/spec.hpp"

namespace specbake::diffraction {

nlohmann::json plan(const DiffractionSpec& spec, JobContext& ctx);
BakeResult bake(const DiffractionSpec& spec, JobContext& ctx);

}  // namespace specbake::diffraction
