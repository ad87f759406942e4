// The written dispersion bundle (what a renderer loads) against the SPECGEN reference data:
// run the CLI on a temporary config with the refdata cases (schemes a and b, N = 4 and 16,
// both Abbe line sets) and read wavelengths.bin, weights.bin, matrices.bin, ior_offsets.bin
// and ior.bin as little-endian float32. Bounds: support/specgen_refdata.hpp for the computed
// double values, plus the float32 rounding of the stored value, |fl(x) − x| ≤ 2^-24·|x|.
#include <gtest/gtest.h>

#include <cmath>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "job/kind.hpp"
#include "support/specgen_refdata.hpp"

namespace {

using namespace specbake;
using namespace specbake::testing::specgen;
namespace t = specbake::testing;

constexpr double u32 = 5.9604644775390625e-08;  // 2^-24, float32 unit roundoff

struct Job {
  Case c;
  AbbeLines lines;
  std::string name() const {
    return std::string(c.sampling == Sampling::uniform ? "a" : "b") + std::to_string(c.n) +
           (lines == AbbeLines::D ? "-seed" : "-dline");
  }
};

std::vector<Job> jobs() {
  std::vector<Job> out;
  for (const Case& c : kCases)
    for (AbbeLines l : {AbbeLines::D, AbbeLines::d}) out.push_back({c, l});
  return out;
}

// One CLI run per test process, baking every case into a temporary output folder.
class DispersionBundle : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    tmp_ = new t::TempDir();
    std::ostringstream y;
    y << "specbake: 1\noutput: out\njobs:\n";
    for (const Job& j : jobs())
      y << "  - name: " << j.name() << "\n    kind: dispersion\n    samples: " << j.c.n
        << "\n    sampling: " << (j.c.sampling == Sampling::uniform ? "uniform" : "gauss-legendre")
        << "\n    range_nm: [380, 780]\n    cmf: cie1931-2deg\n    material: {n_d: 1.5168, v_d: 64.17}\n"
        << "    abbe_lines: " << (j.lines == AbbeLines::D ? "D" : "d") << "\n";
    t::write_file(*tmp_ / "specgen.yaml", y.str());
    run_ = new t::CliResult(t::run_cli({"run", (*tmp_ / "specgen.yaml").string()}));
  }
  static void TearDownTestSuite() {
    delete run_;
    delete tmp_;
  }
  void SetUp() override { ASSERT_EQ(run_->exit_code, 0) << run_->out << run_->err; }
  static t::fs::path bundle(const Job& j) { return *tmp_ / "out" / j.name() / "latest"; }

  static t::TempDir* tmp_;
  static t::CliResult* run_;
};
t::TempDir* DispersionBundle::tmp_ = nullptr;
t::CliResult* DispersionBundle::run_ = nullptr;

// Adds the float32 storage rounding to a bound on the double value.
std::vector<double> stored(const std::vector<double>& tol, const std::vector<double>& expected) {
  std::vector<double> out(tol.size());
  for (std::size_t i = 0; i < tol.size(); ++i)
    out[i] = tol[i] * (1.0 + u32) + u32 * std::fabs(expected[i]) * (1.0 + 1e-6) + 1e-300;
  return out;
}

std::vector<double> as_double(const std::vector<float>& v) { return {v.begin(), v.end()}; }

TEST_F(DispersionBundle, FilesMatchRefdata) {
  for (const Job& j : jobs()) {
    SCOPED_TRACE(j.name());
    const json& rc = case_of(j.c);
    std::vector<double> dl, dw;
    sample_bounds(j.c, rc, dl, dw);
    // The bundle was computed on the device the CLI picked (PoCL: fp64, so u = u53; the
    // manifest says which precision it used).
    const json m = t::read_json(bundle(j) / "manifest.json");
    const double u = m.at("parameters").at("precision") == "float64" ? u53 : u32;
    const Bounds b = bounds_for(rc, dl, dw, u, lines_for(j.lines));

    const auto lambda_ref = flat(rc.at("lambda_nm"));
    expect_within(as_double(t::read_f32(bundle(j) / "wavelengths.bin")), lambda_ref, stored(b.lambda, lambda_ref),
                  "wavelengths.bin");
    const auto w_ref = flat(rc.at("W_norm"));
    expect_within(as_double(t::read_f32(bundle(j) / "weights.bin")), w_ref, stored(b.w_norm, w_ref), "weights.bin");
    const auto K_ref = flat(rc.at("K").at("derived"));
    expect_within(as_double(t::read_f32(bundle(j) / "matrices.bin")), K_ref, stored(b.K, K_ref), "matrices.bin");
    const auto off_ref = flat(rc.at(j.lines == AbbeLines::D ? "offset_seed" : "offset_dline"));
    expect_within(as_double(t::read_f32(bundle(j) / "ior_offsets.bin")), off_ref, stored(b.offset, off_ref),
                  "ior_offsets.bin");
    // n = n_d + (n_d − 1)/V·Offset (the seed's Cauchy model): the offset bound scaled by
    // (n_d − 1)/V plus 4 roundings of n ≈ 1.5 per path.
    std::vector<double> ior_ref, ior_tol;
    for (std::size_t i = 0; i < off_ref.size(); ++i) {
      ior_ref.push_back(1.5168 + (1.5168 - 1.0) / 64.17 * off_ref[i]);
      ior_tol.push_back(b.offset[i] * (1.5168 - 1.0) / 64.17 + 4.0 * (u + u53) * 2.0);
    }
    expect_within(as_double(t::read_f32(bundle(j) / "ior.bin")), ior_ref, stored(ior_tol, ior_ref), "ior.bin");

    // The raw sums and the quadrature weights are in the manifest's parameters (double).
    expect_within(m.at("parameters").at("w_raw_sum").get<std::vector<double>>(), flat(rc.at("W_raw_sum")),
                  b.w_raw_sum, "parameters.w_raw_sum");
    expect_within(m.at("parameters").at("quadrature_weights_nm").get<std::vector<double>>(),
                  flat(rc.at("weight_nm")), b.weight, "parameters.quadrature_weights_nm");
  }
}

