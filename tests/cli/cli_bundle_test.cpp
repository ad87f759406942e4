// The `specbake` command and the bundles it writes: manifest contents, sha256 checks through
// `inspect`, skip-if-unchanged, --force, determinism, --only, --out, plan, devices, help,
// usage errors, and a changed config giving a new bundle that `latest` moves to.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <regex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "core/errors.hpp"
#include "core/hash.hpp"
#include "core/version.hpp"
#include "io/bundle.hpp"
#include "kinds/dispersion/dispersion_job.hpp"
#include "job/kind.hpp"
#include "support/testing.hpp"

namespace {

namespace t = specbake::testing;
namespace fs = std::filesystem;
using nlohmann::json;

std::string config(int samples, const std::string& output = "out", const std::string& extra_jobs = "") {
  return "specbake: 1\noutput: " + output +
         "\njobs:\n  - name: prism\n    kind: dispersion\n    samples: " + std::to_string(samples) +
         "\n    sampling: gauss-legendre\n    range_nm: [390, 780]\n    material: {glass: N-BK7}\n" + extra_jobs;
}

const std::set<std::string> kDataFiles = {"wavelengths.bin", "weights.bin",     "matrices.bin",   "ior_offsets.bin",
                                          "ior.bin",         "dispersion.json", "dispersion.glsl", "preview/prism.png"};

// The files of a bundle without the manifest (whose timestamps and timings differ per run).
std::map<std::string, std::string> data_files(const fs::path& bundle) {
  auto s = t::snapshot(bundle).files;
  s.erase("manifest.json");
  return s;
}

class Cli : public ::testing::Test {
 protected:
  fs::path cfg(const std::string& text, const std::string& name = "c.yaml") {
    t::write_file(tmp_ / name, text);
    return tmp_ / name;
  }
  t::CliResult run(std::vector<std::string> args) { return t::run_cli(args, tmp_.path()); }
  // Builds config(samples) into tmp/out and returns the bundle folder.
  fs::path build(int samples = 6) {
    const auto r = run({"run", cfg(config(samples)).string()});
    EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
    return fs::canonical(tmp_ / "out" / "prism" / "latest");
  }
  t::TempDir tmp_;
};

TEST_F(Cli, ManifestDescribesTheBundle) {
  const fs::path b = build(6);
  const json m = t::read_json(b / "manifest.json");
  EXPECT_EQ(m.at("schema"), "specbake.bundle/1");
  EXPECT_EQ(m.at("tool").at("name"), "specbake");
  EXPECT_EQ(m.at("tool").at("version"), specbake::kVersion);
  // The job and its hash: 64 hex digits, the bundle folder is named by the first 12.
  EXPECT_EQ(m.at("job").at("name"), "prism");
  EXPECT_EQ(m.at("job").at("kind"), "dispersion");
  const std::string hash = m.at("job").at("hash");
  EXPECT_TRUE(std::regex_match(hash, std::regex("[0-9a-f]{64}"))) << hash;
  EXPECT_EQ(b.filename().string(), hash.substr(0, 12));
  EXPECT_EQ(fs::read_symlink(tmp_ / "out" / "prism" / "latest").string(), hash.substr(0, 12));
  // The normalised config holds what defines the result.
  const json& c = m.at("config");
  EXPECT_EQ(c.at("samples"), 6);
  EXPECT_EQ(c.at("sampling"), "gauss-legendre");
  EXPECT_EQ(c.at("range_nm"), json::array({390.0, 780.0}));
  EXPECT_EQ(c.at("material").at("glass"), "N-BK7");
  // Inputs and kernels with the sha256 of the files they were embedded from.
  const auto src = t::source_dir();
  EXPECT_EQ(m.at("inputs").at("data/cie/cie1931_2deg_1nm.csv"),
            specbake::sha256_file(src / "data/cie/cie1931_2deg_1nm.csv"));
  EXPECT_EQ(m.at("inputs").at("data/glass/glasses.csv"), specbake::sha256_file(src / "data/glass/glasses.csv"));
  // Kernels: each program the kind builds, with the sha256 of its fully expanded source (every
  // file it includes, as the device compiles it), so a change to any included file — of this
  // kind or another — changes the hash.
  ASSERT_EQ(m.at("kernels").size(), 1u);
  const std::string program = "kernels/dispersion/kernels.cl";
  ASSERT_TRUE(m.at("kernels").contains(program));
  const std::string expanded = specbake::expanded_program(program);
  EXPECT_EQ(m.at("kernels").at(program), specbake::sha256_hex(expanded));
  for (const char* included : {"kernels/common/real.h", "kernels/common/colour.cl", "kernels/dispersion/dispersion.cl",
                               "kernels/dispersion/kernels.cl"}) {
    EXPECT_NE(expanded.find(std::string("#line 1 \"") + included + "\""), std::string::npos) << included;
    std::ifstream in(src / included);
    std::string first_line;
    std::getline(in, first_line);
    EXPECT_NE(expanded.find(first_line), std::string::npos) << included;
  }
  EXPECT_FALSE(m.at("device").at("name").get<std::string>().empty());
  EXPECT_TRUE(m.contains("created_utc"));
  EXPECT_TRUE(m.at("timings_s").contains("bake"));
  // Resolved parameters and accuracy figures.
  const json& p = m.at("parameters");
  EXPECT_EQ(p.at("samples"), 6);
  EXPECT_EQ(p.at("material").at("ior_model"), "sellmeier");
  // One accuracy record per figure, {name, metric, value, tolerance, reference, passed}; the first
  // is the headline.
  const json& a = m.at("accuracy");
  ASSERT_TRUE(a.is_array());
  EXPECT_EQ(a.at(0).at("name"), "prism_de2000");
  for (const char* k : {"prism_de2000", "sum_K_minus_I", "self_check", "cauchy_vs_sellmeier"}) {
    const json* rec = specbake::find_accuracy(a, k);
    ASSERT_NE(rec, nullptr) << k;
    for (const char* field : {"name", "metric", "value", "tolerance", "reference", "passed"})
      EXPECT_TRUE(rec->contains(field)) << k << "." << field;
    EXPECT_TRUE(rec->at("passed").get<bool>()) << k;
  }
  const json& sum_k = *specbake::find_accuracy(a, "sum_K_minus_I");
  EXPECT_LE(sum_k.at("value").get<double>(), sum_k.at("tolerance").get<double>());
  // Every file: listed once, sha256 and size match, .bin shapes as documented.
  const std::map<std::string, std::vector<std::int64_t>> shapes = {
      {"wavelengths.bin", {6}}, {"weights.bin", {6, 3}}, {"matrices.bin", {6, 3, 3}}, {"ior_offsets.bin", {6}},
      {"ior.bin", {6}}};
  std::set<std::string> listed;
  for (const auto& f : m.at("files")) {
    const std::string path = f.at("path");
    EXPECT_TRUE(listed.insert(path).second) << "listed twice: " << path;
    EXPECT_EQ(f.at("sha256"), specbake::sha256_file(b / path)) << path;
    EXPECT_EQ(f.at("bytes").get<std::uintmax_t>(), fs::file_size(b / path)) << path;
    if (auto it = shapes.find(path); it != shapes.end()) {
      EXPECT_EQ(f.at("dtype"), "float32") << path;
      EXPECT_EQ(f.at("shape").get<std::vector<std::int64_t>>(), it->second) << path;
      std::int64_t count = 1;
      for (auto d : it->second) count *= d;
      EXPECT_EQ(f.at("bytes").get<std::int64_t>(), 4 * count) << path;
      EXPECT_TRUE(f.contains("units")) << path;
      EXPECT_NE(f.at("layout").get<std::string>().find("little-endian"), std::string::npos) << path;
    }
  }
  EXPECT_EQ(listed, kDataFiles);
  // Nothing in the folder that the manifest does not list.
  std::set<std::string> present;
  for (const auto& e : fs::recursive_directory_iterator(b))
    if (e.is_regular_file()) present.insert(fs::relative(e.path(), b).generic_string());
  present.erase("manifest.json");
  EXPECT_EQ(present, kDataFiles);
}

TEST_F(Cli, InspectChecksEveryFile) {
  const fs::path b = build();
  auto r = run({"inspect", (tmp_ / "out" / "prism" / "latest").string()});
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("all 8 files match their sha256"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("prism_de2000"), std::string::npos) << r.out;  // accuracy figures shown
  // One flipped byte (same size) is found.
  {
    std::fstream f(b / "matrices.bin", std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(17);
    f.put('\x5a');
  }
  r = run({"inspect", b.string()});
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("SHA256 MISMATCH  matrices.bin"), std::string::npos) << r.out;
  // A missing file too.
  fs::remove(b / "ior.bin");
  r = run({"inspect", b.string()});
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("MISSING  ior.bin"), std::string::npos) << r.out;
  // Neither a bundle nor a job folder: an input error naming what is expected.
  r = run({"inspect", tmp_.path().string()});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("manifest.json"), std::string::npos) << r.err;
}

