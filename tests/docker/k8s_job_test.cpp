// docker/k8s/nightly-indexed-job.yaml, the Kubernetes recipe docs/docker.md points at: it parses,
// is an Indexed Job whose --shard auto/N matches its completions, and its args, run once per
// index with JOB_COMPLETION_INDEX set as the Job controller sets it, split tests/nightly/configs
// into disjoint shards that together cover every job (`plan`: nothing baked).
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <set>

#include "support/testing.hpp"

namespace specbake {
namespace {

using testing::read_json;
using testing::run_cli;
using testing::source_dir;
using testing::TempDir;

// Kubernetes expands $(VAR) in args from the container's environment.
std::string expand(std::string arg, const std::string& var, const std::string& value) {
  const std::string ref = "$(" + var + ")";
  for (auto at = arg.find(ref); at != std::string::npos; at = arg.find(ref, at + value.size()))
    arg.replace(at, ref.size(), value);
  return arg;
}

TEST(K8sJob, IndexedJobArgsSplitTheConfigsByCompletionIndex) {
  const auto file = source_dir() / "docker" / "k8s" / "nightly-indexed-job.yaml";
  const YAML::Node job = YAML::LoadFile(file.string());
  EXPECT_EQ(job["apiVersion"].as<std::string>(), "batch/v1");
  ASSERT_EQ(job["kind"].as<std::string>(), "Job");
  const YAML::Node spec = job["spec"];
  ASSERT_EQ(spec["completionMode"].as<std::string>(), "Indexed");
  const int n = spec["completions"].as<int>();
  ASSERT_GE(n, 2);
  const YAML::Node pod = spec["template"]["spec"];
  EXPECT_EQ(pod["restartPolicy"].as<std::string>(), "Never");
  EXPECT_EQ(pod["securityContext"]["runAsUser"].as<int>(), 10001);  // the image's user (docker/Dockerfile)
  ASSERT_EQ(pod["containers"].size(), 1u);
  const auto args = pod["containers"][0]["args"].as<std::vector<std::string>>();
  ASSERT_FALSE(args.empty());
  ASSERT_EQ(args[0], "run");
  const auto shard = std::find(args.begin(), args.end(), "--shard");
  ASSERT_NE(shard, args.end());
  ASSERT_NE(shard + 1, args.end());
  EXPECT_EQ(*(shard + 1), "auto/" + std::to_string(n)) << "--shard auto/N must name the Job's completions";

  // The volume at /data: configs/ (the test night's), reports/; assets/ is written by `run`.
  TempDir t;
  const auto data = t.path() / "data";
  std::filesystem::create_directories(data / "reports");
  std::filesystem::copy(source_dir() / "tests" / "nightly" / "configs", data / "configs");
  std::set<std::string> all;
  for (int i = 0; i < n; ++i) {
    std::vector<std::string> a = {"plan"};  // the same selection as run, nothing baked
    for (auto it = args.begin() + 1; it != args.end(); ++it) {
      std::string v = expand(*it, "JOB_COMPLETION_INDEX", std::to_string(i));
      if (v.rfind("/data", 0) == 0) v = data.string() + v.substr(5);
      a.push_back(v);
    }
    const auto r = run_cli(a, {}, {"JOB_COMPLETION_INDEX=" + std::to_string(i), "SLURM_ARRAY_TASK_ID=",
                                   "SPECBAKE_SHARD_INDEX=", "SPECBAKE_SHARD_COUNT=", "SLURM_JOB_ID="});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto rep = read_json(data / "reports" / ("shard-" + std::to_string(i) + ".json"));
    EXPECT_EQ(rep["shard"]["index"], i);
    EXPECT_EQ(rep["shard"]["count"], n);
    for (const auto& j : rep["jobs"]) EXPECT_TRUE(all.insert(j["name"].get<std::string>()).second) << j["name"];
  }
  EXPECT_EQ(all, (std::set<std::string>{"bk7-prism", "sf11-prism", "sine-grating", "small-sky"}));
  const auto merged = run_cli({"report", (data / "reports").string()});
  EXPECT_EQ(merged.exit_code, 0) << merged.out << merged.err;
  // An index past completions (the Job and the args disagree) is a usage error.
  std::vector<std::string> a = {"plan", (data / "configs").string(), "--shard", *(shard + 1)};
  const auto r = run_cli(a, {}, {"JOB_COMPLETION_INDEX=" + std::to_string(n)});
  EXPECT_EQ(r.exit_code, 2) << r.err;
}

}  // namespace
}  // namespace specbake
