#pragma once
// The OpenCL device every benchmark runs on: `--device auto`'s choice, built once per process.
#include "cl/device.hpp"

namespace specbake::bench {
inline cl_util::Device& device() {
  static cl_util::Device d(cl_util::select_device("auto"));
  return d;
}
}  // namespace specbake::bench