TEST_F(Cli, UnchangedJobIsSkippedAndNotRewritten) {
  const fs::path b = build();
  const auto before = t::snapshot(tmp_ / "out");
  const auto times = t::mtimes(b);
  // Coarse file-system timestamps must not hide a rewrite.
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const auto r = run({"run", (tmp_ / "c.yaml").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::regex_search(r.out, std::regex("prism +dispersion +up-to-date"))) << r.out;
  EXPECT_NE(r.out.find("0 built, 1 up to date, 0 failed"), std::string::npos) << r.out;
  EXPECT_EQ(t::mtimes(b), times);
  EXPECT_TRUE(t::snapshot(tmp_ / "out") == before);
}

TEST_F(Cli, ForceRebuildsTheSameBytes) {
  const fs::path b = build();
  const auto data = data_files(b);
  const auto m0 = t::read_json(b / "manifest.json");
  const auto times = t::mtimes(b);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const auto r = run({"run", (tmp_ / "c.yaml").string(), "--force"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("1 built, 0 up to date"), std::string::npos) << r.out;
  EXPECT_NE(t::mtimes(b), times) << "--force did not rewrite the bundle";
  EXPECT_EQ(data_files(b), data);
  EXPECT_EQ(t::read_json(b / "manifest.json").at("job").at("hash"), m0.at("job").at("hash"));
  EXPECT_EQ(fs::read_symlink(tmp_ / "out" / "prism" / "latest"), b.filename());
}

// A truncated file makes the bundle incomplete (sizes are checked before skipping): rebuilt.
TEST_F(Cli, IncompleteBundleIsRebuilt) {
  const fs::path b = build();
  const auto data = data_files(b);
  fs::resize_file(b / "weights.bin", 12);
  const auto r = run({"run", (tmp_ / "c.yaml").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("1 built"), std::string::npos) << r.out;
  EXPECT_EQ(data_files(b), data);
}

TEST_F(Cli, SameInputsGiveIdenticalBytes) {
  const fs::path c = cfg(config(12));
  // Two runs into different folders, from different working directories (the second names its
  // folder with the short -o).
  fs::create_directories(tmp_ / "elsewhere");
  auto r1 = t::run_cli({"run", c.string(), "--out", (tmp_ / "one").string()}, tmp_.path());
  auto r2 = t::run_cli({"run", c.string(), "-o", (tmp_ / "two").string()}, tmp_ / "elsewhere");
  ASSERT_EQ(r1.exit_code, 0) << r1.err;
  ASSERT_EQ(r2.exit_code, 0) << r2.err;
  const fs::path b1 = fs::canonical(tmp_ / "one" / "prism" / "latest"), b2 = fs::canonical(tmp_ / "two" / "prism" / "latest");
  EXPECT_EQ(b1.filename(), b2.filename());
  const auto d1 = data_files(b1);
  EXPECT_EQ(d1.size(), kDataFiles.size());
  EXPECT_EQ(d1, data_files(b2));
  // The manifests differ only in when and how long.
  json m1 = t::read_json(b1 / "manifest.json"), m2 = t::read_json(b2 / "manifest.json");
  for (json* m : {&m1, &m2}) {
    m->erase("created_utc");
    m->erase("timings_s");
  }
  EXPECT_EQ(m1, m2);
}

TEST_F(Cli, OnlyRunsTheNamedJobs) {
  const std::string second = "  - name: second\n    kind: dispersion\n    samples: 4\n    material: {n_d: 1.6, v_d: 40}\n";
  const std::string third = "  - name: third\n    kind: dispersion\n    samples: 5\n    material: {n_d: 1.6, v_d: 40}\n";
  const fs::path c = cfg(config(4, "out", second + third));
  auto r = run({"run", c.string(), "--only", "second"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(tmp_ / "out" / "second" / "latest" / "manifest.json"));
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "prism"));
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "third"));
  r = run({"run", c.string(), "--only", "prism,third"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("2 built, 0 up to date"), std::string::npos) << r.out;
  EXPECT_TRUE(fs::exists(tmp_ / "out" / "prism" / "latest"));
  EXPECT_TRUE(fs::exists(tmp_ / "out" / "third" / "latest"));
  // A name no config defines is a usage error (2), naming it; nothing runs.
  const auto before = t::snapshot(tmp_ / "out");
  r = run({"run", c.string(), "--only", "fourth", "--force"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("fourth"), std::string::npos) << r.err;
  EXPECT_TRUE(t::snapshot(tmp_ / "out") == before);
}

// `output` is relative to the config file (not the working directory); --out overrides it.
TEST_F(Cli, OutputFolderResolution) {
  fs::create_directories(tmp_ / "cfgdir");
  fs::create_directories(tmp_ / "cwd");
  t::write_file(tmp_ / "cfgdir" / "c.yaml", config(4, "../baked"));
  auto r = t::run_cli({"run", (tmp_ / "cfgdir" / "c.yaml").string()}, tmp_ / "cwd");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(tmp_ / "baked" / "prism" / "latest" / "manifest.json"));
  EXPECT_FALSE(fs::exists(tmp_ / "cwd" / "baked"));
  r = t::run_cli({"run", (tmp_ / "cfgdir" / "c.yaml").string(), "--out", "over"}, tmp_ / "cwd");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(tmp_ / "cwd" / "over" / "prism" / "latest" / "manifest.json"));
  // Without `output`: ./assets of the working directory.
  t::write_file(tmp_ / "cfgdir" / "noout.yaml", config(4).replace(config(4).find("output: out\n"), 12, ""));
  r = t::run_cli({"run", (tmp_ / "cfgdir" / "noout.yaml").string()}, tmp_ / "cwd");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(tmp_ / "cwd" / "assets" / "prism" / "latest" / "manifest.json"));
}

