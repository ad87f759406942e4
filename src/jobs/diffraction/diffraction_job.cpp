#include "jobs/diffraction/diffraction_job.hpp"

namespace specbake::diffraction {

nlohmann::json plan(const DiffractionSpec&, JobContext&) { throw JobError("diffraction jobs are not available"); }
BakeResult bake(const DiffractionSpec&, JobContext&) { throw JobError("diffraction jobs are not available"); }

}  // namespace specbake::diffraction
