// A kind defined only here, registered at run time: the registry, config loader, runner and
// bundle writer handle it without knowing it — what adding a kind needs is its folder, its
// kernels and one registry line.
#include <gtest/gtest.h>

#include <cmath>
#include <csignal>
#include <fstream>

#include "core/hash.hpp"
#include "io/inspect.hpp"
#include "registry/registry.hpp"
#include "runner/runner.hpp"
#include "support/testing.hpp"

namespace specbake {
namespace {

using nlohmann::json;

// `kind: squares` — n values i² computed by an OpenCL kernel, checked against the host.
struct SquaresSpec : KindSpec {
  int n = 16;
};

constexpr const char* kSquaresSource = R"CL(
__kernel void squares(__global float* out) {
  const int i = get_global_id(0);
  out[i] = (float)i * (float)i;
}
)CL";

Kind squares_kind() {
  Kind k;
  k.name = "squares";
  k.summary = "test-only: i squared";
  k.parse = [](const yaml::At& job, json& norm, Inputs& inputs) -> std::shared_ptr<const KindSpec> {
    job.allow_keys({"name", "kind", "count"});
    auto s = std::make_shared<SquaresSpec>();
    if (job.has("count")) s->n = static_cast<int>(job.child("count").number_in(1, 4096, "in [1, 4096]"));
    norm = {{"kind", "squares"}, {"count", s->n}};
    inputs.emplace_back("squares.cl", sha256_hex(kSquaresSource));
    return s;
  };
  k.plan = [](const JobSpec& j, JobContext&) { return json{{"count", j.as<SquaresSpec>().n}}; };
  k.bake = [](const JobSpec& j, JobContext& ctx) {
    const int n = j.as<SquaresSpec>().n;
    BakeResult r;
    ctx.enter(Stage::plan);
    r.parameters = {{"count", n}};
    ctx.enter(Stage::compute);
    cl::Program program(ctx.device.context(), kSquaresSource);
    program.build();
    cl::Buffer out(ctx.device.context(), CL_MEM_WRITE_ONLY, n * sizeof(float));
    cl::Kernel kernel(program, "squares");
    kernel.setArg(0, out);
    ctx.device.queue().enqueueNDRangeKernel(kernel, cl::NullRange, cl::NDRange(n));
    std::vector<float> v(n);
    ctx.device.queue().enqueueReadBuffer(out, CL_TRUE, 0, n * sizeof(float), v.data());
    ctx.enter(Stage::check);
    double worst = 0.0;
    for (int i = 0; i < n; ++i) worst = std::max(worst, std::fabs(v[i] - double(i) * i));
    // i² < 2^24 for i < 4096: exact in float32.
    r.accuracy.push_back(Accuracy::judged("exact", "max abs error", worst, 0.0, "i*i in double"));
    ctx.enter(Stage::files);
    r.files.push_back({"squares.bin", float32_le(v, "squares"), "float32", {n}, "little-endian float32", "1", "i^2"});
    return r;
  };
  k.cost_s = [](const JobSpec&) { return 0.01; };
  k.memory = [](const JobSpec& j) {
    const std::uint64_t b = j.as<SquaresSpec>().n * sizeof(float);
    return MemoryEstimate{b, b};
  };
  return k;
}

// `kind: cut-short` — a bake whose library step fails; with `stop: true` a stop (Ctrl-C) is
// requested just before, as when a signal cuts a system call short inside a library.
struct CutShortSpec : KindSpec {
  bool stop = false;
};
Kind cut_short_kind() {
  Kind k;
  k.name = "cut-short";
  k.summary = "test-only: fails in a library step";
  k.parse = [](const yaml::At& job, json& norm, Inputs&) -> std::shared_ptr<const KindSpec> {
    job.allow_keys({"name", "kind", "stop"});
    auto s = std::make_shared<CutShortSpec>();
    s->stop = job.has("stop") && job.child("stop").choice<int>({{"true", 1}, {"false", 0}}) == 1;
    norm = {{"kind", "cut-short"}, {"stop", s->stop}};
    return s;
  };
  k.plan = [](const JobSpec&, JobContext&) { return json::object(); };
  k.bake = [](const JobSpec& j, JobContext& ctx) -> BakeResult {
    ctx.enter(Stage::compute);
    if (j.as<CutShortSpec>().stop) request_stop(SIGINT);
    throw JobError("a library step failed (interrupted system call)");
  };
  k.cost_s = [](const JobSpec&) { return 0.01; };
  k.memory = [](const JobSpec&) { return MemoryEstimate{1, 1}; };
  return k;
}

class TestKind : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    bool known = false;
    for (const auto& k : kinds()) known = known || k.name == "squares";
    if (!known) {
      register_kind(squares_kind());
      register_kind(cut_short_kind());
    }
  }
  testing::TempDir tmp_;
};

