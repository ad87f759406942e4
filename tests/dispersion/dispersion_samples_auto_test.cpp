// `samples: auto`: the smallest N whose thin-prism colour error (mean CIEDE2000 over lit pixels
// against a 0.1 nm spectrum) is within tolerance_de2000. Checked with the host double
// reference (prism_mean_delta_e_reference), independently of the device search that chose N.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "cl/device.hpp"
#include "kinds/dispersion/dispersion_job.hpp"
#include "job/kind.hpp"
#include "support/testing.hpp"

namespace {

using namespace specbake;
using namespace specbake::dispersion;
namespace t = specbake::testing;

constexpr double u53 = 1.1102230246251565e-16;

cl_util::Device& device() {
  static std::unique_ptr<cl_util::Device> dev = std::make_unique<cl_util::Device>(cl_util::select_device("auto"));
  return *dev;
}

DispersionSpec spec_of(Sampling sampling, double spread, double tolerance) {
  DispersionSpec s;
  s.samples.reset();
  s.sampling = sampling;
  s.range_nm = {380.0, 780.0};
  s.spread = spread;
  s.tolerance_de2000 = tolerance;
  s.material.n_ref = 1.5168;
  s.material.v = 64.17;
  return s;
}

// The picture does not depend on the index (only on the offsets), as in choose_samples.
double reference_error(const DispersionSpec& spec, int n) {
  const MaterialModel none{1.5, 50.0, std::nullopt};
  return prism_mean_delta_e_reference(spec, compute_reference(spec, make_samples(spec.sampling, spec.range_nm, n), none));
}

// Device and host errors agree to ≲ 1e-10 (see Ciede2000.PrismJudgeMatchesReference); a
// tolerance that one path meets and the other misses by less than that would make "meets"
// ambiguous, so the checks below demand a margin of 1e-9 on each side.
constexpr double kMargin = 1e-9;

TEST(SamplesAuto, ChosenNIsTheSmallestThatMeetsTheTolerance) {
  struct Case {
    Sampling sampling;
    double spread, tolerance;
  } cases[] = {{Sampling::uniform, 1.3, 2.0}, {Sampling::visible_pdf, 1.3, 1.5}, {Sampling::inverse_square, 4.0, 4.0},
               {Sampling::gauss_legendre, 2.0, 3.0}};
  for (const auto& c : cases) {
    const DispersionSpec spec = spec_of(c.sampling, c.spread, c.tolerance);
    SCOPED_TRACE(std::string(to_string(c.sampling)) + " spread " + std::to_string(c.spread) + " tolerance " +
                 std::to_string(c.tolerance));
    int progress_calls = 0;
    const AutoChoice choice = choose_samples(device(), spec, [&](std::string_view, double f) {
      ++progress_calls;
      EXPECT_GE(f, 0.0);
      EXPECT_LE(f, 1.0);
    });
    const int n = choice.samples;
    ASSERT_GE(n, 1);
    // The chosen N meets the tolerance, by the host reference too.
    const double e_n = reference_error(spec, n);
    EXPECT_LE(e_n, c.tolerance - kMargin) << "N=" << n;
    EXPECT_NEAR(choice.delta_e, e_n, 1e-9) << "the reported error is the device's figure for the chosen N";
    // Every smaller N misses it (N − 1 first; all of them, since "smallest" means that).
    for (int m = n - 1; m >= 1; --m) EXPECT_GT(reference_error(spec, m), c.tolerance + kMargin) << "N=" << m;
    // What was tried is recorded (it goes to the manifest), ending at or above the chosen N.
    ASSERT_FALSE(choice.tried.empty());
    bool chosen_tried = false;
    for (auto& [m, e] : choice.tried) {
      EXPECT_NEAR(e, reference_error(spec, m), 1e-9) << "tried N=" << m;
      chosen_tried = chosen_tried || m == n;
    }
    EXPECT_TRUE(chosen_tried);
    EXPECT_GT(progress_calls, 0);
  }
}

// The error falls roughly as 1/N. Why: sample n paints a box at x_n = s·Offset(λ_n); as a
// pixel moves across the beam's edges, samples enter and leave it one at a time, so the
// XYZ error per edge pixel is a sawtooth of height ≈ one sample's weight, ∝ 1/N. ΔE00 is not
// linear in XYZ: large differences are compressed (S_C = 1 + 0.045·C', S_H grows with C'),
// so where ΔE is large (small N) halving the XYZ error more than halves ΔE; and once the
// samples are closer than a pixel (spacing ≈ 2.5·s/N beam widths, a pixel is 1/32: N ≳ 320
// at s = 4) the pixel's box filter smooths the sawtooth and the error falls faster still. Measured with this reference:
// uniform 19.4, 8.09, 3.24, 1.35, 0.52 for N = 8…128 (slope −1.30), inverse-square
// 18.9, 6.35, 3.08, 1.38, 0.50 (slope −1.31). The check is for the 1/N family, not for an
// exact exponent: over N = 8…128 the least-squares slope of log ΔE on log N is in
// [−1.6, −0.8] (1/N² would give −2, no convergence 0), every doubling of N divides the error
// by more than 1.4 and less than 3.2 (2 for 1/N, 4 for 1/N²).
TEST(SamplesAuto, ErrorFallsAboutAsOneOverN) {
  for (Sampling sampling : {Sampling::uniform, Sampling::inverse_square}) {
    SCOPED_TRACE(to_string(sampling));
    const DispersionSpec spec = spec_of(sampling, 4.0, 1.0);
    std::vector<double> xs, ys;
    double prev = 0.0;
    for (int n = 8; n <= 128; n *= 2) {
      const double e = reference_error(spec, n);
      if (std::getenv("SPECBAKE_TEST_VERBOSE")) std::printf("%s N=%d mean dE2000 %.6f\n", to_string(sampling), n, e);
      if (prev > 0.0) {
        EXPECT_GT(prev / e, 1.4) << "N=" << n;
        EXPECT_LT(prev / e, 3.2) << "N=" << n;
      }
      prev = e;
      xs.push_back(std::log(n));
      ys.push_back(std::log(e));
    }
    double mx = 0, my = 0;
    for (std::size_t i = 0; i < xs.size(); ++i) mx += xs[i] / xs.size(), my += ys[i] / ys.size();
    double sxy = 0, sxx = 0;
    for (std::size_t i = 0; i < xs.size(); ++i) sxy += (xs[i] - mx) * (ys[i] - my), sxx += (xs[i] - mx) * (xs[i] - mx);
    const double slope = sxy / sxx;
    EXPECT_GT(slope, -1.6);
    EXPECT_LT(slope, -0.8);
  }
}

// A tolerance no N ≤ 4096 can meet fails with a JobError naming the tolerance and the limit.
TEST(SamplesAuto, ImpossibleToleranceIsAJobError) {
  const DispersionSpec spec = spec_of(Sampling::uniform, 4.0, 1e-6);
  try {
    choose_samples(device(), spec, [](std::string_view, double) {});
    FAIL() << "expected a JobError";
  } catch (const JobError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("tolerance_de2000"), std::string::npos) << msg;
    EXPECT_NE(msg.find(std::to_string(kMaxSamples)), std::string::npos) << msg;
    EXPECT_EQ(e.exit_code(), ExitCode::job_failed);
  }
  // Through the CLI: exit 1, the message on stderr, no bundle for that job, and the other
  // job of the same config still built (one failing job does not stop the others).
  t::TempDir tmp;
  t::write_file(tmp / "auto.yaml", R"(specbake: 1
output: out
jobs:
  - name: impossible
    kind: dispersion
    samples: auto
    tolerance_de2000: 0.000001
    material: {n_d: 1.5168, v_d: 64.17}
  - name: fine
    kind: dispersion
    samples: 8
    material: {n_d: 1.5168, v_d: 64.17}
)");
  const auto r = t::run_cli({"run", (tmp / "auto.yaml").string()});
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_NE(r.out.find("impossible: failed: "), std::string::npos) << r.out;  // the summary says why, once
  EXPECT_NE(r.out.find("cannot meet tolerance_de2000"), std::string::npos) << r.out;
  EXPECT_FALSE(t::fs::exists(tmp / "out" / "impossible" / "latest"));
  if (t::fs::exists(tmp / "out" / "impossible"))
    for (const auto& e : t::fs::directory_iterator(tmp / "out" / "impossible"))
      EXPECT_EQ(e.path().filename().string().front(), '.') << "unexpected " << e.path();
  EXPECT_TRUE(t::fs::exists(tmp / "out" / "fine" / "latest" / "manifest.json"));
}

