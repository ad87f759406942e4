// The diffraction job end to end through the CLI (bundle files, manifest contract, fixed-T
// warnings, hard failures) and the heightfield readers (8/16-bit PNG, grey BMP, EXR, raw)
// with their errors and exit codes.
#include <gtest/gtest.h>
#include <png.h>

#include <boost/math/special_functions/bessel.hpp>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstring>

#include "core/errors.hpp"
#include "io/exr.hpp"
#include "io/heightfield.hpp"
#include "support/testing.hpp"

using namespace specbake;
namespace tst = specbake::testing;
using cplx = std::complex<double>;

namespace {

std::string config(const std::string& job_body) {
  return "specbake: 1\noutput: out\ndevice: auto\njobs:\n  - name: d\n    kind: diffraction\n" + job_body;
}

// A grey PNG (8 or 16 bit) through libpng's write API.
void write_grey_png(const fs::path& p, int w, int h, int bits, const std::vector<unsigned>& levels) {
  FILE* fp = std::fopen(p.c_str(), "wb");
  ASSERT_TRUE(fp);
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  png_init_io(png, fp);
  png_set_IHDR(png, info, w, h, bits, PNG_COLOR_TYPE_GRAY, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  std::vector<unsigned char> row(w * bits / 8);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const unsigned v = levels[y * w + x];
      if (bits == 16) {
        row[2 * x] = static_cast<unsigned char>(v >> 8);
        row[2 * x + 1] = static_cast<unsigned char>(v & 255);
      } else {
        row[x] = static_cast<unsigned char>(v);
      }
    }
    png_write_row(png, row.data());
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  std::fclose(fp);
}

std::string raw_f32(const std::vector<float>& v) {
  std::string s(v.size() * 4, '\0');
  std::memcpy(s.data(), v.data(), s.size());
  return s;
}

}  // namespace

TEST(DiffractionReaders, Png16And8BitAndRgbGrey) {
  tst::TempDir dir;
  std::vector<unsigned> levels16, levels8;
  for (int i = 0; i < 12 * 5; ++i) {
    levels16.push_back((i * 1097u) % 65536u);
    levels8.push_back((i * 37u) % 256u);
  }
  write_grey_png(dir / "a16.png", 12, 5, 16, levels16);
  write_grey_png(dir / "a8.png", 12, 5, 8, levels8);
  const auto g16 = decode_png_grey(tst::read_file(dir / "a16.png"), dir / "a16.png");
  const auto g8 = decode_png_grey(tst::read_file(dir / "a8.png"), dir / "a8.png");
  EXPECT_EQ(g16.max_level, 65535);
  EXPECT_EQ(g8.max_level, 255);
  ASSERT_EQ(g16.width, 12);
  ASSERT_EQ(g16.height, 5);
  for (int i = 0; i < 60; ++i) {
    EXPECT_EQ(g16.levels[i], levels16[i]);  // exact: integer levels
    EXPECT_EQ(g8.levels[i], levels8[i]);
  }
  HeightfieldRead how{dir / "a16.png", HeightfieldFormat::png, 0.1, 0.5, std::nullopt};
  const Heightfield hf = decode_heightfield(tst::read_file(dir / "a16.png"), how);
  EXPECT_DOUBLE_EQ(hf.h_um[7], levels16[7] / 65535.0 * 0.5);
  // The Elaphe patch is 8-bit grey stored as RGBA (R = G = B): levels 21…244 (PROVENANCE.md).
  const fs::path elaphe = tst::source_dir() / "data/heightfields/Elaph100x100.png";
  const auto e = decode_png_grey(tst::read_file(elaphe), elaphe);
  EXPECT_EQ(e.width, 100);
  EXPECT_EQ(*std::min_element(e.levels.begin(), e.levels.end()), 21);
  EXPECT_EQ(*std::max_element(e.levels.begin(), e.levels.end()), 244);
}

TEST(DiffractionReaders, BmpBlazedRamp) {
  const fs::path p = tst::source_dir() / "data/heightfields/BlazingBump.bmp";
  const auto g = decode_bmp_grey(tst::read_file(p), p);
  ASSERT_EQ(g.width, 100);
  ASSERT_EQ(g.height, 100);
  // A ramp 0 → 255 along x in every row; the last column is 0 (PROVENANCE.md).
  for (int y : {0, 50, 99}) {
    EXPECT_EQ(g.levels[y * 100 + 0], 0);
    EXPECT_EQ(g.levels[y * 100 + 98], 255) << y;
    EXPECT_EQ(g.levels[y * 100 + 99], 0);
    for (int x = 1; x < 99; ++x) EXPECT_GE(g.levels[y * 100 + x], g.levels[y * 100 + x - 1]);
  }
}

