#include "kinds/diffraction/shader.hpp"

#include <sstream>

#include "core/colour_space.hpp"
#include "core/glsl.hpp"
#include "core/text.hpp"
#include "kinds/diffraction/terms.hpp"

namespace specbake::diffraction {

namespace {
template <class T, class F>
std::string array(const char* type, const std::vector<T>& v, F&& show) {
  std::string s = std::string(type) + "[" + std::to_string(v.size()) + "](";
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + show(v[i]);
  return s + ")";
}
}  // namespace

std::string diffraction_glsl(const Field& f, const std::vector<Band>& bands, const TableGeometry& g,
                             const Window& window, double ior, const Wavelengths& fast) {
  std::vector<double> hi, k0, delta;
  std::vector<int> first, count;
  for (const auto& b : bands) {
    hi.push_back(b.kappa_hi);
    k0.push_back(b.kappa0);
    delta.push_back(b.delta);
    first.push_back(b.first_term);
    count.push_back(b.terms);
  }
  const auto real = [](double v) { return glsl_float(v); };
  const auto integer = [](int v) { return std::to_string(v); };
  const Mat3 m = xyz_to_srgb();
  std::ostringstream o;
  o << "// specbake diffraction BRDF from a baked table (docs/diffraction.md, \"Use it in an engine\").\n"
    << "// GLSL 4.50 core or ES 3.20, without #version: include it after yours (ES: precision highp float\n"
    << "// and highp sampler2DArray).\n"
    << "// Textures:\n"
    << "//   terms: sampler2DArray RG32F (RG16F from half EXRs), " << g.size << " x " << g.size
    << " x (layers = terms): layer n holds F_n from\n"
    << "//     table_terms.bin [n][iv][iu][re, im] or table/F_nnn.exr (R = Re, G = Im); texel (x = iu, y = iv).\n"
    << "//     Filtering LINEAR, wrap CLAMP_TO_EDGE, no mipmaps: the filtered fetch is the bilinear\n"
    << "//     interpolation the bake's between-texel error measures.\n"
    << "//   spectrum: sampler2D RGBA32F, L x 1, from spectrum.bin (lambda nm, D65*xbar, D65*ybar, D65*zbar\n"
    << "//     at 1 nm steps, sum of Y = 1); filtering NEAREST.\n"
    << "// Directions: unit vectors in the surface's tangent frame (x along the heightfield's x, z the\n"
    << "// normal); wi towards the light, wo towards the viewer.\n"
    << "#ifndef SPECBAKE_DIFFRACTION_GLSL\n#define SPECBAKE_DIFFRACTION_GLSL\n\n"
    << glsl_subset_prelude() << "\n"
    << glsl_shared_source("kernels/diffraction/brdf.cl") << "\n"
    << "const float DIFFRACTION_TABLE_SIZE = " << glsl_float(g.size) << ";\n"
    << "const float DIFFRACTION_F_MAX = " << glsl_float(g.f_max) << ";  // cycles/um\n"
    << "const float DIFFRACTION_POWER = " << glsl_float(g.power) << ";\n"
    << "const float DIFFRACTION_SAMPLES = " << glsl_float(static_cast<double>(f.count())) << ";  // W*H\n"
    << "const float DIFFRACTION_CENTER_UM = " << glsl_float(f.c) << ";\n"
    << "const float DIFFRACTION_SCALE_UM = " << glsl_float(f.s) << ";\n"
    << "const float DIFFRACTION_WINDOW_SUM = " << glsl_float(window.sum) << ";\n"
    << "const float DIFFRACTION_SIGMA_UM = " << glsl_float(window.sigma_um) << ";  // the coherence window's sigma\n"
    << "const float DIFFRACTION_IOR = " << glsl_float(ior) << ";\n"
    << "const int DIFFRACTION_EXPANSION = " << expansion_id(bands.front().expansion)
    << ";  // 0 taylor, 1 chebyshev\n"
    << "const int DIFFRACTION_BANDS = " << bands.size() << ";\n"
    << "const float DIFFRACTION_BAND_KAPPA_HI[" << bands.size() << "] = " << array("float", hi, real) << ";\n"
    << "const float DIFFRACTION_BAND_KAPPA0[" << bands.size() << "] = " << array("float", k0, real) << ";\n"
    << "const float DIFFRACTION_BAND_DELTA[" << bands.size() << "] = " << array("float", delta, real) << ";\n"
    << "const int DIFFRACTION_BAND_FIRST[" << bands.size() << "] = " << array("int", first, integer) << ";\n"
    << "const int DIFFRACTION_BAND_TERMS[" << bands.size() << "] = " << array("int", count, integer) << ";\n"
    << "const float DIFFRACTION_PI = 3.14159265358979;\n"
    << "// diffraction_srgb_fast's wavelengths (um) and their CIE XYZ weights (D65 x CMF summed over each bin).\n"
    << "const int DIFFRACTION_FAST_COUNT = " << fast.lambda_um.size() << ";\n"
    << "const float DIFFRACTION_FAST_LAMBDA_UM[" << fast.lambda_um.size() << "] = "
    << array("float", fast.lambda_um, real) << ";\n"
    << "const vec3 DIFFRACTION_FAST_XYZ[" << fast.xyz.size() << "] = "
    << array("vec3", fast.xyz, [](const std::array<double, 3>& v) {
         return "vec3(" + glsl_float(v[0]) + ", " + glsl_float(v[1]) + ", " + glsl_float(v[2]) + ")";
       }) << ";\n"
    << "// CIE XYZ -> linear sRGB (D65 white), column-major.\n"
    << "const mat3 DIFFRACTION_XYZ_TO_SRGB = mat3(" << glsl_float(m[0]) << ", " << glsl_float(m[3]) << ", " << glsl_float(m[6]) << ", "
    << glsl_float(m[1]) << ", " << glsl_float(m[4]) << ", " << glsl_float(m[7]) << ", " << glsl_float(m[2]) << ", " << glsl_float(m[5]) << ", " << glsl_float(m[8])
    << ");\n\n"
    << R"GLSL(// P(f; kappa) / sum(w) as (re, im): the band holding kappa (the first whose upper end is >= kappa),
// its coefficients (taylor: ((kappa - kappa0)*s)^n/n!, chebyshev: T_n((kappa - kappa0)/delta)),
// one filtered fetch per term; 0 beyond the table's reach.
vec2 diffraction_p(sampler2DArray terms, vec2 f, float kappa) {
  if (abs(f.x) > DIFFRACTION_F_MAX || abs(f.y) > DIFFRACTION_F_MAX) return vec2(0.0);
  int b = 0;
  while (b + 1 < DIFFRACTION_BANDS && kappa > DIFFRACTION_BAND_KAPPA_HI[b]) ++b;
  vec2 uv = (vec2(diffraction_texel(f.x, DIFFRACTION_F_MAX, DIFFRACTION_POWER, DIFFRACTION_TABLE_SIZE),
                  diffraction_texel(f.y, DIFFRACTION_F_MAX, DIFFRACTION_POWER, DIFFRACTION_TABLE_SIZE)) + 0.5) /
            DIFFRACTION_TABLE_SIZE;
  float x = expansion_variable(DIFFRACTION_EXPANSION, kappa, DIFFRACTION_BAND_KAPPA0[b], DIFFRACTION_BAND_DELTA[b],
                               DIFFRACTION_SCALE_UM);
  float coef = 1.0, previous = 1.0;
  vec2 sum = vec2(0.0);
  for (int n = 0; n < DIFFRACTION_BAND_TERMS[b]; ++n) {
    if (n > 0) {
      float next = expansion_next(DIFFRACTION_EXPANSION, n, x, coef, previous);
      previous = coef;
      coef = next;
    }
    sum += coef * texture(terms, vec3(uv, float(DIFFRACTION_BAND_FIRST[b] + n))).xy;
  }
  float phase = kappa * DIFFRACTION_CENTER_UM;
  vec2 e = vec2(cos(phase), sin(phase));
  return vec2(e.x * sum.x - e.y * sum.y, e.x * sum.y + e.y * sum.x) * (DIFFRACTION_SAMPLES / DIFFRACTION_WINDOW_SUM);
}

// The relative BRDF rho_lambda(wi, wo) (brdf.cl's header): stam_gain * |P / sum(w)|^2.
float diffraction_brdf(sampler2DArray terms, vec3 wi, vec3 wo, float lambda_um) {
  if (wi.z <= 0.0 || wo.z <= 0.0) return 0.0;
  vec2 p = diffraction_p(terms, -(wi.xy + wo.xy) / lambda_um, 2.0 * DIFFRACTION_PI * (wi.z + wo.z) / lambda_um);
  vec3 h = normalize(wi + wo);
  return stam_gain(wi.z, wo.z, dot(wi, wo), dot(wi, h), DIFFRACTION_IOR) * dot(p, p);
}

// Linear sRGB radiance under a D65 light whose mirror reflection is white (Y = 1): the sum over
// every step_nm-th row of the spectrum texture of rho * D65 * (xbar, ybar, zbar) * step_nm.
vec3 diffraction_srgb(sampler2DArray terms, sampler2D spectrum, vec3 wi, vec3 wo, int step_nm) {
  int count = textureSize(spectrum, 0).x;
  vec3 xyz = vec3(0.0);
  for (int i = 0; i < count; i += step_nm) {
    vec4 s = texelFetch(spectrum, ivec2(i, 0), 0);
    xyz += diffraction_brdf(terms, wi, wo, s.x * 1e-3) * s.yzw * float(step_nm);
  }
  return DIFFRACTION_XYZ_TO_SRGB * xyz;
}

// The fast variant: DIFFRACTION_FAST_COUNT wavelengths, each standing for an equal share of the
// range with its bin's summed weights (no spectrum texture). Its error against diffraction_srgb is
// the manifest's shader_fast_vs_full record (the grating orders become that many coloured copies).
vec3 diffraction_srgb_fast(sampler2DArray terms, vec3 wi, vec3 wo) {
  vec3 xyz = vec3(0.0);
  for (int k = 0; k < DIFFRACTION_FAST_COUNT; ++k)
    xyz += diffraction_brdf(terms, wi, wo, DIFFRACTION_FAST_LAMBDA_UM[k]) * DIFFRACTION_FAST_XYZ[k];
  return DIFFRACTION_XYZ_TO_SRGB * xyz;
}

// The fast variant with the specular peak evaluated apart (the thesis's fast shader): P = chi*W(f)
// + P_r, chi(kappa) = P(0; kappa)/sum(w) the mean of e^{i kappa h}, so the peak is
// gain*|chi|^2*specular_peak (brdf.cl): the diffracted remainder gain*|P|^2 - that is summed over
// the DIFFRACTION_FAST_COUNT wavelengths, the peak over every step_nm-th row of the spectrum with
// |chi|^2 interpolated linearly in lambda between the fast wavelengths. Twice the fast variant's
// fetches (P and chi per fast wavelength); its error against diffraction_srgb is the manifest's
// shader_fast_specular_vs_full record.
vec3 diffraction_srgb_fast_specular(sampler2DArray terms, sampler2D spectrum, vec3 wi, vec3 wo, int step_nm) {
  if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
  vec3 h = normalize(wi + wo);
  float gain = stam_gain(wi.z, wo.z, dot(wi, wo), dot(wi, h), DIFFRACTION_IOR);
  vec2 d = -(wi.xy + wo.xy);
  float chi2[DIFFRACTION_FAST_COUNT];
  vec3 xyz = vec3(0.0);
  for (int k = 0; k < DIFFRACTION_FAST_COUNT; ++k) {
    float lambda = DIFFRACTION_FAST_LAMBDA_UM[k];
    vec2 chi = diffraction_p(terms, vec2(0.0), 2.0 * DIFFRACTION_PI * (wi.z + wo.z) / lambda);
    chi2[k] = dot(chi, chi);
    float peak = abs(d.x / lambda) > DIFFRACTION_F_MAX || abs(d.y / lambda) > DIFFRACTION_F_MAX
                     ? 0.0 : specular_peak(dot(d, d), lambda, DIFFRACTION_SIGMA_UM);
    xyz += (diffraction_brdf(terms, wi, wo, lambda) - gain * chi2[k] * peak) * DIFFRACTION_FAST_XYZ[k];
  }
  int count = textureSize(spectrum, 0).x;
  int k = 0;
  for (int i = 0; i < count; i += step_nm) {
    vec4 s = texelFetch(spectrum, ivec2(i, 0), 0);
    float lambda = s.x * 1e-3;
    while (k + 2 < DIFFRACTION_FAST_COUNT && lambda > DIFFRACTION_FAST_LAMBDA_UM[k + 1]) ++k;
    float w = lerp_weight(lambda, DIFFRACTION_FAST_LAMBDA_UM[k], DIFFRACTION_FAST_LAMBDA_UM[k + 1]);
    float peak = abs(d.x / lambda) > DIFFRACTION_F_MAX || abs(d.y / lambda) > DIFFRACTION_F_MAX
                     ? 0.0 : specular_peak(dot(d, d), lambda, DIFFRACTION_SIGMA_UM);
    xyz += gain * (chi2[k] * (1.0 - w) + chi2[k + 1] * w) * peak * s.yzw * float(step_nm);
  }
  return DIFFRACTION_XYZ_TO_SRGB * xyz;
}

)GLSL" << glsl_subset_epilogue() << "#endif  // SPECBAKE_DIFFRACTION_GLSL\n";
  return o.str();
}

}  // namespace specbake::diffraction
