// Diffraction tables: the texel map, the coherence length of a disc source, table terms against
// direct double-precision sums of the windowed field (symmetric, asymmetric and tall fields),
// Parseval's energy over the table, and the table keys, bundle and size budget through the CLI.
#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <cstring>
#include <regex>
#include <tuple>

#include "job/kind.hpp"
#include "io/exr.hpp"
#include "io/png.hpp"
#include "kinds/diffraction/brdf.hpp"
#include "kinds/diffraction/diffraction_job.hpp"
#include "kinds/diffraction/planning.hpp"
#include "kinds/diffraction/table.hpp"
#include "kinds/diffraction/terms.hpp"
#include "support/testing.hpp"

using namespace specbake;
using namespace specbake::diffraction;
namespace tst = specbake::testing;

namespace {

constexpr double kPi = 3.141592653589793238462643;

DiffractionSpec grating(ProceduralField::Type type, int size, double dx, double period, double height, int table,
                        double power, double length_um) {
  DiffractionSpec s;
  ProceduralField p;
  p.type = type;
  p.size = size;
  p.dx_um = dx;
  p.period_um = period;
  p.amplitude_um = height;
  s.procedural = p;
  TableSpec t;
  t.size = table;
  t.power = power;
  t.power_mapping = power != 1.0;
  s.table = t;
  s.coherence.length_um = length_um;
  return s;
}

struct Baked {
  Field f;
  Plan p;
  Window w;
  TableGeometry g;
  std::vector<float> values;
};

Baked bake_table_terms(const DiffractionSpec& spec) {
  Baked b;
  b.f = make_field(spec);
  b.p = make_plan(spec, b.f, spec.tolerance);
  b.w = make_window(b.f, coherence_length_um(spec) / std::sqrt(2.0));
  b.g = table_geometry(spec, *spec.table->size);
  const auto t = table_terms(b.f, b.w, b.p.bands, b.g);
  for (const cplx& v : t) {
    b.values.push_back(static_cast<float>(v.real()));
    b.values.push_back(static_cast<float>(v.imag()));
  }
  return b;
}

// Every texel at κ against the direct sum. The bound over M²: the band's truncation bound
// (rigorous: a per-sample remainder weighted by w_j ≤ 1) plus its roundoff estimate, which here
// covers float32 storage of double-precision values (u·|coef_n|·|F_n| per term, |F_n| ≤ rms|q_n|)
// 4× over; the double sums add ~1e-16·M².
double worst_over_bound(const Baked& b, double kappa, bool mirror) {
  const Band& band = band_for(b.p.bands, kappa);
  const double bound = (band.bound_truncation + band.bound_roundoff) * b.f.count();
  const auto a = windowed_field(b.f, b.w, kappa);
  double worst = 0.0;
  for (int iv = 0; iv < b.g.size; ++iv)
    for (int iu = 0; iu < b.g.size; ++iu) {
      const double fu = b.g.freq(iu) * (mirror ? -1.0 : 1.0), fv = b.g.freq(iv);
      const cplx ex = direct_transform(a, b.f, fu, fv);
      worst = std::max(worst, std::abs(table_value(b.values, b.g, b.f, band, kappa, iu, iv) - ex) / bound);
    }
  return worst;
}

}  // namespace

TEST(DiffractionTable, TexelMapAndItsInverse) {
  TableGeometry g{64, 3.0, 5.0};
  for (int i = 0; i < 64; ++i) {
    EXPECT_NEAR(g.texel_of(g.freq(i)), i, 1e-9) << i;  // round trip, exact up to pow's rounding
    EXPECT_DOUBLE_EQ(g.freq(i), -g.freq(63 - i));       // odd map, centre between texels 31 and 32
  }
  EXPECT_NEAR(g.freq(63), 5.0 * std::pow(63.0 / 64.0, 3.0), 1e-12);
  // Linear: the texel widths tile [−f_max, f_max] exactly.
  TableGeometry lin{100, 1.0, 2.5};
  double sum = 0;
  for (int i = 0; i < 100; ++i) sum += lin.width(i);
  EXPECT_NEAR(sum, 5.0, 1e-12);
}

