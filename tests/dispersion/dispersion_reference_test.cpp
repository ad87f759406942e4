// Dispersion values (SPECGEN) against the independent float64 reference data in
// refdata/specgen/specgen_reference_subset.json (numpy; see its README), for both the double
// reference path (compute_reference) and the OpenCL path (compute_device on PoCL). The error
// model behind every tolerance is in support/specgen_refdata.hpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "cl/device.hpp"
#include "support/specgen_refdata.hpp"

namespace {

using namespace specbake;
using namespace specbake::dispersion;
using namespace specbake::testing::specgen;

cl_util::Device& device() {
  static std::unique_ptr<cl_util::Device> dev =
      std::make_unique<cl_util::Device>(cl_util::select_device("auto"));
  return *dev;
}
double device_u() { return device().info().fp64 ? u53 : 5.9604644775390625e-08; }

TEST(DispersionReference, SampleWavelengthsAndWeights) {
  for (const Case& c : kCases) {
    SCOPED_TRACE(label(c));
    const json& rc = case_of(c);
    std::vector<double> dl, dw;
    sample_bounds(c, rc, dl, dw);
    const Samples s = make_samples(c.sampling, {380.0, 780.0}, c.n);
    expect_within(s.lambda_nm, flat(rc.at("lambda_nm")), dl, "lambda_nm");
    expect_within(s.weight_nm, flat(rc.at("weight_nm")), dw, "weight_nm");
  }
}

// Both paths (double reference, OpenCL device) and both line sets (D = seed, d = Abbe).
void check_tables(const Tables& t, const Case& c, AbbeLines lines_choice, double u, const std::string& path) {
  SCOPED_TRACE(path + (lines_choice == AbbeLines::D ? " lines D" : " lines d"));
  const json& rc = case_of(c);
  std::vector<double> dl, dw;
  sample_bounds(c, rc, dl, dw);
  const Lines lines = lines_for(lines_choice);
  const Bounds b = bounds_for(rc, dl, dw, u, lines);
  expect_within(t.w_raw, flat(rc.at("W_raw")), b.w_raw, "W_raw");
  expect_within({t.w_raw_sum.begin(), t.w_raw_sum.end()}, flat(rc.at("W_raw_sum")), b.w_raw_sum, "W_raw_sum");
  expect_within(t.w_norm, flat(rc.at("W_norm")), b.w_norm, "W_norm");
  expect_within(t.K, flat(rc.at("K").at("derived")), b.K, "K (derived matrices)");
  expect_within(t.offset, flat(rc.at(lines_choice == AbbeLines::D ? "offset_seed" : "offset_dline")), b.offset,
                "offsets");
  // The Cauchy/Abbe index of the seed: n = n_ref + (n_ref − 1)/V·Offset. Abs bound: the offset
  // bound times (n_ref − 1)/V, plus 4 roundings of n ≈ 1.5 in each path.
  const auto off_ref = flat(rc.at(lines_choice == AbbeLines::D ? "offset_seed" : "offset_dline"));
  std::vector<double> ior_ref, ior_tol;
  for (std::size_t i = 0; i < off_ref.size(); ++i) {
    ior_ref.push_back(1.5168 + (1.5168 - 1.0) / 64.17 * off_ref[i]);
    ior_tol.push_back(b.offset[i] * (1.5168 - 1.0) / 64.17 + 4.0 * (u + u53) * 2.0);
  }
  expect_within(t.ior, ior_ref, ior_tol, "ior (Cauchy/Abbe)");
}

TEST(DispersionReference, ReferencePathMatchesRefdata) {
  for (const Case& c : kCases)
    for (AbbeLines l : {AbbeLines::D, AbbeLines::d}) {
      SCOPED_TRACE(label(c));
      const DispersionSpec spec = spec_for(c, l);
      const Samples s = make_samples(c.sampling, spec.range_nm, c.n);
      const Tables t = compute_reference(spec, s, resolve_material(spec.material, lines_for(l)));
      check_tables(t, c, l, u53, "compute_reference");
    }
}

TEST(DispersionReference, DevicePathMatchesRefdata) {
  for (const Case& c : kCases)
    for (AbbeLines l : {AbbeLines::D, AbbeLines::d}) {
      SCOPED_TRACE(label(c));
      const DispersionSpec spec = spec_for(c, l);
      const Samples s = make_samples(c.sampling, spec.range_nm, c.n);
      const Tables t = compute_device(device(), spec, s, resolve_material(spec.material, lines_for(l)));
      check_tables(t, c, l, device_u(), "compute_device on " + device().info().name);
    }
}

// A device without cl_khr_fp64 (the same PoCL device with the capability masked, so the
// kernels build with real = float): the float32 bounds of the error model must hold.
TEST(DispersionReference, DevicePathMatchesRefdataWithoutFp64) {
  cl_util::DeviceInfo info = cl_util::select_device("auto");
  info.fp64 = false;
  cl_util::Device float_only(info);
  for (const Case& c : kCases)
    for (AbbeLines l : {AbbeLines::D, AbbeLines::d}) {
      SCOPED_TRACE(label(c));
      const DispersionSpec spec = spec_for(c, l);
      const Samples s = make_samples(c.sampling, spec.range_nm, c.n);
      const Tables t = compute_device(float_only, spec, s, resolve_material(spec.material, lines_for(l)));
      check_tables(t, c, l, 5.9604644775390625e-08, "compute_device without fp64");
    }
}

// Σ_n K_n = Minv·Diag(Σ_n Ŵ_n)·M = I in exact arithmetic. In double: each K_n entry carries
// ≤ 5 roundings of Σ_k |Minv_rk|·Ŵ_nk·|M_kc|; summed over n (Σ_n Ŵ_nk = 1) that is
// 5 u·(|Minv|·|M|)_rc; Σ_n Ŵ_n = 1 to N roundings; Minv·M = I to ≤ 32 u (see SrgbMatrices);
// the sum over n adds N roundings of values ≤ 1. Total ≤ (5 + N + 32 + N)·u·max(|Minv||M|).
TEST(DispersionReference, SumOfMatricesIsIdentityInDouble) {
  const Mat3 M = srgb_to_xyz(), Minv = xyz_to_srgb();
  double absprod = 0.0;  // max_rc (|Minv|·|M|)_rc
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      double s = 0.0;
      for (int k = 0; k < 3; ++k) s += std::fabs(Minv[3 * r + k]) * std::fabs(M[3 * k + c]);
      absprod = std::max(absprod, s);
    }
  for (Sampling sampling : {Sampling::uniform, Sampling::gauss_legendre, Sampling::visible_pdf, Sampling::inverse_square})
    for (int n : {1, 4, 16, 64, 256}) {
      SCOPED_TRACE(std::string(to_string(sampling)) + " N=" + std::to_string(n));
      DispersionSpec spec = spec_for({"", sampling, n}, AbbeLines::d);
      const Tables t = compute_reference(spec, make_samples(sampling, spec.range_nm, n),
                                         resolve_material(spec.material, lines_for(AbbeLines::d)));
      const double bound = (37.0 + 2.0 * n) * u53 * absprod;
      for (int e = 0; e < 9; ++e) {
        double s = 0.0;
        for (int i = 0; i < n; ++i) s += t.K[9 * i + e];
        EXPECT_LE(std::fabs(s - (e % 4 == 0 ? 1.0 : 0.0)), bound) << "entry " << e;
      }
    }
}

