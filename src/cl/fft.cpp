#include "cl/fft.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <string>

#define VKFFT_BACKEND 3
#include <vkFFT.h>

namespace specbake::cl_util {

struct Fft2d::Impl {
  cl_device_id device = nullptr;
  cl_context context = nullptr;
  cl_command_queue queue = nullptr;
  cl_mem plan_buffer = nullptr;  // VkFFT wants a buffer at plan time; launches pass their own
  std::uint64_t buffer_bytes = 0;
  VkFFTApplication app{};
  bool initialised = false;
};

Fft2d::Fft2d(Device& dev, std::size_t width, std::size_t height, std::size_t batch, FftPrecision precision)
    : dev_(dev), width_(width), height_(height), batch_(batch), precision_(precision), impl_(std::make_unique<Impl>()) {
  if (width < 1 || height < 1 || batch < 1) throw DeviceError("FFT plan: empty size");
  impl_->device = dev.context().getInfo<CL_CONTEXT_DEVICES>().at(0)();
  impl_->context = dev.context()();
  impl_->queue = dev.queue()();
  impl_->buffer_bytes = bytes();
  cl_int err = CL_SUCCESS;
  impl_->plan_buffer = clCreateBuffer(impl_->context, CL_MEM_READ_WRITE, impl_->buffer_bytes, nullptr, &err);
  if (err != CL_SUCCESS)
    throw DeviceError("FFT plan: allocating " + std::to_string(impl_->buffer_bytes) + " bytes failed with " +
                      error_name(err));
  VkFFTConfiguration config{};
  config.FFTdim = height == 1 ? 1 : 2;  // height 1: batched 1D transforms of the rows
  config.size[0] = width;
  config.size[1] = height;
  config.numberBatches = batch;
  config.device = &impl_->device;
  config.context = &impl_->context;
  config.buffer = &impl_->plan_buffer;
  config.bufferSize = &impl_->buffer_bytes;
  config.doublePrecision = precision == FftPrecision::double_ ? 1 : 0;
  config.makeForwardPlanOnly = 1;
  config.specifyOffsetsAtLaunch = 1;
  const auto start = std::chrono::steady_clock::now();
  const VkFFTResult r = initializeVkFFT(&impl_->app, config);
  if (r != VKFFT_SUCCESS) {
    clReleaseMemObject(impl_->plan_buffer);
    throw DeviceError("VkFFT could not plan a " + std::to_string(width) + " x " + std::to_string(height) + " x " +
                      std::to_string(batch) + (precision == FftPrecision::double_ ? " double" : " float") +
                      " FFT (VkFFTResult " + std::to_string(static_cast<int>(r)) + ")");
  }
  impl_->initialised = true;
  spdlog::debug("VkFFT plan {}x{} batch {} ({}): {:.3f} s", width, height, batch,
                precision == FftPrecision::double_ ? "double" : "float",
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
}

Fft2d::~Fft2d() {
  if (impl_->initialised) deleteVkFFT(&impl_->app);
  if (impl_->plan_buffer) clReleaseMemObject(impl_->plan_buffer);
}

std::size_t Fft2d::bytes() const {
  return batch_ * width_ * height_ * 2 * (precision_ == FftPrecision::double_ ? sizeof(double) : sizeof(float));
}

void Fft2d::append(cl::Buffer& buffer, std::size_t first_array) {
  cl_mem mem = buffer();
  VkFFTLaunchParams launch{};
  launch.commandQueue = &impl_->queue;
  launch.buffer = &mem;
  launch.bufferOffset = first_array * (bytes() / batch_);
  // VkFFT enqueues its kernels without events: they are timed as the span between two markers.
  cl::Event before, after;
  checked("VkFFT forward transform: marker", [&] { return dev_.queue().enqueueMarkerWithWaitList(nullptr, &before); });
  const VkFFTResult r = VkFFTAppend(&impl_->app, -1, &launch);
  if (r != VKFFT_SUCCESS)
    throw DeviceError("VkFFT forward transform failed (VkFFTResult " + std::to_string(static_cast<int>(r)) + ")");
  checked("VkFFT forward transform: marker", [&] { return dev_.queue().enqueueMarkerWithWaitList(nullptr, &after); });
  dev_.profiler().record_span(before, after);
}

void Fft2d::forward(cl::Buffer& buffer, std::size_t first_array) {
  append(buffer, first_array);
  const cl_int err = dev_.profiler().wait([&] { return clFinish(impl_->queue); });
  if (err != CL_SUCCESS) throw DeviceError(std::string("VkFFT forward transform: clFinish returned ") + error_name(err));
}

Fft2d& shared_fft(Device& dev, std::size_t width, std::size_t height, std::size_t batch, FftPrecision precision) {
  const std::string key = "fft2d:" + std::to_string(width) + "x" + std::to_string(height) + "x" +
                          std::to_string(batch) + (precision == FftPrecision::single ? ":f32" : ":f64");
  return dev.reusable<Fft2d>(key, [&] { return std::make_unique<Fft2d>(dev, width, height, batch, precision); });
}

namespace {
constexpr std::size_t kRowBatch = 64;
std::size_t row_batch(std::size_t count) { return std::min(count, kRowBatch); }
}  // namespace

cl::Buffer fft_rows_buffer(Device& dev, std::size_t n, std::size_t count) {
  const std::size_t batch = row_batch(std::max<std::size_t>(count, 1)), array_bytes = n * 2 * sizeof(float);
  const std::size_t arrays = (std::max<std::size_t>(count, 1) + batch - 1) / batch * batch;
  cl::Buffer buf = checked("FFT rows: buffer",
                           [&] { return cl::Buffer(dev.context(), CL_MEM_READ_WRITE, arrays * array_bytes); });
  if (arrays > count)
    checked("FFT rows: zero the last batch's tail", [&] {
      cl::Event ev;
      dev.queue().enqueueFillBuffer(buf, 0.0f, count * array_bytes, (arrays - count) * array_bytes, nullptr, &ev);
      dev.profiler().record(ev);
      return CL_SUCCESS;
    });
  return buf;
}

void fft_rows(Device& dev, cl::Buffer& rows, std::size_t n, std::size_t count) {
  if (count == 0) return;
  const std::size_t batch = row_batch(count);
  Fft2d& fft = shared_fft(dev, n, 1, batch, FftPrecision::single);
  // Every batch enqueued, then one wait (a wait per batch costs a host round trip each: ~2000 of
  // them for an 8192² table on a GPU).
  for (std::size_t g = 0; g * batch < count; ++g) fft.append(rows, g * batch);
  const cl_int err = dev.profiler().wait([&] { return dev.queue().finish(); });
  if (err != CL_SUCCESS) throw DeviceError(std::string("FFT rows: clFinish returned ") + error_name(err));
}

}  // namespace specbake::cl_util