TEST(DiffractionTable, DiscCoherenceLengthMatchesVanCittertZernikeCurvature) {
  const double theta = 0.53 * kPi / 180.0, lambda = 0.58;
  const double L = disc_coherence_length_um(theta, lambda);
  EXPECT_NEAR(L, 39.9, 0.05);  // the figure the docs quote for the sun
  // 1 − 2J1(x)/x against 1 − exp(−d²/2L²) at small d: equal to O(d²) relative (x⁴/192 next term).
  for (double d : {0.01 * L, 0.03 * L}) {
    const double x = kPi * theta * d / lambda;
    const double disc = 1.0 - 2.0 * std::cyl_bessel_j(1.0, x) / x, gauss = 1.0 - std::exp(-d * d / (2 * L * L));
    // Relative difference ≈ d²/L²·(1/4 − 1/6)... bounded by d²/L² for d ≤ 0.03 L.
    EXPECT_NEAR(disc / gauss, 1.0, (d / L) * (d / L)) << d;
  }
}

TEST(DiffractionTable, SymmetricAndAsymmetricFieldsMatchDirectSums) {
  // Sine grating (its pattern is symmetric under f → −f) and blazed grating (a sawtooth: its
  // orders are not, so a flipped sign of f is visible), 24² samples, window L = 2 µm over a 3 µm patch.
  for (auto type : {ProceduralField::Type::sine_grating, ProceduralField::Type::blazed_grating}) {
    const auto spec = grating(type, 24, 0.125, 0.75, 0.2, 16, 2.0, 2.0);
    const Baked b = bake_table_terms(spec);
    for (double kappa : {0.0, 0.5 * b.p.kappa_hi, b.p.kappa_hi})
      EXPECT_LE(worst_over_bound(b, kappa, false), 1.0) << static_cast<int>(type) << " kappa " << kappa;
    if (type == ProceduralField::Type::blazed_grating)
      EXPECT_GT(worst_over_bound(b, b.p.kappa_hi, true), 100.0) << "a mirrored f_u must be detected";
  }
}

// The job's FFT path against the direct double sums, term by term, for every table size at once.
// Its error is float32 rounding of the inputs and of the FFTs: per output at most
// u·(log2 n_x + log2 n_y + 2) (u = 2^-24, the standard FFT bound with unit-roundoff inputs)
// times Σ_j |a_j| with a_j the deconvolved inputs — at most 1/φ̂_min ≈ 3.4× Σ_j w_j|q_n(h_j)|
// for R = 1.5 — plus the gridding's aliasing (about 1e-8 relative) and the samples the window
// floor leaves out (at most their weight times max|q_n|), plus the float32 storage of the result
// (u·|F_n| ≤ u·Σ_j w_j|q_n(h_j)|/(W·H)). The tolerance is that bound:
// (4u·(log2 n_x + log2 n_y + 2) + u)·Σ_j w_j|q_n(h_j)|/(W·H) + dropped·Σw·max|q_n|/(W·H), 4
// covering 1/φ̂_min and the aliasing.
void expect_fft_matches_direct(const DiffractionSpec& spec, const std::vector<int>& sizes, const char* what) {
  const Field f = make_field(spec);
  const Plan p = make_plan(spec, f, spec.tolerance);
  const Window w = make_window(f, coherence_length_um(spec) / std::sqrt(2.0));
  std::vector<TableGeometry> geoms;
  for (int n : sizes) geoms.push_back(table_geometry(spec, n));
  const auto fft = table_terms_fft(DeviceHeights(tst::shared_device(), f), f, w, p.bands, geoms);
  const auto pad = [](int m) { return std::log2(3.0 * m); };  // n ≤ 2·(1.5m) after rounding up to a smooth length
  const double u = std::ldexp(1.0, -24), logs = pad(f.width) + pad(f.height) + 2.0;
  for (std::size_t k = 0; k < sizes.size(); ++k) {
    const auto direct = table_terms(f, w, p.bands, geoms[k]);
    ASSERT_EQ(2 * direct.size(), fft[k].size());
    const std::size_t per = static_cast<std::size_t>(sizes[k]) * sizes[k];
    for (const auto& band : p.bands) {
      const auto q = reference_inputs(f, band, 0, band.terms);
      for (int t = 0; t < band.terms; ++t) {
        double mass = 0, q_max = 0;
        for (int iy = 0; iy < f.height; ++iy)
          for (int ix = 0; ix < f.width; ++ix) {
            const std::size_t j = static_cast<std::size_t>(iy) * f.width + ix;
            mass += w.wx[ix] * w.wy[iy] * std::abs(q[t * f.count() + j]);
            q_max = std::max(q_max, std::abs(q[t * f.count() + j]));
          }
        const double tol =
            ((4.0 * logs + 1.0) * u * mass + dropped_window_fraction(w) * w.sum * q_max) / static_cast<double>(f.count());
        double worst = 0;
        for (std::size_t i = 0; i < per; ++i) {
          const std::size_t at = (band.first_term + t) * per + i;
          worst = std::max(worst, std::abs(cplx(fft[k][2 * at], fft[k][2 * at + 1]) - direct[at]));
        }
        EXPECT_LE(worst, tol) << what << ": size " << sizes[k] << " term " << band.first_term + t;
        EXPECT_GT(worst, 0.0) << what << ": the FFT path must not be the direct sums";
      }
    }
  }
}

