#pragma once
// The double-precision reference of the atmosphere maths: kernels/atmosphere/atmosphere.cl
// compiled as C++ with real = double and 3 channels (ref3: R, G, B), followed by the host
// backend and helpers of host_pass.inc. The other pass widths are in reference_widths.hpp.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <new>
#include <memory>
#include <thread>
#include <utility>
#include <vector>

#include "core/parallel.hpp"
#include "kinds/atmosphere/bake/pass.hpp"
#include "kinds/atmosphere/bake/texel_reads.hpp"
#include "kinds/atmosphere/model/kernel_maths.hpp"

namespace specbake::atmosphere {


// A texture of the double reference: its storage from calloc, which hands large blocks over as
// the kernel's zero pages without writing them, and elements created without a write
// (default-initialised), so that a self-check's copy of a device texture, the size of the whole
// texture for the lookups' arithmetic, takes memory only where the check puts the texels it
// fetched, and reads 0 elsewhere.
template <class T>
struct LazyZeroAllocator {
  using value_type = T;
  LazyZeroAllocator() = default;
  template <class U>
  LazyZeroAllocator(const LazyZeroAllocator<U>&) noexcept {}
  T* allocate(std::size_t n) {
    if (void* p = std::calloc(n, sizeof(T))) return static_cast<T*>(p);
    throw std::bad_alloc();
  }
  void deallocate(T* p, std::size_t) noexcept { std::free(p); }
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... A>
  void construct(U* p, A&&... a) {
    ::new (static_cast<void*>(p)) U(std::forward<A>(a)...);
  }
  template <class U>
  bool operator==(const LazyZeroAllocator<U>&) const noexcept {
    return true;
  }
  template <class U>
  bool operator!=(const LazyZeroAllocator<U>&) const noexcept {
    return false;
  }
};
using HostTexture = std::vector<double, LazyZeroAllocator<double>>;

namespace ref3 {
SPECBAKE_ATMOSPHERE_REF_PROLOGUE
#define NCH 3
#include "atmosphere/atmosphere.cl"
#include "kinds/atmosphere/bake/host_pass.inc"
#undef NCH
}  // namespace ref3

}  // namespace specbake::atmosphere
