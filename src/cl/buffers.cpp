#include "cl/buffers.hpp"

namespace specbake::cl_util {

cl::Buffer upload_real(Device& dev, const std::vector<double>& values) {
  return upload_real(dev, values, dev.info().fp64);
}

cl::Buffer upload_real(Device& dev, const std::vector<double>& values, bool as_double) {
  return checked("uploading a buffer", [&] {
    // Copied by the driver as the buffer is made (CL_MEM_COPY_HOST_PTR reads the host memory only):
    // doubles straight from the caller's vector, floats narrowed first; an empty vector gives one zero.
    static const std::vector<double> kZero(1, 0.0);
    const std::vector<double>& src = values.empty() ? kZero : values;
    if (as_double)
      return cl::Buffer(dev.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, src.size() * sizeof(double),
                        const_cast<double*>(src.data()));
    std::vector<float> v(src.begin(), src.end());
    return cl::Buffer(dev.context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, v.size() * sizeof(float), v.data());
  });
}

cl::Buffer device_real(Device& dev, std::size_t count) {
  return checked("allocating a device buffer", [&] {
    const std::size_t elem = dev.info().fp64 ? sizeof(double) : sizeof(float);
    return cl::Buffer(dev.context(), CL_MEM_READ_WRITE, std::max<std::size_t>(count, 1) * elem);
  });
}

std::vector<double> download_real(Device& dev, const cl::Buffer& buf, std::size_t count) {
  return checked("reading a device buffer", [&] {
    // A blocking read: the call waits for the device (and for every command before it).
    auto read = [&](std::size_t bytes, void* to) {
      if (!count) return;
      cl::Event ev;
      dev.profiler().wait([&] { dev.queue().enqueueReadBuffer(buf, CL_TRUE, 0, bytes, to, nullptr, &ev); });
      dev.profiler().record(ev);
    };
    if (dev.info().fp64) {
      std::vector<double> v(count);
      read(count * sizeof(double), v.data());
      return v;
    }
    std::vector<float> f(count);
    read(count * sizeof(float), f.data());
    return std::vector<double>(f.begin(), f.end());
  });
}

void set_real_arg(Device& dev, cl::Kernel& k, cl_uint index, double value) {
  checked("setting a kernel argument", [&] {
    if (dev.info().fp64) k.setArg(index, value);
    else k.setArg(index, static_cast<float>(value));
    return 0;
  });
}

void run_1d(Device& dev, cl::Kernel& k, std::size_t count, std::size_t local) {
  checked("running a kernel", [&] {
    cl::Event ev;
    dev.queue().enqueueNDRangeKernel(k, cl::NullRange, cl::NDRange(count), local ? cl::NDRange(local) : cl::NullRange, nullptr, &ev);
    dev.profiler().record(ev);
    dev.profiler().wait([&] { dev.queue().finish(); });
    return 0;
  });
}

}  // namespace specbake::cl_util