// Σ_n K̃_n = I for the stored float32 matrices K̃_n, summed here in double. Each stored entry is
// within 2^-24·|K_n| of the computed one, so |Σ K̃_n − I| ≤ 2^-24·Σ_n|K_n| plus the double
// path's own error (≤ (37 + 2N)·u53·max(|Minv|·|M|), see DispersionReference) plus the N
// additions here (≤ N·u53·Σ|K_n|).
TEST_F(DispersionBundle, StoredMatricesSumToIdentity) {
  const Mat3 M = srgb_to_xyz(), Minv = xyz_to_srgb();
  double absprod = 0.0;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      double s = 0.0;
      for (int k = 0; k < 3; ++k) s += std::fabs(Minv[3 * r + k]) * std::fabs(M[3 * k + c]);
      absprod = std::max(absprod, s);
    }
  for (const Job& j : jobs()) {
    SCOPED_TRACE(j.name());
    const auto K = t::read_f32(bundle(j) / "matrices.bin");
    const int n = j.c.n;
    ASSERT_EQ(K.size(), static_cast<std::size_t>(9 * n));
    const json m = t::read_json(bundle(j) / "manifest.json");
    for (int e = 0; e < 9; ++e) {
      double s = 0.0, a = 0.0;
      for (int i = 0; i < n; ++i) {
        s += K[9 * i + e];
        a += std::fabs(K[9 * i + e]);
      }
      const double bound = u32 * a * (1.0 + u32) + (37.0 + 2.0 * n) * u53 * absprod + n * u53 * a;
      EXPECT_LE(std::fabs(s - (e % 4 == 0 ? 1.0 : 0.0)), bound) << "entry " << e;
      // The manifest reports the same check on the stored values, and its bound.
      EXPECT_LE(std::fabs(s - (e % 4 == 0 ? 1.0 : 0.0)), specbake::find_accuracy(m.at("accuracy"), "sum_K_minus_I")->at("value").get<double>() + n * u53 * a);
    }
    EXPECT_LE(specbake::find_accuracy(m.at("accuracy"), "sum_K_minus_I")->at("value").get<double>(),
              specbake::find_accuracy(m.at("accuracy"), "sum_K_minus_I")->at("tolerance").get<double>());
  }
}

