// The command line as people use it: mistakes, interrupted and failed runs, nightly runs over
// many configs, and the output people read. Each test pins down a behaviour a user relies on.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <thread>

#include "io/bundle.hpp"
#include "support/testing.hpp"

namespace {

namespace t = specbake::testing;
namespace fs = std::filesystem;
using nlohmann::json;

const std::string kPrism =
    "  - name: prism\n    kind: dispersion\n    samples: 6\n    material: {glass: N-BK7}\n";
const std::string kSky =
    "  - name: sky\n    kind: atmosphere\n    orders: 3\n"
    "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}\n"
    "    scene: {points: 16}\n";

std::string config(const std::string& jobs, const std::string& output = "out") {
  return "specbake: 1\noutput: " + output + "\njobs:\n" + jobs;
}

int count(const std::string& text, const std::string& needle) {
  int n = 0;
  for (auto p = text.find(needle); p != std::string::npos; p = text.find(needle, p + 1)) ++n;
  return n;
}

class CliUser : public ::testing::Test {
 protected:
  fs::path cfg(const std::string& text, const std::string& name = "c.yaml") {
    t::write_file(tmp_ / name, text);
    return tmp_ / name;
  }
  t::CliResult run(std::vector<std::string> args, const std::vector<std::string>& env = {}) {
    return t::run_cli(args, tmp_.path(), env);
  }
  // What `specbake ARGS` writes on a terminal (`script` gives it one); fails the test unless it exits 0.
  std::string run_on_terminal(const std::string& args) {
    const fs::path log = tmp_ / "tty.txt";
    const std::string cmd =
        "script -qec '" + std::string(SPECBAKE_EXE) + " " + args + "' /dev/null > " + log.string() + " 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
    return t::read_file(log);
  }
  t::TempDir tmp_;
};

// A failed job leaves no lock and no empty job folder, and names no bundle that does not exist.
TEST_F(CliUser, FailedJobLeavesNoDebris) {
  const fs::path c = cfg(config(kPrism));
  const fs::path report = tmp_ / "report.json";
  const auto r = t::run_cli({"run", c.string(), "--report", report.string()}, tmp_.path(),
                            {"SPECBAKE_INJECT_BUILD_FAILURE=kernels/dispersion/kernels.cl"});
  EXPECT_EQ(r.exit_code, 4) << r.out << r.err;
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "prism")) << "the failed job left its folder (or its .lock)";
  EXPECT_EQ(r.out.find("bundle:"), std::string::npos) << r.out;
  const json rep = t::read_json(report);
  EXPECT_TRUE(rep["jobs"][0]["bundle"].is_null());
  EXPECT_EQ(rep["jobs"][0]["exit_code"], 4);
  // The kernel build log is printed once.
  EXPECT_EQ(count(r.err, "build log:"), 1) << r.err;
  // A successful job keeps no lock file either.
  const auto ok = run({"run", c.string()});
  EXPECT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "prism" / ".lock"));
}

// --report is checked before any work: a folder is a usage error (2), an unwritable path an I/O
// error (5); neither bakes anything nor leaves a stray file.
TEST_F(CliUser, ReportPathIsCheckedFirst) {
  const fs::path c = cfg(config(kPrism));
  fs::create_directories(tmp_ / "a-folder");
  auto r = run({"run", c.string(), "--report", (tmp_ / "a-folder").string()});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_FALSE(fs::exists(tmp_ / "out"));
  EXPECT_FALSE(fs::exists(tmp_ / "a-folder.tmp"));
  t::write_file(tmp_ / "file", "x");
  r = run({"run", c.string(), "--report", (tmp_ / "file" / "report.json").string()});  // below a regular file
  EXPECT_EQ(r.exit_code, 5) << r.err;
  EXPECT_FALSE(fs::exists(tmp_ / "out"));
  // A config error still writes the report, saying what stopped the run.
  const fs::path bad = cfg("specbake: 1\njobs: [\n", "bad.yaml");
  r = run({"run", bad.string(), "--report", (tmp_ / "r.json").string()});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  const json rep = t::read_json(tmp_ / "r.json");
  EXPECT_NE(rep.value("error", "").find("bad.yaml"), std::string::npos) << rep.dump();
}

