#pragma once
// Moving `real` arrays between the host (always double) and a device whose kernels were
// built with real = float or real = double (Device::real_options()).
#include <CL/opencl.hpp>

#include <vector>

#include "cl/device.hpp"

namespace specbake::cl_util {

cl::Buffer upload_real(Device& dev, const std::vector<double>& values);
// The same for kernels whose real is double exactly when as_double (a program built in float on
// a device with fp64, or in double by choice).
cl::Buffer upload_real(Device& dev, const std::vector<double>& values, bool as_double);
cl::Buffer device_real(Device& dev, std::size_t count);  // uninitialised, read-write
std::vector<double> download_real(Device& dev, const cl::Buffer& buf, std::size_t count);
void set_real_arg(Device& dev, cl::Kernel& k, cl_uint index, double value);
// Enqueue + finish; the command and the wait are recorded in dev.profiler(), as are the reads.
// local: the work-group size (0: the driver chooses).
void run_1d(Device& dev, cl::Kernel& k, std::size_t count, std::size_t local = 0);

}  // namespace specbake::cl_util
