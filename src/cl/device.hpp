#pragma once
// OpenCL device selection, program building and error mapping.
// Build logs and OpenCL error codes surface as DeviceError with names, logged via spdlog.
#include <CL/opencl.hpp>

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "cl/timing.hpp"
#include "core/errors.hpp"

namespace specbake::cl_util {

struct DeviceInfo {
  int platform_index = 0;
  int device_index = 0;
  std::string platform;
  std::string name;
  std::string version;
  std::string type;  // cpu | gpu | accelerator | other
  bool fp64 = false;
  // CL_FP_CORRECTLY_ROUNDED_DIVIDE_SQRT in CL_DEVICE_SINGLE_FP_CONFIG: programs are built with
  // -cl-fp32-correctly-rounded-divide-sqrt there (Device::build)
  bool fp32_correct_divide_sqrt = false;
  unsigned long long global_mem_bytes = 0;
  unsigned long long max_alloc_bytes = 0;
  unsigned long long local_mem_bytes = 0;  // CL_DEVICE_LOCAL_MEM_SIZE
  std::size_t max_work_group_size = 0;     // CL_DEVICE_MAX_WORK_GROUP_SIZE
  unsigned compute_units = 0;
};

// The options every program is built with on this device, before its own: the OpenCL C version
// and, where the device reports CL_FP_CORRECTLY_ROUNDED_DIVIDE_SQRT, correctly rounded float32
// division and square root (OpenCL allows 2.5 and 3 ulp otherwise). Part of a bundle's identity:
// the bytes depend on them.
std::string common_build_options(const DeviceInfo& info);

// Name of an OpenCL status code, e.g. -11 -> "CL_BUILD_PROGRAM_FAILURE".
const char* error_name(int code);

std::vector<DeviceInfo> list_devices();  // empty when no platform is installed

// Picks a device: "auto" (first CPU device, else first device), "cpu", "gpu",
// or a case-insensitive substring of the device or platform name.
// Throws DeviceError naming the selector and the devices seen.
DeviceInfo select_device(const std::string& selector);

class Device {
 public:
  explicit Device(const DeviceInfo& info);
  const DeviceInfo& info() const { return info_; }
  cl::Context& context() { return context_; }
  cl::CommandQueue& queue() { return queue_; }  // in order, with CL_QUEUE_PROFILING_ENABLE
  // Device and host seconds of the stages that callers open (cl/timing.hpp); every command
  // enqueued through the helpers of this layer is recorded here.
  Profiler& profiler() { return profiler_; }
  // Builds the embedded kernel file (includes resolved), once per (path, options); the
  // build log goes to spdlog, and a failed build throws DeviceError carrying the log.
  cl::Program build(const std::string& kernel_path, const std::string& options = "");
  // The same for OpenCL source text named `name` (in logs and errors): the options every
  // program gets (the OpenCL version, correctly rounded float32 division and square root where
  // the device has them), then `options`.
  cl::Program build_source(const std::string& name, const std::string& source, const std::string& options = "");
  // Options selecting `real` = double where the device has cl_khr_fp64.
  std::string real_options() const { return info_.fp64 ? "-DSPECBAKE_REAL_DOUBLE" : ""; }
  // "Device name (Platform, OpenCL x.y)"
  std::string description() const;
  // An object built for this device that later jobs of the same process reuse (FFT plans),
  // made by make() (returning std::unique_ptr<T>) on first use of `key`; it lives as long as
  // the device. Not for concurrent use: jobs run one after another.
  template <class T, class Make>
  T& reusable(const std::string& key, Make&& make) {
    std::shared_ptr<void>& slot = reusable_[key];
    if (!slot) slot = std::shared_ptr<T>(make());
    return *static_cast<T*>(slot.get());
  }

 private:
  DeviceInfo info_;
  cl::Device device_;
  cl::Context context_;
  cl::CommandQueue queue_;
  std::map<std::string, cl::Program> programs_;
  Profiler profiler_;
  std::map<std::string, std::shared_ptr<void>> reusable_;  // declared last: released before the context
};

// Runs f, turning cl::Error into DeviceError("<what>: CL_NAME (code)").
template <class F>
auto checked(const char* what, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const cl::Error& e) {
    throw DeviceError(std::string(what) + ": " + e.what() + " returned " + error_name(e.err()) + " (" +
                      std::to_string(e.err()) + ")");
  }
}

}  // namespace specbake::cl_util