TEST(DiffractionReaders, BadInputsNameTheFile) {
  const fs::path f = "/x/field.raw";
  HeightfieldRead how{f, HeightfieldFormat::raw, 0.1, 1.0, std::make_pair(4, 4)};
  std::vector<float> v(16, 0.25f);
  EXPECT_NO_THROW(decode_heightfield(raw_f32(v), how));
  v[5] = std::nanf("");
  try {
    decode_heightfield(raw_f32(v), how);
    ADD_FAILURE() << "NaN accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("field.raw"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("NaN"), std::string::npos) << e.what();
  }
  v[5] = INFINITY;
  EXPECT_THROW(decode_heightfield(raw_f32(v), how), InputError);
  v[5] = 0.0f;
  v.pop_back();
  EXPECT_THROW(decode_heightfield(raw_f32(v), how), InputError);  // 60 bytes for a 4×4 field
  how.dx_um = 0.0;
  EXPECT_THROW(decode_heightfield(raw_f32(std::vector<float>(16, 0.f)), how), InputError);
  EXPECT_THROW(decode_png_grey("not a png", "/x/a.png"), InputError);
  EXPECT_THROW(decode_bmp_grey("BMxx", "/x/a.bmp"), InputError);
  // EXR with an infinite height.
  ExrImage img;
  img.width = img.height = 4;
  img.channels = {"Y"};
  img.pixels.assign(16, 0.1f);
  img.pixels[3] = INFINITY;
  HeightfieldRead exr{"/x/h.exr", HeightfieldFormat::exr, 0.1, 1.0, std::nullopt};
  EXPECT_THROW(decode_heightfield(exr_bytes(img), exr), InputError);
  img.pixels[3] = 0.3f;
  const Heightfield ok = decode_heightfield(exr_bytes(img), exr);
  EXPECT_FLOAT_EQ(static_cast<float>(ok.h_um[3]), 0.3f);
}

TEST(DiffractionCli, BadConfigsExitWithInputErrors) {
  tst::TempDir dir;
  std::vector<float> v(64, 0.1f);
  tst::write_file(dir / "ok.raw", raw_f32(v));
  v[9] = std::nanf("");
  tst::write_file(dir / "nan.raw", raw_f32(v));
  tst::write_file(dir / "short.raw", raw_f32(std::vector<float>(60, 0.1f)));
  struct Case {
    std::string body, expect;
  };
  const std::vector<Case> cases = {
      {"    heightfield: {file: nan.raw, dx_um: 0.1, size: [8, 8]}\n", "nan.raw"},
      {"    heightfield: {file: short.raw, dx_um: 0.1, size: [8, 8]}\n", "short.raw"},
      {"    heightfield: {file: missing.png, dx_um: 0.1, height_um: 0.2}\n", "missing.png"},
      {"    heightfield: {file: ok.raw, dx_um: 0, size: [8, 8]}\n", "heightfield.dx_um"},
      {"    heightfield: {file: ok.raw, dx_um: -0.1, size: [8, 8]}\n", "heightfield.dx_um"},
      {"    heightfield: {file: ok.raw, dx_um: 0.1, size: [8, 8], height_um: 1}\n", "height_um"},
      {"    heightfield: {file: ok.raw, dx_um: 0.1, size: [8, 8]}\n    terms: 0\n", "terms"},
      {"    heightfield: {file: ok.raw, dx_um: 0.1, size: [8, 8]}\n    expansion: pade\n", "expansion"},
      {"    procedural: {type: sine-grating, size: 32, dx_um: 0.1, period_um: 1, depth_um: 0.1}\n", "depth_um"},
  };
  for (const auto& c : cases) {
    tst::write_file(dir / "c.yaml", config(c.body));
    const auto r = tst::run_cli({"run", (dir / "c.yaml").string()});
    EXPECT_EQ(r.exit_code, 3) << c.body << r.err;
    EXPECT_NE((r.out + r.err).find(c.expect), std::string::npos) << c.expect << " not named in:\n" << r.err;
    EXPECT_FALSE(fs::exists(dir / "out")) << "something was written for " << c.body;
  }
}

