#pragma once
// Per-stage device and host seconds, honest on asynchronous devices.
//
// A wall clock around an enqueue reads ~0 on a GPU (the call returns at once) and the kernel's
// time lands in whatever waits next. The Profiler instead keeps the OpenCL profiling event of
// every command a stage enqueues (the queue is created with CL_QUEUE_PROFILING_ENABLE) and
// reports, per stage:
//   device_s  Σ (CL_PROFILING_COMMAND_END − CL_PROFILING_COMMAND_START) over the stage's
//             commands, whenever they ran: a kernel enqueued by stage A and waited for by
//             stage B counts for A. Commands without events of their own (VkFFT's launches)
//             count as a marker span: END of a marker enqueued after them − END of a marker
//             enqueued before them (this includes any idle gap while the host enqueues them).
//   wall_s    steady-clock time from opening to closing the stage;
//   blocked_s the part of wall_s spent inside calls that wait for the device, i.e. the calls
//             run through Profiler::wait (clFinish, blocking reads and writes, event waits);
//   host_s    wall_s − blocked_s: the time the host thread did its own work (argument set-up,
//             enqueue calls, conversions, sums, reference recomputations). An implementation
//             that executes a kernel inside the enqueue call (a synchronous CPU device) makes
//             that time appear in both device_s and host_s.
// Stages may nest (a runner step around a kind's stages): a command or a wait counts for
// every stage open at the time. Not thread-safe: one job thread records.
#include <CL/opencl.hpp>

#include <chrono>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace specbake::cl_util {

struct StageSeconds {
  std::string stage;
  int order = 0;           // free for the caller (the atmosphere's scattering order)
  double wall_s = 0.0;
  double blocked_s = 0.0;
  double device_s = 0.0;
  int commands = 0;        // profiled commands (a marker span counts once)
  int pending = 0;         // commands whose times are not read yet (Profiler::settle reads them)
  bool closed = false;
  double host_s() const { return wall_s > blocked_s ? wall_s - blocked_s : 0.0; }
};

class Profiler {
 public:
  using Record = std::shared_ptr<StageSeconds>;
  using Clock = std::chrono::steady_clock;

  Profiler() = default;
  Profiler(const Profiler&) = delete;
  Profiler& operator=(const Profiler&) = delete;

  // Opens a stage at `t0` (now by default; a caller chaining stages passes the previous one's
  // end, so that consecutive stages leave no gap); its record fills in as commands complete and
  // stays valid after close().
  Record open(std::string stage, int order = 0, Clock::time_point t0 = Clock::now());
  // Stops the stage's wall clock at `t` and reads the times of commands that have completed
  // (without waiting for the others).
  void close(const Record& r, Clock::time_point t = Clock::now());

  // A command just enqueued with `ev` (an event of a profiling queue).
  void record(const cl::Event& ev);
  // Commands enqueued between the markers `before` and `after` (no events of their own).
  void record_span(const cl::Event& before, const cl::Event& after);
  // Runs f, a call that waits for the device; its wall time counts as blocked in every open
  // stage (nested waits count once).
  template <class F>
  decltype(auto) wait(F&& f) {
    if (waiting_) return f();
    struct Done {
      Profiler* p;
      Clock::time_point t0;
      ~Done() {
        p->waiting_ = false;
        p->add_blocked(std::chrono::duration<double>(Clock::now() - t0).count());
      }
    } done{this, (waiting_ = true, Clock::now())};
    return f();
  }
  // Waits for every recorded command and reads its times.
  void settle();
  // Commands recorded but not read yet.
  std::size_t pending() const { return pending_.size(); }

  // RAII: opens on construction, closes on close() or destruction (also when unwinding).
  class Stage {
   public:
    Stage(Profiler& p, std::string stage, int order = 0, Clock::time_point t0 = Clock::now())
        : p_(&p), r_(p.open(std::move(stage), order, t0)) {}
    ~Stage() { close(); }
    Stage(const Stage&) = delete;
    Stage& operator=(const Stage&) = delete;
    const Record& close(Clock::time_point t = Clock::now()) {
      if (!r_->closed) p_->close(r_, t);
      return r_;
    }
    const Record& record() const { return r_; }

   private:
    Profiler* p_;
    Record r_;
  };

 private:
  struct Pending {
    cl::Event first, last;  // first == last for one command
    bool span = false;
    std::vector<Record> into;
  };
  struct Open {
    Record r;
    Clock::time_point t0;
  };
  void add_blocked(double s);
  void add(Pending p);
  void resolve(bool block);

  std::vector<Open> open_;
  std::vector<Pending> pending_;
  bool waiting_ = false;
};

// A stage timed by the wall clock alone (a program build, a combination of results): runs f and
// returns its wall time as both wall_s and host_s. Any device work inside f (a layout check's
// kernel) counts as host time: use it for stages that are host work but for such small parts.
template <class F>
StageSeconds host_only(std::string stage, F&& f) {
  const auto t0 = std::chrono::steady_clock::now();
  f();
  StageSeconds s;
  s.stage = std::move(stage);
  s.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  s.closed = true;
  return s;
}

// Adds s's seconds and commands into `into` (sums over passes, orders, repeats).
void accumulate(StageSeconds& into, const StageSeconds& s);
// {"device_s": …, "host_s": …, "wall_s": …}
nlohmann::json seconds_json(const StageSeconds& s);

}  // namespace specbake::cl_util
