// Bad configs, through the CLI: each gives its documented exit code (README, "Exit codes":
// 3 invalid config, 5 I/O, 2 usage) and a message naming the file, line:column (and key)
// and what was expected; nothing is written, and a bundle from an earlier good run into the
// same output folder stays exactly as it was (every file's sha256, `latest`).
#include <gtest/gtest.h>
#include <unistd.h>

#include <sys/stat.h>

#include <cstdio>
#include <regex>
#include <string>
#include <vector>

#include "support/testing.hpp"

namespace {

namespace t = specbake::testing;
namespace fs = std::filesystem;

const char* kGood = R"(specbake: 1
output: out
jobs:
  - name: good
    kind: dispersion
    samples: 8
    material: {n_d: 1.5168, v_d: 64.17}
)";

struct BadConfig {
  const char* label;
  std::string yaml;
  int exit_code;
  // Where the error is: the token it is about (its occurrence-th copy in yaml gives the
  // expected line:column), or an explicit "line:column" for a whole-document error, or, for
  // malformed YAML, "lines A-B": the parser reports where it gave up, which is the faulty
  // line or the next one.
  std::string at_token;
  int occurrence;
  std::string at;           // when at_token is empty
  std::string key;          // the key path the message must name ("" if none)
  std::vector<std::string> expected;  // phrases saying what was expected
};

std::string job(const std::string& body) {
  return "specbake: 1\noutput: fresh\njobs:\n  - name: j\n    kind: dispersion\n" + body;
}
std::string sky(const std::string& body) {
  return "specbake: 1\noutput: fresh\njobs:\n  - name: j\n    kind: atmosphere\n" + body;
}
const std::string kMat = "    material: {n_d: 1.5168, v_d: 64.17}\n";

