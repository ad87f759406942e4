#pragma once
// The GLSL a renderer evaluates a diffraction table with (the bundle's
// shader/diffraction_brdf.glsl): the table's constants, the shared maths of
// kernels/diffraction/brdf.cl pasted after a GLSL prelude (one source with the host's
// reference), and the lookup and spectral-sum functions (docs/diffraction.md, "Use it in an engine").
#include <string>
#include <vector>

#include "kinds/diffraction/brdf.hpp"
#include "kinds/diffraction/planning.hpp"
#include "kinds/diffraction/table.hpp"

namespace specbake::diffraction {

// `fast`: the wavelengths and XYZ weights of diffraction_srgb_fast (and of the diffracted part of
// diffraction_srgb_fast_specular); `window`: the coherence window (Σw, σ).
std::string diffraction_glsl(const Field& f, const std::vector<Band>& bands, const TableGeometry& g,
                             const Window& window, double ior, const Wavelengths& fast);

}  // namespace specbake::diffraction
