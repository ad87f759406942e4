#include "cl/device.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cctype>
#include <cstdlib>

#include "core/resources.hpp"

namespace specbake::cl_util {

const char* error_name(int code) {
  switch (code) {
#define SPECBAKE_CL_CASE(x) case x: return #x;
    SPECBAKE_CL_CASE(CL_SUCCESS)
    SPECBAKE_CL_CASE(CL_DEVICE_NOT_FOUND)
    SPECBAKE_CL_CASE(CL_DEVICE_NOT_AVAILABLE)
    SPECBAKE_CL_CASE(CL_COMPILER_NOT_AVAILABLE)
    SPECBAKE_CL_CASE(CL_MEM_OBJECT_ALLOCATION_FAILURE)
    SPECBAKE_CL_CASE(CL_OUT_OF_RESOURCES)
    SPECBAKE_CL_CASE(CL_OUT_OF_HOST_MEMORY)
    SPECBAKE_CL_CASE(CL_PROFILING_INFO_NOT_AVAILABLE)
    SPECBAKE_CL_CASE(CL_MEM_COPY_OVERLAP)
    SPECBAKE_CL_CASE(CL_IMAGE_FORMAT_MISMATCH)
    SPECBAKE_CL_CASE(CL_IMAGE_FORMAT_NOT_SUPPORTED)
    SPECBAKE_CL_CASE(CL_BUILD_PROGRAM_FAILURE)
    SPECBAKE_CL_CASE(CL_MAP_FAILURE)
    SPECBAKE_CL_CASE(CL_MISALIGNED_SUB_BUFFER_OFFSET)
    SPECBAKE_CL_CASE(CL_EXEC_STATUS_ERROR_FOR_EVENTS_IN_WAIT_LIST)
    SPECBAKE_CL_CASE(CL_COMPILE_PROGRAM_FAILURE)
    SPECBAKE_CL_CASE(CL_LINKER_NOT_AVAILABLE)
    SPECBAKE_CL_CASE(CL_LINK_PROGRAM_FAILURE)
    SPECBAKE_CL_CASE(CL_DEVICE_PARTITION_FAILED)
    SPECBAKE_CL_CASE(CL_KERNEL_ARG_INFO_NOT_AVAILABLE)
    SPECBAKE_CL_CASE(CL_INVALID_VALUE)
    SPECBAKE_CL_CASE(CL_INVALID_DEVICE_TYPE)
    SPECBAKE_CL_CASE(CL_INVALID_PLATFORM)
    SPECBAKE_CL_CASE(CL_INVALID_DEVICE)
    SPECBAKE_CL_CASE(CL_INVALID_CONTEXT)
    SPECBAKE_CL_CASE(CL_INVALID_QUEUE_PROPERTIES)
    SPECBAKE_CL_CASE(CL_INVALID_COMMAND_QUEUE)
    SPECBAKE_CL_CASE(CL_INVALID_HOST_PTR)
    SPECBAKE_CL_CASE(CL_INVALID_MEM_OBJECT)
    SPECBAKE_CL_CASE(CL_INVALID_IMAGE_FORMAT_DESCRIPTOR)
    SPECBAKE_CL_CASE(CL_INVALID_IMAGE_SIZE)
    SPECBAKE_CL_CASE(CL_INVALID_SAMPLER)
    SPECBAKE_CL_CASE(CL_INVALID_BINARY)
    SPECBAKE_CL_CASE(CL_INVALID_BUILD_OPTIONS)
    SPECBAKE_CL_CASE(CL_INVALID_PROGRAM)
    SPECBAKE_CL_CASE(CL_INVALID_PROGRAM_EXECUTABLE)
    SPECBAKE_CL_CASE(CL_INVALID_KERNEL_NAME)
    SPECBAKE_CL_CASE(CL_INVALID_KERNEL_DEFINITION)
    SPECBAKE_CL_CASE(CL_INVALID_KERNEL)
    SPECBAKE_CL_CASE(CL_INVALID_ARG_INDEX)
    SPECBAKE_CL_CASE(CL_INVALID_ARG_VALUE)
    SPECBAKE_CL_CASE(CL_INVALID_ARG_SIZE)
    SPECBAKE_CL_CASE(CL_INVALID_KERNEL_ARGS)
    SPECBAKE_CL_CASE(CL_INVALID_WORK_DIMENSION)
    SPECBAKE_CL_CASE(CL_INVALID_WORK_GROUP_SIZE)
    SPECBAKE_CL_CASE(CL_INVALID_WORK_ITEM_SIZE)
    SPECBAKE_CL_CASE(CL_INVALID_GLOBAL_OFFSET)
    SPECBAKE_CL_CASE(CL_INVALID_EVENT_WAIT_LIST)
    SPECBAKE_CL_CASE(CL_INVALID_EVENT)
    SPECBAKE_CL_CASE(CL_INVALID_OPERATION)
    SPECBAKE_CL_CASE(CL_INVALID_GL_OBJECT)
    SPECBAKE_CL_CASE(CL_INVALID_BUFFER_SIZE)
    SPECBAKE_CL_CASE(CL_INVALID_MIP_LEVEL)
    SPECBAKE_CL_CASE(CL_INVALID_GLOBAL_WORK_SIZE)
    SPECBAKE_CL_CASE(CL_INVALID_PROPERTY)
    SPECBAKE_CL_CASE(CL_INVALID_IMAGE_DESCRIPTOR)
    SPECBAKE_CL_CASE(CL_INVALID_COMPILER_OPTIONS)
    SPECBAKE_CL_CASE(CL_INVALID_LINKER_OPTIONS)
    SPECBAKE_CL_CASE(CL_INVALID_DEVICE_PARTITION_COUNT)
    SPECBAKE_CL_CASE(CL_PLATFORM_NOT_FOUND_KHR)
#undef SPECBAKE_CL_CASE
    default: return "CL_UNKNOWN_ERROR";
  }
}

namespace {

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

std::string trim(std::string s) {
  while (!s.empty() && (s.back() == '\0' || std::isspace(static_cast<unsigned char>(s.back())))) s.pop_back();
  return s;
}

std::vector<std::pair<cl::Platform, std::vector<cl::Device>>> enumerate() {
  std::vector<std::pair<cl::Platform, std::vector<cl::Device>>> out;
  std::vector<cl::Platform> platforms;
  try {
    cl::Platform::get(&platforms);
  } catch (const cl::Error& e) {
    if (e.err() == CL_PLATFORM_NOT_FOUND_KHR) return out;
    throw;
  }
  for (auto& p : platforms) {
    std::vector<cl::Device> devices;
    try {
      p.getDevices(CL_DEVICE_TYPE_ALL, &devices);
    } catch (const cl::Error& e) {
      if (e.err() != CL_DEVICE_NOT_FOUND) throw;
    }
    out.emplace_back(p, std::move(devices));
  }
  return out;
}

DeviceInfo describe(int pi, int di, const cl::Platform& p, const cl::Device& d) {
  DeviceInfo info;
  info.platform_index = pi;
  info.device_index = di;
  info.platform = trim(p.getInfo<CL_PLATFORM_NAME>());
  info.name = trim(d.getInfo<CL_DEVICE_NAME>());
  info.version = trim(d.getInfo<CL_DEVICE_VERSION>());
  const auto type = d.getInfo<CL_DEVICE_TYPE>();
  info.type = (type & CL_DEVICE_TYPE_GPU) ? "gpu" : (type & CL_DEVICE_TYPE_CPU) ? "cpu"
              : (type & CL_DEVICE_TYPE_ACCELERATOR) ? "accelerator" : "other";
  info.fp64 = trim(d.getInfo<CL_DEVICE_EXTENSIONS>()).find("cl_khr_fp64") != std::string::npos;
  info.global_mem_bytes = d.getInfo<CL_DEVICE_GLOBAL_MEM_SIZE>();
  info.max_alloc_bytes = d.getInfo<CL_DEVICE_MAX_MEM_ALLOC_SIZE>();
  info.local_mem_bytes = d.getInfo<CL_DEVICE_LOCAL_MEM_SIZE>();
  info.fp32_correct_divide_sqrt = (d.getInfo<CL_DEVICE_SINGLE_FP_CONFIG>() & CL_FP_CORRECTLY_ROUNDED_DIVIDE_SQRT) != 0;
  info.max_work_group_size = d.getInfo<CL_DEVICE_MAX_WORK_GROUP_SIZE>();
  info.compute_units = d.getInfo<CL_DEVICE_MAX_COMPUTE_UNITS>();
  return info;
}

cl::Device device_at(int pi, int di) {
  auto all = enumerate();
  return all.at(static_cast<std::size_t>(pi)).second.at(static_cast<std::size_t>(di));
}

}  // namespace

std::vector<DeviceInfo> list_devices() {
  return checked("enumerating OpenCL devices", [] {
    std::vector<DeviceInfo> out;
    auto all = enumerate();
    for (std::size_t pi = 0; pi < all.size(); ++pi)
      for (std::size_t di = 0; di < all[pi].second.size(); ++di)
        out.push_back(describe(static_cast<int>(pi), static_cast<int>(di), all[pi].first, all[pi].second[di]));
    return out;
  });
}

DeviceInfo select_device(const std::string& selector) {
  const auto devices = list_devices();
  if (devices.empty())
    throw DeviceError("no OpenCL device found (is an ICD such as pocl-opencl-icd installed? see `specbake devices`)");
  const std::string sel = lower(selector);
  auto pick = [&](auto pred) -> const DeviceInfo* {
    for (const auto& d : devices)
      if (pred(d)) return &d;
    return nullptr;
  };
  const DeviceInfo* chosen = nullptr;
  if (sel == "auto") {
    chosen = pick([](const DeviceInfo& d) { return d.type == "cpu"; });
    if (!chosen) chosen = &devices.front();
  } else if (sel == "cpu" || sel == "gpu") {
    chosen = pick([&](const DeviceInfo& d) { return d.type == sel; });
  } else {
    chosen = pick([&](const DeviceInfo& d) {
      return lower(d.name).find(sel) != std::string::npos || lower(d.platform).find(sel) != std::string::npos;
    });
  }
  if (!chosen) {
    std::string seen;
    for (const auto& d : devices) seen += "\n  " + d.name + " [" + d.type + "] (" + d.platform + ")";
    throw DeviceError("no OpenCL device matches '" + selector + "'; devices found:" + seen);
  }
  return *chosen;
}

Device::Device(const DeviceInfo& info) : info_(info) {
  checked("creating the OpenCL context", [&] {
    device_ = device_at(info.platform_index, info.device_index);
    context_ = cl::Context(device_);
    queue_ = cl::CommandQueue(context_, device_, CL_QUEUE_PROFILING_ENABLE);
    return 0;
  });
}

std::string Device::description() const {
  return info_.name + " (" + info_.platform + ", " + info_.version + ")";
}

std::string common_build_options(const DeviceInfo& info) {
  // float32 division and square root correctly rounded wherever the device can (NVIDIA's driver
  // uses the 2.5/3 ulp freedom otherwise): the kernels' float32 error bounds (docs/atmosphere.md,
  // the tests' kFloat32Chain) count one rounding per operation, and the atmosphere's near-horizon
  // geometry decides ground or sky from such quotients and roots
  return std::string("-cl-std=CL1.2") + (info.fp32_correct_divide_sqrt ? " -cl-fp32-correctly-rounded-divide-sqrt" : "");
}

cl::Program Device::build(const std::string& kernel_path, const std::string& options) {
  const std::string key = kernel_path + "\n" + options;
  if (auto it = programs_.find(key); it != programs_.end()) return it->second;
  const auto start = std::chrono::steady_clock::now();
  cl::Program program = build_source(kernel_path, kernel_source(kernel_path), options);
  spdlog::debug("OpenCL build of {}: {:.3f} s", kernel_path,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  programs_.emplace(key, program);
  return program;
}

cl::Program Device::build_source(const std::string& name, const std::string& source,
                                 const std::string& options) {
  cl::Program program = checked("creating program", [&] { return cl::Program(context_, source); });
  std::string opts = common_build_options(info_) + " " + options;
  if (const char* inject = std::getenv("SPECBAKE_INJECT_BUILD_FAILURE");
      inject && name.find(inject) != std::string::npos)
    opts += " -DSPECBAKE_INJECTED_BUILD_FAILURE";
  cl_int status = CL_SUCCESS;
  try {
    status = program.build({device_}, opts.c_str());
  } catch (const cl::BuildError& e) {
    status = e.err();
  } catch (const cl::Error& e) {
    status = e.err();
  }
  std::string log;
  try {
    log = trim(program.getBuildInfo<CL_PROGRAM_BUILD_LOG>(device_));
  } catch (const cl::Error&) {
  }
  if (status != CL_SUCCESS) {
    // The log goes to the log once; the error carries its first line.
    spdlog::error("OpenCL build of {} failed ({}); build log:\n{}", name, error_name(status), log);
    const std::string first = log.substr(0, log.find('\n'));
    throw DeviceError("building kernel " + name + " failed with " + error_name(status) +
                      (first.empty() ? "" : ": " + first + (first.size() < log.size() ? " (build log above)" : "")));
  }
  if (!log.empty()) spdlog::debug("OpenCL build log for {}:\n{}", name, log);
  return program;
}

}  // namespace specbake::cl_util