TEST(DiffractionTable, FftPathMatchesDirectSums) {
  // Asymmetric (sawtooth) field, the window inside the patch (samples cropped), power mapping,
  // two sizes from one pass.
  auto blazed = grating(ProceduralField::Type::blazed_grating, 192, 0.125, 0.75, 0.3, 16, 3.0, 2.0);
  ASSERT_GT(dropped_window_fraction(make_window(make_field(blazed), 2.0 / std::sqrt(2.0))), 0.0) << "crops nothing";
  expect_fft_matches_direct(blazed, {16, 24}, "blazed, cropped window");
  // f_max beyond the sampling's Nyquist frequency 1/(2dx) = 2: the transform's periodic images.
  auto coarse = grating(ProceduralField::Type::eggcrate, 20, 0.25, 1.0, 0.3, 12, 1.0, 1e6);
  coarse.table->f_max_per_um = 3.5;
  expect_fft_matches_direct(coarse, {12}, "beyond Nyquist");
  // An odd size: the patch centre falls on a sample.
  expect_fft_matches_direct(grating(ProceduralField::Type::eggcrate, 75, 0.1, 0.9, 0.2, 12, 2.0, 1.2), {12, 14},
                            "odd size");
  // Tall field across bands (y_max ≈ 40).
  expect_fft_matches_direct(grating(ProceduralField::Type::sine_grating, 20, 0.1, 0.4, 1.21, 12, 1.0, 1.5), {12},
                            "tall field");
}

TEST(DiffractionTable, ExactGridOnTheDeviceMatchesHostAndSinglePointSums) {
  // The measurement's ground truth on the device (fp64) against the host's row-by-row sums and
  // against direct_transform's single-point 2D sums (the phase of each sample formed at once).
  // A field without symmetry (a tilt plus pseudo-random heights, 60 × 44: W ≠ H catches swapped
  // axes), a window narrower than it, more frequencies on one axis than a SIMD width divides, κ
  // across the range.
  Field f;
  f.width = 60;
  f.height = 44;
  f.dx_um = 0.125;
  std::uint64_t state = 12345;
  for (int iy = 0; iy < f.height; ++iy)
    for (int ix = 0; ix < f.width; ++ix) {
      state = state * 6364136223846793005ULL + 1442695040888963407ULL;
      f.h_um.push_back(0.004 * ix + 0.2 * static_cast<double>(state >> 11) * 0x1p-53);
    }
  const Window w = make_window(f, 1.5);
  cl_util::Device& dev = tst::shared_device();
  if (!dev.info().fp64) GTEST_SKIP() << "the device has no fp64: the exact sums stay on the host";
  const DeviceHeights heights(dev, f);
  const ExactGrid grid(&heights, f, w);
  ASSERT_TRUE(grid.on_device());
  std::vector<double> fu, fv;
  for (int k = 0; k < 37; ++k) fu.push_back(-3.7 + 0.23 * k);
  for (int k = 0; k < 5; ++k) fv.push_back(-1.1 + 0.61 * k);
  double sum_w = 0;
  for (double y : w.wy)
    for (double x : w.wx) sum_w += x * y;
  // Each value is a sum of W·H terms of modulus w_j (times unit phasors), by rows of W then H
  // rows: recursive summation errs by at most about (W + H + 8)·u·Σw per evaluation (the 8: the
  // phasors' and products' few roundings); two evaluations differ by at most twice that.
  const double bound = 2.0 * (f.width + f.height + 8) * 0x1p-53 * sum_w;
  for (double kappa : {0.0, 4.1, 33.0}) {
    const auto device = grid(kappa, fu, fv), host = direct_transform_grid(f, w, kappa, fu, fv);
    const auto a = windowed_field(f, w, kappa);
    ASSERT_EQ(device.size(), fu.size() * fv.size());
    double worst_host = 0, worst_single = 0, largest = 0;
    for (std::size_t b = 0; b < fv.size(); ++b)
      for (std::size_t i = 0; i < fu.size(); ++i) {
        const std::size_t at = b * fu.size() + i;
        worst_host = std::max(worst_host, std::abs(device[at] - host[at]));
        worst_single = std::max(worst_single, std::abs(device[at] - direct_transform(a, f, fu[i], fv[b])));
        largest = std::max(largest, std::abs(device[at]));
      }
    EXPECT_LE(worst_host, bound) << "kappa " << kappa;
    EXPECT_LE(worst_single, bound) << "kappa " << kappa;
    EXPECT_GT(largest, 1e-3 * sum_w) << "kappa " << kappa << ": the grid must hold more than rounding";
  }
}

