// Every GLSL file a bundle ships — the atmosphere's sampling.glsl (and sampling_spectral.glsl of
// `store: radiance`), the dispersion's
// dispersion.glsl, a diffraction table's shader/diffraction_brdf.glsl — compiles with
// glslangValidator as a GL 4.50 core and a GLES 3.20 fragment shader (each is a library without
// #version or main: the includer adds both).
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "support/testing.hpp"

namespace t = specbake::testing;
namespace fs = std::filesystem;

TEST(CliShaders, EveryEmittedShaderCompilesForGlAndGles) {
  if (!t::have_glslang()) GTEST_SKIP() << "glslangValidator not found (Debian: glslang-tools; scripts/setup.sh installs it)";
  t::TempDir dir;
  t::write_file(dir / "c.yaml",
                "specbake: 1\noutput: out\njobs:\n"
                "  - name: prism\n    kind: dispersion\n    samples: 6\n    material: {glass: N-BK7}\n"
                "  - name: sky\n    kind: atmosphere\n    orders: 2\n    scene: none\n"
                "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}\n"
                "  - name: sky-radiance\n    kind: atmosphere\n    orders: 2\n    scene: none\n    previews: none\n"
                "    spectrum: {min_nm: 400, max_nm: 700, count: 8, store: radiance}\n"
                "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 4, mu: 8, mu_s: 6, nu: 3}}\n"
                "  - name: grating\n    kind: diffraction\n"
                "    procedural: {type: sine-grating, size: 32, dx_um: 0.125, period_um: 1.0, amplitude_um: 0.2}\n"
                "    table: {size: 16}\n    coherence: {length_um: 3}\n"
                "    tolerance_advisory: true\n");  // a table this small misses its tolerance between texels
  const auto r = t::run_cli({"run", (dir / "c.yaml").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::vector<fs::path> shaders;
  for (const auto& e : fs::recursive_directory_iterator(dir / "out"))
    if (e.is_regular_file() && e.path().extension() == ".glsl") shaders.push_back(e.path());
  ASSERT_EQ(shaders.size(), 5u) << "one shader per kind, and the radiance bundle's spectral one";
  const std::string es = "#version 320 es\nprecision highp float;\nprecision highp sampler2D;\n"
                         "precision highp sampler3D;\nprecision highp sampler2DArray;\n";
  int k = 0;
  for (const auto& path : shaders) {
    const std::string glsl = t::read_file(path);
    for (const auto& [stage, head] : {std::pair<std::string, std::string>{"gl450", "#version 450\n"}, {"es320", es}}) {
      const auto [status, log] = t::glslang_validate(dir.path(), std::to_string(k++) + "_" + stage + ".frag", head + glsl);
      EXPECT_EQ(status, 0) << path.filename() << " as " << stage << ":\n" << log;
      EXPECT_EQ(log.find("ERROR"), std::string::npos) << path.filename() << " as " << stage << ":\n" << log;
    }
  }
  // A shader cut in half does not compile: the checks above can fail.
  const std::string cut = t::read_file(shaders.front());
  EXPECT_NE(t::glslang_validate(dir.path(), "cut.frag", "#version 450\n" + cut.substr(0, cut.size() / 2)).first, 0);
}
