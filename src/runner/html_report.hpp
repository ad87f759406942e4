#pragma once
// The morning page (`specbake report DIR...`, `run --report-html FILE`): one static HTML file
// that opens from disk with no server and no network. CSS and scripts are inline (the embedded
// src/runner/report/*.css, *.js); the previews and sweep plots are inline data: URIs.
// Per job: status, time, bundle size, headline accuracy and the whole accuracy record, the
// warnings, the previews, a live WebGL2 view run by the bundle's own shipped GLSL on its data
// (atmosphere: the sky; dispersion: the prism; diffraction tables: the BRDF lobes), and what
// changed since the job's earlier bundle (io/bundle_diff).
//
// The page is built from PageJob rows, which come from an output folder's bundles
// (page_job(OutputJob)), from a run's reports (page_job(JobReport)) or from the `jobs` entries
// of a --report JSON file (page_job_from_report_entry): what one source lacks stays empty.
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "io/output_folder.hpp"
#include "runner/runner.hpp"

namespace specbake {

struct PageJob {
  std::string name, kind, status, reason, config, hash, created_utc;
  double seconds = -1.0;     // the bake's wall seconds; < 0 unknown
  fs::path bundle;           // the bundle shown; empty when there is none (failed, invalid, ...)
  fs::path previous;         // an earlier bundle of the job; empty when there is none
  nlohmann::json accuracy = nlohmann::json::array();  // the manifest's list of records
  std::vector<std::string> warnings;
  nlohmann::json parameters;
};

PageJob page_job(const OutputJob& j);
PageJob page_job(const JobReport& r);
// One entry of a --report file's "jobs" list (schema specbake.report/1).
PageJob page_job_from_report_entry(const nlohmann::json& entry);

struct ReportPage {
  std::string title = "specbake report";
  std::vector<std::string> sources;  // what the page was made from (folders, files), shown at the top
  std::vector<PageJob> jobs;
  std::vector<fs::path> sweeps;      // folders holding a sweep's sweep.json (and sweep.png)
};

// A page over output folders: every job folder's latest bundle, and the sweeps found in each
// folder or one level below it. InputError naming a folder that is not an output folder.
ReportPage report_page_from_output(const std::vector<fs::path>& dirs);

// The sweep folders (holding sweep.json) in dir or one level below it, sorted.
std::vector<fs::path> find_sweeps(const fs::path& dir);

// The page as HTML text. Reads the bundles' previews, the sweep plots, and the earlier bundles
// for the comparison; a bundle file that cannot be read is named on the page, not fatal.
std::string report_html(const ReportPage& page);

// Where `--out FILE_OR_DIR` writes: a folder (existing, or written with a trailing '/': made if
// missing) gets report.html inside; anything else is the file itself. Default (empty): ./report.html.
fs::path report_html_path(const std::string& file_or_dir);

// Writes the page atomically (a temporary beside it, renamed). IoError if it cannot.
void write_report_html(const ReportPage& page, const fs::path& file);

// Checks, before a run starts, that `file` can be written (its folder exists and is writable, it
// is not a folder): UsageError / IoError naming it.
void check_report_html_path(const fs::path& file, const std::string& option);

}  // namespace specbake