// dispersion.json holds the same numbers as the .bin files (float32 values written as JSON
// numbers: exact), and dispersion.glsl the same values printed with 9 significant digits
// (which round-trip float32 exactly), matrices as GLSL mat3 (column-major constructor).
TEST_F(DispersionBundle, JsonAndGlslHoldTheSameNumbers) {
  for (const Job& j : jobs()) {
    SCOPED_TRACE(j.name());
    const int n = j.c.n;
    const auto lambda = t::read_f32(bundle(j) / "wavelengths.bin");
    const auto w = t::read_f32(bundle(j) / "weights.bin");
    const auto K = t::read_f32(bundle(j) / "matrices.bin");
    const auto off = t::read_f32(bundle(j) / "ior_offsets.bin");
    const auto ior = t::read_f32(bundle(j) / "ior.bin");
    const json d = t::read_json(bundle(j) / "dispersion.json");
    ASSERT_EQ(d.at("samples").get<int>(), n);
    for (int i = 0; i < n; ++i) {
      EXPECT_EQ(d.at("wavelengths_nm")[i].get<float>(), lambda[i]);
      EXPECT_EQ(d.at("ior_offsets")[i].get<float>(), off[i]);
      EXPECT_EQ(d.at("ior")[i].get<float>(), ior[i]);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(d.at("weights")[i][c].get<float>(), w[3 * i + c]);
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) EXPECT_EQ(d.at("matrices")[i][r][c].get<float>(), K[9 * i + 3 * r + c]);
    }

    const std::string glsl = t::read_file(bundle(j) / "dispersion.glsl");
    EXPECT_NE(glsl.find("const int SPECBAKE_SAMPLES = " + std::to_string(n) + ";"), std::string::npos);
    auto numbers_of = [&](const std::string& name) {
      const std::regex re(name + R"(\[\d+\]\s*=\s*\w+\[\d+\]\(([^;]*)\);)");
      std::smatch m;
      std::vector<float> out;
      if (!std::regex_search(glsl, m, re)) {
        ADD_FAILURE() << name << " not found in dispersion.glsl";
        return out;
      }
      const std::string body = std::regex_replace(m[1].str(), std::regex(R"(vec3|mat3|\(|\))"), " ");
      std::stringstream ss(std::regex_replace(body, std::regex(","), " "));
      for (std::string tok; ss >> tok;) out.push_back(std::stof(tok));
      return out;
    };
    EXPECT_EQ(numbers_of("SPECBAKE_WAVELENGTH_NM"), lambda);
    EXPECT_EQ(numbers_of("SPECBAKE_WEIGHT"), w);
    EXPECT_EQ(numbers_of("SPECBAKE_IOR_OFFSET"), off);
    EXPECT_EQ(numbers_of("SPECBAKE_IOR"), ior);
    // mat3(c0, c1, c2) takes columns: element (col c, row r) is K[r][c].
    const auto mats = numbers_of("SPECBAKE_K");
    ASSERT_EQ(mats.size(), K.size());
    for (int i = 0; i < n; ++i)
      for (int c = 0; c < 3; ++c)
        for (int r = 0; r < 3; ++r) EXPECT_EQ(mats[9 * i + 3 * c + r], K[9 * i + 3 * r + c]) << "K_" << i;
  }
}

}  // namespace

namespace {

// `formats:` picks the copies a dispersion bundle holds: [json] leaves out the .bin tables,
// [bin] dispersion.json; the GLSL and the preview come either way, and the manifest lists exactly
// what is there (inspect verifies it). An empty list, another kind's format or a repeat is an
// input error (exit 3) naming the key.
TEST(DispersionFormats, OnlyTheListedCopies) {
  t::TempDir tmp;
  auto config = [&](const std::string& formats) {
    return "specbake: 1\noutput: out\njobs:\n  - name: p\n    kind: dispersion\n    samples: 8\n"
           "    material: {glass: N-BK7}\n" + (formats.empty() ? "" : "    formats: " + formats + "\n");
  };
  const char* bins[] = {"wavelengths.bin", "weights.bin", "matrices.bin", "ior_offsets.bin", "ior.bin"};
  for (const std::string f : {"[json]", "[bin]", "[bin, json]"}) {
    SCOPED_TRACE(f);
    t::write_file(tmp / "c.yaml", config(f));
    const auto r = t::run_cli({"run", (tmp / "c.yaml").string(), "--force"});
    ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
    const auto b = tmp / "out" / "p" / "latest";
    for (const char* bin : bins) EXPECT_EQ(t::fs::exists(b / bin), f != "[json]") << bin;
    EXPECT_EQ(t::fs::exists(b / "dispersion.json"), f != "[bin]");
    EXPECT_TRUE(t::fs::exists(b / "dispersion.glsl"));
    EXPECT_TRUE(t::fs::exists(b / "preview" / "prism.png"));
    const json m = t::read_json(b / "manifest.json");
    for (const auto& file : m["files"]) EXPECT_TRUE(t::fs::exists(b / file["path"].get<std::string>())) << file["path"];
    const auto inspect = t::run_cli({"inspect", b.string()});
    EXPECT_EQ(inspect.exit_code, 0) << inspect.out << inspect.err;
  }
  // the default list keeps the bundle of a config that does not name it: [bin, json] and no key
  // hash alike
  t::write_file(tmp / "d.yaml", config(""));
  const auto d = t::run_cli({"run", (tmp / "d.yaml").string()});
  ASSERT_EQ(d.exit_code, 0) << d.err;
  EXPECT_NE(d.out.find("up to date"), std::string::npos) << d.out;

  for (const auto& [f, says] : std::vector<std::pair<std::string, std::string>>{
           {"[]", "non-empty list of formats (bin, json)"},
           {"[exr]", "expected a format of this kind (bin, json), got 'exr'"},
           {"[jsn]", "did you mean 'json'?"},
           {"[bin, bin]", "format 'bin' is listed twice"}}) {
    t::write_file(tmp / "bad.yaml", config(f));
    const auto r = t::run_cli({"run", (tmp / "bad.yaml").string()});
    EXPECT_EQ(r.exit_code, 3) << f << r.err;
    EXPECT_NE(r.err.find(says), std::string::npos) << f << ": " << r.err;
    EXPECT_NE(r.err.find("formats"), std::string::npos) << r.err;
  }
}

}  // namespace
