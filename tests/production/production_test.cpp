// Production use: run reports, sharding, locking between concurrent runs, gc, diff, and the
// fault paths (kernel build failure, full disk, unwritable output). Each fault must leave the
// previous bundle and `latest` intact and report clearly with the documented exit code.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <map>
#include <set>

#include "core/hash.hpp"
#include "runner/runner.hpp"
#include "job/kind.hpp"
#include "support/testing.hpp"

namespace specbake {
namespace {

using testing::read_file;
using testing::read_json;
using testing::TempDir;
using testing::write_file;

const char* kConfig = R"(specbake: 1
jobs:
  - name: prism-a
    kind: dispersion
    samples: 8
    material: {glass: N-BK7}
  - name: prism-b
    kind: dispersion
    samples: 12
    sampling: gauss-legendre
    material: {n_d: 1.6, v_d: 40}
)";

struct Spawned {
  int exit_code = -1;
  std::string out, err;
};

// Runs the CLI with extra environment variables and an optional file-size limit (bytes; 0 =
// none). SIGXFSZ is ignored in the child so a write past the limit fails with EFBIG, as a
// full disk fails with ENOSPC.
Spawned spawn(const std::vector<std::string>& args, const std::map<std::string, std::string>& env = {},
              rlim_t fsize_limit = 0) {
  TempDir tmp;
  const auto out_path = tmp / "out", err_path = tmp / "err";
  const pid_t pid = ::fork();
  if (pid == 0) {
    FILE* o = std::fopen(out_path.c_str(), "w");
    FILE* e = std::fopen(err_path.c_str(), "w");
    ::dup2(fileno(o), 1);
    ::dup2(fileno(e), 2);
    for (const auto& [k, v] : env) ::setenv(k.c_str(), v.c_str(), 1);
    if (fsize_limit) {
      ::signal(SIGXFSZ, SIG_IGN);
      rlimit rl{fsize_limit, fsize_limit};
      ::setrlimit(RLIMIT_FSIZE, &rl);
    }
    std::vector<char*> argv;
    const std::string exe = testing::specbake_exe().string();
    argv.push_back(const_cast<char*>(exe.c_str()));
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(exe.c_str(), argv.data());
    _exit(127);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  Spawned r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  r.out = read_file(out_path);
  r.err = read_file(err_path);
  return r;
}

// sha256 of every file under dir (relative path → hash), `latest` link targets included.
std::map<std::string, std::string> snapshot(const fs::path& dir) {
  std::map<std::string, std::string> s;
  for (auto it = fs::recursive_directory_iterator(dir); it != fs::recursive_directory_iterator(); ++it) {
    const auto rel = fs::relative(it->path(), dir).string();
    if (it->is_symlink()) s[rel] = "-> " + fs::read_symlink(it->path()).string();
    else if (it->is_regular_file() && it->path().filename() != ".lock") s[rel] = sha256_file(it->path());
  }
  return s;
}

std::set<std::string> hidden_entries(const fs::path& job_dir) {
  std::set<std::string> s;
  for (const auto& e : fs::directory_iterator(job_dir)) {
    const auto n = e.path().filename().string();
    if (n.front() == '.' && n != ".lock") s.insert(n);
  }
  return s;
}

TEST(Production, ReportListsEveryJobWithStatusParametersAndTimings) {
  TempDir t;
  write_file(t / "c.yaml", kConfig);
  auto r = spawn({"run", (t / "c.yaml").string(), "--out", (t / "out").string(), "--report", (t / "r.json").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto rep = read_json(t / "r.json");
  EXPECT_EQ(rep["schema"], "specbake.report/1");
  EXPECT_EQ(rep["summary"]["built"], 2);
  ASSERT_EQ(rep["jobs"].size(), 2u);
  for (const auto& j : rep["jobs"]) {
    EXPECT_EQ(j["status"], "built");
    EXPECT_TRUE(fs::is_directory(j["bundle"].get<std::string>()));
    EXPECT_GT(j["parameters"]["samples"].get<int>(), 0);
    EXPECT_NE(specbake::find_accuracy(j["accuracy"], "sum_K_minus_I"), nullptr);
    EXPECT_GE(j["timings"]["total_s"].get<double>(), 0.0);
  }
  // Second run: both up to date, reported as such.
  r = spawn({"run", (t / "c.yaml").string(), "--out", (t / "out").string(), "--report", (t / "r.json").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  rep = read_json(t / "r.json");
  EXPECT_EQ(rep["summary"]["up_to_date"], 2);
}

TEST(Production, FailingJobDoesNotStopOthersAndRunExitsNonZero) {
  TempDir t;
  // prism-bad cannot meet its tolerance with any N ≤ 4096 (ΔE 1e-9 is below float roundoff
  // of the picture), so it fails at run time; prism-a must still be written.
  write_file(t / "c.yaml", R"(specbake: 1
jobs:
  - {name: prism-bad, kind: dispersion, samples: auto, tolerance_de2000: 1e-9, material: {n_d: 1.5, v_d: 60}}
  - {name: prism-a, kind: dispersion, samples: 4, material: {n_d: 1.5, v_d: 60}}
)");
  auto r = spawn({"run", (t / "c.yaml").string(), "--out", (t / "out").string(), "--report", (t / "r.json").string()});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("prism-bad"), std::string::npos);
  EXPECT_TRUE(fs::exists(t / "out" / "prism-a" / "latest" / "manifest.json"));
  EXPECT_FALSE(fs::exists(t / "out" / "prism-bad" / "latest"));
  const auto rep = read_json(t / "r.json");
  EXPECT_EQ(rep["summary"]["failed"], 1);
  EXPECT_EQ(rep["summary"]["built"], 1);
}

TEST(Production, ShardsPartitionJobsDeterministicallyAndBalanced) {
  std::vector<std::pair<std::string, double>> jobs;
  for (int i = 0; i < 23; ++i) jobs.emplace_back("job" + std::to_string(i), 1.0 + (i % 5) * 3.0);
  for (int n : {1, 2, 3, 7}) {
    const auto a = assign_shards(jobs, n), b = assign_shards(jobs, n);
    EXPECT_EQ(a, b);  // deterministic
    std::vector<double> load(n, 0.0);
    double total = 0.0, biggest = 0.0;
    for (std::size_t i = 0; i < jobs.size(); ++i) {
      ASSERT_GE(a[i], 0);
      ASSERT_LT(a[i], n);
      load[a[i]] += jobs[i].second;
      total += jobs[i].second;
      biggest = std::max(biggest, jobs[i].second);
    }
    // Greedy largest-first: no shard exceeds the mean by more than one job's cost.
    for (double l : load) EXPECT_LE(l, total / n + biggest);
  }
}

TEST(Production, ShardedRunsTogetherBuildEveryJobOnce) {
  TempDir t;
  write_file(t / "c.yaml", kConfig);
  std::set<std::string> built;
  for (int i = 0; i < 3; ++i) {
    const auto rep_path = t / ("r" + std::to_string(i) + ".json");
    auto r = spawn({"run", (t / "c.yaml").string(), "--out", (t / "out").string(), "--shard",
                    std::to_string(i) + "/3", "--report", rep_path.string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto rep = read_json(rep_path);
    for (const auto& j : rep["jobs"]) EXPECT_TRUE(built.insert(j["name"].get<std::string>()).second) << j["name"];
  }
  EXPECT_EQ(built, (std::set<std::string>{"prism-a", "prism-b"}));
  EXPECT_EQ(spawn({"run", (t / "c.yaml").string(), "--shard", "3/3"}).exit_code, 2);
}

// --shard auto: a Slurm array task, a Kubernetes index or SPECBAKE_SHARD_* pick the same jobs as
// the explicit I/N, and the report records the shard and where it came from; a missing or
// contradictory environment is a usage error (exit 2) that names the variables, with the
// report written (shard null) and nothing baked.
TEST(Production, ShardAutoReadsTheSchedulersEnvironment) {
  TempDir t;
  write_file(t / "c.yaml", kConfig);
  // No inherited shard variables: each run sets exactly the ones it names (empty = unset).
  const std::map<std::string, std::string> none = {
      {"SLURM_JOB_ID", ""},         {"SLURM_ARRAY_TASK_ID", ""},  {"SLURM_ARRAY_TASK_MIN", ""},
      {"SLURM_ARRAY_TASK_MAX", ""}, {"SLURM_ARRAY_TASK_COUNT", ""}, {"JOB_COMPLETION_INDEX", ""},
      {"SPECBAKE_SHARD_INDEX", ""}, {"SPECBAKE_SHARD_COUNT", ""}};
  const auto with = [&](std::map<std::string, std::string> vars) {
    vars.insert(none.begin(), none.end());  // insert keeps the given values
    return vars;
  };
  const auto jobs_of = [&](const std::vector<std::string>& shard_args, const std::map<std::string, std::string>& env) {
    const auto rep = t / "plan.json";
    std::vector<std::string> args = {"plan", (t / "c.yaml").string(), "--out", (t / "out").string(), "--report",
                                     rep.string()};
    args.insert(args.end(), shard_args.begin(), shard_args.end());
    const auto r = spawn(args, env);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    std::set<std::string> names;
    const auto j = read_json(rep);
    for (const auto& job : j["jobs"]) names.insert(job["name"].get<std::string>());
    return std::make_pair(names, j["shard"]);
  };
  for (int i = 0; i < 2; ++i) {
    const auto [expected, explicit_shard] = jobs_of({"--shard", std::to_string(i) + "/2"}, none);
    EXPECT_EQ(explicit_shard["index"], i);
    EXPECT_EQ(explicit_shard["count"], 2);
    ASSERT_EQ(expected.size(), 1u);  // two jobs, two shards
    // sbatch --array=1-2: task ID i+1 is shard i.
    const auto [slurm, slurm_shard] = jobs_of(
        {"--shard", "auto"},
        with({{"SLURM_ARRAY_TASK_ID", std::to_string(i + 1)}, {"SLURM_ARRAY_TASK_MIN", "1"},
              {"SLURM_ARRAY_TASK_MAX", "2"}, {"SLURM_ARRAY_TASK_COUNT", "2"}}));
    EXPECT_EQ(slurm, expected);
    EXPECT_EQ(slurm_shard["index"], i);
    EXPECT_NE(slurm_shard["source"].get<std::string>().find("SLURM_ARRAY_TASK_ID=" + std::to_string(i + 1)),
              std::string::npos);
    EXPECT_EQ(jobs_of({"--shard", "auto/2"}, with({{"JOB_COMPLETION_INDEX", std::to_string(i)}})).first, expected);
    EXPECT_EQ(jobs_of({"--shard", "auto"},
                      with({{"SPECBAKE_SHARD_INDEX", std::to_string(i)}, {"SPECBAKE_SHARD_COUNT", "2"}})).first,
              expected);
  }
  const auto refused = [&](const std::vector<std::string>& shard_args, const std::map<std::string, std::string>& env,
                           const std::string& phrase) {
    const auto rep = t / "refused.json";
    std::vector<std::string> args = {"run", (t / "c.yaml").string(), "--out", (t / "refused-out").string(),
                                     "--report", rep.string()};
    args.insert(args.end(), shard_args.begin(), shard_args.end());
    const auto r = spawn(args, env);
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(r.err.find(phrase), std::string::npos) << r.err;
    const auto j = read_json(rep);
    EXPECT_TRUE(j["shard"].is_null());
    EXPECT_NE(j["error"].get<std::string>().find(phrase), std::string::npos);
    EXPECT_FALSE(fs::exists(t / "refused-out"));
  };
  refused({"--shard", "auto"}, none, "no shard in the environment");
  refused({"--shard", "auto"}, with({{"SLURM_JOB_ID", "12"}}), "not an array task");
  refused({"--shard", "auto"}, with({{"JOB_COMPLETION_INDEX", "1"}}), "expected --shard auto/N");
  refused({"--shard", "auto"},
          with({{"SLURM_ARRAY_TASK_ID", "0"}, {"SLURM_ARRAY_TASK_COUNT", "2"}, {"SPECBAKE_SHARD_INDEX", "1"},
                {"SPECBAKE_SHARD_COUNT", "2"}}),
          "the environment disagrees");
  refused({"--shard", "auto/3"}, with({{"SLURM_ARRAY_TASK_ID", "0"}, {"SLURM_ARRAY_TASK_COUNT", "2"}}),
          "2 shards, not 3");
  refused({"--shard", "auto/x"}, none, "--shard auto/N expects a count");
}

// `specbake report` over the shard reports of real runs: one table, exit 0 for a complete night,
// 1 when a shard's job failed (with its reason), 3 for a file that is not a report, 5 for a path
// that does not exist; --json gives the same merge.
TEST(Production, ReportMergesTheShardsOfANight) {
  TempDir t;
  write_file(t / "c.yaml", R"(specbake: 1
jobs:
  - {name: prism-bad, kind: dispersion, samples: auto, tolerance_de2000: 1e-9, material: {n_d: 1.5, v_d: 60}}
  - {name: prism-a, kind: dispersion, samples: 4, material: {n_d: 1.5, v_d: 60}}
  - {name: prism-b, kind: dispersion, samples: 8, material: {glass: N-BK7}}
)");
  std::set<std::string> failed_shard_jobs;
  for (int i = 0; i < 2; ++i) {
    const auto rep = t / "reports" / ("shard-" + std::to_string(i) + ".json");
    fs::create_directories(rep.parent_path());
    const auto r = spawn({"run", (t / "c.yaml").string(), "--out", (t / "out").string(), "--shard",
                          std::to_string(i) + "/2", "--report", rep.string()});
    EXPECT_TRUE(r.exit_code == 0 || r.exit_code == 1) << r.err;
    const auto shard_report = read_json(rep);
    for (const auto& j : shard_report["jobs"])
      if (r.exit_code != 0) failed_shard_jobs.insert(j["name"].get<std::string>());
  }
  ASSERT_TRUE(failed_shard_jobs.count("prism-bad"));
  auto r = spawn({"report", (t / "reports").string()});
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  for (const char* phrase : {"prism-bad", "failed", "1 failed", "the night FAILED", "shard-0.json", "shard-1.json"})
    EXPECT_NE(r.out.find(phrase), std::string::npos) << phrase << "\n" << r.out;
  r = spawn({"report", (t / "reports").string(), "--json"});
  EXPECT_EQ(r.exit_code, 1);
  const auto night = nlohmann::json::parse(r.out);
  EXPECT_EQ(night["summary"]["jobs"], 3);
  EXPECT_EQ(night["summary"]["statuses"]["built"], 2);
  EXPECT_EQ(night["summary"]["statuses"]["failed"], 1);
  EXPECT_EQ(night["failed"], true);

  // Without the failing job, the next night is complete: every job up to date, exit 0.
  write_file(t / "c.yaml", R"(specbake: 1
jobs:
  - {name: prism-a, kind: dispersion, samples: 4, material: {n_d: 1.5, v_d: 60}}
  - {name: prism-b, kind: dispersion, samples: 8, material: {glass: N-BK7}}
)");
  for (int i = 0; i < 2; ++i)
    ASSERT_EQ(spawn({"run", (t / "c.yaml").string(), "--out", (t / "out").string(), "--shard",
                     std::to_string(i) + "/2", "--report", (t / "night2" / ("s" + std::to_string(i) + ".json")).string()})
                  .exit_code,
              5);  // no folder night2 yet: the report path is checked first (exit 5)
  fs::create_directories(t / "night2");
  for (int i = 0; i < 2; ++i)
    ASSERT_EQ(spawn({"run", (t / "c.yaml").string(), "--out", (t / "out").string(), "--shard",
                     std::to_string(i) + "/2", "--report", (t / "night2" / ("s" + std::to_string(i) + ".json")).string()})
                  .exit_code,
              0);
  r = spawn({"report", (t / "night2" / "s0.json").string(), (t / "night2" / "s1.json").string()});
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("2 jobs from 2 shard reports: 0 built, 2 up to date"), std::string::npos) << r.out;

  write_file(t / "not-a-report.json", "{\"jobs\": 3}");
  r = spawn({"report", (t / "not-a-report.json").string()});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("not-a-report.json"), std::string::npos) << r.err;
  EXPECT_EQ(spawn({"report", (t / "nowhere.json").string()}).exit_code, 5);
  EXPECT_EQ(spawn({"report"}).exit_code, 2);
}

TEST(Production, ConcurrentRunsOnOneOutputDoNotCorruptIt) {
  TempDir t;
  write_file(t / "c.yaml", kConfig);
  const std::string out = (t / "out").string();
  std::vector<pid_t> pids;
  for (int i = 0; i < 3; ++i) {
    const pid_t pid = ::fork();
    if (pid == 0) {
      const auto r = spawn({"run", (t / "c.yaml").string(), "--out", out, "-q",
                            "--report", (t / ("r" + std::to_string(i) + ".json")).string()});
      _exit(r.exit_code);
    }
    pids.push_back(pid);
  }
  for (pid_t p : pids) {
    int st = 0;
    ::waitpid(p, &st, 0);
    EXPECT_TRUE(WIFEXITED(st) && WEXITSTATUS(st) == 0);
  }
  // Each job was built by exactly one run; the others waited for its lock and skipped.
  std::map<std::string, int> built;
  for (int i = 0; i < 3; ++i) {
    const auto rep = read_json(t / ("r" + std::to_string(i) + ".json"));
    for (const auto& j : rep["jobs"]) built[j["name"].get<std::string>()] += j["status"] == "built";
  }
  EXPECT_EQ(built["prism-a"], 1);
  EXPECT_EQ(built["prism-b"], 1);
  for (const char* job : {"prism-a", "prism-b"}) {
    EXPECT_TRUE(hidden_entries(fs::path(out) / job).empty());
    EXPECT_EQ(spawn({"inspect", (fs::path(out) / job / "latest").string()}).exit_code, 0);
  }
}

TEST(Production, InjectedKernelBuildFailureKeepsPreviousBundle) {
  TempDir t;
  write_file(t / "c.yaml", kConfig);
  const std::string out = (t / "out").string();
  ASSERT_EQ(spawn({"run", (t / "c.yaml").string(), "--out", out}).exit_code, 0);
  const auto before = snapshot(out);
  const auto r = spawn({"run", (t / "c.yaml").string(), "--out", out, "--force"},
                       {{"SPECBAKE_INJECT_BUILD_FAILURE", "kernels/dispersion"}});
  EXPECT_EQ(r.exit_code, 4) << r.err;                             // device/OpenCL failure
  EXPECT_NE(r.err.find("CL_BUILD_PROGRAM_FAILURE"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("build failure injected"), std::string::npos) << r.err;  // the build log
  EXPECT_EQ(snapshot(out), before);
}

TEST(Production, FullDiskFailsWithIoErrorAndKeepsPreviousBundle) {
  // A 256 KiB tmpfs, mounted in a private user + mount namespace (no root needed): bake once,
  // fill the disk, rebuild with --force. The rebuild must fail with an I/O error (exit 5)
  // and leave the first bundle and `latest` as they were.
  TempDir t;
  write_file(t / "c.yaml", kConfig);
  const std::string exe = testing::specbake_exe().string(), disk = (t / "disk").string();
  fs::create_directories(disk);
  const std::string script =
      "set -u; mount -t tmpfs -o size=256k tmpfs " + disk + " || exit 99; cd " + t.path().string() + "; " +
      exe + " run c.yaml --out " + disk + " -q >/dev/null 2>&1 || exit 98; " +
      "find " + disk + " -type f ! -name .lock -exec sha256sum {} + | sort > before.txt; " +
      "readlink " + disk + "/prism-a/latest >> before.txt; " +
      "dd if=/dev/zero of=" + disk + "/filler bs=4k 2>/dev/null; " +
      exe + " run c.yaml --out " + disk + " --force > err.txt 2>&1; echo $? > rc.txt; " +
      "rm " + disk + "/filler; " +
      "find " + disk + " -type f ! -name .lock -exec sha256sum {} + | sort > after.txt; " +
      "readlink " + disk + "/prism-a/latest >> after.txt; " +
      "ls -a " + disk + "/prism-a " + disk + "/prism-b > entries.txt; " +
      exe + " inspect " + disk + "/prism-a/latest > /dev/null; echo $? > inspect.txt";
  const int rc = std::system(("unshare -rm sh -c '" + script + "'").c_str());
  if (WEXITSTATUS(rc) == 99) GTEST_SKIP() << "this machine cannot mount a tmpfs in a user namespace";
  ASSERT_EQ(WEXITSTATUS(rc), 0);
  EXPECT_EQ(read_file(t / "rc.txt"), "5\n") << read_file(t / "err.txt");
  EXPECT_NE(read_file(t / "err.txt").find("No space left on device"), std::string::npos) << read_file(t / "err.txt");
  EXPECT_EQ(read_file(t / "after.txt"), read_file(t / "before.txt"));
  EXPECT_EQ(read_file(t / "inspect.txt"), "0\n");
  EXPECT_EQ(read_file(t / "entries.txt").find(".tmp-"), std::string::npos) << read_file(t / "entries.txt");
}

TEST(Production, UnwritableOutputIsRefusedBeforeAnyJobRuns) {
  TempDir t;
  write_file(t / "c.yaml", kConfig);
  write_file(t / "a-file", "not a folder");
  // A path below a regular file cannot be created, whoever runs the test (root included).
  const auto r = spawn({"run", (t / "c.yaml").string(), "--out", (t / "a-file" / "out").string()});
  EXPECT_EQ(r.exit_code, 5) << r.err;
  EXPECT_NE(r.err.find((t / "a-file" / "out").string()), std::string::npos) << r.err;
}

TEST(Production, GcKeepsNewestAndLatest) {
  TempDir t;
  const std::string out = (t / "out").string();
  // Three configs of one job → three bundles; then the oldest config again → latest = oldest.
  for (int n : {4, 5, 6, 4}) {
    write_file(t / "c.yaml", "specbake: 1\njobs: [{name: p, kind: dispersion, samples: " + std::to_string(n) +
                                 ", material: {n_d: 1.5, v_d: 60}}]\n");
    ASSERT_EQ(spawn({"run", (t / "c.yaml").string(), "--out", out}).exit_code, 0);
    ::usleep(1100 * 1000);  // manifests record creation time to the second
  }
  const auto latest = fs::read_symlink(fs::path(out) / "p" / "latest");
  auto bundles = [&] {
    std::set<std::string> s;
    for (const auto& e : fs::directory_iterator(fs::path(out) / "p"))
      if (e.is_directory() && !e.is_symlink() && e.path().filename().string().front() != '.')
        s.insert(e.path().filename().string());
    return s;
  };
  ASSERT_EQ(bundles().size(), 3u);
  ASSERT_EQ(spawn({"gc", out, "--keep", "1"}).exit_code, 0);
  // Kept: the newest bundle (N=6) and latest (the N=4 bundle, created first, re-selected by
  // the last run), although latest is the oldest. The N=5 bundle is gone.
  const auto left = bundles();
  ASSERT_EQ(left.size(), 2u);
  EXPECT_TRUE(left.count(latest.string()));
  std::set<int> samples;
  for (const auto& b : left) samples.insert(read_json(fs::path(out) / "p" / b / "manifest.json")["config"]["samples"].get<int>());
  EXPECT_EQ(samples, (std::set<int>{4, 6}));
  EXPECT_EQ(spawn({"inspect", (fs::path(out) / "p" / "latest").string()}).exit_code, 0);
}

TEST(Production, DiffReportsWhereAndFailsPastThresholds) {
  TempDir t;
  write_file(t / "c.yaml", kConfig);
  ASSERT_EQ(spawn({"run", (t / "c.yaml").string(), "--out", (t / "out").string()}).exit_code, 0);
  const fs::path a = t / "out" / "prism-a" / "latest";
  fs::copy(a, t / "copy", fs::copy_options::recursive);
  EXPECT_EQ(spawn({"diff", a.string(), (t / "copy").string()}).exit_code, 0);
  // Scale K_2[1][2] by (1 + 1e-3).
  auto k = testing::read_f32(t / "copy" / "matrices.bin");
  const std::size_t flat = 2 * 9 + 1 * 3 + 2;
  k[flat] *= 1.001f;
  write_file(t / "copy" / "matrices.bin", std::string(reinterpret_cast<const char*>(k.data()), k.size() * 4));
  auto r = spawn({"diff", a.string(), (t / "copy").string(), "--fail-rel", "1e-4"});
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("matrices.bin"), std::string::npos);
  EXPECT_NE(r.out.find("[2,1,2]"), std::string::npos) << r.out;
  // 1e-3 relative change: passes a 2e-3 relative threshold (float rounding adds < 1e-7).
  EXPECT_EQ(spawn({"diff", a.string(), (t / "copy").string(), "--fail-rel", "2e-3"}).exit_code, 0);
  // Different jobs: parameters differ and are listed.
  r = spawn({"diff", a.string(), (t / "out" / "prism-b" / "latest").string(), "--fail-rel", "1"});
  EXPECT_NE(r.out.find("config.samples"), std::string::npos) << r.out;
  EXPECT_EQ(r.exit_code, 1);  // shapes differ (8 vs 12 samples)
  // Job folders are taken as inspect takes them (their latest bundle); anything else is named.
  EXPECT_EQ(spawn({"diff", (t / "out" / "prism-a").string(), a.string()}).exit_code, 0);
  r = spawn({"diff", (t / "out" / "prism-a").string(), (t / "out" / "prism-b").string(), "--fail-rel", "1"});
  EXPECT_NE(r.out.find("config.samples"), std::string::npos) << r.out;
  r = spawn({"diff", (t / "out").string(), a.string()});
  EXPECT_EQ(r.exit_code, 3) << r.err;  // an invalid input
  EXPECT_NE(r.err.find("expected a bundle folder (with manifest.json) or a job folder"), std::string::npos) << r.err;
}

TEST(Production, ByteIdenticalAcrossRunsAndDeviceSelectors) {
  TempDir t;
  // One job of each kind, small enough to run four times.
  write_file(t / "c.yaml", std::string(kConfig) + R"(  - name: grating
    kind: diffraction
    procedural: {type: sine-grating, size: 64, dx_um: 0.0625, period_um: 2.0, amplitude_um: 0.15}
    terms: 8
    tolerance: 1e-2
  - name: tiny-sky
    kind: atmosphere
    orders: 2
    sizes: {transmittance: [16, 8], irradiance: [8, 4], scattering: {r: 4, mu: 8, mu_s: 4, nu: 2}}
    scene: {points: 16}
)");
  std::vector<std::map<std::string, std::string>> snaps;
  int i = 0;
  for (const char* dev : {"auto", "cpu", "auto", "portable"}) {
    const auto out = t / ("out" + std::to_string(i++));
    ASSERT_EQ(spawn({"run", (t / "c.yaml").string(), "--out", out.string(), "--device", dev}).exit_code, 0);
    auto s = snapshot(out);
    std::erase_if(s, [](const auto& kv) { return kv.first.find("manifest.json") != std::string::npos; });
    snaps.push_back(s);
  }
  for (std::size_t k = 1; k < snaps.size(); ++k) EXPECT_EQ(snaps[k], snaps[0]);
}

TEST(Production, AliasBombAndMultiDocumentConfigsAreRefused) {
  TempDir t;
  std::string bomb = "specbake: 1\nx0: &a0 [1,1,1,1,1,1,1,1,1,1]\n";
  for (int i = 1; i < 8; ++i)
    bomb += "x" + std::to_string(i) + ": &a" + std::to_string(i) + " [*a" + std::to_string(i - 1) + ",*a" +
            std::to_string(i - 1) + ",*a" + std::to_string(i - 1) + ",*a" + std::to_string(i - 1) + ",*a" +
            std::to_string(i - 1) + ",*a" + std::to_string(i - 1) + ",*a" + std::to_string(i - 1) + ",*a" +
            std::to_string(i - 1) + ",*a" + std::to_string(i - 1) + ",*a" + std::to_string(i - 1) + "]\n";
  write_file(t / "bomb.yaml", bomb + "jobs: []\n");
  auto r = spawn({"run", (t / "bomb.yaml").string(), "--out", (t / "out").string()});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("alias"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(t / "out"));
  write_file(t / "two.yaml", std::string(kConfig) + "---\nspecbake: 1\n");
  r = spawn({"run", (t / "two.yaml").string(), "--out", (t / "out").string()});
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_NE(r.err.find("one YAML document"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(t / "out"));
}

}  // namespace
}  // namespace specbake

namespace specbake {
namespace {

TEST(Production, JobsTooBigForTheDeviceAreRefusedBeforeAllocation) {
  const Config c = parse_config(R"(specbake: 1
jobs:
  - name: big
    kind: diffraction
    procedural: {type: sine-grating, size: 4096, dx_um: 0.0625, period_um: 2.0, amplitude_um: 0.15}
)", "mem.yaml");
  cl_util::DeviceInfo small;
  small.name = "small device";
  small.global_mem_bytes = 256ull << 20;
  small.max_alloc_bytes = 64ull << 20;
  try {
    check_device_memory(c.jobs.at(0), small);
    FAIL() << "a 4096² field (128 MiB per complex float field) must not fit 256 MiB";
  } catch (const InputError& e) {
    EXPECT_EQ(e.where().line, 3);  // the job's entry
    EXPECT_NE(std::string(e.what()).find("small device"), std::string::npos) << e.what();
  }
  cl_util::DeviceInfo big = small;
  big.global_mem_bytes = 8ull << 30;
  big.max_alloc_bytes = 2ull << 30;
  EXPECT_NO_THROW(check_device_memory(c.jobs.at(0), big));
}

}  // namespace
}  // namespace specbake