// --keep-going: one config whose heightfield is missing does not stop the others; the invalid
// one is reported with its location and the run exits 3. Without it, today's strict behaviour.
TEST_F(CliUser, KeepGoingRunsEveryValidJob) {
  cfg(config(kPrism), "a.yaml");
  cfg(config("  - name: grating\n    kind: diffraction\n    heightfield: {file: missing.png, dx_um: 0.1, height_um: 0.2}\n"),
      "b.yaml");
  cfg(config("  - name: second\n    kind: dispersion\n    samples: 3\n    material: {n_d: 1.6, v_d: 40}\n"), "c.yaml");
  fs::rename(tmp_ / "c.yaml", tmp_ / "cfgs-c.yaml");
  fs::create_directories(tmp_ / "cfgs");
  for (const char* f : {"a.yaml", "b.yaml", "cfgs-c.yaml"}) fs::rename(tmp_ / f, tmp_ / "cfgs" / f);
  auto r = run({"run", (tmp_ / "cfgs").string(), "--out", (tmp_ / "strict").string()});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_FALSE(fs::exists(tmp_ / "strict" / "prism"));
  r = run({"run", (tmp_ / "cfgs").string(), "--out", (tmp_ / "out").string(), "--keep-going", "--report",
           (tmp_ / "rep.json").string()});
  EXPECT_EQ(r.exit_code, 3) << r.out << r.err;
  EXPECT_TRUE(fs::exists(tmp_ / "out" / "prism" / "latest"));
  EXPECT_TRUE(fs::exists(tmp_ / "out" / "second" / "latest"));
  EXPECT_TRUE(std::regex_search(r.out, std::regex("2 built.*1 invalid"))) << r.out;
  const json rep = t::read_json(tmp_ / "rep.json");
  bool found = false;
  for (const auto& j : rep["jobs"])
    if (j["status"] == "invalid") {
      found = true;
      EXPECT_EQ(j["exit_code"], 3);
      EXPECT_TRUE(std::regex_search(j["reason"].get<std::string>(), std::regex("b\\.yaml:[0-9]+:[0-9]+")))
          << j["reason"];
      EXPECT_NE(j["reason"].get<std::string>().find("missing.png"), std::string::npos) << j["reason"];
    }
  EXPECT_TRUE(found) << rep.dump(1);
}

// Invalid jobs are named by their name and kind where the config gives them (else file:jobs[i]),
// counted as invalid, said once; plan counts only what it planned; a config error without
// --keep-going is in the report as an invalid job too.
TEST_F(CliUser, InvalidJobsAreNamedAndCounted) {
  const fs::path a = cfg(config("  - name: bad-a\n    kind: dispersion\n    sampels: 3\n    material: {glass: N-BK7}\n" +
                                kPrism),
                         "a.yaml");
  const fs::path b = cfg(config("  - kind: diffraction\n    heightfield: {file: missing.png, dx_um: 0.1, height_um: 0.2}\n"),
                         "b.yaml");
  auto r = run({"plan", a.string(), b.string(), "--keep-going", "--report", (tmp_ / "p.json").string()});
  EXPECT_EQ(r.exit_code, 3) << r.out << r.err;
  EXPECT_NE(r.out.find("1 planned, 0 failed, 2 invalid"), std::string::npos) << r.out;
  EXPECT_TRUE(std::regex_search(r.out, std::regex("\nbad-a +dispersion +invalid"))) << r.out;
  EXPECT_NE(r.out.find(b.string() + ":jobs[0]: invalid: "), std::string::npos) << r.out;
  EXPECT_EQ(count(r.out + r.err, "unknown key 'sampels'"), 1) << r.out << r.err;
  json rep = t::read_json(tmp_ / "p.json");
  EXPECT_EQ(rep["summary"]["planned"], 1);
  EXPECT_EQ(rep["summary"]["invalid"], 2);
  EXPECT_EQ(rep["jobs"][1]["name"], "bad-a");
  EXPECT_EQ(rep["jobs"][1]["kind"], "dispersion");
  EXPECT_EQ(rep["jobs"][1]["status"], "invalid");
  EXPECT_EQ(rep["jobs"][2]["name"], b.string() + ":jobs[0]");

  r = run({"run", a.string(), "--report", (tmp_ / "r.json").string()});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "prism"));
  rep = t::read_json(tmp_ / "r.json");
  EXPECT_EQ(rep["summary"]["invalid"], 1);
  ASSERT_EQ(rep["jobs"].size(), 1u) << rep.dump();
  EXPECT_EQ(rep["jobs"][0]["name"], "bad-a");
  EXPECT_EQ(rep["jobs"][0]["exit_code"], 3);
  EXPECT_NE(rep.value("error", "").find("sampels"), std::string::npos);
}

