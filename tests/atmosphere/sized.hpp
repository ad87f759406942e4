#pragma once
// A spec with the given texture sizes, for tests that bake at their own (small or odd) sizes.
#include <array>

#include "kinds/atmosphere/model/spec.hpp"

namespace specbake::testing {

// s with transmittance {mu, r}, irradiance {mu_s, r} and scattering {r, mu, mu_s, nu}.
inline AtmosphereSpec sized(AtmosphereSpec s, std::array<int, 2> transmittance, std::array<int, 2> irradiance,
                            std::array<int, 4> scattering) {
  s.transmittance_mu = transmittance[0];
  s.transmittance_r = transmittance[1];
  s.irradiance_mu_s = irradiance[0];
  s.irradiance_r = irradiance[1];
  s.scattering_r = scattering[0];
  s.scattering_mu = scattering[1];
  s.scattering_mu_s = scattering[2];
  s.scattering_nu = scattering[3];
  return s;
}

}  // namespace specbake::testing
