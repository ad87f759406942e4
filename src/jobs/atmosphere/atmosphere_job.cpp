#include "jobs/atmosphere/atmosphere_job.hpp"

namespace specbake::atmosphere {

nlohmann::json plan(const AtmosphereSpec&, JobContext&) { throw JobError("atmosphere jobs are not available"); }
BakeResult bake(const AtmosphereSpec&, JobContext&) { throw JobError("atmosphere jobs are not available"); }

}  // namespace specbake::atmosphere
