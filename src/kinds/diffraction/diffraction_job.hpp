#pragma once
#include "job/kind.hpp"
#include "kinds/diffraction/spec.hpp"

namespace specbake::diffraction {

nlohmann::json plan(const DiffractionSpec& spec, JobContext& ctx);
BakeResult bake(const DiffractionSpec& spec, JobContext& ctx);

struct Field;
struct Plan;
// Spectrum rows (λ nm, D65·x̄, D65·ȳ, D65·z̄) at 1 nm steps over range_nm, Σ D65·ȳ·1 nm = 1.
std::vector<double> spectrum_rows(const RangeNm& r, double& y_norm);
// κ values where the error is measured: κ_lo, κ_hi, band edges and middles.
std::vector<double> measurement_kappas(const Plan& p);

// With a table (table_job.cpp): the bake, the plan's table block, and the size budget: the
// planned bundle in MB, or an InputError at max_bundle_mb (or the table, or the job) naming
// the settings that drive the size.
BakeResult bake_table(const DiffractionSpec& spec, JobContext& ctx);
nlohmann::json table_plan_json(const DiffractionSpec& spec, const Field& f, const Plan& p);
double check_bundle_budget(const DiffractionSpec& spec, const Field& f, const Plan& p);

}  // namespace specbake::diffraction