std::vector<BadConfig> bad_configs() {
  return {
      {"malformed YAML (unclosed flow sequence)", job("    range_nm: [380, 780\n" + kMat), 3, "[", 1, "", "",
       {"'[' is never closed"}},
      {"malformed YAML (bad indentation)", "specbake: 1\njobs:\n  - name: j\n   kind: dispersion\n", 3, "", 0, "lines 4-5", "",
       {"malformed YAML"}},
      {"unknown top-level key", "specbake: 1\noutptu: fresh\n" + job(kMat).substr(12), 3, "outptu", 1, "", "outptu",
       {"unknown key 'outptu'", "specbake, output, device, jobs"}},
      {"unknown job key", job("    sample: 16\n" + kMat), 3, "sample:", 1, "", "jobs[0].sample",
       {"unknown key 'sample'", "samples"}},
      {"unknown material key", job("    material: {n_d: 1.5168, vd: 64.17}\n"), 3, "vd", 1, "",
       "jobs[0].material.vd", {"unknown key 'vd'", "v_d"}},
      {"wrong type: samples is text", job("    samples: sixteen\n" + kMat), 3, "sixteen", 1, "", "jobs[0].samples",
       {"expected an integer", "auto", "'sixteen'"}},
      {"wrong type: samples is fractional", job("    samples: 16.5\n" + kMat), 3, "16.5", 1, "", "jobs[0].samples",
       {"expected an integer", "'16.5'"}},
      {"wrong type: range_nm is a number", job("    range_nm: 380\n" + kMat), 3, "380", 1, "", "jobs[0].range_nm",
       {"expected a list of numbers"}},
      {"wrong type: range_nm holds text", job("    range_nm: [380, red]\n" + kMat), 3, "red", 1, "",
       "jobs[0].range_nm[1]", {"expected a number", "'red'"}},
      {"wrong type: tolerance is a list", job("    tolerance_de2000: [1]\n" + kMat), 3, "[1]", 1, "",
       "jobs[0].tolerance_de2000", {"expected a number"}},
      {"wrong type: material is text", job("    material: BK7\n"), 3, "BK7", 1, "", "jobs[0].material",
       {"expected a material", "mapping"}},
      {"negative range", job("    range_nm: [-10, 780]\n" + kMat), 3, "[-10", 1, "", "jobs[0].range_nm",
       {"range inside", "360, 830"}},
      {"reversed range", job("    range_nm: [780, 380]\n" + kMat), 3, "[780", 1, "", "jobs[0].range_nm",
       {"lo < hi"}},
      {"empty range", job("    range_nm: [500, 500]\n" + kMat), 3, "[500", 1, "", "jobs[0].range_nm", {"lo < hi"}},
      {"samples 0", job("    samples: 0\n" + kMat), 3, "0\n", 1, "", "jobs[0].samples",
       {"expected an integer in [1, 4096]", "'0'"}},
      {"samples negative", job("    samples: -4\n" + kMat), 3, "-4", 1, "", "jobs[0].samples",
       {"expected an integer in [1, 4096]"}},
      {"samples 5000", job("    samples: 5000\n" + kMat), 3, "5000", 1, "", "jobs[0].samples",
       {"expected an integer in [1, 4096]", "'5000'"}},
      {"unknown glass", job("    material: {glass: N-BK8}\n"), 3, "N-BK8", 1, "", "jobs[0].material.glass",
       {"unknown glass 'N-BK8'", "N-BK7"}},
      {"Sellmeier C in nm² instead of µm²",
       job("    material: {sellmeier: {B: [1.03961212, 0.231792344, 1.01046945], C: [6000.69867, 20017.9144, "
           "103560653.0]}}\n"),
       3, "{B: [1.03961212", 1, "", "jobs[0].material.sellmeier", {"transparent glass", "nm²", "divide by 10^6"}},
      // n rises with λ (n_F 1.486 < n_C 1.607), its pole at √0.8 µm = 894 nm outside the range.
      {"Sellmeier with anomalous dispersion", job("    material: {sellmeier: {B: [1.0, -0.5], C: [0.0, 0.8]}}\n"), 3,
       "{B: [1.0, -0.5]", 1, "", "jobs[0].material.sellmeier", {"normal dispersion"}},
      {"Sellmeier pole inside the range", job("    material: {sellmeier: {B: [1.0, 0.2], C: [0.006, 0.25]}}\n"), 3,
       "0.25", 1, "", "jobs[0].material.sellmeier.C[1]", {"pole", "puts it at 500 nm"}},
      {"unknown sampling", job("    sampling: random\n" + kMat), 3, "random", 1, "", "jobs[0].sampling",
       {"uniform | gauss-legendre | visible-pdf | inverse-square", "'random'"}},
      {"n_d out of range", job("    material: {n_d: 0.9, v_d: 64.17}\n"), 3, "0.9", 1, "", "jobs[0].material.n_d",
       {"(1, 5]"}},
      {"duplicate job names",
       "specbake: 1\noutput: fresh\njobs:\n  - name: twice\n    kind: dispersion\n" + kMat +
           "  - name: twice\n    kind: dispersion\n" + kMat,
       3, "twice", 2, "", "jobs[1].name", {"duplicate job name 'twice'", ":4:"}},
      {"missing specbake version", "output: fresh\njobs:\n  - name: j\n    kind: dispersion\n" + kMat, 3, "", 0, "1:1",
       "", {"specbake: 1", "schema version"}},
      {"wrong schema version", "specbake: 2\n" + job(kMat).substr(12), 3, "2\n", 1, "", "specbake",
       {"unsupported schema version '2'", "version 1"}},
      {"bad job name: path", job(kMat).replace(job(kMat).find("name: j"), 7, "name: ../x"), 3, "../x", 1, "",
       "jobs[0].name", {"[a-z0-9][a-z0-9._-]*", "'../x'"}},
      {"bad job name: upper case", job(kMat).replace(job(kMat).find("name: j"), 7, "name: Upper"), 3, "Upper", 1, "",
       "jobs[0].name", {"[a-z0-9][a-z0-9._-]*", "'Upper'"}},
      {"unknown kind", "specbake: 1\noutput: fresh\njobs:\n  - name: j\n    kind: refraction\n" + kMat, 3,
       "refraction", 1, "", "jobs[0].kind", {"dispersion | diffraction | atmosphere", "'refraction'"}},
      {"duplicate YAML key", job("    samples: 16\n    samples: 8\n" + kMat), 3, "samples", 2, "",
       "jobs[0].samples", {"duplicate key 'samples'"}},
      {"duplicate top-level key", "specbake: 1\noutput: fresh\noutput: other\njobs:\n  - name: j\n    kind: dispersion\n" + kMat,
       3, "output", 2, "", "output", {"duplicate key 'output'"}},
      {"empty jobs list", "specbake: 1\noutput: fresh\njobs: []\n", 3, "[]", 1, "", "jobs", {"non-empty list of jobs"}},
      // the atmosphere's scene (docs/atmosphere.md, "The scene check")
      {"scene: unknown views", sky("    scene: {views: skyy}\n"), 3, "skyy", 1, "", "jobs[0].scene.views",
       {"sky | ground | all", "did you mean 'sky'"}},
      {"scene: a sun below what the textures hold", sky("    scene: {sun_elevation_deg: [-20, 10]}\n"), 3, "-20", 1,
       "", "jobs[0].scene.sun_elevation_deg", {"sun elevations >= -12", "raise max_sun_zenith_deg to 110"}},
      {"scene: min above max", sky("    scene: {camera_altitude_km: [2, 1]}\n"), 3, "[2, 1]", 1, "",
       "jobs[0].scene.camera_altitude_km", {"min <= max"}},
      {"scene: no points", sky("    scene: {points: -5}\n"), 3, "-5", 1, "", "jobs[0].scene.points",
       {"integer in [1, 65536]"}},
      {"scene: two tolerances", sky("    scene: {tolerance_de2000: 2, tolerance_relative: 0.25}\n"), 3, "0.25", 1, "",
       "jobs[0].scene.tolerance_relative", {"one of tolerance_de2000 and tolerance_relative"}},
      {"scene: ground views above the horizon", sky("    scene: {views: ground, view_elevation_deg: [0, 10]}\n"), 3,
       "[0, 10]", 1, "", "jobs[0].scene.view_elevation_deg", {"meet the ground views"}},
      {"scene: unknown key", sky("    scene: {point: 10}\n"), 3, "point", 1, "", "jobs[0].scene.point",
       {"unknown key 'point'", "points"}},
      {"scene: not none", sky("    scene: nothing\n"), 3, "nothing", 1, "", "jobs[0].scene", {"none"}},
      // the quadratures (docs/atmosphere.md, "Config")
      {"quadrature: unknown phase weights", sky("    quadrature: {phase_weights: normalized}\n"), 3, "normalized", 1, "",
       "jobs[0].quadrature.phase_weights", {"normalised | plain", "did you mean 'normalised'"}},
      // sizes as a percentage of the defaults (docs/atmosphere.md, "Config")
      {"sizes: not a percentage", sky("    sizes: large\n"), 3, "large", 1, "", "jobs[0].sizes",
       {"percentage of the sizes", "e.g. 150%"}},
      {"sizes: 0%", sky("    sizes: 0%\n"), 3, "0%", 1, "", "jobs[0].sizes", {"(0%, 1000%]"}},
      {"sizes.scale: too large for nu", sky("    sizes: {scale: 900%}\n"), 3, "900%", 1, "", "jobs[0].sizes.scale",
       {"nu size 72 exceeds 64"}},
      {"sizes: auto without a scene tolerance", sky("    sizes: auto\n"), 3, "auto", 1, "", "jobs[0].sizes",
       {"sizes: auto searches", "tolerance_de2000"}},
      {"spectrum: auto with a relative tolerance", sky("    spectrum: auto\n    scene: {tolerance_relative: 0.1}\n"), 3,
       "auto", 1, "", "jobs[0].spectrum", {"spectrum: auto searches", "colour difference"}},
      {"spectrum: neither rgb nor auto", sky("    spectrum: rbg\n"), 3, "rbg", 1, "", "jobs[0].spectrum",
       {"rgb | auto", "did you mean 'rgb'"}},
      {"store: radiance with a count not a multiple of 4", sky("    spectrum: {count: 10, store: radiance}\n"), 3,
       "10", 1, "", "jobs[0].spectrum.count", {"multiple of 4", "got 10"}},
      {"store: radiance without a count, default 48 is fine; a typo in store is not",
       sky("    spectrum: {store: radiant}\n"), 3, "radiant", 1, "", "jobs[0].spectrum.store",
       {"luminance | radiance", "did you mean 'radiance'"}},
      {"sizes: unknown key beside scale", sky("    sizes: {scal: 50%}\n"), 3, "scal", 1, "", "jobs[0].sizes.scal",
       {"did you mean 'scale'"}},
  };
}

