#pragma once
// The double-precision reference of the atmosphere maths: kernels/atmosphere/atmosphere.cl
// compiled as C++ with real = double and 3 channels (ref3: R, G, B), followed by the host
// backend and helpers of host_pass.inc. The other pass widths are in reference_widths.hpp.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <cstddef>
#include <cstring>
#include <memory>
#include <thread>
#include <utility>
#include <vector>

#include "core/parallel.hpp"
#include "kinds/atmosphere/pass.hpp"
#include "kinds/atmosphere/texel_reads.hpp"

namespace specbake::atmosphere {


// A texture of the double reference: sized without writing its values (default-initialised
// elements), so that a self-check's copy of a device texture, the size of the whole texture for
// the lookups' arithmetic, takes memory only where the check has put the texels it fetched.
template <class T>
struct UninitialisedAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = UninitialisedAllocator<U>;
  };
  UninitialisedAllocator() = default;
  template <class U>
  UninitialisedAllocator(const UninitialisedAllocator<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... A>
  void construct(U* p, A&&... a) {
    ::new (static_cast<void*>(p)) U(std::forward<A>(a)...);
  }
};
using HostTexture = std::vector<double, UninitialisedAllocator<double>>;

#define SPECBAKE_ATMOSPHERE_REF_PROLOGUE                                                                    \
  using real = double;                                                                                    \
  using std::cos, std::exp, std::floor, std::fmax, std::fmin, std::sin, std::sqrt;

namespace ref3 {
SPECBAKE_ATMOSPHERE_REF_PROLOGUE
#define NCH 3
#include "atmosphere/atmosphere.cl"
#include "kinds/atmosphere/host_pass.inc"
#undef NCH
}  // namespace ref3

}  // namespace specbake::atmosphere