// Ctrl-C (or SIGTERM) ends the run at a safe point: no temporary folder, no lock, the report
// and the summary say what finished, exit 130 (143 for SIGTERM).
TEST_F(CliUser, InterruptStopsAtASafePoint) {
  for (int sig : {SIGINT, SIGTERM}) {
    SCOPED_TRACE(sig == SIGINT ? "SIGINT" : "SIGTERM");
    const fs::path out = tmp_ / ("out" + std::to_string(sig));
    // prism first (finishes quickly), then a sky bake long enough to be interrupted.
    const fs::path c = cfg(config(kPrism + kSky.substr(0, kSky.find("    sizes")) +
                                      "    sizes: {scattering: {r: 16, mu: 64, mu_s: 16, nu: 8}}\n",
                                  out.string()),
                           "int.yaml");
    const fs::path report = tmp_ / ("rep" + std::to_string(sig) + ".json");
    const pid_t pid = t::spawn_cli({"run", c.string(), "--report", report.string()}, tmp_.path(), tmp_ / "int.out",
                                   tmp_ / "int.err");
    // Wait until the sky job is baking (its job folder and lock exist), then signal.
    const auto t0 = std::chrono::steady_clock::now();
    while (!fs::exists(out / "sky" / ".lock") && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(60))
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    ASSERT_TRUE(fs::exists(out / "sky" / ".lock")) << "the sky job never started";
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    ::kill(pid, sig);
    int status = 0;
    ::waitpid(pid, &status, 0);
    ASSERT_TRUE(WIFEXITED(status)) << "killed by the signal instead of stopping";
    EXPECT_EQ(WEXITSTATUS(status), sig == SIGINT ? 130 : 143);
    EXPECT_TRUE(fs::exists(out / "prism" / "latest"));
    EXPECT_FALSE(fs::exists(out / "sky")) << "the interrupted job left its folder (temporary or lock)";
    const json rep = t::read_json(report);
    EXPECT_EQ(rep["jobs"][0]["status"], "built");
    EXPECT_EQ(rep["jobs"][1]["status"], "interrupted");
    EXPECT_NE(rep.value("error", "").find("stopped"), std::string::npos);
    std::ifstream o(tmp_ / "int.out");
    const std::string text((std::istreambuf_iterator<char>(o)), std::istreambuf_iterator<char>());
    EXPECT_NE(text.find("1 built"), std::string::npos) << text;
    EXPECT_NE(text.find("1 interrupted"), std::string::npos) << text;
  }
}

// -q prints nothing but warnings and errors; -v adds the full JSON; -vv is more than -v.
TEST_F(CliUser, QuietVerboseAndWarnings) {
  const fs::path c = cfg(config("  - name: flint\n    kind: dispersion\n    samples: 8\n    range_nm: [390, 780]\n"
                                "    material: {glass: N-SF11}\n"));
  auto r = run({"run", c.string(), "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, "");
  EXPECT_EQ(count(r.err, "\n"), 1) << r.err;  // the glass's one warning, nothing else
  EXPECT_NE(r.err.find("[warning] flint: the Cauchy/Abbe model"), std::string::npos) << r.err;
  r = run({"run", c.string(), "-q"});  // up to date: its warning again
  EXPECT_EQ(r.out, "");
  EXPECT_NE(r.err.find("[warning] flint: the Cauchy/Abbe model"), std::string::npos) << r.err;
  // Up to date: the bundle's warnings are repeated and counted.
  r = run({"run", c.string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("warning: flint: the Cauchy/Abbe model"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("0 built, 1 up to date, 0 failed, 1 warning"), std::string::npos) << r.out;
  EXPECT_LT(r.out.size(), 2000u) << "the default output is a summary, not a dump";
  const auto v = run({"run", c.string(), "-v"});
  EXPECT_NE(v.out.find("\n    quadrature_weights_nm: ["), std::string::npos) << v.out;  // a line per parameter
  EXPECT_NE(v.out.find("\n    prism_de2000 "), std::string::npos) << v.out;              // a line per accuracy record
  const auto vv = run({"run", c.string(), "-vv"});
  EXPECT_NE(vv.err.find("[trace]"), std::string::npos) << vv.err;
  EXPECT_EQ(v.err.find("[trace]"), std::string::npos) << v.err;
}

// A job that misses a tolerance it has fails (exit 1, nothing published), and its report keeps
// what it resolved and measured; `tolerance_advisory: true` publishes it with a warning. A
// dispersion job's colour error is judged when the config gives tolerance_de2000.
TEST_F(CliUser, AMissedToleranceFailsUnlessAdvisory) {
  const std::string grating =
      "  - name: grating\n    kind: diffraction\n"
      "    procedural: {type: sine-grating, size: 64, dx_um: 0.25, period_um: 2.0, amplitude_um: 0.15}\n"
      "    terms: 2\n";  // 2 Taylor terms at y_max = 5: an error of order 1 against the default 1e-4
  const std::string prism = "  - name: prism\n    kind: dispersion\n    samples: 3\n    material: {glass: N-BK7}\n";
  const fs::path strict = cfg(config(grating + prism + "    tolerance_de2000: 0.5\n"));
  auto r = run({"run", strict.string(), "--report", (tmp_ / "r.json").string()});
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_NE(r.out.find("0 built, 0 up to date, 2 failed"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("grating: failed: missed its tolerance: vs_exact_transform"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("prism: failed: missed its tolerance: prism_de2000"), std::string::npos) << r.out;
  EXPECT_TRUE(std::regex_search(r.out, std::regex("\ngrating +diffraction +failed +[0-9.]+ s "))) << r.out;
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "grating"));
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "prism"));
  // a full-bin diffraction bundle carries no shader, and the summary says so
  EXPECT_NE(r.out.find("2 taylor terms, field 64x64, no GLSL (table: none)"), std::string::npos) << r.out;
  const json rep = t::read_json(tmp_ / "r.json");
  for (const auto& j : rep["jobs"]) {
    EXPECT_EQ(j["status"], "failed");
    EXPECT_EQ(j["exit_code"], 1);
    EXPECT_TRUE(j["parameters"].is_object() && !j["parameters"].empty()) << j.dump();
    ASSERT_TRUE(j["accuracy"].is_array() && !j["accuracy"].empty()) << j.dump();
    EXPECT_FALSE(j["accuracy"][0]["passed"].get<bool>()) << j.dump();
  }
  EXPECT_EQ(rep["summary"]["failed"], 2);

  // advisory: both published, each with a warning naming what it missed
  const fs::path advisory =
      cfg(config(grating + "    tolerance_advisory: true\n" + prism + "    tolerance_de2000: 0.5\n    tolerance_advisory: true\n"),
          "advisory.yaml");
  r = run({"run", advisory.string()});
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("2 built"), std::string::npos) << r.out;
  EXPECT_EQ(count(r.out, "tolerance_advisory: published although it misses its tolerance"), 2) << r.out;
  const json m = t::read_json(tmp_ / "out" / "prism" / "latest" / "manifest.json");
  EXPECT_EQ(m["config"]["tolerance_advisory"], true);

  // no tolerance_de2000 given with fixed samples: the colour error is reported, not judged
  r = run({"run", cfg(config(prism), "reported.yaml").string(), "--out", (tmp_ / "o2").string()});
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  const json m2 = t::read_json(tmp_ / "o2" / "prism" / "latest" / "manifest.json");
  EXPECT_TRUE(m2["accuracy"][0]["tolerance"].is_null()) << m2["accuracy"][0].dump();
  EXPECT_FALSE(m2["config"].contains("tolerance_advisory"));

  r = run({"run", cfg(config(prism + "    tolerance_advisory: yes\n"), "bad.yaml").string()});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("tolerance_advisory"), std::string::npos) << r.err;
}

