// `specbake report DIR...`, `run --report-html` and `inspect OUT` on a small output folder: a
// prism baked twice (two bundles: the page shows what changed) and a small grating (previews).
#include <gtest/gtest.h>

#include <regex>
#include <string>

#include "io/output_folder.hpp"
#include "runner/html_report.hpp"
#include "support/testing.hpp"

namespace {

namespace t = specbake::testing;
namespace fs = std::filesystem;
using nlohmann::json;

const char* kGrating =
    "  - name: grating\n    kind: diffraction\n"
    "    procedural: {type: sine-grating, size: 32, dx_um: 0.125, period_um: 1.0, amplitude_um: 0.2}\n"
    "    table: {size: 16}\n    coherence: {length_um: 3}\n    tolerance_advisory: true\n";

std::string prism(int samples) {
  return "  - name: prism\n    kind: dispersion\n    samples: " + std::to_string(samples) +
         "\n    material: {glass: N-BK7}\n";
}

class Report : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new t::TempDir;
    t::write_file(*dir_ / "a.yaml", "specbake: 1\noutput: out\njobs:\n" + prism(3) + kGrating);
    t::write_file(*dir_ / "b.yaml", "specbake: 1\noutput: out\njobs:\n" + prism(4));
    const auto a = t::run_cli({"run", (*dir_ / "a.yaml").string()});
    ASSERT_EQ(a.exit_code, 0) << a.err;
    const auto b = t::run_cli({"run", (*dir_ / "b.yaml").string(), "--report-html", (*dir_ / "run.html").string(),
                               "--report", (*dir_ / "run.json").string()});
    ASSERT_EQ(b.exit_code, 0) << b.err;
    const auto s = t::run_cli({"sweep", (*dir_ / "b.yaml").string(), "--job", "prism", "--vary", "samples=2,3",
                               "--out", (*dir_ / "sweeps" / "prism").string()});
    ASSERT_EQ(s.exit_code, 0) << s.err;
  }
  static void TearDownTestSuite() { delete dir_; }
  static fs::path out() { return *dir_ / "out"; }
  static t::TempDir* dir_;
};
t::TempDir* Report::dir_ = nullptr;

int count(const std::string& s, const std::string& needle) {
  int n = 0;
  for (auto p = s.find(needle); p != std::string::npos; p = s.find(needle, p + 1)) ++n;
  return n;
}

