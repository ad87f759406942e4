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
struct Band;
class Timings;
// spectrum.bin: those rows as float32 [L][4], and parameters.spectrum_normalisation (Σ D65·ȳ·1 nm);
// returns the rows.
std::vector<double> add_spectrum_file(const RangeNm& range, BakeResult& r);
// One EXR per term of `values` ([T][height][width][re, im] float32), `folder`/F_nnn.exr with
// R = Re F_n, G = Im F_n (half when storage is half), naming the band it belongs to.
void add_term_exrs(const std::vector<float>& values, const std::vector<Band>& bands, int width, int height,
                   Storage storage, const std::string& folder, const std::string& source_file,
                   const std::string& rows_columns, Timings& tm, BakeResult& r);
// κ values where the error is measured: κ_lo, κ_hi, band edges and middles.
std::vector<double> measurement_kappas(const Plan& p);

// The non-table job's preview: CIE XYZ of each pixel of an n² picture (kPreviewSize by default) of the (u, v)
// disk, white D65 light at normal incidence, XYZ(u,v) = Σ_λ |P(u/λ, v/λ; κ)/M²|²·D65·x̄ȳz̄·Δλ every
// 5 nm, w = 1 + √(1 − u² − v²), κ = 2πw/λ, |P|² bilinear between bins; no Fresnel or geometry
// factor (kernels/diffraction/table.cl, bins_preview_xyz). On `dev` when given (diffraction_bins_preview,
// one work item per pixel over the bundle's [T][kv][ku] terms), else on the host's threads in
// double (the terms regrouped per bin first); each pixel's sum in wavelength order either way.
inline constexpr int kPreviewSize = 192;
struct Terms;
std::vector<double> preview_xyz(cl_util::Device* dev, const Field& f, const Plan& p, const Terms& t,
                                const std::vector<double>& spectrum, double w_max, int n = kPreviewSize);

// With a table (table_job.cpp): the bake, the plan's table block, and the size budget: the
// planned bundle in MB, or an InputError at max_bundle_mb (or the table, or the job) naming
// the settings that drive the size.
BakeResult bake_table(const DiffractionSpec& spec, JobContext& ctx);
nlohmann::json table_plan_json(const DiffractionSpec& spec, const Field& f, const Plan& p);
double check_bundle_budget(const DiffractionSpec& spec, const Field& f, const Plan& p);

}  // namespace specbake::diffraction
