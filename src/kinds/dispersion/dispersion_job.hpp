#pragma once
// The dispersion job (SPECGEN and beyond): spectral integration matrices K_n, normalised
// CMF weights, IOR offsets and indices for N sample wavelengths; `samples: auto` picks N
// from a thin-prism colour-error test. Maths: kernels/dispersion/dispersion.cl.
#include <array>
#include <optional>
#include <vector>

#include "kinds/dispersion/sampling.hpp"
#include "job/kind.hpp"

namespace specbake::dispersion {

// The OpenCL program of the dispersion kernels (embedded path).
inline constexpr const char* kProgram = "kernels/dispersion/kernels.cl";

struct Lines {
  double ref_nm, F_nm, C_nm;
};
Lines lines_for(AbbeLines lines);

// The material as the bake uses it: the shader's Cauchy/Abbe pair (n_ref, V) on the chosen
// lines, and the Sellmeier fit when one is known (then ior.bin comes from it).
struct MaterialModel {
  double n_ref = 0.0, v = 0.0;
  std::optional<Sellmeier> sellmeier;
};
MaterialModel resolve_material(const Material& m, Lines lines);

struct Tables {
  Samples samples;
  std::vector<double> w_raw, w_norm, K, offset, ior;  // [N,3], [N,3], [N,3,3], [N], [N]
  std::array<double, 3> w_raw_sum{};
};

Tables compute_device(cl_util::Device& dev, const DispersionSpec& spec, const Samples& s, const MaterialModel& m);
Tables compute_reference(const DispersionSpec& spec, const Samples& s, const MaterialModel& m);

// The thin-prism picture behind `samples: auto` (see dispersion.cl, prism_pixel).
struct PrismGeometry {
  double x0 = 0.0, dx = 0.0;
  int pixels = 0;
  double lit_y = 1e-3;            // pixels whose reference luminance (white = 1) is at most this are unlit
  static constexpr int kPixelsPerBeam = 32;
  static constexpr double kDenseStepNm = 0.1;
};
PrismGeometry prism_geometry(const DispersionSpec& spec);
Samples dense_samples(const DispersionSpec& spec);

// Mean CIEDE2000 over lit pixels between the picture of `t` and the dense spectrum's.
class PrismJudge {
 public:
  PrismJudge(cl_util::Device& dev, const DispersionSpec& spec);
  double mean_delta_e(const Tables& t);
  const PrismGeometry& geometry() const { return geo_; }

 private:
  cl::Buffer render(const Tables& t);  // XYZ [pixels, 3] of the picture of t
  cl_util::Device& dev_;
  DispersionSpec spec_;
  PrismGeometry geo_;
  cl::Buffer ref_xyz_;
};
// The same figure from the double reference path, on the host (for tests).
double prism_mean_delta_e_reference(const DispersionSpec& spec, const Tables& t);

struct AutoChoice {
  int samples = 0;
  double delta_e = 0.0;
  std::vector<std::pair<int, double>> tried;  // (N, mean ΔE2000)
};
// Smallest N meeting spec.tolerance_de2000: doubles N until the tolerance is met, then scans
// the last octave upward. Throws JobError if N = kMaxSamples does not meet it.
AutoChoice choose_samples(cl_util::Device& dev, const DispersionSpec& spec, const Progress& progress);

nlohmann::json plan(const DispersionSpec& spec, JobContext& ctx);
BakeResult bake(const DispersionSpec& spec, JobContext& ctx);

}  // namespace specbake::dispersion
