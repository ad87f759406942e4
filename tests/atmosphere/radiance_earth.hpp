#pragma once
// The spectral-radiance tests' bake: Bruneton's demo Earth with `spectrum: {min_nm: 400,
// max_nm: 700, count: 8, store: radiance}` (two wavelength sets) and 2 orders, at small sizes.
#include <array>

#include "atmosphere/sized.hpp"
#include "kinds/atmosphere/model/spec.hpp"

namespace specbake::testing {

// transmittance [mu, r], irradiance [mu_s, r], scattering {r, mu, mu_s, nu}
inline AtmosphereSpec radiance_earth(std::array<int, 2> transmittance, std::array<int, 2> irradiance,
                                     std::array<int, 4> scattering) {
  AtmosphereSpec s;
  set_earth_profiles(s);
  s = sized(s, transmittance, irradiance, scattering);
  s.orders = 2;
  s.spectral = s.store_radiance = true;
  s.min_nm = 400.0;
  s.max_nm = 700.0;
  s.count = 8;
  return s;
}

}  // namespace specbake::testing
