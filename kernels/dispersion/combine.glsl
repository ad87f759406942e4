/* combine.glsl — the final colour of a spectral render from its per-sample colours
 * (docs/dispersion.md, "Use it in an engine"):
 *   rgb = Σ_n K_n · rgb_n     linear sRGB; K_n = M_XYZ→sRGB · Diag(Ŵ_n) · M_sRGB→XYZ, Σ_n K_n = I
 * rgb_n is what the renderer produced with sample n's wavelength (its IOR, its light), as a
 * linear sRGB colour of a white spectrum; per-sample colours leave the gamut (negative
 * components), so they are summed unclamped.
 *
 * Written once in the common subset of GLSL and C++ (GLM): the bundle's dispersion.glsl carries
 * it verbatim after its SPECBAKE_SAMPLES and SPECBAKE_K constants (the matrices as mat3, column
 * major), and the host compiles the same text over the bundle's matrices
 * (src/kinds/dispersion/combine.hpp) for the prism preview and the GL test's reference.
 * TEXEL_RGB(renders, texel, n) is texelFetch(renders, ivec3(texel, n), 0).rgb in GLSL.
 */
vec3 specbake_dispersion_combine(sampler2DArray renders, ivec2 texel) {
  vec3 sum = vec3(0.0);
  for (int n = 0; n < SPECBAKE_SAMPLES; ++n) sum += SPECBAKE_K[n] * TEXEL_RGB(renders, texel, n);
  return sum;
}