// The matrices of src/core/colour_space against meta.matrices.derived (BT.709 primaries, D65
// xy, float64, exact inverse). Both are built in double from the same chromaticities with a
// 3×3 inverse in between: the primaries' matrix has condition number ≈ 10 (|P|·|P⁻¹|), so
// the two constructions agree entrywise to ≤ 32 u53 relative to the largest entry of the row.
TEST(DispersionReference, SrgbMatrices) {
  const json& m = refdata().at("meta").at("matrices").at("derived");
  const auto M_ref = flat(m.at("M_sRGB_to_XYZ")), Minv_ref = flat(m.at("M_XYZ_to_sRGB"));
  const Mat3 M = srgb_to_xyz(), Minv = xyz_to_srgb();
  for (int r = 0; r < 3; ++r) {
    double row_M = 0.0, row_Minv = 0.0;
    for (int c = 0; c < 3; ++c) {
      row_M = std::max(row_M, std::fabs(M_ref[3 * r + c]));
      row_Minv = std::max(row_Minv, std::fabs(Minv_ref[3 * r + c]));
    }
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(M[3 * r + c], M_ref[3 * r + c], 32.0 * u53 * row_M) << "M_sRGB_to_XYZ[" << r << "][" << c << "]";
      EXPECT_NEAR(Minv[3 * r + c], Minv_ref[3 * r + c], 32.0 * u53 * row_Minv)
          << "M_XYZ_to_sRGB[" << r << "][" << c << "]";
    }
  }
  // An exact inverse pair: Minv·M = I to a few roundings of |Minv|·|M| (≤ 1.7): ≤ 32 u53.
  const Mat3 P = multiply(Minv, M);
  for (int e = 0; e < 9; ++e) EXPECT_NEAR(P[e], e % 4 == 0 ? 1.0 : 0.0, 32.0 * u53) << "(Minv·M)[" << e << "]";
  // The white: M·(1,1,1) = D65 XYZ with Y = 1 and x, y = (0.3127, 0.3290).
  const double X = M[0] + M[1] + M[2], Y = M[3] + M[4] + M[5], Z = M[6] + M[7] + M[8];
  EXPECT_NEAR(Y, 1.0, 8 * u53);
  EXPECT_NEAR(X / (X + Y + Z), 0.3127, 16 * u53);
  EXPECT_NEAR(Y / (X + Y + Z), 0.3290, 16 * u53);
}