TEST_F(TestKind, RegisteredKindIsParsedPlannedBakedAndWritten) {
  const Config c = parse_config("specbake: 1\njobs:\n  - name: sq\n    kind: squares\n    count: 100\n", "sq.yaml");
  ASSERT_EQ(c.jobs.size(), 1u);
  EXPECT_EQ(c.jobs[0].as<SquaresSpec>().n, 100);
  RunOptions opts;
  opts.out = tmp_.path() / "out";
  {
    Runner plan({c}, opts);
    const auto reports = plan.plan();
    ASSERT_EQ(reports.size(), 1u);
    EXPECT_EQ(reports[0].status, "planned") << reports[0].reason;
    EXPECT_EQ(reports[0].parameters.at("count"), 100);
  }
  Runner run({c}, opts);
  const auto reports = run.run();
  ASSERT_EQ(reports.size(), 1u);
  ASSERT_EQ(reports[0].status, "built") << reports[0].reason;
  const fs::path bundle = reports[0].bundle;
  std::ifstream in(bundle / "manifest.json");
  const json m = json::parse(in);
  EXPECT_EQ(m.at("job").at("kind"), "squares");
  const json* exact = find_accuracy(m.at("accuracy"), "exact");
  ASSERT_NE(exact, nullptr);
  EXPECT_EQ(exact->at("value").get<double>(), 0.0);
  EXPECT_TRUE(exact->at("passed").get<bool>());
  // inspect (through the job folder's `latest`) finds every file as the manifest lists it.
  const Inspection seen = inspect_bundle(opts.out.value() / "sq");
  EXPECT_EQ(seen.bad, 0);
  ASSERT_EQ(seen.files.size(), 1u);
  EXPECT_EQ(seen.files[0].path, "squares.bin");
  EXPECT_EQ(seen.files[0].status, "ok");
  // The same job again is up to date.
  Runner again({c}, opts);
  EXPECT_EQ(again.run().at(0).status, "up-to-date");
}

TEST_F(TestKind, ItsConfigErrorsNameTheKeyAndSuggest) {
  try {
    parse_config("specbake: 1\njobs:\n  - name: sq\n    kind: squares\n    cout: 3\n", "sq.yaml");
    FAIL() << "unknown key accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(e.where().line, 5);
    EXPECT_NE(std::string(e.what()).find("did you mean 'count'"), std::string::npos) << e.what();
  }
  try {
    parse_config("specbake: 1\njobs:\n  - name: sq\n    kind: sqares\n", "sq.yaml");
    FAIL() << "unknown kind accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("squares"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("did you mean 'squares'"), std::string::npos) << e.what();
  }
}

// A job that fails after a stop was requested is reported interrupted (the stop's exit code, the
// failure named as the step it stopped), and without a stop the same failure is a failure.
TEST_F(TestKind, AFailureAfterAStopIsTheInterruption) {
  RunOptions opts;
  opts.out = tmp_.path() / "out";
  for (const bool stop : {true, false}) {
    const Config c = parse_config(std::string("specbake: 1\njobs:\n  - name: cut\n    kind: cut-short\n    stop: ") +
                                      (stop ? "true" : "false") + "\n",
                                  "cut.yaml");
    Runner run({c}, opts);
    const auto reports = run.run();
    clear_stop_request();
    ASSERT_EQ(reports.size(), 1u);
    EXPECT_EQ(reports[0].status, stop ? "interrupted" : "failed") << reports[0].reason;
    EXPECT_EQ(reports[0].code, stop ? ExitCode::interrupted : ExitCode::job_failed);
    EXPECT_NE(reports[0].reason.find("interrupted system call"), std::string::npos) << reports[0].reason;
    EXPECT_FALSE(fs::exists(opts.out.value() / "cut" / "latest"));
  }
}

// A built job's bundle is written while the next job bakes: every report is still finished in the
// jobs' order (the `done` callback sees them so), a bundle is complete and `latest` once its report
// is, and a later job's failure or stop leaves an earlier job's bundle published.
TEST_F(TestKind, BundlesWrittenWhileTheNextJobBakesAreReportedInOrder) {
  RunOptions opts;
  opts.out = tmp_.path() / "out";
  for (const char* last : {"    kind: squares\n    count: 30\n", "    kind: cut-short\n    stop: false\n",
                           "    kind: cut-short\n    stop: true\n"}) {
    fs::remove_all(opts.out.value());
    const Config c = parse_config(std::string("specbake: 1\njobs:\n  - name: a\n    kind: squares\n    count: 10\n"
                                              "  - name: b\n    kind: squares\n    count: 20\n  - name: c\n") +
                                      last,
                                  "three.yaml");
    std::vector<std::string> seen;
    Runner run({c}, opts, {}, [&](const JobReport& r) {
      seen.push_back(r.name);
      // when a report is finished its bundle is in place
      if (r.status == "built") {
        EXPECT_TRUE(fs::exists(r.bundle / "manifest.json")) << r.name;
        EXPECT_TRUE(fs::exists(opts.out.value() / r.name / "latest")) << r.name;
        EXPECT_TRUE(r.timings.contains("write_s")) << r.name;
        EXPECT_GE(r.timings.at("total_s").get<double>(), r.timings.at("bake_s").get<double>()) << r.name;
      }
    });
    const auto reports = run.run();
    clear_stop_request();
    ASSERT_EQ(reports.size(), 3u);
    EXPECT_EQ(seen, (std::vector<std::string>{"a", "b", "c"})) << last;
    for (int k : {0, 1}) {
      EXPECT_EQ(reports[k].status, "built") << reports[k].reason;
      EXPECT_EQ(inspect_bundle(opts.out.value() / reports[k].name).bad, 0) << reports[k].name;
    }
    const std::string want = std::string(last).find("squares") != std::string::npos ? "built"
                             : std::string(last).find("true") != std::string::npos ? "interrupted"
                                                                                 : "failed";
    EXPECT_EQ(reports[2].status, want) << reports[2].reason;
    EXPECT_EQ(fs::exists(opts.out.value() / "c" / "latest"), want == "built");
  }
}

TEST_F(TestKind, NamesAreUnique) { EXPECT_THROW(register_kind(squares_kind()), std::invalid_argument); }

}  // namespace
}  // namespace specbake
