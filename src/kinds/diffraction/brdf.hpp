#pragma once
// The diffraction BRDF a shader evaluates from a table, and the previews drawn with it.
//
// Stam's BRDF (Stam 1999, "Diffraction shaders") in the relative form of the diffraction thesis
// (seeds/003, eqs. 19–20: reflected radiance over that of a flat mirror's specular reflection):
//   ρ_λ(ω_i, ω_o) = C(ω_i, ω_o)·|P(f; κ) / Σ_j w_j|²,
//   C = R(ω_i·h)·(1 + ω_i·ω_o)² / (R(1)·(cos θ_i + cos θ_o)²·cos θ_o),
// with ω_i (towards the light) and ω_o (towards the viewer) in the surface's tangent frame
// (x along the field's x axis, z the normal), h = normalize(ω_i + ω_o), R the unpolarised Fresnel
// reflectance of a dielectric of index n (Stam's F², here divided by its value at normal
// incidence), (u, v, w) = −(ω_i + ω_o) (Stam's k̂₁ − k̂₂), the table looked up at
// f = (u, v)/λ cycles/µm and κ = 2π·(cos θ_i + cos θ_o)/λ. |P/Σw|² = 1 for a flat mirror at
// f = 0, so ρ = 1 there: a mirror reflects the light source's spectrum unchanged. The table is
// fetched bilinearly (a shader's filtered fetch); beyond f_max it reads 0.
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "kinds/diffraction/table.hpp"
#include "kinds/diffraction/terms.hpp"

namespace specbake::diffraction {

struct BrdfTable {
  const Field& f;
  const std::vector<Band>& bands;
  const TableGeometry& g;
  const std::vector<float>& terms;  // [T][N][N][2]
  double window_sum = 1.0;           // Σ w_j
  double ior = 1.5;                  // Fresnel: dielectric index
  double sigma_um = 0.0;             // the coherence window's σ (the specular peak's width)
};

// ρ_λ for unit vectors in the tangent frame (0 below the horizon on either side).
double brdf(const BrdfTable& t, const std::array<double, 3>& wi, const std::array<double, 3>& wo, double lambda_um);

// The wavelengths a spectral sum visits and each one's weight (D65·x̄ȳz̄ times the wavelengths
// it stands for, CIE XYZ). `spectrum`: rows λ nm, D65·x̄, D65·ȳ, D65·z̄ at 1 nm (spectrum.bin).
struct Wavelengths {
  std::vector<double> lambda_um;
  std::vector<std::array<double, 3>> xyz;
};
// Every step_nm-th row, weight row·step_nm (the previews and diffraction_srgb: 10 nm).
Wavelengths every_nm(const std::vector<double>& spectrum, int step_nm);
// `count` equal bins of the rows: the weight is the bin's sum, the wavelength its Y-weighted
// centre (diffraction_srgb_fast: the fast variant's few wavelengths).
Wavelengths bins(const std::vector<double>& spectrum, int count);

// The fast variant with the specular peak evaluated apart (diffraction_srgb_fast_specular;
// the thesis's fast shader, seeds/003 § 3: "treats specular separately"). P = χ(κ)·Ŵ(f) + P_r:
// χ(κ) = P(0; κ)/Σw is the window-weighted mean of e^{iκh} (the coherent, mirror-like part) and
// Ŵ(f)/Σw ≈ exp(−2π²σ²|f|²) the Gaussian window's transform, so the specular peak is
// C·|χ(κ)|²·G(f), G = exp(−4π²σ²|f|²): analytic in f, smooth in κ. The diffracted remainder
// C·(|P|² − |χ|²G) is summed over the few wavelengths `few` (as diffraction_srgb_fast); the
// peak over every wavelength of `all` (as diffraction_srgb), with |χ|² interpolated linearly in
// λ between its values at `few` (clamped at the ends). CIE XYZ of one pair of directions.
std::array<double, 3> xyz_fast_specular(const BrdfTable& t, const std::array<double, 3>& wi,
                                        const std::array<double, 3>& wo, const Wavelengths& few, const Wavelengths& all);

// Linear sRGB images (row-major, 3 floats per pixel, 0 outside the lit pixels) of the radiance
// ρ·D65 summed over the wavelengths, from one table:
//  - lobes: for each light angle (degrees from the normal, in the x–z plane), the outgoing
//    hemisphere seen from above (pixel (x, y) ↦ ω_o = (x, y, √(1 − x² − y²))), panels side by side;
//  - lobes_fast_specular: the same picture through xyz_fast_specular;
//  - sphere: a unit sphere seen along −z (orthographic), tangent x along the lines of latitude
//    around the view axis, lit by a point light at `light` (sphere radii) of D65 spectrum.
// Each lit pixel's CIE XYZ is table.cl's table_xyz / table_xyz_fast_specular: on `dev` when given
// (diffraction_brdf_xyz, one work item per pixel, the table uploaded once; what a bake draws), else
// on the host's threads in double (the reference the tests compare with).
class BrdfPictures {
 public:
  explicit BrdfPictures(const BrdfTable& t, cl_util::Device* dev = nullptr);
  std::vector<float> lobes(const Wavelengths& wl, const std::vector<double>& light_deg, int panel) const;
  std::vector<float> lobes_fast_specular(const Wavelengths& few, const Wavelengths& all,
                                         const std::vector<double>& light_deg, int panel) const;
  std::vector<float> sphere(const Wavelengths& wl, const std::array<double, 3>& light, int size) const;
  bool on_device() const;

 private:
  // CIE XYZ of each pair of directions (six reals each): table_xyz over `wl`, or with `few`
  // table_xyz_fast_specular over few and wl.
  std::vector<double> shade(const std::vector<double>& dirs, const Wavelengths& wl, const Wavelengths* few) const;
  struct OnDevice;
  const BrdfTable& t_;
  std::shared_ptr<OnDevice> device_;
};

// The specular peak's shape G (specular_peak, brdf.cl) at `lambda_um` over the lobes picture's
// pixels (in all three channels): where the peak lies.
std::vector<float> brdf_lobes_specular_peak(const BrdfTable& t, const std::vector<double>& light_deg, int panel,
                                            double lambda_um);

}  // namespace specbake::diffraction
