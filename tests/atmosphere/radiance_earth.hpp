#pragma once
// The spectral-radiance tests' bake: Bruneton's demo Earth with `spectrum: {min_nm: 400,
// max_nm: 700, count: 8, store: radiance}` (two wavelength sets) and 2 orders, at small sizes.
#include <array>

#include "kinds/atmosphere/spec.hpp"

namespace specbake::testing {

// transmittance [mu, r], irradiance [mu_s, r], scattering {r, mu, mu_s, nu}
inline AtmosphereSpec radiance_earth(std::array<int, 2> transmittance, std::array<int, 2> irradiance,
                                     std::array<int, 4> scattering) {
  AtmosphereSpec s;
  set_earth_profiles(s);
  s.transmittance_mu = transmittance[0];
  s.transmittance_r = transmittance[1];
  s.irradiance_mu_s = irradiance[0];
  s.irradiance_r = irradiance[1];
  s.scattering_r = scattering[0];
  s.scattering_mu = scattering[1];
  s.scattering_mu_s = scattering[2];
  s.scattering_nu = scattering[3];
  s.orders = 2;
  s.spectral = s.store_radiance = true;
  s.min_nm = 400.0;
  s.max_nm = 700.0;
  s.count = 8;
  return s;
}

}  // namespace specbake::testing