TEST_F(Cli, PlanWritesNothing) {
  const fs::path c = cfg(config(7));
  auto r = run({"plan", c.string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("prism"), std::string::npos);
  EXPECT_NE(r.out.find("would be built"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("7 samples"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(tmp_ / "out"));
  // After a run: up to date, and still nothing changes.
  build(7);
  const auto before = t::snapshot(tmp_ / "out");
  r = run({"plan", c.string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("up to date"), std::string::npos) << r.out;
  EXPECT_TRUE(t::snapshot(tmp_ / "out") == before);
  r = run({"plan", c.string(), "--out", (tmp_ / "planned").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(fs::exists(tmp_ / "planned"));
}

// A changed config is a new hash: a new bundle folder, `latest` moves to it, the old bundle
// stays; going back to the old config finds the old bundle up to date and moves `latest` back.
TEST_F(Cli, ChangedConfigGivesNewBundleAndMovesLatest) {
  const fs::path b1 = build(6);
  const auto old_bundle = t::snapshot(b1);
  const fs::path b2 = build(7);
  EXPECT_NE(b1.filename(), b2.filename());
  EXPECT_EQ(fs::read_symlink(tmp_ / "out" / "prism" / "latest"), b2.filename());
  EXPECT_TRUE(t::snapshot(b1) == old_bundle);
  EXPECT_EQ(t::read_f32(b2 / "wavelengths.bin").size(), 7u);
  const auto r = run({"run", cfg(config(6)).string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("up-to-date"), std::string::npos) << r.out;
  EXPECT_EQ(fs::read_symlink(tmp_ / "out" / "prism" / "latest"), b1.filename());
  // Whitespace, comments and key order do not change the hash; any value does.
  const std::string reordered =
      "# same job\nspecbake: 1\njobs:\n  - kind: dispersion\n    name: prism\n    range_nm: [390.0, 780]\n"
      "    material: {glass: N-BK7}\n    sampling: gauss-legendre\n    samples: 6\noutput: out\n";
  const auto r2 = run({"run", cfg(reordered).string()});
  EXPECT_EQ(r2.exit_code, 0) << r2.err;
  EXPECT_NE(r2.out.find("up-to-date"), std::string::npos) << r2.out;
}

TEST_F(Cli, DevicesListsPocl) {
  const auto r = run({"devices"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("Portable Computing Language"), std::string::npos) << r.out;
  EXPECT_TRUE(std::regex_search(r.out, std::regex(R"((^|\n)\* \[\d+\.\d+\] )")))
      << "no device marked as the auto pick:\n" << r.out;
  EXPECT_NE(r.out.find("type: cpu"), std::string::npos) << r.out;
}

TEST_F(Cli, VersionAndHelp) {
  auto r = run({"--version"});
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find(std::string("specbake ") + specbake::kVersion), std::string::npos) << r.out;
  r = run({"--help"});
  EXPECT_EQ(r.exit_code, 0);
  for (const char* s : {"run", "plan", "devices", "inspect", "--version", "-v", "-q"})
    EXPECT_NE(r.out.find(s), std::string::npos) << s << " missing from --help:\n" << r.out;
  r = run({"run", "--help"});
  EXPECT_EQ(r.exit_code, 0);
  for (const char* s : {"--out", "--device", "--only", "--force"})
    EXPECT_NE(r.out.find(s), std::string::npos) << s << " missing from run --help:\n" << r.out;
  // Defaults are shown: where output goes without --out, which device without --device.
  EXPECT_NE(r.out.find("else ./assets"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("else auto"), std::string::npos) << r.out;
}

TEST_F(Cli, UsageErrorsExitTwo) {
  const fs::path c = cfg(config(4));
  const std::vector<std::vector<std::string>> bad = {
      {},                                   // no subcommand
      {"bake", c.string()},                 // unknown subcommand
      {"run"},                              // no config
      {"run", c.string(), "--bogus"},       // unknown option
      {"run", c.string(), "--out"},         // option without its value
      {"inspect"},                          // no bundle folder
      {"devices", "extra"},                 // stray argument
  };
  for (const auto& args : bad) {
    std::string shown;
    for (const auto& a : args) shown += a + " ";
    const auto r = run(args);
    EXPECT_EQ(r.exit_code, 2) << "specbake " << shown << "\n" << r.out << r.err;
  }
  EXPECT_FALSE(fs::exists(tmp_ / "out"));
}

// --out gathers every config's jobs in one folder: two configs with a job of the same name
// would then share a bundle folder (and `latest`). A usage error naming both; nothing runs.
TEST_F(Cli, OutCannotMergeTwoJobsOfTheSameName) {
  fs::create_directories(tmp_ / "a");
  fs::create_directories(tmp_ / "b");
  t::write_file(tmp_ / "a" / "c.yaml", config(4));
  t::write_file(tmp_ / "b" / "c.yaml", config(5));
  // Each into its own output (relative to its file): fine.
  auto r = run({"run", (tmp_ / "a" / "c.yaml").string(), (tmp_ / "b" / "c.yaml").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  r = run({"run", (tmp_ / "a" / "c.yaml").string(), (tmp_ / "b" / "c.yaml").string(), "--out", "merged"});
  EXPECT_EQ(r.exit_code, 2) << r.out << r.err;
  EXPECT_NE(r.err.find((tmp_ / "a" / "c.yaml").string() + ":4:5"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find((tmp_ / "b" / "c.yaml").string() + ":4:5"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(tmp_ / "merged"));
  r = run({"plan", (tmp_ / "a" / "c.yaml").string(), (tmp_ / "b" / "c.yaml").string(), "--out", "merged"});
  EXPECT_EQ(r.exit_code, 2) << r.out << r.err;
  // --only picking one of them is fine.
  const std::string second = "  - name: other\n    kind: dispersion\n    samples: 4\n    material: {n_d: 1.6, v_d: 40}\n";
  t::write_file(tmp_ / "b" / "c.yaml", config(5, "out", second));
  r = run({"run", (tmp_ / "a" / "c.yaml").string(), (tmp_ / "b" / "c.yaml").string(), "--out", "merged", "--only", "other"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
}

// Device problems exit 4 and name what failed: a selector nothing matches, a kernel that does
// not build (the build log is shown). An up-to-date bundle is skipped without the device.
int count_of(const std::string& text, const std::string& needle) {
  int n = 0;
  for (auto p = text.find(needle); p != std::string::npos; p = text.find(needle, p + 1)) ++n;
  return n;
}

TEST_F(Cli, DeviceErrorsExitFour) {
  const fs::path c = cfg(config(4));
  auto r = run({"run", c.string(), "--device", "no-such-device"});
  EXPECT_EQ(r.exit_code, 4) << r.out << r.err;
  // said once, in the summary (not also as a log line)
  EXPECT_EQ(count_of(r.out + r.err, "no OpenCL device matches 'no-such-device'"), 1) << r.out << r.err;
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "prism" / "latest"));
  r = run({"plan", c.string(), "--device", "no-such-device"});
  EXPECT_EQ(r.exit_code, 4) << r.out << r.err;
  r = t::run_cli({"run", c.string()}, tmp_.path(), {"SPECBAKE_INJECT_BUILD_FAILURE=kernels/dispersion/kernels.cl"});
  EXPECT_EQ(r.exit_code, 4) << r.out << r.err;
  EXPECT_NE(r.err.find("kernels/dispersion/kernels.cl"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("build failure injected"), std::string::npos) << "no build log in:\n" << r.err;
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "prism" / "latest"));
  // The device is part of the bundle hash: a bundle baked on this CPU is up to date for the
  // same device named another way, and does not satisfy a device that cannot be found.
  const fs::path b = build(4);
  const auto before = t::snapshot(tmp_ / "out");
  r = run({"run", c.string(), "--device", "cpu"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("up-to-date"), std::string::npos) << r.out;
  r = run({"run", c.string(), "--device", "no-such-device"});
  EXPECT_EQ(r.exit_code, 4) << r.out << r.err;
  r = run({"plan", c.string(), "--device", "no-such-device"});
  EXPECT_EQ(r.exit_code, 4) << r.out << r.err;  // plan and run agree
  EXPECT_TRUE(t::snapshot(tmp_ / "out") == before);
}

// Non-finite values never reach a bundle: the float32 writer refuses them (and values that
// overflow float32), naming the array and the index.
TEST(BundleWriter, RefusesNonFiniteValues) {
  EXPECT_EQ(specbake::float32_le(std::vector<double>{1.0, -2.5}, "x").size(), 8u);
  for (double bad : {std::nan(""), HUGE_VAL, -HUGE_VAL, 1e39}) {
    try {
      specbake::float32_le(std::vector<double>{0.0, 1.0, bad}, "weights");
      ADD_FAILURE() << "accepted " << bad;
    } catch (const specbake::JobError& e) {
      EXPECT_NE(std::string(e.what()).find("weights"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("index 2"), std::string::npos) << e.what();
    }
  }
  // The float overload (terms written straight from the device's floats) checks the same.
  EXPECT_EQ(specbake::float32_le(std::vector<float>{1.0f, -2.5f}, "x").size(), 8u);
  EXPECT_THROW(specbake::float32_le(std::vector<float>{0.0f, std::nanf("")}, "terms"), specbake::JobError);
}

// Non-finite values in an output fail the job (exit 1) and nothing is published: a
// Sellmeier material with a pole (λ² = C) inside the range gives n² < 0 at some samples.
TEST_F(Cli, NonFiniteOutputFailsTheJob) {
  // Such a glass is refused when the config is read (n² < 0 at the d line)...
  const fs::path c = cfg(
      "specbake: 1\noutput: out\njobs:\n  - name: pole\n    kind: dispersion\n    samples: 4\n"
      "    material: {sellmeier: {B: [5.0], C: [1.0]}}\n");  // n² < 0 below 1 µm: NaN index
  auto r = run({"run", c.string()});
  EXPECT_EQ(r.exit_code, 3) << r.out << r.err;
  EXPECT_NE(r.err.find("transparent glass"), std::string::npos) << r.err;
  // ... and a spec that reaches the job anyway (built in code, not from a config) fails it
  // before anything is published.
  specbake::DispersionSpec spec;
  spec.samples = 4;
  spec.material.kind = specbake::Material::Kind::sellmeier;
  spec.material.sellmeier = specbake::Sellmeier{{5.0}, {1.0}};
  specbake::cl_util::Device dev(specbake::cl_util::select_device("auto"));
  specbake::JobContext ctx{dev};
  try {
    specbake::dispersion::bake(spec, ctx);
    ADD_FAILURE() << "a NaN index reached the files";
  } catch (const specbake::JobError& e) {
    EXPECT_NE(std::string(e.what()).find("non-finite"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "pole" / "latest"));
  if (fs::exists(tmp_ / "out" / "pole"))
    for (const auto& e : fs::directory_iterator(tmp_ / "out" / "pole"))
      EXPECT_EQ(e.path().filename().string().front(), '.') << "left behind: " << e.path();
}

// A folder argument runs every *.yaml / *.yml in it (sorted); a folder without one is an
// invalid input (3) naming the folder.
TEST_F(Cli, FolderOfConfigs) {
  t::write_file(tmp_ / "cfgs" / "a.yaml", config(4, "../out"));
  t::write_file(tmp_ / "cfgs" / "b.yml",
                "specbake: 1\noutput: ../out\njobs:\n  - name: second\n    kind: dispersion\n    samples: 3\n"
                "    material: {n_d: 1.6, v_d: 40}\n");
  t::write_file(tmp_ / "cfgs" / "notes.txt", "not a config: {{{\n");
  auto r = run({"run", (tmp_ / "cfgs").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("2 built"), std::string::npos) << r.out;
  EXPECT_LT(r.out.find("prism "), r.out.find("second "));  // a.yaml before b.yml
  EXPECT_TRUE(fs::exists(tmp_ / "out" / "prism" / "latest"));
  EXPECT_TRUE(fs::exists(tmp_ / "out" / "second" / "latest"));
  fs::create_directories(tmp_ / "empty");
  r = run({"run", (tmp_ / "empty").string()});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find((tmp_ / "empty").string()), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("no *.yaml"), std::string::npos) << r.err;
}

// `plan` resolves samples: auto (the search runs) and shows the choice, writing nothing.
TEST_F(Cli, PlanResolvesAuto) {
  const fs::path c = cfg(
      "specbake: 1\noutput: out\njobs:\n  - name: auto\n    kind: dispersion\n    samples: auto\n"
      "    tolerance_de2000: 20\n    material: {n_d: 1.5, v_d: 50}\n");
  const auto r = run({"plan", c.string(), "-v"});  // -v: the full resolved parameters
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("\n    samples_auto: {"), std::string::npos) << r.out;
  EXPECT_TRUE(std::regex_search(r.out, std::regex("\"chosen\":[0-9]+"))) << r.out;
  EXPECT_FALSE(fs::exists(tmp_ / "out"));
}

// -q: warnings and errors only; -vv: debug output (samples: auto logs every N it tries at debug level).
TEST_F(Cli, QuietAndVerbose) {
  const fs::path c = cfg(config(4));
  auto r = run({"-q", "run", c.string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("[info]"), std::string::npos) << r.err;
  r = run({"-q", "run", (tmp_ / "missing.yaml").string()});
  EXPECT_EQ(r.exit_code, 5);
  EXPECT_NE(r.err.find("[error]"), std::string::npos) << r.err;
  const fs::path a = cfg(
      "specbake: 1\noutput: out\njobs:\n  - name: auto\n    kind: dispersion\n    samples: auto\n"
      "    tolerance_de2000: 20\n    material: {n_d: 1.5, v_d: 50}\n",
      "auto.yaml");
  r = run({"-vv", "run", a.string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("[info]"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("[debug] samples: auto: N = 1 gives"), std::string::npos) << r.err;
  r = run({"run", a.string(), "--force"});
  EXPECT_EQ(r.err.find("[debug]"), std::string::npos) << r.err;
}

}  // namespace