// The sanity values printed in refdata/specgen/README.md (6 decimals: ± half a unit of the
// last printed digit, 5e-7).
TEST(DispersionReference, ReadmeSanityValues) {
  DispersionSpec spec = spec_for({"", Sampling::uniform, 4}, AbbeLines::D);
  const Samples s = make_samples(Sampling::uniform, spec.range_nm, 4);
  const std::vector<double> lambda = {430, 530, 630, 730};
  for (int i = 0; i < 4; ++i) EXPECT_DOUBLE_EQ(s.lambda_nm[i], lambda[i]);
  for (const bool on_device : {false, true}) {
    SCOPED_TRACE(on_device ? "device" : "reference");
    const MaterialModel mat = resolve_material(spec.material, lines_for(AbbeLines::D));
    const Tables t = on_device ? compute_device(device(), spec, s, mat) : compute_reference(spec, s, mat);
    const double w0[3] = {0.259687, 0.010183, 0.970437};
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(t.w_norm[c], w0[c], 5e-7) << "W_norm[0][" << c << "]";
    const double off[4] = {1.324199, 0.356305, -0.188537, -0.525248};
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(t.offset[i], off[i], 5e-7) << "offset_seed[" << i << "]";
    // README: every K_n has negative entries and every K_n·(1,1,1) a negative component.
    for (int i = 0; i < 4; ++i) {
      EXPECT_LT(*std::min_element(t.K.begin() + 9 * i, t.K.begin() + 9 * i + 9), 0.0) << "K_" << i;
      double white_min = 1e9;
      for (int r = 0; r < 3; ++r) white_min = std::min(white_min, t.K[9 * i + 3 * r] + t.K[9 * i + 3 * r + 1] + t.K[9 * i + 3 * r + 2]);
      EXPECT_LT(white_min, 0.0) << "K_" << i << "·(1,1,1)";
    }
  }
}

// K_n·(1,1,1), the colour a white input gets from sample n (refdata K_white_rgb, derived
// matrices): out of gamut per sample, as the README says; only the sum is white.
TEST(DispersionReference, WhiteThroughEachMatrix) {
  for (const Case& c : kCases) {
    SCOPED_TRACE(label(c));
    const json& rc = case_of(c);
    const DispersionSpec spec = spec_for(c, AbbeLines::D);
    const Tables t = compute_reference(spec, make_samples(c.sampling, spec.range_nm, c.n),
                                       resolve_material(spec.material, lines_for(AbbeLines::D)));
    std::vector<double> dl, dw;
    sample_bounds(c, rc, dl, dw);
    const Bounds b = bounds_for(rc, dl, dw, u53, lines_for(AbbeLines::D));
    std::vector<double> white, tol;
    for (int i = 0; i < c.n; ++i)
      for (int r = 0; r < 3; ++r) {
        white.push_back(t.K[9 * i + 3 * r] + t.K[9 * i + 3 * r + 1] + t.K[9 * i + 3 * r + 2]);
        // Row sum of three K entries: their bounds plus 2 roundings of the row's magnitude.
        tol.push_back(b.K[9 * i + 3 * r] + b.K[9 * i + 3 * r + 1] + b.K[9 * i + 3 * r + 2] + 4.0 * u53 * 2.0);
      }
    expect_within(white, flat(rc.at("K_white_rgb").at("derived")), tol, "K_n·(1,1,1)");
  }
}

}  // namespace
