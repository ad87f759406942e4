// The GLSL a table bundle ships (shader/diffraction_brdf.glsl): it carries kernels/diffraction/
// brdf.cl verbatim (one source with the host's reference) and compiles with glslangValidator as a
// GL 4.50 core and a GLES 3.20 fragment shader that calls its entry points.
#include <gtest/gtest.h>

#include <string>

#include "core/resources.hpp"
#include "support/testing.hpp"

namespace tst = specbake::testing;
namespace fs = std::filesystem;

namespace {

const char* kMain =
    "void main() { colour = vec4(diffraction_srgb(terms, spectrum, normalize(wi), normalize(wo), 10), 1.0)"
    " + vec4(diffraction_brdf(terms, normalize(wi), normalize(wo), 0.55)); }\n";

}  // namespace

TEST(DiffractionShader, ShipsTheSharedMathsAndCompilesForGlAndGles) {
  tst::TempDir dir;
  tst::write_file(dir / "c.yaml",
                  "specbake: 1\noutput: out\ndevice: auto\njobs:\n  - name: d\n    kind: diffraction\n"
                  "    procedural: {type: blazed-grating, size: 32, dx_um: 0.125, period_um: 1.0, depth_um: 0.3}\n"
                  "    expansion: chebyshev\n    tolerance: 1e-6\n"  // tall enough for more than one band
                  "    table: {size: 32}\n    coherence: {length_um: 3}\n"
                  "    tolerance_advisory: true\n");  // a fixed small table misses its tolerance between texels
  const auto r = tst::run_cli({"run", (dir / "c.yaml").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string glsl = tst::read_file(dir / "out/d/latest/shader/diffraction_brdf.glsl");
  // One source: brdf.cl's functions are in the shader as written (its include line aside).
  std::string shared(specbake::resource("kernels/diffraction/brdf.cl"));
  shared.erase(0, shared.find("#include \"common/real.h\"\n") + 25);
  EXPECT_NE(glsl.find(shared), std::string::npos) << "the shader does not carry brdf.cl verbatim";
  for (const char* fn : {"diffraction_texel", "fresnel_dielectric", "stam_gain", "diffraction_p", "diffraction_brdf",
                         "diffraction_srgb"})
    EXPECT_NE(glsl.find(fn), std::string::npos) << fn;

  if (!tst::have_glslang()) GTEST_SKIP() << "glslangValidator not found (Debian: glslang-tools; scripts/setup.sh installs it)";
  const std::string gl = std::string("#version 450\n") + glsl +
                         "layout(binding = 0) uniform sampler2DArray terms;\n"
                         "layout(binding = 1) uniform sampler2D spectrum;\n"
                         "layout(location = 0) in vec3 wi;\nlayout(location = 1) in vec3 wo;\n"
                         "layout(location = 0) out vec4 colour;\n" + kMain;
  const std::string es = std::string("#version 320 es\nprecision highp float;\nprecision highp sampler2DArray;\n") +
                         glsl + "uniform sampler2DArray terms;\nuniform sampler2D spectrum;\nin vec3 wi;\nin vec3 wo;\n"
                         "out vec4 colour;\n" + kMain;
  for (const auto& [name, source] : {std::pair<std::string, std::string>{"gl450.frag", gl}, {"es320.frag", es}}) {
    const auto [status, log] = tst::glslang_validate(dir.path(), name, source);
    EXPECT_EQ(status, 0) << name << ":\n" << log;
    EXPECT_EQ(log.find("ERROR"), std::string::npos) << name << ":\n" << log;
  }
  // The validator does catch a broken shader (so the checks above can fail).
  const auto [status, log] = tst::glslang_validate(dir.path(), "broken.frag", gl.substr(0, gl.size() / 2));
  EXPECT_NE(status, 0) << log;
}
