// --shard: I/N and auto[/N] from a scheduler's environment (src/runner/shard.hpp).
#include <gtest/gtest.h>

#include <map>

#include "core/errors.hpp"
#include "runner/shard.hpp"

namespace specbake {
namespace {

Environment env_of(std::map<std::string, std::string> vars) {
  return [vars = std::move(vars)](const std::string& name) -> std::optional<std::string> {
    const auto it = vars.find(name);
    if (it == vars.end()) return std::nullopt;
    return it->second;
  };
}

std::pair<int, int> shard_of(const std::string& text, std::map<std::string, std::string> vars = {}) {
  const Shard s = parse_shard(text, env_of(std::move(vars)));
  return {s.index, s.count};
}

// The UsageError's message (the test fails when nothing is thrown).
std::string refusal(const std::string& text, std::map<std::string, std::string> vars = {}) {
  try {
    parse_shard(text, env_of(std::move(vars)));
  } catch (const UsageError& e) {
    return e.what();
  }
  ADD_FAILURE() << "--shard " << text << " was accepted";
  return "";
}

TEST(Shard, ExplicitIndexOfCount) {
  EXPECT_EQ(shard_of("2/5"), std::make_pair(2, 5));
  EXPECT_EQ(shard_of("0/1"), std::make_pair(0, 1));
  EXPECT_EQ(parse_shard("2/5", env_of({})).source, "--shard 2/5");
  // An explicit I/N ignores the environment.
  EXPECT_EQ(shard_of("1/2", {{"SLURM_ARRAY_TASK_ID", "7"}, {"SLURM_ARRAY_TASK_COUNT", "9"}}), std::make_pair(1, 2));
  for (const char* bad : {"5/5", "-1/3", "1", "a/b", "1/0", "1/2x", "+1/3", " 1/3", "1/", "/3", "auto/", "auto/x",
                          "auto/0", "auto/-2", "autox", "Auto"})
    EXPECT_NE(refusal(bad).find("--shard"), std::string::npos) << bad;
}

TEST(Shard, SlurmArrayFromMinAndMax) {
  // sbatch --array=0-3: IDs 0..3 are shards 0..3 of 4.
  for (int id = 0; id < 4; ++id)
    EXPECT_EQ(shard_of("auto", {{"SLURM_ARRAY_TASK_ID", std::to_string(id)},
                                {"SLURM_ARRAY_TASK_MIN", "0"},
                                {"SLURM_ARRAY_TASK_MAX", "3"},
                                {"SLURM_ARRAY_TASK_COUNT", "4"}}),
              std::make_pair(id, 4));
  // --array=1-3 (no COUNT, as older Slurm): ID 1 is shard 0 of 3.
  EXPECT_EQ(shard_of("auto", {{"SLURM_ARRAY_TASK_ID", "1"}, {"SLURM_ARRAY_TASK_MIN", "1"}, {"SLURM_ARRAY_TASK_MAX", "3"}}),
            std::make_pair(0, 3));
  EXPECT_EQ(shard_of("auto/3", {{"SLURM_ARRAY_TASK_ID", "3"}, {"SLURM_ARRAY_TASK_MIN", "1"}, {"SLURM_ARRAY_TASK_MAX", "3"}}),
            std::make_pair(2, 3));
  // COUNT alone: the ID is the index.
  EXPECT_EQ(shard_of("auto", {{"SLURM_ARRAY_TASK_ID", "2"}, {"SLURM_ARRAY_TASK_COUNT", "5"}}), std::make_pair(2, 5));
  const Shard s = parse_shard("auto", env_of({{"SLURM_ARRAY_TASK_ID", "1"}, {"SLURM_ARRAY_TASK_MIN", "1"},
                                              {"SLURM_ARRAY_TASK_MAX", "2"}}));
  EXPECT_NE(s.source.find("SLURM_ARRAY_TASK_ID=1"), std::string::npos) << s.source;
}

TEST(Shard, SlurmArraysThatDoNotMapOntoShardsAreRefused) {
  // --array=0-6:2 (IDs 0,2,4,6): 4 tasks over a span of 7.
  EXPECT_NE(refusal("auto", {{"SLURM_ARRAY_TASK_ID", "4"}, {"SLURM_ARRAY_TASK_MIN", "0"},
                             {"SLURM_ARRAY_TASK_MAX", "6"}, {"SLURM_ARRAY_TASK_COUNT", "4"}})
                .find("contiguous"),
            std::string::npos);
  EXPECT_NE(refusal("auto", {{"SLURM_ARRAY_TASK_ID", "4"}}).find("number of shards is unknown"), std::string::npos);
  EXPECT_NE(refusal("auto", {{"SLURM_ARRAY_TASK_ID", "4"}, {"SLURM_ARRAY_TASK_COUNT", "4"}}).find("0 <= index < count"),
            std::string::npos);
  EXPECT_NE(refusal("auto", {{"SLURM_ARRAY_TASK_ID", "9"}, {"SLURM_ARRAY_TASK_MIN", "0"}, {"SLURM_ARRAY_TASK_MAX", "3"}})
                .find("not within"),
            std::string::npos);
  EXPECT_NE(refusal("auto", {{"SLURM_ARRAY_TASK_ID", "x1"}, {"SLURM_ARRAY_TASK_COUNT", "4"}})
                .find("SLURM_ARRAY_TASK_ID='x1'; expected a non-negative integer"),
            std::string::npos);
  // auto/N must agree with the array.
  EXPECT_NE(refusal("auto/3", {{"SLURM_ARRAY_TASK_ID", "1"}, {"SLURM_ARRAY_TASK_COUNT", "4"}}).find("4 shards, not 3"),
            std::string::npos);
}

TEST(Shard, KubernetesIndexTakesTheCountFromAutoN) {
  EXPECT_EQ(shard_of("auto/4", {{"JOB_COMPLETION_INDEX", "3"}}), std::make_pair(3, 4));
  EXPECT_NE(refusal("auto", {{"JOB_COMPLETION_INDEX", "3"}}).find("expected --shard auto/N"), std::string::npos);
  EXPECT_NE(refusal("auto/3", {{"JOB_COMPLETION_INDEX", "3"}}).find("0 <= index < count"), std::string::npos);
}

TEST(Shard, SpecbakeVariables) {
  EXPECT_EQ(shard_of("auto", {{"SPECBAKE_SHARD_INDEX", "1"}, {"SPECBAKE_SHARD_COUNT", "2"}}), std::make_pair(1, 2));
  EXPECT_EQ(shard_of("auto/6", {{"SPECBAKE_SHARD_INDEX", "5"}}), std::make_pair(5, 6));
  EXPECT_NE(refusal("auto", {{"SPECBAKE_SHARD_INDEX", "1"}}).find("SPECBAKE_SHARD_COUNT is not"), std::string::npos);
  EXPECT_NE(refusal("auto", {{"SPECBAKE_SHARD_COUNT", "2"}}).find("SPECBAKE_SHARD_INDEX is not"), std::string::npos);
  EXPECT_NE(refusal("auto", {{"SPECBAKE_SHARD_INDEX", "2"}, {"SPECBAKE_SHARD_COUNT", "0"}}).find("0 <= index < count"),
            std::string::npos);
}

TEST(Shard, NothingSetIsRefusedAndSaysWhereItLooked) {
  for (const char* text : {"auto", "auto/4"}) {
    const std::string e = refusal(text);
    for (const char* var : {"SLURM_ARRAY_TASK_ID", "JOB_COMPLETION_INDEX", "SPECBAKE_SHARD_INDEX"})
      EXPECT_NE(e.find(var), std::string::npos) << e;
  }
  // Empty values count as unset.
  EXPECT_NE(refusal("auto", {{"SLURM_ARRAY_TASK_ID", ""}, {"SPECBAKE_SHARD_INDEX", ""}}).find("no shard in the environment"),
            std::string::npos);
  // A Slurm job that is not an array task is told so.
  EXPECT_NE(refusal("auto", {{"SLURM_JOB_ID", "17"}}).find("not an array task"), std::string::npos);
}

TEST(Shard, SourcesThatAgreeAreAcceptedAndDisagreeingOnesRefused) {
  const Shard s = parse_shard("auto/4", env_of({{"SLURM_ARRAY_TASK_ID", "2"}, {"SLURM_ARRAY_TASK_COUNT", "4"},
                                                {"JOB_COMPLETION_INDEX", "2"}, {"SPECBAKE_SHARD_INDEX", "2"}}));
  EXPECT_EQ(std::make_pair(s.index, s.count), std::make_pair(2, 4));
  EXPECT_NE(s.source.find("JOB_COMPLETION_INDEX=2"), std::string::npos) << s.source;
  const std::string e = refusal("auto", {{"SLURM_ARRAY_TASK_ID", "2"}, {"SLURM_ARRAY_TASK_COUNT", "4"},
                                         {"SPECBAKE_SHARD_INDEX", "1"}, {"SPECBAKE_SHARD_COUNT", "4"}});
  EXPECT_NE(e.find("disagrees"), std::string::npos) << e;
  EXPECT_NE(e.find("gives shard 2/4"), std::string::npos) << e;
  EXPECT_NE(e.find("gives 1/4"), std::string::npos) << e;
  // Same index, different count: also a disagreement.
  EXPECT_NE(refusal("auto", {{"SLURM_ARRAY_TASK_ID", "1"}, {"SLURM_ARRAY_TASK_COUNT", "4"},
                             {"SPECBAKE_SHARD_INDEX", "1"}, {"SPECBAKE_SHARD_COUNT", "3"}})
                .find("disagrees"),
            std::string::npos);
}

}  // namespace
}  // namespace specbake