TEST(DiffractionTable, TallFieldAcrossBands) {
  // y_max = κ_hi·s ≈ 40: amplitude 1.21 µm, κ_hi = 2π·2/0.38 µm.
  const auto spec = grating(ProceduralField::Type::sine_grating, 20, 0.1, 0.4, 1.21, 12, 1.0, 1.5);
  const Baked b = bake_table_terms(spec);
  ASSERT_NEAR(b.p.y_max, 40.0, 0.1);
  ASSERT_GT(b.p.bands.size(), 1u);
  for (double kappa : measurement_kappas(b.p))
    EXPECT_LE(worst_over_bound(b, kappa, false), 1.0) << "kappa " << kappa;
}

TEST(DiffractionTable, ParsevalOverOnePeriodAndACoarseTableBreaksIt) {
  // 16² samples at dx = 0.25 µm; f_max = 2 = 1/(2dx) spans one period of P(f). |P|² is a
  // trigonometric polynomial of degree ≤ 15 in f·dx, so the midpoint rule over N ≥ 16 uniform
  // texels of the period integrates it exactly: the ratio is 1 up to the stored values' error
  // (relative r = bound·M²/rms|P|: |ratio − 1| ≤ 2r + r²). N = 8 does not integrate it.
  auto spec = grating(ProceduralField::Type::eggcrate, 16, 0.25, 1.0, 0.3, 32, 1.0, 1e6);
  spec.table->f_max_per_um = 2.0;
  for (int n : {32, 8}) {
    spec.table->size = n;
    const Baked b = bake_table_terms(spec);
    const auto e = measure_table(b.f, b.w, b.p.bands, b.g, b.values, {0.0, 0.5 * b.p.kappa_hi, b.p.kappa_hi});
    for (std::size_t k = 0; k < e.kappas.size(); ++k) {
      const double kappa = e.kappas[k];
      const Band& band = band_for(b.p.bands, kappa);
      double ms = 0;
      for (int iv = 0; iv < n; ++iv)
        for (int iu = 0; iu < n; ++iu) ms += std::norm(table_value(b.values, b.g, b.f, band, kappa, iu, iv));
      const double r = (band.bound_truncation + band.bound_roundoff) * b.f.count() / std::sqrt(ms / (n * n));
      if (n == 32)
        EXPECT_NEAR(e.energy_ratio[k], 1.0, 2 * r + r * r) << "kappa " << kappa;
      else if (kappa > 0)
        EXPECT_GT(std::fabs(e.energy_ratio[k] - 1.0), 1e-2) << "kappa " << kappa;
    }
  }
}