// The good bundle every bad run must leave alone.
class ConfigErrors : public ::testing::Test {
 protected:
  void SetUp() override {
    t::write_file(tmp_ / "good.yaml", kGood);
    const auto r = t::run_cli({"run", (tmp_ / "good.yaml").string()});
    ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
    before_ = t::snapshot(tmp_ / "out");
    ASSERT_EQ(before_.links.size(), 1u);  // good/latest
    ASSERT_GE(before_.files.size(), 8u);
  }
  t::TempDir tmp_;
  t::TreeSnapshot before_;
};

TEST_F(ConfigErrors, EachBadConfigNamesWhereAndWhatAndWritesNothing) {
  int i = 0;
  for (const BadConfig& c : bad_configs()) {
    SCOPED_TRACE(c.label);
    const fs::path dir = tmp_ / ("case" + std::to_string(i++));
    const fs::path file = dir / "bad.yaml";
    t::write_file(file, c.yaml);
    // 1) As written: its own output folder ("fresh", relative to the config) must not appear.
    const auto r = t::run_cli({"run", file.string()}, dir);
    EXPECT_EQ(r.exit_code, c.exit_code) << r.out << r.err;
    if (c.at.rfind("lines ", 0) == 0) {
      int lo = 0, hi = 0;
      ASSERT_EQ(std::sscanf(c.at.c_str(), "lines %d-%d", &lo, &hi), 2);
      std::smatch m;
      const std::regex re(std::regex_replace(file.string(), std::regex(R"([.^$|()\[\]{}*+?\\])"), R"(\$&)") +
                          R"(:(\d+):(\d+): )");
      ASSERT_TRUE(std::regex_search(r.err, m, re)) << "expected " << file.string() << ":line:column in:\n" << r.err;
      EXPECT_GE(std::stoi(m[1]), lo) << r.err;
      EXPECT_LE(std::stoi(m[1]), hi) << r.err;
    } else {
      const std::string where = c.at_token.empty() ? c.at : t::line_col(c.yaml, c.at_token, c.occurrence);
      EXPECT_NE(r.err.find(file.string() + ":" + where), std::string::npos)
          << "expected the location " << file.string() << ":" << where << " in:\n" << r.err;
    }
    if (!c.key.empty()) EXPECT_NE(r.err.find(c.key), std::string::npos) << "expected key " << c.key << " in:\n" << r.err;
    for (const auto& phrase : c.expected) EXPECT_NE(r.err.find(phrase), std::string::npos) << "expected '" << phrase << "' in:\n" << r.err;
    EXPECT_FALSE(fs::exists(dir / "fresh")) << "an invalid config wrote its output folder";
    EXPECT_FALSE(fs::exists(dir / "assets"));
    // 2) With --out at the folder that holds a good bundle: it stays byte for byte.
    const auto r2 = t::run_cli({"run", file.string(), "--out", (tmp_ / "out").string()}, dir);
    EXPECT_EQ(r2.exit_code, c.exit_code) << r2.err;
    EXPECT_TRUE(t::snapshot(tmp_ / "out") == before_) << "the earlier bundle changed";
    // 3) `plan` rejects it the same way.
    const auto r3 = t::run_cli({"plan", file.string()}, dir);
    EXPECT_EQ(r3.exit_code, c.exit_code) << r3.err;
  }
}

