// `specbake sweep` (docs/sweep.md): the --vary grammar, the combinations and the Pareto front;
// each kind swept from the CLI on a small config, its error equal to what `run` records for the
// same settings; sweep.json, sweep.csv and the picture (size, not blank, one marker per point);
// bad --vary keys and values (exit 2 / exit 3) with nothing written.
#include <gtest/gtest.h>

#include <cmath>
#include <algorithm>
#include <iomanip>
#include <set>
#include <sstream>

#include "core/errors.hpp"
#include "runner/sweep.hpp"
#include "support/testing.hpp"

namespace {

namespace t = specbake::testing;
namespace fs = std::filesystem;
using nlohmann::json;
using specbake::parse_vary;
using specbake::SweepPoint;
using specbake::UsageError;

std::string config(const std::string& jobs) { return "specbake: 1\noutput: out\njobs:\n" + jobs; }

const std::string kPrism = "  - name: prism\n    kind: dispersion\n    samples: 6\n    material: {glass: N-BK7}\n";
const std::string kGrating =
    "  - name: grating\n    kind: diffraction\n"
    "    procedural: {type: sine-grating, size: 64, dx_um: 0.125, period_um: 2.0, amplitude_um: 0.15}\n"
    "    expansion: chebyshev\n    terms: 4\n    tolerance: 1e-3\n";
const std::string kSky =
    "  - name: sky\n    kind: atmosphere\n    orders: 2\n"
    "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}\n"
    "    scene: {points: 6, relative_se: 0.1, sun_elevation_deg: [20, 60]}\n";

// ---- the grammar --------------------------------------------------------------------------

TEST(SweepVary, RangesListsAndScalars) {
  auto v = parse_vary("orders=1..4,8");
  EXPECT_EQ(v.key, "orders");
  EXPECT_EQ(v.values, (std::vector<std::string>{"1", "2", "3", "4", "8"}));
  v = parse_vary("sizes.transmittance=[128,32],[256, 64]");
  EXPECT_EQ(v.key, "sizes.transmittance");
  EXPECT_EQ(v.values, (std::vector<std::string>{"[128,32]", "[256, 64]"}));
  v = parse_vary("sizes=50%, 100%");
  EXPECT_EQ(v.values, (std::vector<std::string>{"50%", "100%"}));
}

TEST(SweepVary, MistakesAreUsageErrors) {
  for (const char* bad : {"orders", "=1,2", "orders=", "orders=1,,2", "orders=3..1", "orders=1..x", "orders=1,1",
                          "or ders=1", "orders=[1,", "orders=0..100000"})
    EXPECT_THROW(parse_vary(bad), UsageError) << bad;
}

TEST(SweepVary, CombinationsFirstVarySlowestAndBounded) {
  const auto c = specbake::sweep_combinations({parse_vary("a=1,2"), parse_vary("b=x,y,z")});
  ASSERT_EQ(c.size(), 6u);
  EXPECT_EQ(c[0], (std::vector<std::string>{"1", "x"}));
  EXPECT_EQ(c[2], (std::vector<std::string>{"1", "z"}));
  EXPECT_EQ(c[3], (std::vector<std::string>{"2", "x"}));
  EXPECT_THROW(specbake::sweep_combinations({parse_vary("a=1..20"), parse_vary("b=1..20")}), UsageError);
  EXPECT_THROW(specbake::sweep_combinations({parse_vary("a=1"), parse_vary("a=2")}), UsageError);
  EXPECT_THROW(specbake::sweep_combinations({parse_vary("sizes=50%"), parse_vary("sizes.scattering.nu=4")}),
               UsageError);
  EXPECT_THROW(specbake::sweep_combinations({}), UsageError);
}

// The bake order is a fixed shuffle: a permutation, the same every time, not the listed order
// for a sweep of any size worth shuffling (so the first listed point is not always the first baked).
TEST(SweepVary, BakeOrderIsAFixedPermutation) {
  for (std::size_t n : {1u, 2u, 3u, 8u, 256u}) {
    const auto a = specbake::bake_order(n), b = specbake::bake_order(n);
    EXPECT_EQ(a, b) << n;
    std::vector<std::size_t> sorted = a;
    std::sort(sorted.begin(), sorted.end());
    for (std::size_t i = 0; i < n; ++i) EXPECT_EQ(sorted[i], i) << n;
  }
  std::vector<std::size_t> listed(8);
  for (std::size_t i = 0; i < 8; ++i) listed[i] = i;
  EXPECT_NE(specbake::bake_order(8), listed);
}

TEST(SweepVary, ParetoFront) {
  auto pt = [](double s, double e, const char* status = "measured") {
    SweepPoint p;
    p.bake_s = s;
    p.error = e;
    p.status = status;
    return p;
  };
  // (1, 10) front; (2, 5) front; (2, 6) dominated by (2, 5); (3, 5) dominated (slower, same error);
  // (4, 1) front; a failed point is never on it; a tie (two equal points) keeps both.
  std::vector<SweepPoint> v{pt(1, 10), pt(2, 5), pt(2, 6), pt(3, 5), pt(4, 1), pt(0.1, 0.1, "failed"), pt(4, 1)};
  specbake::mark_pareto(v);
  const std::vector<bool> want{true, true, false, false, true, false, true};
  for (std::size_t i = 0; i < v.size(); ++i) EXPECT_EQ(v[i].pareto, want[i]) << i;
}

// ---- the picture --------------------------------------------------------------------------


// Connected groups (4-neighbour) of at least `min_pixels` pixels within `tol` of the colour:
// the markers of one colour (scripts/sweep_plot.py draws them in two colours no line or text
// uses; a 7 pt marker at 150 dpi covers ~150 pixels, antialiased edges aside).
int blobs(const t::Image& im, int r, int g, int b, int tol = 24, int min_pixels = 40) {
  auto near = [&](int i) {
    const unsigned char* p = &im.rgba[4 * i];
    return std::abs(p[0] - r) <= tol && std::abs(p[1] - g) <= tol && std::abs(p[2] - b) <= tol;
  };
  std::vector<char> seen(static_cast<std::size_t>(im.width) * im.height, 0);
  int count = 0;
  for (int start = 0; start < im.width * im.height; ++start) {
    if (seen[start] || !near(start)) continue;
    int size = 0;
    std::vector<int> stack{start};
    seen[start] = 1;
    while (!stack.empty()) {
      const int i = stack.back();
      stack.pop_back();
      ++size;
      const int x = i % im.width, y = i / im.width;
      for (auto [dx, dy] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
        const int nx = x + dx, ny = y + dy;
        if (nx < 0 || ny < 0 || nx >= im.width || ny >= im.height) continue;
        const int j = ny * im.width + nx;
        if (!seen[j] && near(j)) seen[j] = 1, stack.push_back(j);
      }
    }
    if (size >= min_pixels) ++count;
  }
  return count;
}

int pixels_near(const t::Image& im, int r, int g, int b, int tol = 24) {
  int n = 0;
  for (std::size_t i = 0; i + 3 < im.rgba.size(); i += 4)
    n += std::abs(im.rgba[i] - r) <= tol && std::abs(im.rgba[i + 1] - g) <= tol && std::abs(im.rgba[i + 2] - b) <= tol;
  return n;
}

// The picture of a sweep with `points` measured points: 1200 x 825 (scripts/sweep_plot.py), not
// blank, one marker per point in each of the two panels (error against time, against bundle size;
// front: #d62728 red, dominated: #1f77b4 blue), the tolerance line.
void expect_picture(const fs::path& png, int points, bool tolerance_line) {
  const t::Image im = t::read_png(png);
  ASSERT_EQ(im.width, 1200) << png << " (is python3-matplotlib installed? scripts/setup.sh installs it)";
  ASSERT_EQ(im.height, 825);
  int not_white = 0;
  for (std::size_t i = 0; i + 3 < im.rgba.size(); i += 4)
    not_white += im.rgba[i] < 250 || im.rgba[i + 1] < 250 || im.rgba[i + 2] < 250;
  EXPECT_GT(not_white, 5000) << "blank picture";
  // the legend shows one swatch of each colour: two more blobs
  EXPECT_EQ(blobs(im, 0xd6, 0x27, 0x28) + blobs(im, 0x1f, 0x77, 0xb4), 2 * points + 2) << "markers in " << png;
  // the dashed tolerance line crosses the axes (~930 px wide, about half of it ink)
  if (tolerance_line) EXPECT_GT(pixels_near(im, 0x2c, 0xa0, 0x2c), 300);
  else EXPECT_LT(pixels_near(im, 0x2c, 0xa0, 0x2c), 50);
}

std::vector<std::vector<std::string>> read_csv(const fs::path& p) {
  std::vector<std::vector<std::string>> rows;
  std::istringstream in(t::read_file(p));
  for (std::string line; std::getline(in, line);) {
    std::vector<std::string> row;
    std::string cell;
    bool quoted = false;
    for (char c : line) {
      if (c == '"') quoted = !quoted;
      else if (c == ',' && !quoted) row.push_back(cell), cell.clear();
      else cell += c;
    }
    row.push_back(cell);
    rows.push_back(row);
  }
  return rows;
}

class Sweep : public ::testing::Test {
 protected:
  fs::path cfg(const std::string& text, const std::string& name = "c.yaml") {
    t::write_file(tmp_ / name, text);
    return tmp_ / name;
  }
  t::CliResult run(const std::vector<std::string>& args) { return t::run_cli(args, tmp_.path()); }
  t::TempDir tmp_;
};

// Dispersion: each point's error is the prism_de2000 `run` records for the same samples; the
// files hold every point; nothing is published.
TEST_F(Sweep, DispersionMeasuresWhatRunRecords) {
  const fs::path c = cfg(config(kPrism));
  const auto r = run({"sweep", c.string(), "--job", "prism", "--vary", "samples=2,6,24", "--out", "sw"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_FALSE(fs::exists(tmp_ / "out")) << "a sweep publishes no bundle";
  const json s = t::read_json(tmp_ / "sw" / "sweep.json");
  EXPECT_EQ(s["schema"], "specbake.sweep/1");
  EXPECT_EQ(s["kind"], "dispersion");
  ASSERT_EQ(s["points"].size(), 3u);
  std::set<int> orders;
  for (const auto& p : s["points"]) {
    EXPECT_EQ(p["status"], "measured");
    EXPECT_EQ(p["record"], "prism_de2000");
    EXPECT_GT(p["bake_s"].get<double>(), 0.0);
    EXPECT_GE(p["runs"].get<int>(), 1);
    // bake_s is plan + compute of the fastest run: the check and the files (the prism preview)
    // are timed apart, and the steps are chained end to start, so the three partition the whole
    // bake's wall time: equal up to the rounding of summing a handful of doubles (1e-12 relative)
    EXPECT_GT(p["files_s"].get<double>(), 0.0);
    EXPECT_NEAR(p["bake_s"].get<double>() + p["check_s"].get<double>() + p["files_s"].get<double>(),
                p["wall_s"].get<double>(), 1e-12 * p["wall_s"].get<double>());
    EXPECT_LE(p["bake_s_spread"][0].get<double>(), p["bake_s"].get<double>());
    EXPECT_EQ(p["bake_s_spread"][0].get<double>(), p["bake_s"].get<double>()) << "the fastest run is kept";
    EXPECT_GE(p["bake_s_spread"][1].get<double>(), p["bake_s"].get<double>());
    orders.insert(p["order"].get<int>());
  }
  EXPECT_EQ(orders, (std::set<int>{1, 2, 3})) << "every point baked once, in some order";
  const auto order = specbake::bake_order(3);  // points listed in the --vary order, baked in this one
  for (std::size_t k = 0; k < order.size(); ++k)
    EXPECT_EQ(s["points"][order[k]]["order"].get<int>(), int(k) + 1) << k;
  EXPECT_FALSE(s["warmup"]["point"].get<std::string>().empty());
  // 24 samples see the prism's spectrum far better than 2 (6.6e1 against ~1 CIEDE2000 here)
  EXPECT_LT(s["points"][2]["error"].get<double>(), 0.2 * s["points"][0]["error"].get<double>());

  // `run` with samples: 24 records the same error (the bake is deterministic)
  const fs::path c24 = cfg(config("  - name: prism\n    kind: dispersion\n    samples: 24\n    material: {glass: N-BK7}\n"),
                           "c24.yaml");
  ASSERT_EQ(run({"run", c24.string()}).exit_code, 0);
  const json m = t::read_json(tmp_ / "out" / "prism" / "latest" / "manifest.json");
  // the bundle size the sweep plots is what `run` publishes: the manifest's files
  std::uint64_t bytes = 0;
  for (const auto& f : m["files"]) bytes += f["bytes"].get<std::uint64_t>();
  EXPECT_EQ(s["points"][2]["bundle_bytes"].get<std::uint64_t>(), bytes);
  EXPECT_LT(s["points"][0]["bundle_bytes"].get<std::uint64_t>(), bytes) << "2 samples: smaller tables";
  const json* rec = nullptr;
  for (const auto& a : m["accuracy"])
    if (a["name"] == "prism_de2000") rec = &a;
  ASSERT_NE(rec, nullptr);
  EXPECT_EQ((*rec)["value"].get<double>(), s["points"][2]["error"].get<double>()) << std::setprecision(17) << *rec;

  const auto rows = read_csv(tmp_ / "sw" / "sweep.csv");
  ASSERT_EQ(rows.size(), 4u);
  EXPECT_EQ(rows[0], (std::vector<std::string>{"samples", "status", "bake_s", "wall_s", "device_s", "host_s", "error",
                                               "unit", "record", "tolerance", "passed", "pareto", "settings",
                                               "check_s", "files_s", "bake_s_min", "bake_s_max", "order"}));
  EXPECT_EQ(rows[3][0], "24");
  EXPECT_EQ(std::stod(rows[3][6]), s["points"][2]["error"].get<double>());
  // the job's tolerance_de2000 (default 1) is the line drawn
  EXPECT_EQ(s["points"][0]["tolerance"].get<double>(), 1.0);
  expect_picture(tmp_ / "sw" / "sweep.png", 3, true);
  EXPECT_TRUE(fs::exists(tmp_ / "sw" / "sweep_plot.py"));
}

// Diffraction: fixed term counts and both expansions; more Chebyshev terms, less error; the
// exact-transform record; a given --tolerance is the one judged.
TEST_F(Sweep, DiffractionAgainstTheExactTransform) {
  const fs::path c = cfg(config(kGrating));
  const auto r = run({"sweep", c.string(), "--job", "grating", "--vary", "terms=2,8", "--vary",
                      "expansion=taylor,chebyshev", "--tolerance", "1e-3", "--out", "sw"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const json s = t::read_json(tmp_ / "sw" / "sweep.json");
  ASSERT_EQ(s["points"].size(), 4u);
  for (const auto& p : s["points"]) {
    EXPECT_EQ(p["record"], "vs_exact_transform");
    EXPECT_EQ(p["tolerance"].get<double>(), 1e-3);
    EXPECT_EQ(p["passed"].get<bool>(), p["error"].get<double>() <= 1e-3);
  }
  EXPECT_EQ(s["points"][3]["values"]["terms"], "8");
  EXPECT_EQ(s["points"][3]["values"]["expansion"], "chebyshev");
  // Chebyshev, 2 → 8 terms: the truncation bound 2(z/2)^T/T! falls by orders of magnitude
  EXPECT_LT(s["points"][3]["error"].get<double>(), 1e-2 * s["points"][1]["error"].get<double>());
  expect_picture(tmp_ / "sw" / "sweep.png", 4, true);
  EXPECT_NE(r.out.find("terms  expansion"), std::string::npos) << r.out;
}

// With a table, the error is what a shader's filtered fetch reads (between texels), and a finer
// table reads closer to the exact transform (bilinear error ~ texel width squared).
TEST_F(Sweep, DiffractionTablesBetweenTexels) {
  const fs::path c = cfg(config(kGrating));
  const auto r = run({"sweep", c.string(), "--job", "grating", "--vary", "table.size=32,128", "--out", "sw"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const json s = t::read_json(tmp_ / "sw" / "sweep.json");
  ASSERT_EQ(s["points"].size(), 2u);
  for (const auto& p : s["points"]) EXPECT_EQ(p["record"], "table_between_texels");
  EXPECT_NE(s["points"][1]["settings"].get<std::string>().find("table 128^2"), std::string::npos);
  EXPECT_LT(s["points"][1]["error"].get<double>(), 0.5 * s["points"][0]["error"].get<double>());
}

// Atmosphere: the path-traced scene is the truth; a percentage of a job's own sizes scales them.
TEST_F(Sweep, AtmosphereAgainstThePathTracedScene) {
  const fs::path c = cfg(config(kSky));
  const auto r = run({"sweep", c.string(), "--job", "sky", "--vary", "sizes=100%,200%", "--out", "sw"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const json s = t::read_json(tmp_ / "sw" / "sweep.json");
  ASSERT_EQ(s["points"].size(), 2u);
  for (const auto& p : s["points"]) {
    EXPECT_EQ(p["record"], "vs_path_traced");
    EXPECT_EQ(p["unit"], "p99 CIEDE2000");
    EXPECT_TRUE(p["tolerance"].is_null());  // the scene gives none here: none is drawn
  }
  // {r 4, mu 8, mu_s 6, nu 3} at 200 %: every axis doubled
  EXPECT_NE(s["points"][0]["settings"].get<std::string>().find("4x8x6x3"), std::string::npos) << s["points"][0]["settings"];
  EXPECT_NE(s["points"][1]["settings"].get<std::string>().find("8x16x12x6"), std::string::npos) << s["points"][1]["settings"];
  expect_picture(tmp_ / "sw" / "sweep.png", 2, false);

  // scene: none leaves nothing to measure against
  const fs::path none = cfg(config("  - name: sky\n    kind: atmosphere\n    scene: none\n"), "none.yaml");
  const auto n = run({"sweep", none.string(), "--job", "sky", "--vary", "orders=1,2", "--out", "sw2"});
  EXPECT_EQ(n.exit_code, 3) << n.err;
  EXPECT_NE(n.err.find("scene: none"), std::string::npos) << n.err;
  EXPECT_FALSE(fs::exists(tmp_ / "sw2"));
}

// Mistakes: exit 2 for the command line, exit 3 for a value the schema refuses (naming the key
// and the --vary that set it); nothing is written either way.
TEST_F(Sweep, BadVaryKeysAndValues) {
  const fs::path c = cfg(config(kPrism));
  struct Case {
    std::vector<std::string> args;
    int code;
    std::vector<std::string> says;
  };
  const std::vector<Case> cases{
      {{"--vary", "samples"}, 2, {"KEY=V1,V2"}},
      {{"--vary", "smples=4,8"}, 2, {"unknown key 'smples'", "did you mean 'samples'"}},
      {{"--vary", "samples=8..4"}, 2, {"range 8..4 is empty"}},
      {{"--vary", "samples=1..200", "--vary", "sampling=uniform,gauss-legendre"}, 2, {"more than 256 combinations"}},
      {{"--vary", "samples=0,4"}, 3, {"jobs[0].samples", "integer in [1, 4096]", "--vary samples=0"}},
      {{"--vary", "sampling=uniform,cdf"}, 3, {"jobs[0].sampling", "uniform | gauss-legendre", "--vary sampling=cdf"}},
      {{"--job", "prsm", "--vary", "samples=4"}, 2, {"'prsm'", "did you mean 'prism'"}},
  };
  for (const auto& k : cases) {
    std::vector<std::string> args{"sweep", c.string(), "--out", "sw"};
    if (std::find(k.args.begin(), k.args.end(), "--job") == k.args.end()) args.insert(args.end(), {"--job", "prism"});
    args.insert(args.end(), k.args.begin(), k.args.end());
    const auto r = run(args);
    EXPECT_EQ(r.exit_code, k.code) << k.args.back() << ": " << r.err;
    for (const auto& s : k.says) EXPECT_NE(r.err.find(s), std::string::npos) << k.args.back() << ": " << r.err;
    EXPECT_FALSE(fs::exists(tmp_ / "sw")) << k.args.back();
  }
}

}  // namespace