TEST(DiffractionCli, SineGratingBundleFollowsTheContract) {
  tst::TempDir dir;
  tst::write_file(dir / "c.yaml",
                  config("    procedural: {type: sine-grating, size: 64, dx_um: 0.125, period_um: 2.0, amplitude_um: "
                         "0.15}\n    expansion: taylor\n    tolerance: 1e-4\n    storage: half\n"));
  const auto r = tst::run_cli({"run", (dir / "c.yaml").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const fs::path b = dir / "out/d/latest";
  const auto m = tst::read_json(b / "manifest.json");
  // The contract puts the block at the manifest's top level, not among the parameters.
  EXPECT_FALSE(m["parameters"].contains("diffraction"));
  const auto& dj = m["diffraction"];
  const int M = dj["size"].get<int>(), kmin = dj["bins"][0].get<int>(), kmax = dj["bins"][1].get<int>();
  const int K = kmax - kmin + 1, T = dj["terms"].get<int>();
  EXPECT_EQ(M, 64);
  EXPECT_EQ(dj["error"]["meets_tolerance"], true);
  EXPECT_LE(dj["error"]["max_over_M2"].get<double>(), 1e-4);
  const auto terms = tst::read_f32(b / "terms.bin");
  ASSERT_EQ(terms.size(), static_cast<std::size_t>(T) * K * K * 2);
  for (int n = 0; n < T; ++n) EXPECT_TRUE(fs::exists(b / ("terms/F_" + std::string(n < 10 ? "00" : "0") + std::to_string(n) + ".exr")));
  EXPECT_TRUE(fs::exists(b / "preview/white_normal.png"));
  // The log view spans the decades below the brightest pixel that hold 99 % of the lit ones, each
  // pixel's largest channel at its level: a channel reaches code 255 (linear ≥ 0.9957) only within
  // 0.0043 · D decades (1 % for D ≤ 2) of the brightest, the grating's order peaks, a few pixels.
  // Both views carry their label in the top-left corner (black: outside the (u, v) disk).
  for (const char* png : {"preview/white_normal.png", "preview/white_normal_log.png"}) {
    const auto img = tst::read_png(b / png);
    int lit = 0, clipped = 0, ink = 0;
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) {
        const unsigned char* q = &img.rgba[4 * (static_cast<std::size_t>(y) * img.width + x)];
        const int top = std::max({q[0], q[1], q[2]});
        lit += top > 0;
        clipped += top == 255;
        ink += x < 20 && y < 12 && top >= 128;
      }
    EXPECT_GT(ink, 10) << png << ": no label";
    if (std::string(png) == "preview/white_normal_log.png") EXPECT_LE(clipped, 0.01 * lit) << clipped << " of " << lit;
  }
  const auto spectrum = tst::read_f32(b / "spectrum.bin");
  EXPECT_EQ(spectrum.size(), 401u * 4);
  EXPECT_FLOAT_EQ(spectrum[0], 380.0f);
  // Reconstruct P from the files alone with the manifest's formula and compare to the analytic
  // Jacobi–Anger orders: 4 periods of 16 samples over 64, order m at ku = 4m, orders m ± 16 alias.
  const double c = dj["center_um"].get<double>(), s = dj["scale_um"].get<double>();
  for (double kappa : {3.0, 20.0, dj["kappa_range"][1].get<double>()}) {
    const nlohmann::json* band = nullptr;
    for (const auto& bj : dj["bands"])
      if (kappa <= bj["kappa_range"][1].get<double>()) {
        band = &bj;
        break;
      }
    ASSERT_TRUE(band);
    ASSERT_EQ((*band)["expansion"], "taylor");
    const double k0 = (*band)["kappa_expansion"].get<double>();
    const int first = (*band)["first_term"].get<int>(), nt = (*band)["terms"].get<int>();
    for (int ku = kmin; ku <= kmax; ++ku) {
      const int kv = ku % 3 == 0 ? 0 : 1;  // rows kv = 0 (orders) and kv = 1 (dark)
      cplx sum = 0.0, coef = 1.0;
      for (int n = 0; n < nt; ++n) {
        if (n > 0) coef *= (kappa - k0) * s / n;
        const std::size_t i = ((static_cast<std::size_t>(first + n) * K + (kv - kmin)) * K + (ku - kmin)) * 2;
        sum += coef * cplx(terms[i], terms[i + 1]);
      }
      const cplx P_over_M2 = std::polar(1.0, kappa * c) * sum;
      double want = 0.0;
      if (kv == 0 && ku % 4 == 0)
        for (int j = -3; j <= 3; ++j) want += boost::math::cyl_bessel_j(ku / 4 + 16 * j, kappa * 0.15);
      // The job's measured error bound (over M²), which it checked against double DFTs.
      EXPECT_NEAR(std::abs(P_over_M2 - want), 0.0, 1e-4) << "kappa " << kappa << " ku " << ku << " kv " << kv;
    }
  }
}

TEST(DiffractionCli, FixedTermsBelowToleranceAreFlaggedAndAutoFailsClearly) {
  tst::TempDir dir;
  const std::string field = "    procedural: {type: eggcrate, size: 32, dx_um: 0.1, period_um: 0.8, peak_to_valley_um: 1.2}\n";
  tst::write_file(dir / "fixed.yaml", config(field + "    expansion: taylor\n    terms: 6\n    crop: none\n"));
  // a tolerance it misses fails the job (nothing published) ...
  auto r = tst::run_cli({"run", (dir / "fixed.yaml").string()});
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_NE(r.out.find("missed its tolerance: vs_exact_transform"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir / "out/d/latest"));
  // ... unless the job says it is advisory: then it is shipped, flagged
  tst::write_file(dir / "fixed.yaml",
                  config(field + "    expansion: taylor\n    terms: 6\n    crop: none\n    tolerance_advisory: true\n"));
  r = tst::run_cli({"run", (dir / "fixed.yaml").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE((r.out + r.err).find("FIXED TERMS DO NOT MEET THE TOLERANCE"), std::string::npos) << r.err;
  const auto m = tst::read_json(dir / "out/d/latest/manifest.json");
  EXPECT_EQ(m["diffraction"]["error"]["meets_tolerance"], false);
  EXPECT_GT(m["diffraction"]["error"]["max_over_M2"].get<double>(), 1e-4);
  EXPECT_FALSE(m["warnings"].empty());
  // y_max ≈ 20 with a tolerance beyond float32: auto refuses with a message, exit code 1.
  tst::write_file(dir / "auto.yaml", config(field + "    expansion: taylor\n    tolerance: 1e-10\n"));
  r = tst::run_cli({"run", (dir / "auto.yaml").string(), "--out", (dir / "out2").string()});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE((r.out + r.err).find("cannot meet tolerance"), std::string::npos) << r.err;
  // Chebyshev reaches 1e-6 at the same y_max in one band.
  tst::write_file(dir / "cheb.yaml", config(field + "    expansion: chebyshev\n    tolerance: 1e-6\n"));
  r = tst::run_cli({"run", (dir / "cheb.yaml").string(), "--out", (dir / "out3").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto mc = tst::read_json(dir / "out3/d/latest/manifest.json");
  EXPECT_LE(mc["diffraction"]["error"]["max_over_M2"].get<double>(), 1e-6);
}

TEST(DiffractionCli, ExampleConfigsAndRawNonSquareInput) {
  tst::TempDir dir;
  for (const char* cfg : {"configs/elaphe-diffraction.yaml", "configs/sine-grating.yaml"}) {
    const auto r = tst::run_cli({"run", (tst::source_dir() / cfg).string(), "--out", (dir / "assets").string()});
    EXPECT_EQ(r.exit_code, 0) << cfg << "\n" << r.err;
  }
  // A 24 × 10 raw field (non-square, non-power-of-two) with 8-bit BMP-free float input.
  std::vector<float> v;
  for (int iy = 0; iy < 10; ++iy)
    for (int ix = 0; ix < 24; ++ix) v.push_back(0.1f * std::sin(0.9f * ix + 0.3f * iy * iy));
  tst::write_file(dir / "f.raw", raw_f32(v));
  tst::write_file(dir / "c.yaml", config("    heightfield: {file: f.raw, dx_um: 0.2, size: [24, 10]}\n    crop: none\n"));
  const auto r = tst::run_cli({"run", (dir / "c.yaml").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto m = tst::read_json(dir / "out/d/latest/manifest.json");
  const auto& dj = m["diffraction"];
  EXPECT_EQ(dj["size"], nlohmann::json({24, 10}));
  EXPECT_EQ(dj["bins"]["ku"], nlohmann::json({-12, 11}));
  EXPECT_EQ(dj["bins"]["kv"], nlohmann::json({-5, 4}));
  EXPECT_TRUE(dj["error"]["meets_tolerance"].get<bool>());
}