TEST(DiffractionTable, CliBundleBudgetAndBadKeys) {
  tst::TempDir dir;
  const std::string head = "specbake: 1\noutput: out\ndevice: auto\njobs:\n  - name: d\n    kind: diffraction\n";
  const std::string field = "    procedural: {type: blazed-grating, size: 32, dx_um: 0.125, period_um: 1.0, depth_um: 0.2}\n";
  tst::write_file(dir / "c.yaml", head + field + "    table: {size: 32, mapping: power, power: 2}\n    coherence: {length_um: 3}\n"
                                    "    tolerance_advisory: true\n");  // a fixed small table: its misses are warnings
  auto r = tst::run_cli({"run", (dir / "c.yaml").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const fs::path b = dir / "out/d/latest";
  const auto m = tst::read_json(b / "manifest.json");
  const auto& t = m["diffraction"]["table"];
  EXPECT_EQ(t["size"], 32);
  EXPECT_EQ(t["mapping"], "power");
  EXPECT_DOUBLE_EQ(t["coherence_length_um"].get<double>(), 3.0);
  EXPECT_NEAR(t["window"]["sigma_um"].get<double>(), 3.0 / std::sqrt(2.0), 1e-12);
  const int T = m["diffraction"]["terms"].get<int>();
  EXPECT_EQ(tst::read_f32(b / "table_terms.bin").size(), static_cast<std::size_t>(T) * 32 * 32 * 2);
  EXPECT_FALSE(fs::exists(b / "terms.bin"));
  EXPECT_TRUE(fs::exists(b / "table/F_000.exr"));
  EXPECT_TRUE(find_accuracy(m["accuracy"], "table_vs_exact_transform"));

  struct Case {
    std::string body, expect;
  };
  const std::vector<Case> cases = {
      // A 1024² field's full bins: 16 bytes × T × ~1100² bins, far above 1 MB.
      {"    procedural: {type: sine-grating, size: 1024, dx_um: 0.05, period_um: 1.0, amplitude_um: 0.2}\n"
       "    max_bundle_mb: 1\n", "max_bundle_mb"},
      {field + "    table: {size: 1024}\n    max_bundle_mb: 2\n", "table 1024 x 1024"},
      {field + "    coherence: {length_um: 3}\n", "coherence"},
      {field + "    table: {size: 33}\n", "table.size"},
      {field + "    table: {size: 32, mapping: linear, power: 2}\n", "table.power"},
      {field + "    table: {size: 32}\n    coherence: {length_um: 3, source_angular_diameter_deg: 0.5}\n", "coherence"},
      {field + "    table: {size: 32, mapping: cubic}\n", "table.mapping"},
      // σ = L/√2 below dx = 0.125 µm: a window of about one sample.
      {field + "    table: {size: 32}\n    coherence: {length_um: 0.1}\n", "coherence.length_um"},
      {"    procedural: {type: blazed-grating, size: 32, dx_um: 1.0, period_um: 4.0, depth_um: 0.2}\n"
       "    table: {size: 32}\n    coherence: {source_angular_diameter_deg: 30}\n",  // L = 0.71 µm
       "coherence.source_angular_diameter_deg"},
  };
  for (const auto& c : cases) {
    fs::remove_all(dir / "out");
    tst::write_file(dir / "c.yaml", head + c.body);
    r = tst::run_cli({"run", (dir / "c.yaml").string()});
    EXPECT_EQ(r.exit_code, 3) << c.body << r.err;
    EXPECT_NE((r.out + r.err).find(c.expect), std::string::npos) << c.expect << " not named in:\n" << r.err;
    // Every refusal points at the config's line and column.
    // (refused at load: on stderr; refused when the job starts: in the summary, as invalid)
    EXPECT_TRUE(std::regex_search(r.out + r.err, std::regex("c\\.yaml:[0-9]+:[0-9]+: ")))
        << "no file:line:col in:\n" << r.out << r.err;
    EXPECT_FALSE(fs::exists(dir / "out/d/latest")) << "a bundle was written for " << c.body;
  }
}

TEST(DiffractionTable, AnAutoSizeThatFailsNamesWhatWouldHelp) {
  // A blazed grating whose orders a 64² table cannot hold, with a bundle budget that leaves only
  // 64²: the error names the budget as what stopped the ladder and does not suggest the mapping it
  // already has (power by default); with mapping: linear it does.
  tst::TempDir dir;
  const std::string job = "specbake: 1\noutput: out\njobs:\n  - name: t\n    kind: diffraction\n"
                          "    procedural: {type: blazed-grating, size: 256, dx_um: 0.05, period_um: 2.0, depth_um: 1.2}\n"
                          "    expansion: chebyshev\n    tolerance: 1e-4\n    max_bundle_mb: 2\n";
  for (const std::string mapping : {"", ", mapping: linear"}) {
    tst::write_file(dir / "c.yaml", job + "    table: {size: auto" + mapping + "}\n");
    const auto r = tst::run_cli({"-q", "run", (dir / "c.yaml").string()});
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_NE(r.err.find("no size of the ladder up to 64"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("the larger sizes exceed max_bundle_mb = 2"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("a larger max_bundle_mb"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("mapping: power") != std::string::npos, !mapping.empty()) << r.err;
    EXPECT_FALSE(fs::exists(dir / "out/t/latest"));
  }
}

TEST(DiffractionTable, BrdfOfAFlatMirrorIsFresnelTimesCosine) {
  // A flat field: P(f) is the window's transform, real and positive at the centred origin, and at
  // a specular pair (ω_o the mirror of ω_i) the lookup f = −(ω_i + ω_o)_xy/λ = 0 falls between the
  // four centre texels, which all hold |P| of (f1, f1), f1 the first texel's frequency. There
  // C = R(θ)/R(0)·(1 + cos 2θ)²/((2 cos θ)²·cos θ) = R(θ)/R(0)·cos θ, so
  // ρ = R(θ)/R(0)·cos θ·|P(f1, f1)/Σw|², to the float32 rounding of the stored terms (≈ 1e-7).
  auto spec = grating(ProceduralField::Type::sine_grating, 32, 0.1, 1.0, 0.0, 16, 3.0, 1.0);
  const Baked b = bake_table_terms(spec);
  const BrdfTable t{b.f, b.p.bands, b.g, b.values, b.w.sum, 1.5};
  const double f1 = b.g.freq(8);
  const double peak = std::norm(direct_transform(windowed_field(b.f, b.w, 0.0), b.f, f1, f1) / b.w.sum);
  ASSERT_GT(peak, 0.5);
  const auto fresnel = [](double c) {  // unpolarised, n = 1.5, written out independently
    const double n = 1.5, st = std::sqrt(1 - c * c) / n, ct = std::sqrt(1 - st * st);
    const double rs = (c - n * ct) / (c + n * ct), rp = (ct - n * c) / (ct + n * c);
    return 0.5 * (rs * rs + rp * rp);
  };
  for (double deg : {0.0, 30.0, 60.0}) {
    const double a = deg * kPi / 180.0, c = std::cos(a);
    const double rho = brdf(t, {std::sin(a), 0.0, c}, {-std::sin(a), 0.0, c}, 0.55);
    EXPECT_NEAR(rho, fresnel(c) / fresnel(1.0) * c * peak, 1e-6) << deg;
  }
  // Beyond the table's reach (|f| > f_max = 2/0.38 µm⁻¹) the lookup reads nothing, and nothing
  // is reflected from below the horizon.
  const double s9 = std::sqrt(1 - 0.81);
  EXPECT_EQ(brdf(t, {0.9, 0.0, s9}, {0.9, 0.0, s9}, 0.3), 0.0);
  EXPECT_EQ(brdf(t, {0.0, 0.0, 1.0}, {0.0, 0.0, -1.0}, 0.55), 0.0);
}

TEST(DiffractionTable, FastSpecularSplitLosesNoLightAndFollowsThePeak) {
  // diffraction_srgb_fast_specular (brdf.hpp, xyz_fast_specular) writes |P|² as the peak
  // |χ|²·G plus the remainder |P|² − |χ|²·G. Summed over the same wavelengths for both parts
  // (|χ|² then interpolated at its own wavelengths, weight 0 or 1) the split must give back the
  // plain sum: only double rounding apart (~1e-15 relative; 1e-12 asserted).
  auto spec = grating(ProceduralField::Type::blazed_grating, 48, 0.1, 1.2, 0.25, 32, 3.0, 3.0);
  const Baked b = bake_table_terms(spec);
  const BrdfTable t{b.f, b.p.bands, b.g, b.values, b.w.sum, 1.5, b.w.sigma_um};
  double y_norm = 0;
  const auto rows = spectrum_rows(spec.range_nm, y_norm);
  const Wavelengths few = bins(rows, 8), all = every_nm(rows, 10);
  const double a = 30.0 * kPi / 180.0;
  const std::array<double, 3> wi{std::sin(a), 0.0, std::cos(a)};
  double largest_peak_share = 0;
  for (double x : {-0.5, -0.48, -0.3, 0.0, 0.4}) {
    const std::array<double, 3> wo{x, 0.05, std::sqrt(1.0 - x * x - 0.0025)};
    std::array<double, 3> plain{0, 0, 0};
    for (std::size_t k = 0; k < few.lambda_um.size(); ++k)
      for (int c = 0; c < 3; ++c) plain[c] += brdf(t, wi, wo, few.lambda_um[k]) * few.xyz[k][c];
    const auto split = xyz_fast_specular(t, wi, wo, few, few);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(split[c], plain[c], 1e-12 * std::fabs(plain[c]) + 1e-300) << x;
    // With the peak summed every 10 nm the result moves only where the peak lies (x near
    // −sin 30° = −0.5, the mirror direction). For |x + 0.5| > 0.45, |d|² > 0.2 and
    // G = exp(−(2πσ/λ)²|d|²) < e^-58 at every λ ≤ 0.78 µm (σ = 3/√2 µm): nothing visible changes.
    const auto fine = xyz_fast_specular(t, wi, wo, few, all);
    const double moved = std::fabs(fine[1] - plain[1]) / std::max(std::fabs(plain[1]), 1e-300);
    if (std::fabs(x + 0.5) > 0.45) EXPECT_LT(moved, 1e-12) << x;
    largest_peak_share = std::max(largest_peak_share, moved);
  }
  EXPECT_GT(largest_peak_share, 1e-3) << "near the mirror direction the peak's finer spectral sum must show";
}

TEST(DiffractionTable, PreviewsOnTheDeviceMatchTheHostsDoubleEvaluation) {
  // The bake draws its BRDF previews on the device (diffraction_brdf_xyz over table.cl); the host
  // evaluates the same functions in double. With fp64 both run in double and differ by rounding
  // only: contractions and libm's pow/exp/sqrt, ~1e-15 relative per value, times the cancellation
  // in Σ coef_n·F_n, which the planner keeps within the float32 roundoff budget (tolerance/u_f32 ≈
  // 1e3 here): 1e-9 of the picture's peak leaves 1e3 of margin (and is 1e-7 of an 8-bit step).
  // Without fp64 the kernel runs in float: (4T + 8)·2^-24·1e3 ≈ 1e-2 of the peak.
  auto spec = grating(ProceduralField::Type::blazed_grating, 48, 0.1, 1.2, 0.25, 32, 3.0, 3.0);
  spec.expansion = Expansion::chebyshev;
  const Baked b = bake_table_terms(spec);
  const BrdfTable t{b.f, b.p.bands, b.g, b.values, b.w.sum, 1.5, b.w.sigma_um};
  double y_norm = 0;
  const auto rows = spectrum_rows(spec.range_nm, y_norm);
  const Wavelengths few = bins(rows, 8), all = every_nm(rows, 10);
  cl_util::Device& dev = tst::shared_device();
  const BrdfPictures host(t), device(t, &dev);
  ASSERT_FALSE(host.on_device());
  ASSERT_TRUE(device.on_device());
  const double tol = dev.info().fp64 ? 1e-9 : 1e-2;
  const std::vector<double> angles = {0.0, 45.0};
  const std::vector<std::pair<std::vector<float>, std::vector<float>>> pictures = {
      {host.lobes(all, angles, 48), device.lobes(all, angles, 48)},
      {host.lobes_fast_specular(few, all, angles, 48), device.lobes_fast_specular(few, all, angles, 48)},
      {host.sphere(all, {2.0, 1.5, 3.0}, 64), device.sphere(all, {2.0, 1.5, 3.0}, 64)}};
  for (std::size_t k = 0; k < pictures.size(); ++k) {
    const auto& [h, d] = pictures[k];
    ASSERT_EQ(h.size(), d.size()) << k;
    double peak = 0, worst = 0;
    for (std::size_t i = 0; i < h.size(); ++i) {
      peak = std::max(peak, static_cast<double>(std::fabs(h[i])));
      worst = std::max(worst, static_cast<double>(std::fabs(h[i] - d[i])));
    }
    EXPECT_GT(peak, 0.0) << k;
    EXPECT_LE(worst, tol * peak) << "picture " << k;
  }
  // A different table (f_u mirrored: the blazed grating's orders are not symmetric) must show:
  // the comparison can fail.
  std::vector<float> mirrored(b.values.size());
  const std::size_t n = b.g.size;
  for (std::size_t row = 0; row < b.values.size() / (2 * n); ++row)
    for (std::size_t iu = 0; iu < n; ++iu)
      for (int c = 0; c < 2; ++c) mirrored[2 * (row * n + iu) + c] = b.values[2 * (row * n + n - 1 - iu) + c];
  const BrdfTable m{b.f, b.p.bands, b.g, mirrored, b.w.sum, 1.5, b.w.sigma_um};
  const auto h = host.lobes(all, angles, 48), d = BrdfPictures(m, &dev).lobes(all, angles, 48);
  double peak = 0, worst = 0;
  for (std::size_t i = 0; i < h.size(); ++i) {
    peak = std::max(peak, static_cast<double>(std::fabs(h[i])));
    worst = std::max(worst, static_cast<double>(std::fabs(h[i] - d[i])));
  }
  EXPECT_GT(worst, 1e-3 * peak) << "the blazed grating's mirrored table must draw differently";
}

TEST(DiffractionTable, TableBakesFromEveryHeightfieldSource) {
  // size: auto from every source the job reads: a grey PNG, a single-channel EXR, a non-square raw
  // float32 field and a procedural binary grating; each must meet both tolerances at the measured
  // points and ship the table, its EXRs and BRDF previews that are not blank.
  tst::TempDir dir;
  const int w = 40, h = 24;
  std::vector<float> v, grey;
  for (int iy = 0; iy < h; ++iy)
    for (int ix = 0; ix < w; ++ix) {
      const float z = 0.05f * (1.0f + std::sin(0.7f * ix + 0.2f * iy * iy));
      v.push_back(z);
      for (int c = 0; c < 3; ++c) grey.push_back(z / 0.1f);
    }
  std::string raw(v.size() * 4, '\0');
  std::memcpy(raw.data(), v.data(), raw.size());
  tst::write_file(dir / "f.raw", raw);
  ExrImage exr;
  exr.width = w;
  exr.height = h;
  exr.channels = {"H"};
  exr.pixels = v;
  tst::write_file(dir / "f.exr", exr_bytes(exr));
  tst::write_file(dir / "f.png", png_from_linear(w, h, grey));
  const std::string table = "    table: {size: auto}\n    coherence: {length_um: 1.5}\n";  // mapping: power by default
  const std::vector<std::pair<std::string, std::string>> sources = {
      {"png", "    heightfield: {file: f.png, dx_um: 0.1, height_um: 0.1}\n"},
      {"exr", "    heightfield: {file: f.exr, dx_um: 0.1}\n"},
      {"raw", "    heightfield: {file: f.raw, dx_um: 0.1, size: [40, 24]}\n"},
      {"binary", "    procedural: {type: binary-grating, size: 48, dx_um: 0.1, period_um: 1.2, depth_um: 0.1}\n"},
  };
  for (const auto& [name, source] : sources) {
    fs::remove_all(dir / "out");
    tst::write_file(dir / "c.yaml", "specbake: 1\noutput: out\ndevice: auto\njobs:\n  - name: d\n    kind: diffraction\n" +
                                        source + table);
    const auto r = tst::run_cli({"run", (dir / "c.yaml").string()});
    ASSERT_EQ(r.exit_code, 0) << name << "\n" << r.err;
    const fs::path b = dir / "out/d/latest";
    const auto m = tst::read_json(b / "manifest.json");
    const auto& d = m["diffraction"];
    const int n = d["table"]["size"].get<int>(), T = d["terms"].get<int>();
    EXPECT_EQ(d["table"]["mapping"], "power") << name;
    EXPECT_EQ(d["table"]["power"], 3.0) << name;
    EXPECT_NE(std::find(std::begin(kTableLadder), std::end(kTableLadder), n), std::end(kTableLadder)) << name;
    EXPECT_LE(d["error"]["between_texels_bilinear"]["max_over_window_sum"].get<double>(), 1e-2) << name;
    EXPECT_LE(d["error"]["at_texels"]["max_over_window_sum"].get<double>(), 1e-4) << name;
    for (const char* rec : {"table_vs_exact_transform", "table_between_texels"}) {
      const auto a = find_accuracy(m["accuracy"], rec);
      ASSERT_TRUE(a) << name << " " << rec;
      EXPECT_TRUE((*a)["passed"].get<bool>()) << name << " " << rec;
    }
    EXPECT_EQ(tst::read_f32(b / "table_terms.bin").size(), static_cast<std::size_t>(T) * n * n * 2) << name;
    EXPECT_TRUE(fs::exists(b / "table/F_000.exr")) << name;
    // The ladder was climbed in order and stopped at the first size that met table.tolerance.
    const auto& attempts = d["error"]["attempts"];
    ASSERT_FALSE(attempts.empty()) << name;
    for (std::size_t k = 0; k < attempts.size(); ++k) {
      EXPECT_EQ(attempts[k]["size"].get<int>(), kTableLadder[k]) << name;
      const double between = attempts[k]["between_texels_max"].get<double>();
      if (k + 1 < attempts.size()) EXPECT_GT(between, 1e-2) << name << " stopped late";
      else EXPECT_LE(between, 1e-2) << name;
    }
    if (name == "binary") EXPECT_GT(n, kTableLadder[0]) << "the grating's sharp orders need more than the first size";
    for (const auto& [file, width, height] :
         std::vector<std::tuple<std::string, int, int>>{{"preview/brdf_lobes.png", 768, 256}, {"preview/sphere.png", 512, 512}}) {
      const auto im = tst::read_png(b / file);
      EXPECT_EQ(im.width, width) << name << " " << file;
      EXPECT_EQ(im.height, height) << name << " " << file;
      int lit = 0;
      for (std::size_t i = 0; i < im.rgba.size(); i += 4) lit += std::max({im.rgba[i], im.rgba[i + 1], im.rgba[i + 2]}) > 16;
      EXPECT_GT(lit, 20) << name << " " << file << ": blank";
    }
  }
}
