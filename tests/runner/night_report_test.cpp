// `specbake report`: shard reports merged into one night (src/runner/night_report.hpp).
#include <gtest/gtest.h>

#include "core/errors.hpp"
#include "runner/night_report.hpp"
#include "support/testing.hpp"

namespace specbake {
namespace {

using nlohmann::json;
using testing::TempDir;
using testing::write_file;

json job(const std::string& name, const std::string& status, const std::string& reason = "", double total_s = 1.5) {
  return {{"name", name},     {"kind", "dispersion"}, {"config", "c.yaml"}, {"status", status},
          {"reason", reason}, {"bundle", status == "built" || status == "up-to-date" ? json("out/" + name + "/x") : json()},
          {"timings", {{"total_s", total_s}}}};
}

// A report as `run --report` writes it (the fields the merge reads).
std::string report(std::optional<std::pair<int, int>> shard, std::vector<json> jobs, const std::string& error = "") {
  json r = {{"schema", "specbake.report/1"},
            {"tool", {{"name", "specbake"}, {"version", "0.1.0"}}},
            {"created_utc", "2026-01-01T00:00:00Z"},
            {"shard", shard ? json{{"index", shard->first}, {"count", shard->second}, {"source", "test"}} : json()},
            {"summary", json::object()},
            {"jobs", jobs}};
  if (!error.empty()) r["error"] = error;
  return r.dump(2);
}

const NightJob& job_named(const NightReport& n, const std::string& name) {
  for (const auto& j : n.jobs)
    if (j.name == name) return j;
  throw std::runtime_error("no job " + name);
}

TEST(NightReport, ShardsOfACompleteNightMergeIntoOneTable) {
  TempDir t;
  write_file(t / "r" / "shard-0.json", report(std::make_pair(0, 2), {job("a", "built"), job("b", "up-to-date")}));
  write_file(t / "r" / "shard-1.json", report(std::make_pair(1, 2), {job("c", "built", "", 12.25)}));
  write_file(t / "r" / "notes.txt", "not a report");  // only *.json files are read
  const NightReport n = merge_night({t / "r"});
  EXPECT_FALSE(n.failed());
  ASSERT_EQ(n.shards.size(), 2u);
  ASSERT_EQ(n.jobs.size(), 3u);
  EXPECT_EQ(n.jobs[0].name, "a");  // by name
  EXPECT_EQ(n.counts.at("built"), 2);
  EXPECT_EQ(n.counts.at("up-to-date"), 1);
  EXPECT_EQ(n.shards[job_named(n, "c").decision().shard].label(), "1/2");
  EXPECT_DOUBLE_EQ(job_named(n, "c").decision().seconds, 12.25);
  const std::string text = night_text(n);
  EXPECT_NE(text.find("3 jobs from 2 shard reports: 2 built, 1 up to date, 0 failed"), std::string::npos) << text;
  EXPECT_NE(text.find("the night is complete"), std::string::npos);
  EXPECT_NE(text.find("c    dispersion  built       1/2    12 s"), std::string::npos) << text;
  const json j = night_json(n);
  EXPECT_EQ(j["schema"], "specbake.night/1");
  EXPECT_EQ(j["summary"]["statuses"]["built"], 2);
  EXPECT_EQ(j["jobs"][2]["shard"], "1/2");
  EXPECT_EQ(j["failed"], false);
}

TEST(NightReport, FailuresAndShardErrorsFailTheNightWithTheirReasons) {
  TempDir t;
  write_file(t / "0.json", report(std::make_pair(0, 3), {job("a", "failed", "tolerance 1e-4 not met: 3e-4")}));
  write_file(t / "1.json", report(std::make_pair(1, 3), {job("b", "invalid", "c.yaml:4:5: unknown key 'smaples'")}));
  write_file(t / "2.json", report(std::make_pair(2, 3), {job("c", "built"), job("d", "not-run")}, "stopped by SIGTERM"));
  const NightReport n = merge_night({t / "0.json", t / "1.json", t / "2.json"});
  EXPECT_TRUE(n.failed());
  EXPECT_EQ(job_named(n, "a").status, "failed");
  EXPECT_EQ(job_named(n, "d").status, "not-run");
  const std::string text = night_text(n);
  for (const char* phrase : {"tolerance 1e-4 not met: 3e-4", "unknown key 'smaples'", "stopped by SIGTERM",
                             "shard 0/3 (", "1 failed, 1 invalid, 0 interrupted, 1 not run", "the night FAILED"})
    EXPECT_NE(text.find(phrase), std::string::npos) << phrase << "\n" << text;
}

// Two arrays over one output folder: the job one shard built is up to date in the other; a job
// built in two shards is flagged (the lock should have stopped that) but is not a failure.
TEST(NightReport, AJobInSeveralShardsTakesItsBestOutcomeAndTwoBuildsAreFlagged) {
  TempDir t;
  write_file(t / "a0.json", report(std::make_pair(0, 1), {job("x", "built"), job("y", "built"), job("z", "interrupted")}));
  write_file(t / "b0.json", report(std::make_pair(0, 2), {job("x", "up-to-date"), job("z", "built")}));
  write_file(t / "b1.json", report(std::make_pair(1, 2), {job("y", "built")}));
  const NightReport n = merge_night({t / "a0.json", t / "b0.json", t / "b1.json"});
  EXPECT_FALSE(n.failed()) << n.problems.front();
  EXPECT_EQ(job_named(n, "x").status, "built");
  EXPECT_EQ(job_named(n, "x").builds, 1);
  EXPECT_TRUE(job_named(n, "x").notes.empty());
  EXPECT_EQ(job_named(n, "y").builds, 2);
  EXPECT_EQ(n.built_twice, 1);
  ASSERT_EQ(job_named(n, "y").notes.size(), 1u);
  EXPECT_NE(job_named(n, "y").notes[0].find("built 2 times, in shards 0/1 (a0.json), 1/2 (b1.json)"), std::string::npos)
      << job_named(n, "y").notes[0];
  // An interrupted run of z, then a build elsewhere: built, with the interruption noted.
  EXPECT_EQ(job_named(n, "z").status, "built");
  EXPECT_EQ(n.shards[job_named(n, "z").decision().shard].label(), "0/2");
  ASSERT_EQ(job_named(n, "z").notes.size(), 1u);
  EXPECT_NE(job_named(n, "z").notes[0].find("interrupted in shard 0/1"), std::string::npos);
  const std::string text = night_text(n);
  EXPECT_NE(text.find("built x2"), std::string::npos) << text;
  EXPECT_NE(text.find("1 built in more than one shard"), std::string::npos) << text;
  EXPECT_EQ(night_json(n)["summary"]["built_twice"], 1);
}

TEST(NightReport, MissingShardsAndUnfinishedJobsFailTheNight) {
  TempDir t;
  write_file(t / "0.json", report(std::make_pair(0, 4), {job("a", "built")}));
  write_file(t / "2.json", report(std::make_pair(2, 4), {job("b", "interrupted", "stopped by SIGTERM")}));
  const NightReport n = merge_night({t / "0.json", t / "2.json"});
  ASSERT_TRUE(n.failed());
  const std::string all = night_text(n);
  EXPECT_NE(all.find("no report from shard 1/4, 3/4"), std::string::npos) << all;
  EXPECT_NE(all.find("b interrupted in shard 2/4"), std::string::npos) << all;
  // An unsharded run's report (no shard) merges as "-" and asks for no other shard.
  TempDir u;
  write_file(u / "r.json", report(std::nullopt, {job("a", "up-to-date")}));
  const NightReport single = merge_night({u / "r.json"});
  EXPECT_FALSE(single.failed());
  EXPECT_EQ(single.shards[0].label(), "-");
}

TEST(NightReport, InputsThatAreNotReportsAreRefusedWithWhere) {
  TempDir t;
  write_file(t / "bad.json", "{\n  \"schema\": \"specbake.report/1\",\n  \"jobs\": [,]\n}\n");
  try {
    merge_night({t / "bad.json"});
    ADD_FAILURE() << "accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(e.where().line, 3) << e.what();
    EXPECT_NE(std::string(e.what()).find("bad.json"), std::string::npos) << e.what();
  }
  write_file(t / "manifest.json", R"({"schema": "specbake.bundle/1", "files": []})");
  EXPECT_THROW(merge_night({t / "manifest.json"}), InputError);
  write_file(t / "status.json", report(std::make_pair(0, 1), {job("a", "done")}));
  try {
    merge_night({t / "status.json"});
    ADD_FAILURE() << "accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(e.where().key, "jobs[0]");
  }
  EXPECT_THROW(merge_night({t / "missing.json"}), IoError);
  TempDir empty;
  EXPECT_THROW(merge_night({empty.path()}), UsageError);
}

}  // namespace
}  // namespace specbake
