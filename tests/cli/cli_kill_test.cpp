// A run killed with SIGKILL at any moment — while baking, while writing a bundle's files,
// between the bundle's rename and the `latest` update — leaves every earlier bundle and every
// `latest` intact: `latest` always names a complete bundle (every file matches the manifest's
// sha256), no half-written bundle is visible under a hash name, and the next run removes the
// temporary folders the killed run left.
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/hash.hpp"
#include "support/testing.hpp"

namespace {

namespace t = specbake::testing;
namespace fs = std::filesystem;

constexpr int kJobs = 16;

std::string job_name(int i) { return "job" + std::to_string(100 + i).substr(1); }

// kJobs jobs; `samples` changes every job's hash.
std::string config(int samples) {
  std::ostringstream y;
  y << "specbake: 1\noutput: out\njobs:\n";
  for (int i = 0; i < kJobs; ++i)
    y << "  - name: " << job_name(i) << "\n    kind: dispersion\n    samples: " << samples + i
      << "\n    sampling: visible-pdf\n    material: {glass: N-SF11}\n";
  return y.str();
}

// A bundle folder is complete when its manifest parses and lists files that all match.
::testing::AssertionResult complete(const fs::path& bundle) {
  nlohmann::json m;
  try {
    m = t::read_json(bundle / "manifest.json");
  } catch (const std::exception& e) {
    return ::testing::AssertionFailure() << bundle << ": no readable manifest (" << e.what() << ")";
  }
  std::set<std::string> present;  // every file, previews in their folder too
  for (const auto& e : fs::recursive_directory_iterator(bundle))
    if (e.is_regular_file()) present.insert(fs::relative(e.path(), bundle).generic_string());
  present.erase("manifest.json");
  std::set<std::string> listed;
  for (const auto& f : m.at("files")) {
    const std::string p = f.at("path");
    listed.insert(p);
    if (!fs::exists(bundle / p) || specbake::sha256_file(bundle / p) != f.at("sha256"))
      return ::testing::AssertionFailure() << bundle << ": " << p << " missing or altered";
  }
  if (listed != present) return ::testing::AssertionFailure() << bundle << ": files not in the manifest";
  return ::testing::AssertionSuccess();
}

bool is_temporary(const std::string& name) {
  return name.rfind(".tmp-", 0) == 0 || name.rfind(".latest-", 0) == 0 || name.rfind(".old-", 0) == 0;
}

// The invariant after any kill: for every job, `latest` exists and names a complete bundle,
// every non-hidden folder is a complete bundle, and the first run's bundle is unchanged.
void check_job_dirs(const fs::path& out, const std::vector<t::TreeSnapshot>& first, const std::vector<std::string>& first_hash,
                    int& temporaries) {
  for (int i = 0; i < kJobs; ++i) {
    SCOPED_TRACE(job_name(i));
    const fs::path dir = out / job_name(i);
    ASSERT_TRUE(fs::is_symlink(dir / "latest"));
    EXPECT_TRUE(complete(dir / "latest"));
    EXPECT_TRUE(t::snapshot(dir / first_hash[i]) == first[i]) << "the earlier bundle changed";
    for (const auto& e : fs::directory_iterator(dir)) {
      const std::string name = e.path().filename().string();
      if (name == "latest" || name == ".lock") continue;
      if (is_temporary(name)) {
        ++temporaries;
        continue;
      }
      EXPECT_TRUE(e.is_directory() && !e.is_symlink()) << name;
      EXPECT_TRUE(complete(e.path()));
    }
  }
}

TEST(KilledRun, LeavesPreviousBundlesAndLatestIntact) {
  t::TempDir tmp;
  const fs::path out = tmp / "out";
  t::write_file(tmp / "first.yaml", config(4));
  t::write_file(tmp / "second.yaml", config(40));
  const auto r = t::run_cli({"run", (tmp / "first.yaml").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::vector<t::TreeSnapshot> first;
  std::vector<std::string> first_hash;
  for (int i = 0; i < kJobs; ++i) {
    first_hash.push_back(fs::read_symlink(out / job_name(i) / "latest").string());
    first.push_back(t::snapshot(out / job_name(i) / first_hash.back()));
  }

  // The second config uninterrupted, into another folder: its hashes and bytes, and how
  // long it takes.
  const auto t0 = std::chrono::steady_clock::now();
  const auto full = t::run_cli({"run", (tmp / "second.yaml").string(), "--out", (tmp / "timing").string()});
  ASSERT_EQ(full.exit_code, 0) << full.err;
  const double run_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::vector<std::string> second_hash;
  for (int i = 0; i < kJobs; ++i) second_hash.push_back(fs::read_symlink(tmp / "timing" / job_name(i) / "latest").string());

  // Kill runs of the second config (every job a new hash; --force, so later runs rebuild
  // what earlier ones finished, through the replace path). The kill points are found by
  // watching the output folder, so they do not depend on the machine's speed:
  //   "writing"   as soon as job j's temporary folder appears (files half written),
  //   "written"   as soon as its manifest is in the temporary folder (before the rename),
  //   "published" as soon as job j's `latest` names the new bundle (then job j+1 is baking);
  // plus kills after fixed fractions of the uninterrupted run's duration.
  struct Kill {
    const char* when;
    int job;
    double fraction;
  };
  const Kill kills[] = {{"writing", 1, 0}, {"written", 3, 0}, {"published", 5, 0}, {"writing", 8, 0},
                        {"written", 11, 0}, {"writing", 14, 0}, {"published", 15, 0}, {"time", 0, 0.1},
                        {"time", 0, 0.5}, {"time", 0, 0.9}};
  int temporaries = 0, hit = 0, attempts = 0;
  for (const Kill& k : kills) {
    SCOPED_TRACE(std::string("kill when ") + k.when + " job " + std::to_string(k.job) + " fraction " +
                 std::to_string(k.fraction));
    // Make the watched state fresh: job j's `latest` back on the first bundle.
    if (std::string(k.when) == "published") {
      const fs::path link = out / job_name(k.job) / "latest", tmp_link = out / job_name(k.job) / "relink";
      fs::create_symlink(first_hash[k.job], tmp_link);
      fs::rename(tmp_link, link);
    }
    ++attempts;
    const pid_t pid = t::spawn_cli({"run", (tmp / "second.yaml").string(), "--force", "-q"}, tmp.path(),
                                   tmp / "kill.out", tmp / "kill.err");
    ASSERT_GT(pid, 0);
    const fs::path job_dir = out / job_name(k.job);
    const fs::path tmp_dir = job_dir / (".tmp-" + second_hash[k.job] + "-" + std::to_string(pid));
    const auto start = std::chrono::steady_clock::now();
    bool reached = false;
    int status = 0;
    pid_t done = 0;
    while (!reached) {
      std::error_code ec;
      if (std::string(k.when) == "writing") reached = fs::exists(tmp_dir, ec);
      else if (std::string(k.when) == "written") reached = fs::exists(tmp_dir / "manifest.json", ec);
      else if (std::string(k.when) == "published") reached = fs::read_symlink(job_dir / "latest", ec) == second_hash[k.job];
      else reached = std::chrono::steady_clock::now() - start > std::chrono::duration<double>(k.fraction * run_s);
      if (reached) break;
      done = ::waitpid(pid, &status, WNOHANG);
      if (done == pid) break;  // finished before the point was seen
      if (std::chrono::steady_clock::now() - start > std::chrono::seconds(60)) break;
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
    if (done != pid) {
      ::kill(pid, SIGKILL);
      ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    }
    hit += reached && WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL;
    check_job_dirs(out, first, first_hash, temporaries);
  }
  // Most kill points must have been reached (a state can flash by between two polls).
  EXPECT_GE(hit, attempts - 3);
  std::printf("%d of %d kill points hit; %d temporary entries were left behind\n", hit, attempts, temporaries);
  EXPECT_GT(temporaries, 0) << "no kill left a temporary folder: the clean-up below proves less";

  // A stale temporary folder of a process that no longer exists (a reaped child's pid).
  const pid_t dead = ::fork();
  if (dead == 0) _exit(0);
  ::waitpid(dead, nullptr, 0);
  const fs::path stale = out / job_name(0) / (".tmp-" + first_hash[0] + "-" + std::to_string(dead));
  t::write_file(stale / "weights.bin", "half");

  // The next (uninterrupted) run of the first config: all up to date, `latest` back on the
  // first bundles, nothing temporary left.
  const auto again = t::run_cli({"run", (tmp / "first.yaml").string()});
  EXPECT_EQ(again.exit_code, 0) << again.err;
  EXPECT_NE(again.out.find("0 built, " + std::to_string(kJobs) + " up to date"), std::string::npos) << again.out;
  for (int i = 0; i < kJobs; ++i) {
    SCOPED_TRACE(job_name(i));
    EXPECT_EQ(fs::read_symlink(out / job_name(i) / "latest").string(), first_hash[i]);
    EXPECT_TRUE(t::snapshot(out / job_name(i) / first_hash[i]) == first[i]);
    for (const auto& e : fs::directory_iterator(out / job_name(i)))
      EXPECT_FALSE(is_temporary(e.path().filename().string())) << "left behind: " << e.path();
  }
  // And the second config completes after all its interruptions, byte-identical to the
  // uninterrupted run.
  const auto second = t::run_cli({"run", (tmp / "second.yaml").string()});
  EXPECT_EQ(second.exit_code, 0) << second.err;
  for (int i = 0; i < kJobs; ++i) {
    SCOPED_TRACE(job_name(i));
    const fs::path a = fs::canonical(out / job_name(i) / "latest"), b = fs::canonical(tmp / "timing" / job_name(i) / "latest");
    EXPECT_EQ(a.filename(), b.filename());
    auto sa = t::snapshot(a).files, sb = t::snapshot(b).files;
    sa.erase("manifest.json");
    sb.erase("manifest.json");
    EXPECT_EQ(sa, sb);
  }
}

}  // namespace
