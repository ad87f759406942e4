#pragma once
// The atmosphere tests' comparison of two R,G,B textures (or value lists, channel innermost).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace specbake::testing {

// max over values of |a − b| / (|b| + floor · max |b| of its channel), over 3 channels.
inline double max_rel(const std::vector<double>& a, const std::vector<double>& b, double floor) {
  EXPECT_EQ(a.size(), b.size());
  double mx[3] = {0, 0, 0};
  for (std::size_t i = 0; i < b.size(); ++i) mx[i % 3] = std::max(mx[i % 3], std::fabs(b[i]));
  double e = 0.0;
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    e = std::max(e, std::fabs(a[i] - b[i]) / (std::fabs(b[i]) + floor * mx[i % 3] + 1e-300));
  return e;
}

}  // namespace specbake::testing
