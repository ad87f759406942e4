#pragma once
// The kernels' maths on the host: a namespace opens with SPECBAKE_ATMOSPHERE_REF_PROLOGUE, defines
// NCH and includes kernels/atmosphere/atmosphere.cl, which then compiles as C++ with real = double
// (the double reference of bake/reference.hpp; the model's profile integrals in model.cpp).
#include <cmath>

#include "media/media.hpp"

#define SPECBAKE_ATMOSPHERE_REF_PROLOGUE                                                                    \
  using real = double;                                                                                    \
  using std::cos, std::exp, std::floor, std::fmax, std::fmin, std::sin, std::sqrt;

namespace specbake::atmosphere {

// atmosphere.cl's DensityProfile (of any such namespace) from a config's two layers.
template <class DensityProfile>
void fill_profile(DensityProfile& p, const DensityLayer* layers) {
  for (int i = 0; i < 2; ++i) {
    p.width[i] = layers[i].width_km;
    p.exp_term[i] = layers[i].exp_term;
    p.exp_scale[i] = layers[i].exp_scale_per_km;
    p.linear_term[i] = layers[i].linear_term_per_km;
    p.constant_term[i] = layers[i].constant_term;
  }
}

}  // namespace specbake::atmosphere