// The manifest of an auto job records the choice and the error figure for the chosen N.
TEST(SamplesAuto, ManifestReportsTheChoice) {
  t::TempDir tmp;
  t::write_file(tmp / "auto.yaml", R"(specbake: 1
output: out
jobs:
  - name: auto
    kind: dispersion
    samples: auto
    sampling: uniform
    range_nm: [380, 780]
    spread: 1.3
    tolerance_de2000: 2.0
    material: {n_d: 1.5168, v_d: 64.17}
)");
  const auto r = t::run_cli({"run", (tmp / "auto.yaml").string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const auto m = t::read_json(tmp / "out" / "auto" / "latest" / "manifest.json");
  const auto& p = m.at("parameters");
  const int n = p.at("samples").get<int>();
  EXPECT_EQ(p.at("samples_auto").at("chosen").get<int>(), n);
  EXPECT_EQ(p.at("samples_auto").at("tolerance_de2000").get<double>(), 2.0);
  EXPECT_LE(p.at("samples_auto").at("mean_de2000").get<double>(), 2.0);
  // The bundle's accuracy figure is the same prism error for the baked tables.
  EXPECT_NEAR(specbake::find_accuracy(m.at("accuracy"), "prism_de2000")->at("value").get<double>(), p.at("samples_auto").at("mean_de2000").get<double>(),
              1e-9);
  EXPECT_EQ(t::read_f32(tmp / "out" / "auto" / "latest" / "wavelengths.bin").size(), static_cast<std::size_t>(n));
  const DispersionSpec spec = spec_of(Sampling::uniform, 1.3, 2.0);
  EXPECT_LE(reference_error(spec, n), 2.0);
  EXPECT_GT(reference_error(spec, n - 1), 2.0);
}

}  // namespace
