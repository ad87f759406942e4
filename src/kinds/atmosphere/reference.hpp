#pragma once
// The double-precision reference of the atmosphere maths: kernels/atmosphere/atmosphere.cl
// compiled as C++ with real = double and 3 channels (ref3: R, G, B), followed by the host
// backend and helpers of host_pass.inc. The other pass widths are in reference_widths.hpp.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <thread>
#include <vector>

#include "kinds/atmosphere/pass.hpp"

namespace specbake::atmosphere {

// Runs f(i) for i in [0, n) on the hardware threads.
template <class F>
void parallel_for(long long n, F&& f) {
  const long long threads = std::max(1u, std::min(8u, std::thread::hardware_concurrency()));
  if (n < 64 || threads == 1) {
    for (long long i = 0; i < n; ++i) f(i);
    return;
  }
  std::vector<std::thread> pool;
  for (long long t = 0; t < threads; ++t)
    pool.emplace_back([&, t] {
      for (long long i = t; i < n; i += threads) f(i);
    });
  for (auto& th : pool) th.join();
}

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
