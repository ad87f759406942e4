// Device and host seconds per stage from OpenCL profiling events (cl/timing.hpp).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <vector>

#include "cl/buffers.hpp"
#include "cl/device.hpp"
#include "cl/fft.hpp"
#include "cl/timing.hpp"
#include "support/testing.hpp"

using namespace specbake;
using cl_util::Profiler;

namespace {

cl_util::Device& device() { return specbake::testing::shared_device(); }

// A dependent chain of multiply-adds per work item: the compiler can neither vectorise nor
// shorten it, and the result is stored, so the loop runs.
constexpr const char* kSlowSource = R"CL(
__kernel void slow(__global float* out, int n) {
  const int i = get_global_id(0);
  float x = 1.0f + 0.001f * (float)i;
  for (int k = 0; k < n; ++k) x = x * 0.9999999f + 1.0e-7f;
  out[i] = x;
}
)CL";
constexpr int kItems = 4;

struct Slow {
  cl::Program program;
  cl::Kernel kernel;
  cl::Buffer out;
};

Slow make_slow(cl_util::Device& dev) {
  return cl_util::checked("slow kernel", [&] {
    Slow s;
    s.program = cl::Program(dev.context(), kSlowSource);
    s.program.build({dev.queue().getInfo<CL_QUEUE_DEVICE>()}, "-cl-std=CL1.2");
    s.kernel = cl::Kernel(s.program, "slow");
    s.out = cl::Buffer(dev.context(), CL_MEM_READ_WRITE, kItems * sizeof(float));
    s.kernel.setArg(0, s.out);
    return s;
  });
}

