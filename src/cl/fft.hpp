#pragma once
// Batched 2D complex FFTs on the OpenCL device with VkFFT (OpenCL backend).
// Forward sign: F[kv][ku] = Σ_{iy,ix} f[iy][ix]·e^{−2πi(ku·ix/W + kv·iy/H)} (numpy.fft.fft2),
// unnormalised, in place on `batch` consecutive W×H arrays of interleaved (re, im) pairs,
// row-major [iy][ix]. Any sizes (VkFFT uses Bluestein's algorithm for large prime factors).
#include <CL/opencl.hpp>

#include <cstddef>
#include <memory>
#include <vector>

#include "cl/device.hpp"

namespace specbake::cl_util {

enum class FftPrecision { single, double_ };

class Fft2d {
 public:
  // Compiles the plan (VkFFT generates and builds its kernels); DeviceError on failure.
  Fft2d(Device& dev, std::size_t width, std::size_t height, std::size_t batch, FftPrecision precision);
  ~Fft2d();
  Fft2d(const Fft2d&) = delete;
  Fft2d& operator=(const Fft2d&) = delete;

  // In-place forward transform of the `batch` arrays of `buffer` starting at array index
  // `first_array` (the buffer holds at least (first_array + batch) arrays); waits for completion.
  // Recorded in dev.profiler() as a marker span (VkFFT's launches carry no events).
  void forward(cl::Buffer& buffer, std::size_t first_array = 0);
  // The same transform enqueued without waiting: the caller finishes the queue before it reads
  // the buffer on the host or releases it.
  void append(cl::Buffer& buffer, std::size_t first_array = 0);
  std::size_t bytes() const;  // batch·W·H·2·sizeof(element)
  std::size_t width() const { return width_; }
  std::size_t height() const { return height_; }
  std::size_t batch() const { return batch_; }

 private:
  struct Impl;
  Device& dev_;
  std::size_t width_, height_, batch_;
  FftPrecision precision_;
  std::unique_ptr<Impl> impl_;
};

// The plan for (width, height, batch, precision) on `dev`, built on first use and reused by
// later jobs in the process (a 1024² plan takes ~0.08 s to build on PoCL).
Fft2d& shared_fft(Device& dev, std::size_t width, std::size_t height, std::size_t batch, FftPrecision precision);

// Forward FFTs of `count` consecutive length-n complex arrays (interleaved float re, im, as the
// 2D transform's sign), in place, on the device in float32: batches of up to 64 rows share one
// plan (a Fft2d of height 1).
// A device buffer for fft_rows: `count` rows rounded up to whole batches, the rows past `count`
// zeroed (they are transformed with the last batch and never read).
cl::Buffer fft_rows_buffer(Device& dev, std::size_t n, std::size_t count);
// The rows of a buffer from fft_rows_buffer(dev, n, count), on the device (every batch enqueued,
// then one wait).
void fft_rows(Device& dev, cl::Buffer& rows, std::size_t n, std::size_t count);

}  // namespace specbake::cl_util