// A second config reusing a job name with the same output folder: both locations named.
TEST_F(ConfigErrors, JobNameSharedAcrossConfigs) {
  t::write_file(tmp_ / "other.yaml", kGood);
  const auto r = t::run_cli({"run", (tmp_ / "good.yaml").string(), (tmp_ / "other.yaml").string()});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("other.yaml:4:5"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("good.yaml:4:5"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("same output folder"), std::string::npos) << r.err;
  EXPECT_TRUE(t::snapshot(tmp_ / "out") == before_);
}

// A config that is not there, or not a file: an I/O error (5), naming the path.
TEST_F(ConfigErrors, MissingConfigIsAnIoError) {
  const auto r = t::run_cli({"run", (tmp_ / "nope.yaml").string()});
  EXPECT_EQ(r.exit_code, 5) << r.err;
  EXPECT_NE(r.err.find((tmp_ / "nope.yaml").string()), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("No such file or directory; expected a YAML file"), std::string::npos) << r.err;  // says why
  if (::geteuid() != 0) {  // root reads any file; others get the system's reason
    t::write_file(tmp_ / "locked.yaml", kGood);
    fs::permissions(tmp_ / "locked.yaml", fs::perms::none);
    const auto l = t::run_cli({"run", (tmp_ / "locked.yaml").string()});
    EXPECT_EQ(l.exit_code, 5) << l.err;
    EXPECT_NE(l.err.find("Permission denied"), std::string::npos) << l.err;
  }
}

// An output folder that cannot be created: exit 5, naming the folder; nothing else written.
// Under root chmod does not stop writes, so the path goes below a regular file (mkdir then
// fails with ENOTDIR for everyone); a read-only folder is tried as well when not root.
TEST_F(ConfigErrors, UnwritableOutputIsAnIoError) {
  t::write_file(tmp_ / "blocker", "a regular file\n");
  const std::string yaml = std::string(kGood).replace(std::string(kGood).find("output: out"), 11, "output: blocker/out");
  t::write_file(tmp_ / "blocked.yaml", yaml);
  const auto r = t::run_cli({"run", (tmp_ / "blocked.yaml").string()});
  EXPECT_EQ(r.exit_code, 5) << r.out << r.err;
  EXPECT_NE(r.err.find((tmp_ / "blocker" / "out").string()), std::string::npos) << r.err;
  EXPECT_EQ(t::read_file(tmp_ / "blocker"), "a regular file\n");
  // --out pointing there fails the same way, before any job runs (the good output untouched).
  const auto r2 = t::run_cli({"run", (tmp_ / "good.yaml").string(), "--out", (tmp_ / "blocker" / "x").string(), "--force"});
  EXPECT_EQ(r2.exit_code, 5) << r2.err;
  EXPECT_TRUE(t::snapshot(tmp_ / "out") == before_);

  if (t::running_as_root()) {
    std::printf("running as root: read-only folder case skipped (chmod does not stop root)\n");
    return;
  }
  fs::create_directories(tmp_ / "ro");
  ASSERT_EQ(::chmod((tmp_ / "ro").c_str(), 0555), 0);
  const std::string ro = std::string(kGood).replace(std::string(kGood).find("output: out"), 11, "output: ro/out");
  t::write_file(tmp_ / "ro.yaml", ro);
  const auto r3 = t::run_cli({"run", (tmp_ / "ro.yaml").string()});
  EXPECT_EQ(r3.exit_code, 5) << r3.err;
  EXPECT_NE(r3.err.find((tmp_ / "ro" / "out").string()), std::string::npos) << r3.err;
  EXPECT_TRUE(fs::is_empty(tmp_ / "ro"));
  ::chmod((tmp_ / "ro").c_str(), 0755);
}

}  // namespace
