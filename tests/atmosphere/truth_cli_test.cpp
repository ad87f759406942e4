// `specbake truth`: the command-line contract other tools call (POINTS.csv in, RESULT.csv out).
#include <gtest/gtest.h>

#include <fstream>
#include <regex>
#include <sstream>

#include "support/testing.hpp"

namespace {

namespace t = specbake::testing;
namespace fs = std::filesystem;

const char* kSky =
    "specbake: 1\noutput: out\njobs:\n  - name: sky\n    kind: atmosphere\n    orders: 3\n"
    "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}\n"
    "    scene: {points: 16}\n"
    "  - name: prism\n    kind: dispersion\n    samples: 4\n    material: {n_d: 1.5, v_d: 60}\n";

std::string read(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

std::vector<std::vector<std::string>> csv(const std::string& text) {
  std::vector<std::vector<std::string>> rows;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (line.empty()) continue;
    rows.emplace_back();
    std::istringstream l(line);
    for (std::string f; std::getline(l, f, ',');) rows.back().push_back(f);
  }
  return rows;
}

TEST(TruthCli, ContractColumnsDeterminismAndBundleLookups) {
  t::TempDir tmp;
  t::write_file(tmp / "c.yaml", kSky);
  t::write_file(tmp / "p.csv", "altitude_km,view_zenith_deg,sun_zenith_deg,view_sun_azimuth_deg\n0,0,30,0\n2,70,50,120\n");
  ASSERT_EQ(t::run_cli({"run", (tmp / "c.yaml").string(), "--only", "sky"}, tmp.path()).exit_code, 0);
  auto truth = [&](const std::string& out, const std::vector<std::string>& extra) {
    std::vector<std::string> args = {"truth", (tmp / "c.yaml").string(), "--job", "sky", "--points",
                                     (tmp / "p.csv").string(), "--out", (tmp / out).string(), "--paths", "256"};
    args.insert(args.end(), extra.begin(), extra.end());
    return t::run_cli(args, tmp.path());
  };
  auto r = truth("r1.csv", {"--bundle", (tmp / "out" / "sky" / "latest").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto rows = csv(read(tmp / "r1.csv"));
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[0], (std::vector<std::string>{"altitude_km", "view_zenith_deg", "sun_zenith_deg",
                                               "view_sun_azimuth_deg", "L_R", "se_R", "L_G", "se_G", "L_B", "se_B",
                                               "lut_R", "lut_G", "lut_B"}));
  for (std::size_t i = 1; i < rows.size(); ++i) {
    ASSERT_EQ(rows[i].size(), rows[0].size());
    for (std::size_t c = 4; c < rows[i].size(); ++c) EXPECT_GT(std::stod(rows[i][c]), 0.0) << rows[0][c];
    // The LUT and the truth describe the same sky: within a factor of 2 at these sunlit views
    // (the LUT error measured in docs/atmosphere.md is a few percent to ~15 %; 256 walks carry
    // a few percent of standard error).
    for (int c = 0; c < 3; ++c) {
      const double L = std::stod(rows[i][4 + 2 * c]), lut = std::stod(rows[i][10 + c]);
      EXPECT_LT(std::fabs(std::log(L / lut)), std::log(2.0)) << rows[0][4 + 2 * c];
    }
  }
  // Same seed, same bytes (the job folder names its latest bundle, as for inspect and diff);
  // another seed, other numbers.
  ASSERT_EQ(truth("r2.csv", {"--bundle", (tmp / "out" / "sky").string()}).exit_code, 0);
  EXPECT_EQ(read(tmp / "r1.csv"), read(tmp / "r2.csv"));
  ASSERT_EQ(truth("r3.csv", {"--seed", "7", "--orders", "1"}).exit_code, 0);
  EXPECT_NE(read(tmp / "r3.csv").substr(read(tmp / "r3.csv").find('\n')), read(tmp / "r1.csv").substr(read(tmp / "r1.csv").find('\n')));
}

TEST(TruthCli, BadInputs) {
  t::TempDir tmp;
  t::write_file(tmp / "c.yaml", kSky);
  t::write_file(tmp / "bad.csv", "altitude_km,view_zenith_deg,sun_zenith_deg,view_sun_azimuth_deg\n0,0,30\n");
  auto run = [&](const std::string& job, const std::string& points, const std::vector<std::string>& extra = {}) {
    std::vector<std::string> args = {"truth", (tmp / "c.yaml").string(), "--job", job, "--points",
                                     (tmp / points).string(), "--out", (tmp / "r.csv").string()};
    args.insert(args.end(), extra.begin(), extra.end());
    return t::run_cli(args, tmp.path());
  };
  auto r = run("sky", "bad.csv");
  EXPECT_EQ(r.exit_code, 3) << r.err;  // a bad POINTS.csv: file:line:col
  EXPECT_TRUE(std::regex_search(r.err, std::regex("bad\\.csv:2:[0-9]+"))) << r.err;
  EXPECT_FALSE(fs::exists(tmp / "r.csv"));
  EXPECT_EQ(run("sky", "missing.csv").exit_code, 5);
  r = run("skyy", "bad.csv");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("did you mean 'sky'"), std::string::npos) << r.err;
  EXPECT_EQ(run("prism", "bad.csv").exit_code, 2);  // not an atmosphere job
  EXPECT_EQ(run("sky", "bad.csv", {"--orders", "zero"}).exit_code, 2);
  // An output it cannot write, or a --bundle that is no bundle, is found before the trace (which
  // at 10^9 walks a point would not end within the test's timeout).
  t::write_file(tmp / "p.csv", "altitude_km,view_zenith_deg,sun_zenith_deg,view_sun_azimuth_deg\n0,0,30,0\n");
  r = t::run_cli({"truth", (tmp / "c.yaml").string(), "--job", "sky", "--points", (tmp / "p.csv").string(), "--out",
                  (tmp / "no-such-folder" / "r.csv").string(), "--paths", "1000000000"},
                 tmp.path());
  EXPECT_EQ(r.exit_code, 5) << r.err;
  EXPECT_NE(r.err.find("no-such-folder"), std::string::npos) << r.err;
  r = run("sky", "p.csv", {"--paths", "1000000000", "--bundle", tmp.path().string()});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("expected a bundle folder"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(tmp / "r.csv"));
}

}  // namespace