// The page names every job, shows every accuracy record of every manifest (by name), embeds the
// previews as data: URIs, compares the prism with its earlier bundle, and asks for nothing over
// the network.
TEST_F(Report, PageOverAnOutputFolder) {
  const fs::path page = *dir_ / "page" / "";
  const auto r = t::run_cli({"report", out().string(), "--out", page.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("2 job(s)"), std::string::npos) << r.out;
  const std::string html = t::read_file(*dir_ / "page" / "report.html");
  int previews = 0;
  for (const char* job : {"grating", "prism"}) {
    EXPECT_NE(html.find(">" + std::string(job) + "</a>"), std::string::npos) << job;
    const json m = t::read_json(out() / job / "latest" / "manifest.json");
    for (const auto& a : m["accuracy"]) EXPECT_NE(html.find(a["name"].get<std::string>()), std::string::npos);
    for (const auto& w : m["warnings"]) EXPECT_NE(html.find(w.get<std::string>().substr(0, 30)), std::string::npos);
    for (const auto& f : m["files"]) {
      const std::string p = f["path"];
      if (p.rfind("preview/", 0) == 0 && p != "preview/contact_sheet.png") {
        ++previews;
        EXPECT_NE(html.find(p.substr(8) + ": "), std::string::npos) << "captioned: " << p;
      }
    }
  }
  // every preview inline (the contact sheet repeats them: left out)
  EXPECT_GE(previews, 2);
  EXPECT_EQ(count(html, "src=\"data:image/png;base64,"), previews);
  // the prism's two bundles: 3 samples, then 4
  EXPECT_EQ(count(html, "Changes since the earlier bundle"), 1);
  EXPECT_NE(html.find("config.samples</td><td>3</td><td>4"), std::string::npos);
  // nothing fetched: no external scripts, styles or images
  EXPECT_FALSE(std::regex_search(html, std::regex(R"((src|href)\s*=\s*"(https?:)?//)"))) << "a network reference";
  EXPECT_EQ(html.find("<link"), std::string::npos);
  EXPECT_NE(html.find("<style>"), std::string::npos);
  EXPECT_NE(html.find("data-ready"), std::string::npos) << "the page's script is inline";
}

// run --report-html: the run's jobs (here the prism alone), with its earlier bundle.
TEST_F(Report, RunWritesThePage) {
  const std::string html = t::read_file(*dir_ / "run.html");
  EXPECT_NE(html.find(">prism</a>"), std::string::npos);
  EXPECT_EQ(html.find(">grating</a>"), std::string::npos);
  EXPECT_NE(html.find("<td>built</td>"), std::string::npos);
  EXPECT_NE(html.find("Changes since the earlier bundle"), std::string::npos);
}

// Mistakes: a folder without job folders (exit 3), an --out in a missing folder (exit 5),
// --report-html on plan (exit 2); nothing written.
TEST_F(Report, Mistakes) {
  fs::create_directories(*dir_ / "empty");
  auto r = t::run_cli({"report", (*dir_ / "empty").string(), "--out", (*dir_ / "x.html").string()});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("expected an output folder"), std::string::npos) << r.err;
  r = t::run_cli({"report", out().string(), "--out", (*dir_ / "missing" / "x.html").string()});
  EXPECT_EQ(r.exit_code, 5) << r.err;
  EXPECT_NE(r.err.find("no folder"), std::string::npos) << r.err;
  r = t::run_cli({"plan", (*dir_ / "b.yaml").string(), "--report-html", (*dir_ / "p.html").string()});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  r = t::run_cli({"run", (*dir_ / "b.yaml").string(), "--report-html", (*dir_ / "missing" / "r.html").string()});
  EXPECT_EQ(r.exit_code, 5) << r.err;
  EXPECT_FALSE(fs::exists(*dir_ / "x.html"));
  EXPECT_FALSE(fs::exists(*dir_ / "p.html"));
  EXPECT_FALSE(fs::exists(*dir_ / "missing"));
}

// inspect OUT: one line per job with its latest bundle, size, age and headline; --json the same.
TEST_F(Report, InspectAnOutputFolder) {
  const auto r = t::run_cli({"inspect", out().string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("2 job(s)"), std::string::npos) << r.out;
  const auto j = t::run_cli({"inspect", out().string(), "--json"});
  ASSERT_EQ(j.exit_code, 0) << j.err;
  const json list = json::parse(j.out)["jobs"];
  ASSERT_EQ(list.size(), 2u);
  for (const auto& e : list) {
    const std::string name = e["name"];
    const fs::path bundle = fs::canonical(out() / name / "latest");
    EXPECT_EQ(e["bundle"], bundle.string());
    const json m = t::read_json(bundle / "manifest.json");
    std::uint64_t bytes = fs::file_size(bundle / "manifest.json");
    for (const auto& f : m["files"]) {
      EXPECT_EQ(fs::file_size(bundle / f["path"].get<std::string>()), f["bytes"].get<std::uint64_t>());
      bytes += f["bytes"].get<std::uint64_t>();
    }
    EXPECT_EQ(e["bytes"], bytes) << name;
    EXPECT_EQ(e["headline"], specbake::accuracy_headline(m["accuracy"]));
    EXPECT_GE(e["age_s"].get<double>(), 0.0);
    EXPECT_LT(e["age_s"].get<double>(), 3600.0) << "baked by this test";
    // the line names the job, its bundle's hash12 and the headline
    EXPECT_TRUE(std::regex_search(r.out, std::regex(name + R"( +\w+ +)" + bundle.filename().string()))) << r.out;
    EXPECT_NE(r.out.find(e["headline"].get<std::string>()), std::string::npos) << r.out;
    EXPECT_EQ(e["previous"].is_string(), name == "prism") << "the prism was baked twice";
  }
  // a single job folder still gets the per-file check
  const auto one = t::run_cli({"inspect", (out() / "prism").string()});
  EXPECT_EQ(one.exit_code, 0) << one.err;
  EXPECT_NE(one.out.find("match their sha256"), std::string::npos);
}

// A folder of sweeps beside the output folder: each sweep's plot, titled by its job and keys.
TEST_F(Report, Sweeps) {
  const auto r = t::run_cli({"report", out().string(), (*dir_ / "sweeps").string(), "--out", (*dir_ / "s.html").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("1 sweep(s)"), std::string::npos) << r.out;
  const std::string html = t::read_file(*dir_ / "s.html");
  EXPECT_NE(html.find("prism (dispersion): 2 points over samples"), std::string::npos);
  if (fs::exists(*dir_ / "sweeps" / "prism" / "sweep.png"))
    EXPECT_NE(html.find("speed against error (sweep.png)"), std::string::npos);
}

// Rows from a --report file's entries (what a night's shard reports hold): the same fields as
// from the bundle, and the earlier bundle found beside it.
TEST_F(Report, RowsFromAReportFile) {
  const json report = t::read_json(*dir_ / "run.json");
  ASSERT_EQ(report["jobs"].size(), 1u);
  const specbake::PageJob j = specbake::page_job_from_report_entry(report["jobs"][0]);
  EXPECT_EQ(j.name, "prism");
  EXPECT_EQ(j.kind, "dispersion");
  EXPECT_EQ(j.status, "built");
  EXPECT_EQ(fs::canonical(j.bundle), fs::canonical(out() / "prism" / "latest"));
  EXPECT_FALSE(j.previous.empty());
  EXPECT_EQ(j.accuracy, report["jobs"][0]["accuracy"]);
  EXPECT_GT(j.seconds, 0.0);
  specbake::ReportPage page;
  page.jobs = {j, specbake::page_job_from_report_entry(json{{"name", "broken"}, {"status", "invalid"},
                                                            {"reason", "c.yaml:3:5: <expected> a number"}})};
  const std::string html = specbake::report_html(page);
  EXPECT_NE(html.find("Changes since the earlier bundle"), std::string::npos);
  EXPECT_NE(html.find("c.yaml:3:5: &lt;expected&gt; a number"), std::string::npos) << "escaped";
}

// A bundle without what a live view needs gets a note saying which file is missing, not a broken view.
TEST(ReportPage, LiveViewNotes) {
  t::TempDir d;
  for (const char* kind : {"atmosphere", "dispersion", "diffraction"}) {
    const fs::path b = d / "out" / kind / "0123456789ab";
    fs::create_directories(b);
    t::write_file(b / "manifest.json", json{{"job", {{"name", kind}, {"kind", kind}}},
                                            {"created_utc", "2026-01-01T00:00:00Z"},
                                            {"files", json::array()},
                                            {"accuracy", json::array()}}
                                           .dump());
    fs::create_directory_symlink("0123456789ab", d / "out" / kind / "latest");
  }
  const auto page = specbake::report_page_from_output({d / "out"});
  ASSERT_EQ(page.jobs.size(), 3u);
  const std::string html = specbake::report_html(page);
  for (const char* file : {"sampling.glsl", "dispersion.glsl", "shader/diffraction_brdf.glsl"})
    EXPECT_NE(html.find(std::string("no live view of this bundle: it has no ") + file), std::string::npos) << file;
  EXPECT_EQ(html.find("class=\"live-data\""), std::string::npos);
}

TEST(OutputFolder, Formats) {
  EXPECT_EQ(specbake::human_bytes(512), "512 B");
  EXPECT_EQ(specbake::human_bytes(3 * 1024 * 1024 + 200 * 1024), "3.2 MiB");
  EXPECT_EQ(specbake::human_age(45), "45 s");
  EXPECT_EQ(specbake::human_age(3 * 3600), "3.0 h");
  EXPECT_LT(specbake::seconds_since_utc("2026-11-28T07:35:44"), 0.0);
  EXPECT_GT(specbake::seconds_since_utc("2020-01-01T00:00:00Z"), 1e8);
  EXPECT_EQ(specbake::accuracy_headline(json::array()), "-");
  EXPECT_EQ(specbake::accuracy_headline(json::parse(
                R"([{"name":"self_check","value":5.6e-6,"tolerance":0.002,"passed":true}])")),
            "self_check 5.6e-06 <= 0.002");
}

}  // namespace