// Options given an empty value, and an option followed by a config path.
TEST_F(CliUser, EmptyValuesAndOptionArity) {
  const fs::path c = cfg(config(kPrism));
  for (const char* opt : {"--out", "--shard", "--only", "--device", "--report"}) {
    const auto r = run({"plan", c.string(), opt, ""});
    EXPECT_EQ(r.exit_code, 2) << opt << ": " << r.err;
  }
  // `--only prism t5`: t5 is a config path, not a second job name.
  const auto r = run({"plan", "--only", "prism", c.string(), "t5.yaml"});
  EXPECT_EQ(r.exit_code, 5) << r.err;  // t5.yaml cannot be read
  EXPECT_NE(r.err.find("t5.yaml"), std::string::npos) << r.err;
}

TEST_F(CliUser, SuggestionsForTypos) {
  auto r = run({"rnu", "x.yaml"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("did you mean 'run'"), std::string::npos) << r.err;
  const fs::path c = cfg(config("  - name: prism\n    kind: dispresion\n    samples: 6\n"));
  r = run({"plan", c.string()});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("did you mean 'dispersion'"), std::string::npos) << r.err;
  const fs::path k = cfg(config("  - name: prism\n    kind: dispersion\n    sampels: 6\n"), "k.yaml");
  r = run({"plan", k.string()});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("did you mean 'samples'"), std::string::npos) << r.err;
  r = run({"plan", c.string(), "--only", "prizm"});
  // options, and `help` as a command
  r = run({"run", "--frce", c.string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("unknown option '--frce' (did you mean '--force'?)"), std::string::npos) << r.err;
  r = run({"help"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("Usage: specbake"), std::string::npos) << r.out;
  r = run({"help", "run"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("--keep-going"), std::string::npos) << r.out;
  r = run({"hlep"});
  EXPECT_NE(r.err.find("did you mean 'help'"), std::string::npos) << r.err;
}

// diff: accuracy changes shown old -> new, every line short enough to read, a bad threshold
// said in words.
TEST_F(CliUser, DiffShowsAccuracyChangesInShortLines) {
  const auto sky = [](int mu) {
    return "  - name: sky\n    kind: atmosphere\n    orders: 3\n"
           "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: " +
           std::to_string(mu) + ", mu_s: 6, nu: 3}}\n    scene: {points: 16}\n";
  };
  ASSERT_EQ(run({"run", cfg(config(sky(8)), "a.yaml").string(), "--out", (tmp_ / "a").string()}).exit_code, 0);
  ASSERT_EQ(run({"run", cfg(config(sky(10)), "b.yaml").string(), "--out", (tmp_ / "b").string()}).exit_code, 0);
  auto r = run({"diff", (tmp_ / "a" / "sky").string(), (tmp_ / "b" / "sky").string()});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_TRUE(std::regex_search(r.out, std::regex("accuracy changes:\n(  .*\n)*  vs_path_traced: [0-9.e+-]+ -> [0-9.e+-]+\n")))
      << r.out;
  EXPECT_NE(r.out.find("parameters.orders.per_order: list of 3, "), std::string::npos) << r.out;
  std::istringstream lines(r.out);
  for (std::string line; std::getline(lines, line);) EXPECT_LT(line.size(), 300u) << line;
  r = run({"diff", (tmp_ / "a" / "sky").string(), (tmp_ / "b" / "sky").string(), "--fail-rel", "-1"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("expected a number >= 0, got '-1'"), std::string::npos) << r.err;
  EXPECT_LT(r.err.size(), 200u) << r.err;
}

// A config without `output:` writes into ./assets of the working folder; the summary says so.
TEST_F(CliUser, DefaultOutputIsSaid) {
  const fs::path c = cfg("specbake: 1\njobs:\n" + kPrism, "no-output.yaml");
  const auto r = run({"plan", c.string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("bundles would go to " + (tmp_ / "assets").string() + " (the working folder's ./assets: " +
                       c.string() + " has no `output:`"),
            std::string::npos)
      << r.out;
  EXPECT_EQ(run({"plan", cfg(config(kPrism)).string()}).out.find("working folder's"), std::string::npos);
}

// YAML mistakes are reported where they begin.
TEST_F(CliUser, YamlMistakesPointAtTheirStart) {
  const fs::path c = cfg("specbake: 1\njobs:\n  - name: prism\n    kind: dispersion\n\tsamples: 6\n");
  auto r = run({"plan", c.string()});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("c.yaml:5:1"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("tab"), std::string::npos) << r.err;
  const fs::path d = cfg("specbake: 1\njobs:\n  - name: prism\n    kind: dispersion\n    range_nm: [390, 780\n"
                         "    samples: 6\n",
                         "d.yaml");
  r = run({"plan", d.string()});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("d.yaml:5:15"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("never closed"), std::string::npos) << r.err;
}

// A config given twice (directly and through its folder) is read once, not reported as its own
// duplicate; `output: ~/x` means the home folder.
TEST_F(CliUser, SameConfigTwiceAndHomeFolder) {
  const fs::path c = cfg(config(kPrism, "~/baked"));
  const auto r = run({"run", c.string(), tmp_.path().string(), (tmp_ / "." / "c.yaml").string()},
                     {"HOME=" + (tmp_ / "home").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(tmp_ / "home" / "baked" / "prism" / "latest"));
  EXPECT_FALSE(fs::exists(tmp_ / "~"));
  EXPECT_NE(r.out.find("1 built"), std::string::npos) << r.out;
}

// An unreadable heightfield says why.
TEST_F(CliUser, UnreadableHeightfieldSaysWhy) {
  fs::create_directories(tmp_ / "field.png");  // a folder where a file is expected
  const fs::path c = cfg(config(
      "  - name: g\n    kind: diffraction\n    heightfield: {file: field.png, dx_um: 0.1, height_um: 0.2}\n"));
  const auto r = run({"plan", c.string()});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("field.png"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("a folder"), std::string::npos) << r.err;
}

// `mie: false` with a single-Mie output asked for is a config error (it would be all zeros);
// without outputs given, the single-Mie texture is left out.
TEST_F(CliUser, NoMieMeansNoSingleMieTexture) {
  const std::string sizes =
      "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}\n";
  const fs::path c = cfg(config("  - name: sky\n    kind: atmosphere\n    mie: false\n    orders: 2\n" + sizes +
                                "    outputs: [scattering, single_mie_scattering]\n"));
  auto r = run({"plan", c.string()});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("c.yaml:9:"), std::string::npos) << r.err;  // the outputs item
  EXPECT_NE(r.err.find("mie is false"), std::string::npos) << r.err;
  const fs::path d = cfg(config("  - name: sky\n    kind: atmosphere\n    mie: false\n    orders: 2\n" + sizes), "d.yaml");
  r = run({"run", d.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "sky" / "latest" / "single_mie_scattering.bin"));
  EXPECT_TRUE(fs::exists(tmp_ / "out" / "sky" / "latest" / "scattering.bin"));
}

// plan shows what a job will cost before anything runs.
TEST_F(CliUser, PlanShowsEstimates) {
  const fs::path c = cfg(config(kSky));
  const fs::path report = tmp_ / "plan.json";
  const auto r = run({"plan", c.string(), "--report", report.string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::regex_search(r.out, std::regex("sky +atmosphere +would be built +~[0-9.]+ s +[0-9]+ MiB +[0-9]+ MiB")))
      << r.out;
  const json rep = t::read_json(report);
  const json& e = rep["jobs"][0]["estimate"];
  EXPECT_GT(e["seconds_2core_cpu"].get<double>(), 0.0);
  EXPECT_GT(e["device_bytes"].get<double>(), 0.0);
  EXPECT_GT(e["host_bytes"].get<double>(), 0.0);
  EXPECT_FALSE(fs::exists(tmp_ / "out"));
}

// After a bake, plan scales the cost model to the device by the job's last bake on it: the
// model of what the next run costs (here with the scene's truth kept by the first run: no trace,
// so less than the first run's model) times that bake's seconds over the model it recorded; once
// a run recorded the kept model, the same settings estimate that bake's own seconds. A bundle
// baked on another device does not calibrate it.
TEST_F(CliUser, PlanCalibratesOnTheLastBakeOnThisDevice) {
  const fs::path c = cfg(config(kSky));
  ASSERT_EQ(run({"run", c.string()}).exit_code, 0);
  const fs::path latest = tmp_ / "out" / "sky" / "latest";
  const json manifest = t::read_json(latest / "manifest.json");
  const double bake_s = manifest["timings_s"]["bake"].get<double>();
  const double model_s = manifest["timings_s"]["model_2core_cpu_s"].get<double>();
  ASSERT_GT(bake_s, 0.0);
  ASSERT_GT(model_s, 0.0);

  const fs::path report = tmp_ / "plan.json";
  auto r = run({"plan", c.string(), "--report", report.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  json e = t::read_json(report)["jobs"][0]["estimate"];
  const double kept_model_s = e["seconds_2core_cpu"].get<double>();
  EXPECT_LT(kept_model_s, model_s);  // the scene's truth is kept: the check traces nothing
  EXPECT_NEAR(e["seconds"].get<double>(), kept_model_s * bake_s / model_s, 1e-12 * bake_s);
  EXPECT_EQ(e["basis"], "last bake on this device");
  EXPECT_EQ(e["calibrated_on"].get<std::string>(), fs::canonical(latest).string());
  EXPECT_TRUE(std::regex_search(r.out, std::regex("sky +atmosphere +up to date; would be skipped +~[0-9.]+ s\\* ")))
      << r.out;
  EXPECT_NE(r.out.find("* est. time scaled to this device"), std::string::npos) << r.out;

  // a rebake records the model it was estimated at (the truth kept); the same settings then
  // estimate its own seconds
  ASSERT_EQ(run({"run", c.string(), "--force"}).exit_code, 0);
  const json again = t::read_json(latest / "manifest.json");
  EXPECT_DOUBLE_EQ(again["timings_s"]["model_2core_cpu_s"].get<double>(), kept_model_s);
  const double rebake_s = again["timings_s"]["bake"].get<double>();
  r = run({"plan", c.string(), "--report", report.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  e = t::read_json(report)["jobs"][0]["estimate"];
  EXPECT_NEAR(e["seconds"].get<double>(), rebake_s, 1e-12 * rebake_s);

  json other = again;
  other["device"]["name"] = "another device";
  t::write_file(latest / "manifest.json", other.dump(2));
  r = run({"plan", c.string(), "--report", report.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  e = t::read_json(report)["jobs"][0]["estimate"];
  EXPECT_FALSE(e.contains("calibrated_on"));
  EXPECT_EQ(e["basis"], "2-core CPU model, the scene's truth kept");
  EXPECT_DOUBLE_EQ(e["seconds"].get<double>(), kept_model_s);
  EXPECT_EQ(r.out.find("* est. time"), std::string::npos) << r.out;

  // without the kept truth, the whole job's model
  fs::remove_all(tmp_ / "out" / ".results");
  r = run({"plan", c.string(), "--report", report.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  e = t::read_json(report)["jobs"][0]["estimate"];
  EXPECT_EQ(e["basis"], "2-core CPU model");
  EXPECT_DOUBLE_EQ(e["seconds"].get<double>(), model_s);
}

}  // namespace

namespace {

// inspect works on a bundle of each kind, through the job folder too, and as JSON.
TEST_F(CliUser, InspectEveryKind) {
  const fs::path c = cfg(config(kPrism + kSky +
                                "  - name: grating\n    kind: diffraction\n"
                                "    procedural: {type: sine-grating, size: 64, dx_um: 0.25, period_um: 4.0, amplitude_um: 0.1}\n"));
  ASSERT_EQ(run({"run", c.string()}).exit_code, 0);
  for (const char* job : {"prism", "sky", "grating"}) {
    SCOPED_TRACE(job);
    auto r = run({"inspect", (tmp_ / "out" / job / "latest").string()});
    EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
    EXPECT_NE(r.out.find("files match their sha256"), std::string::npos) << r.out;
    r = run({"inspect", (tmp_ / "out" / job).string(), "--json"});  // the job folder: its latest bundle
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const json j = json::parse(r.out);
    EXPECT_EQ(j["job"]["name"], job);
    EXPECT_TRUE(j["ok"].get<bool>());
    EXPECT_GT(j["files"].size(), 3u);
    EXPECT_TRUE(j["accuracy"].is_array());
  }
  // the output folder: its jobs listed (tests/cli/cli_report_test.cpp); a folder of none of these is exit 3
  auto r = run({"inspect", (tmp_ / "out").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("3 job(s)"), std::string::npos) << r.out;
  fs::create_directories(tmp_ / "empty");
  r = run({"inspect", (tmp_ / "empty").string()});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("expected a bundle folder"), std::string::npos) << r.err;
}

// gc: --dry-run changes nothing; a run removes old bundles, temporary folders of interrupted
// runs and lock files of dead processes, and leaves jobs a live run holds alone.
TEST_F(CliUser, GcDryRunAndLeftovers) {
  for (int n : {4, 5, 6}) {
    const std::string jobs = "  - name: prism\n    kind: dispersion\n    samples: " + std::to_string(n) +
                             "\n    material: {glass: N-BK7}\n";
    ASSERT_EQ(run({"run", cfg(config(jobs)).string()}).exit_code, 0);
  }
  fs::create_directories(tmp_ / "out" / "prism" / ".tmp-0123456789ab-999999");
  t::write_file(tmp_ / "out" / "prism" / ".lock", "999999\n");  // no process holds it
  const auto before = t::snapshot(tmp_ / "out");
  // A job or bundle folder given for the output folder is refused, naming the folder to give.
  for (const fs::path& wrong : {tmp_ / "out" / "prism", tmp_ / "out" / "prism" / "latest"}) {
    const auto w = run({"gc", wrong.string(), "--keep", "1"});
    EXPECT_EQ(w.exit_code, 2) << w.out << w.err;
    EXPECT_NE(w.err.find("gc takes the output folder that holds the job folders: " + (tmp_ / "out").string()),
              std::string::npos)
        << w.err;
  }
  EXPECT_TRUE(t::snapshot(tmp_ / "out") == before);
  // Three bundles created within a second: keep 1 keeps latest and one newest (2 when they
  // differ by name order); the dry run and the real run agree on the list.
  auto r = run({"gc", (tmp_ / "out").string(), "--keep", "1", "--dry-run"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.out, m, std::regex("would remove ([12]) bundle\\(s\\), 0 kept result\\(s\\) and 2 leftover\\(s\\)"))) << r.out;
  const std::string n = m[1];
  EXPECT_TRUE(t::snapshot(tmp_ / "out") == before);
  r = run({"gc", (tmp_ / "out").string(), "--keep", "1"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("removed " + n + " bundle(s), 0 kept result(s) and 2 leftover(s)"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "prism" / ".tmp-0123456789ab-999999"));
  EXPECT_FALSE(fs::exists(tmp_ / "out" / "prism" / ".lock"));
  EXPECT_TRUE(fs::exists(tmp_ / "out" / "prism" / "latest" / "manifest.json"));
}

// Kept results (<output>/.results): a bake's scene truth is kept there and listed in its
// manifest; a bake of the same atmosphere and scene at other sizes reuses it and lists it too;
// another scene seed keeps other entries. gc keeps the entries a remaining bundle lists, removes
// those only removed bundles listed and those no bundle lists (the dry run lists the same),
// leaves them all while a run holds a job, and a bake after they are gone traces again.
TEST_F(CliUser, GcKeepsTheResultsBundlesList) {
  const std::string sky = "  - name: sky\n    kind: atmosphere\n    preset: earth\n    orders: 2\n"
                          "    sizes: {transmittance: [64, 16], irradiance: [16, 4], scattering: {r: 8, mu: MU, mu_s: 8, nu: 4}}\n"
                          "    scene: {points: 6, relative_se: 0.1, seed: SEED}\n";
  auto sky_at = [&](int mu, int seed) {
    return cfg(config(std::regex_replace(std::regex_replace(sky, std::regex("MU"), std::to_string(mu)),
                                         std::regex("SEED"), std::to_string(seed))));
  };
  auto truth_of = [](const json& manifest, const char* which) {
    for (const auto& a : manifest.at("accuracy"))
      if (a.at("name") == "vs_path_traced") return a.at("details").at(which).at("reused");
    ADD_FAILURE() << "no vs_path_traced record";
    return json();
  };
  const fs::path results = tmp_ / "out" / ".results", latest = tmp_ / "out" / "sky" / "latest";
  auto entries = [&] {
    std::set<std::string> names;
    for (const auto& e : fs::directory_iterator(results)) names.insert(e.path().filename().string());
    return names;
  };
  ASSERT_EQ(run({"run", sky_at(16, 1).string()}).exit_code, 0);
  const std::set<std::string> first = entries();
  ASSERT_EQ(first.size(), 2u);  // the rgb truth and the 48-wavelength reference
  json m = t::read_json(latest / "manifest.json");
  EXPECT_EQ(m.at("results_kept").get<std::set<std::string>>(), first);
  EXPECT_TRUE(truth_of(m, "truth").is_null());
  // other sizes: the same scene, reused
  ASSERT_EQ(run({"run", sky_at(32, 1).string()}).exit_code, 0);
  m = t::read_json(latest / "manifest.json");
  EXPECT_EQ(m.at("results_kept").get<std::set<std::string>>(), first);
  EXPECT_TRUE(first.count(truth_of(m, "truth").get<std::string>()));
  EXPECT_TRUE(first.count(truth_of(m, "spectral_truth").get<std::string>()));
  EXPECT_EQ(entries(), first);
  // another scene seed: other points, other entries; only this (the latest) bundle lists them
  ASSERT_EQ(run({"run", sky_at(24, 2).string()}).exit_code, 0);
  m = t::read_json(latest / "manifest.json");
  const std::set<std::string> second = m.at("results_kept").get<std::set<std::string>>();
  ASSERT_EQ(second.size(), 2u);
  for (const auto& name : second) EXPECT_FALSE(first.count(name)) << name;
  // an entry no bundle lists, and a temporary file of a writer that died
  t::write_file(results / "0123456789abcdef0123456789abcdef.zst", "stale");
  t::write_file(results / ".tmp-0123456789abcdef0123456789abcdef.zst-999999", "half");
  {
    // a run holding a job: gc removes old bundles of the other jobs only, and no kept result
    specbake::JobLock held(tmp_ / "out" / "sky", "sky");
    const auto r = run({"gc", (tmp_ / "out").string(), "--keep", "1"});
    EXPECT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.out.find("removed 0 bundle(s), 0 kept result(s) and 0 leftover(s)"), std::string::npos) << r.out;
    EXPECT_EQ(entries().size(), 6u);
  }
  // --keep 1: the two bundles of seed 1 go, and with them the entries only they listed
  auto r = run({"gc", (tmp_ / "out").string(), "--keep", "1", "--dry-run"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("would remove 2 bundle(s), 3 kept result(s) and 1 leftover(s)"), std::string::npos) << r.out;
  EXPECT_EQ(entries().size(), 6u);
  r = run({"gc", (tmp_ / "out").string(), "--keep", "1"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("removed 2 bundle(s), 3 kept result(s) and 1 leftover(s)"), std::string::npos) << r.out;
  EXPECT_EQ(entries(), second);
  // without them, the next bake traces again (and keeps the same entries)
  fs::remove_all(results);
  ASSERT_EQ(run({"run", sky_at(24, 2).string(), "--force"}).exit_code, 0);
  EXPECT_TRUE(truth_of(t::read_json(latest / "manifest.json"), "truth").is_null());
  EXPECT_EQ(entries(), second);
}

}  // namespace

namespace {

// On a terminal the progress is one line redrawn in place (carriage return, erase line), with
// the step, what is running, the percentage and an ETA. `script` gives the run a terminal.
TEST_F(CliUser, LiveProgressOnATerminal) {
  if (std::system("command -v script > /dev/null 2>&1") != 0) GTEST_SKIP() << "no `script` to provide a terminal";
  const fs::path c = cfg(config(kSky + "  - name: flint\n    kind: dispersion\n    samples: 8\n    range_nm: [390, 780]\n"
                                       "    material: {glass: N-SF11}\n"));
  const std::string text = run_on_terminal("run " + c.string() + " --out " + (tmp_ / "out").string());
  EXPECT_NE(text.find("\r\033[K[1/2] sky: compute, order 2: scattering density"), std::string::npos) << text;
  EXPECT_TRUE(std::regex_search(text, std::regex("[0-9]+ %, ETA [0-9.]+ s"))) << text;
  EXPECT_NE(text.find("2 built"), std::string::npos) << text;
  // read as someone new: no log lines but warnings at the default verbosity, each warning once,
  // the files step named once, and each job's percentage never going back
  EXPECT_EQ(text.find("[info]"), std::string::npos) << text;
  EXPECT_EQ(count(text, "the Cauchy/Abbe model"), 1) << text;
  EXPECT_EQ(text.find("files, files"), std::string::npos) << text;
  EXPECT_NE(text.find("flint: files "), std::string::npos) << text;
  std::map<std::string, int> last;
  const std::regex line("\\[[0-9]+/2\\] ([a-z]+): [^\r\n]*? +([0-9]+) %");
  for (auto it = std::sregex_iterator(text.begin(), text.end(), line); it != std::sregex_iterator(); ++it) {
    const std::string job = (*it)[1];
    const int percent = std::stoi((*it)[2]);
    EXPECT_GE(percent, last[job]) << job << " went back to " << percent << " %";
    last[job] = percent;
  }
  EXPECT_EQ(last.size(), 2u) << text;
}

// Before 5 % of a job is done the ETA comes from the estimate `plan` shows: the cost model
// scaled by the job's last bake on this device. A last bake recorded as 5000 s for the model's
// seconds of a rebake (a first run keeps the scene's truth; the rebake the model recorded)
// makes the first ETA of the next --force rebake about 83 min; the uncalibrated model of this
// small sky is under a second.
TEST_F(CliUser, TheFirstEtaIsTheCalibratedEstimate) {
  if (std::system("command -v script > /dev/null 2>&1") != 0) GTEST_SKIP() << "no `script` to provide a terminal";
  const fs::path c = cfg(config(kSky));
  ASSERT_EQ(run({"run", c.string()}).exit_code, 0);
  ASSERT_EQ(run({"run", c.string(), "--force"}).exit_code, 0);
  const fs::path manifest = tmp_ / "out" / "sky" / "latest" / "manifest.json";
  json m = t::read_json(manifest);
  ASSERT_LT(m["timings_s"]["model_2core_cpu_s"].get<double>(), 60.0);
  m["timings_s"]["bake"] = 5000.0;
  t::write_file(manifest, m.dump(2));
  const std::string text = run_on_terminal("run " + c.string() + " --force --out " + (tmp_ / "out").string());
  EXPECT_TRUE(std::regex_search(text, std::regex("sky: plan, planning +0 %, ETA 8[23] min [0-9]{2} s"))) << text;
}

}  // namespace