cl::Event enqueue_slow(cl_util::Device& dev, Slow& s, int n) {
  return cl_util::checked("slow kernel", [&] {
    cl::Event ev;
    s.kernel.setArg(1, n);
    dev.queue().enqueueNDRangeKernel(s.kernel, cl::NullRange, cl::NDRange(kItems), cl::NullRange, nullptr, &ev);
    return ev;
  });
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

// The slow kernel is enqueued in stage "slow" without waiting; stage "read" then blocks on a
// 16-byte read, which on an asynchronous device waits out the kernel. The kernel's device
// time must stay with "slow"; "read" holds neither device nor host time worth mentioning.
TEST(Timing, SlowKernelsDeviceTimeStaysWithItsStage) {
  cl_util::Device& dev = device();
  Profiler& prof = dev.profiler();
  Slow s = make_slow(dev);
  // Size the loop so that the kernel runs ≥ 50 ms on this device (the first launch also
  // makes PoCL compile the work-group function, outside the measured sequence). This sizes
  // the work; nothing below compares against a fixed time.
  int n = 1 << 20;
  for (;;) {
    Profiler::Stage warm(prof, "warm-up");
    prof.record(enqueue_slow(dev, s, n));
    prof.wait([&] { dev.queue().finish(); });
    const auto r = warm.close();
    prof.settle();
    ASSERT_EQ(r->pending, 0);
    if (r->device_s >= 0.05 || n >= (1 << 30)) break;
    n *= 2;
  }

  const auto t0 = std::chrono::steady_clock::now();
  Profiler::Stage slow(prof, "slow");
  prof.record(enqueue_slow(dev, s, n));
  const Profiler::Record rs = slow.close();
  Profiler::Stage read(prof, "read");
  float got[kItems] = {};
  cl::Event ev;
  cl_util::checked("reading", [&] {
    prof.wait([&] { dev.queue().enqueueReadBuffer(s.out, CL_TRUE, 0, sizeof(got), got, nullptr, &ev); });
    return 0;
  });
  prof.record(ev);
  const Profiler::Record rr = read.close();
  prof.settle();
  const double wall = seconds_since(t0);

  ASSERT_EQ(rs->commands, 1);
  ASSERT_EQ(rr->commands, 1);
  EXPECT_EQ(rs->pending, 0);
  EXPECT_EQ(rr->pending, 0);
  EXPECT_EQ(prof.pending(), 0u);
  EXPECT_TRUE(std::isfinite(got[0]) && got[0] > 0.0f);
  EXPECT_GE(rs->device_s, 0.0);
  EXPECT_GE(rr->device_s, 0.0);
  // The two commands ran inside the sequence, one after the other (in-order queue): their
  // device times add up to at most its wall time. Tolerance: 2 ms + 2 % for the device's
  // timer and the host's steady clock being different clocks with their own granularity.
  EXPECT_LE(rs->device_s + rr->device_s, wall + 2e-3 + 0.02 * wall)
      << "slow " << rs->device_s << " s, read " << rr->device_s << " s, wall " << wall << " s";
  // Most of the sequence is the kernel: outside it there are only an enqueue, a 16-byte read
  // and the bookkeeping, well under a millisecond against ≥ 50 ms, so half is a wide margin.
  EXPECT_GT(rs->device_s, 0.5 * wall) << "slow " << rs->device_s << " s of " << wall << " s";
  // The read stage: its own command is a 16-byte copy, and its wait for the kernel is
  // blocked time, not host time. This holds whether the device runs the kernel behind the
  // host's back (a GPU; PoCL's worker threads) or inside the enqueue call (then the time sits
  // in "slow"'s wall, and "read" waits for nothing): in both cases "read" keeps < 10 %.
  EXPECT_LT(rr->device_s, 0.1 * rs->device_s) << "read " << rr->device_s << " s";
  EXPECT_LT(rr->host_s(), 0.1 * rs->device_s) << "read host " << rr->host_s() << " s, wall " << rr->wall_s;
  EXPECT_LE(rr->blocked_s, rr->wall_s);
  EXPECT_LE(rs->blocked_s, rs->wall_s);
  // The kernel's time is somewhere in the sequence's stages: wall of both ≥ the kernel.
  EXPECT_GE(rs->wall_s + rr->wall_s + 2e-3, rs->device_s);
}

// Host work alone: no command, no wait: all of the wall time is host time.
TEST(Timing, HostWorkIsHostTime) {
  Profiler prof;
  Profiler::Stage st(prof, "host");
  volatile double x = 0.0;
  for (int i = 0; i < 200000; ++i) x = x + std::sqrt(static_cast<double>(i));
  const auto r = st.close();
  EXPECT_EQ(r->commands, 0);
  EXPECT_EQ(r->device_s, 0.0);
  EXPECT_EQ(r->blocked_s, 0.0);
  EXPECT_GT(r->wall_s, 0.0);
  EXPECT_EQ(r->host_s(), r->wall_s);
  // Closing twice changes nothing.
  const double wall = r->wall_s;
  st.close();
  EXPECT_EQ(r->wall_s, wall);
}

// Nested stages (a runner step around a kind's stage) both count a command and a wait;
// commands enqueued with no stage open are not kept.
TEST(Timing, NestedStagesAndUnmeasuredCommands) {
  cl_util::Device& dev = device();
  Profiler& prof = dev.profiler();
  Slow s = make_slow(dev);
  prof.record(enqueue_slow(dev, s, 1000));
  EXPECT_EQ(prof.pending(), 0u);
  dev.queue().finish();

  Profiler::Stage outer(prof, "step");
  Profiler::Stage inner(prof, "kernel", 3);
  prof.record(enqueue_slow(dev, s, 100000));
  prof.wait([&] { dev.queue().finish(); });
  const auto ri = inner.close();
  Profiler::Stage after(prof, "after");
  const auto ra = after.close();
  const auto ro = outer.close();
  prof.settle();
  EXPECT_EQ(ri->order, 3);
  EXPECT_EQ(ri->commands, 1);
  EXPECT_EQ(ro->commands, 1);
  EXPECT_EQ(ra->commands, 0);
  EXPECT_GT(ri->device_s, 0.0);
  EXPECT_EQ(ri->device_s, ro->device_s);
  EXPECT_EQ(ri->blocked_s, ro->blocked_s);
  EXPECT_GE(ro->wall_s, ri->wall_s + ra->wall_s);
}

// VkFFT's launches carry no events: Fft2d::forward records a marker span, which must hold
// the transform's device time within the stage's wall time.
TEST(Timing, FftIsTimedAsAMarkerSpan) {
  cl_util::Device& dev = device();
  Profiler& prof = dev.profiler();
  cl_util::Fft2d fft(dev, 256, 256, 1, cl_util::FftPrecision::single);
  std::vector<float> v(2 * 256 * 256, 1.0f);
  cl::Buffer buf(dev.context(), CL_MEM_READ_WRITE | CL_MEM_COPY_HOST_PTR, v.size() * sizeof(float), v.data());
  fft.forward(buf);  // warm-up
  const auto t0 = std::chrono::steady_clock::now();
  Profiler::Stage st(prof, "fft");
  for (int i = 0; i < 4; ++i) fft.forward(buf);
  const auto r = st.close();
  prof.settle();
  const double wall = seconds_since(t0);
  EXPECT_EQ(r->commands, 4);
  EXPECT_EQ(r->pending, 0);
  EXPECT_GT(r->device_s, 0.0);
  EXPECT_GT(r->blocked_s, 0.0);  // forward() waits for its transform
  EXPECT_LE(r->device_s, wall + 2e-3 + 0.02 * wall);
}

// JSON of a stage, and sums over stages.
TEST(Timing, SecondsJsonAndAccumulate) {
  cl_util::StageSeconds a, b;
  a.wall_s = 2.0;
  a.blocked_s = 1.5;
  a.device_s = 1.25;
  b.wall_s = 1.0;
  b.blocked_s = 0.25;
  b.device_s = 0.5;
  cl_util::accumulate(a, b);
  const auto j = cl_util::seconds_json(a);
  EXPECT_DOUBLE_EQ(j.at("device_s").get<double>(), 1.75);
  EXPECT_DOUBLE_EQ(j.at("host_s").get<double>(), 1.25);
  EXPECT_DOUBLE_EQ(j.at("wall_s").get<double>(), 3.0);
}
