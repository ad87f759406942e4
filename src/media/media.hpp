#pragma once
// Participating media of a planetary atmosphere, shared by every kind that models one:
// Rayleigh scattering, Mie scattering/absorption and an absorbing (ozone-like) layer, each with
// a Bruneton 2017 density profile, plus their config syntax and canonical JSON. Units: km for
// altitudes, m⁻¹ for coefficients (at 1 µm; λ-scaling in the kernels), Dobson units for columns.
#include <nlohmann/json.hpp>

#include "core/yaml_at.hpp"

namespace specbake {

// One layer of a Bruneton density profile: exp_term·exp(exp_scale·h) + linear_term·h + constant_term,
// clamped to [0, 1]; h = altitude in km; layer 0 applies below its width.
struct DensityLayer {
  double width_km = 0.0, exp_term = 0.0, exp_scale_per_km = 0.0, linear_term_per_km = 0.0, constant_term = 0.0;
};
// A two-layer profile as the config's `density:` list writes it (also used in manifests, so a
// manifest's profile can be pasted back into a config).
nlohmann::json density_profile_json(const DensityLayer* layers);
DensityLayer exponential_layer(double scale_height_km);
// Ozone-like tent: 0 below a, rising to 1 at b, back to 0 at c (km).
void tent_layers(double a, double b, double c, DensityLayer* out);

struct AtmosphereMedia {
  bool rayleigh = true;
  double rayleigh_scattering_per_m_at_1um = 1.24062e-6;  // beta(l) = b * l_um^-4
  DensityLayer rayleigh_density[2]{};
  bool mie = true;
  double mie_extinction_per_m = 4.44e-6;  // at 1 um; beta_e(l) = e * l_um^-alpha
  double mie_angstrom_alpha = 0.0, mie_single_scattering_albedo = 0.9, mie_phase_g = 0.8;
  DensityLayer mie_density[2]{};
  bool ozone = true;
  double ozone_column_du = 300.0;
  DensityLayer ozone_density[2]{};  // shape only; scaled so its column is ozone_column_du
};

// Bruneton's demo Earth profiles: Rayleigh 8 km and Mie 1.2 km scale heights, ozone tent 10-25-40 km.
void set_earth_profiles(AtmosphereMedia& m);

// Config syntax of the three constituents: a mapping of overrides, or `false` to leave it out.
void parse_rayleigh(const yaml::At& at, AtmosphereMedia& m);
void parse_mie(const yaml::At& at, AtmosphereMedia& m);
void parse_ozone(const yaml::At& at, AtmosphereMedia& m);
// Canonical JSON of the three (keys "rayleigh", "mie", "ozone"), merged into a job's normalised config.
nlohmann::json media_json(const AtmosphereMedia& m);

}  // namespace specbake
