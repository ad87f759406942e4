#include "cl/timing.hpp"

#include <algorithm>

#include "cl/device.hpp"

namespace specbake::cl_util {

namespace {

double profiling_s(const cl::Event& ev, cl_profiling_info what) {
  cl_ulong ns = 0;
  const cl_int err = clGetEventProfilingInfo(ev(), what, sizeof(ns), &ns, nullptr);
  if (err != CL_SUCCESS)
    throw DeviceError(std::string("reading a command's profiling time: clGetEventProfilingInfo returned ") +
                      error_name(err) + " (" + std::to_string(err) + ")");
  return 1e-9 * static_cast<double>(ns);
}

cl_int status_of(const cl::Event& ev) {
  cl_int status = CL_COMPLETE;
  const cl_int err =
      clGetEventInfo(ev(), CL_EVENT_COMMAND_EXECUTION_STATUS, sizeof(status), &status, nullptr);
  if (err != CL_SUCCESS)
    throw DeviceError(std::string("reading a command's status: clGetEventInfo returned ") + error_name(err) + " (" +
                      std::to_string(err) + ")");
  return status;
}

}  // namespace

Profiler::Record Profiler::open(std::string stage, int order, Clock::time_point t0) {
  auto r = std::make_shared<StageSeconds>();
  r->stage = std::move(stage);
  r->order = order;
  open_.push_back({r, t0});
  return r;
}

void Profiler::close(const Record& r, Clock::time_point now) {
  const auto it = std::find_if(open_.begin(), open_.end(), [&](const Open& o) { return o.r == r; });
  if (it == open_.end()) return;
  r->wall_s += std::chrono::duration<double>(now - it->t0).count();
  r->closed = true;
  open_.erase(it);
  resolve(false);
}

void Profiler::add(Pending p) {
  if (open_.empty()) return;  // nobody measures: nothing to keep
  for (const Open& o : open_) {
    p.into.push_back(o.r);
    ++o.r->commands;
    ++o.r->pending;
  }
  pending_.push_back(std::move(p));
}

void Profiler::record(const cl::Event& ev) { add({ev, ev, false, {}}); }

void Profiler::record_span(const cl::Event& before, const cl::Event& after) { add({before, after, true, {}}); }

void Profiler::add_blocked(double s) {
  for (const Open& o : open_) o.r->blocked_s += s;
}

void Profiler::resolve(bool block) {
  std::vector<Pending> keep;
  for (Pending& p : pending_) {
    cl_int status = status_of(p.last);
    if (status > CL_COMPLETE && block) {
      clWaitForEvents(1, &p.last());  // a failed command reports through its status below
      status = status_of(p.last);
    }
    if (status > CL_COMPLETE) {
      keep.push_back(std::move(p));
      continue;
    }
    double s = 0.0;
    if (status == CL_COMPLETE) {  // a failed command (status < 0) has no times; its error surfaces elsewhere
      s = p.span ? profiling_s(p.last, CL_PROFILING_COMMAND_END) - profiling_s(p.first, CL_PROFILING_COMMAND_END)
                 : profiling_s(p.last, CL_PROFILING_COMMAND_END) - profiling_s(p.first, CL_PROFILING_COMMAND_START);
      s = std::max(0.0, s);
    }
    for (const Record& r : p.into) {
      r->device_s += s;
      --r->pending;
    }
  }
  pending_ = std::move(keep);
}

void Profiler::settle() {
  if (pending_.empty()) return;
  wait([&] { resolve(true); });
}

void accumulate(StageSeconds& into, const StageSeconds& s) {
  into.wall_s += s.wall_s;
  into.blocked_s += s.blocked_s;
  into.device_s += s.device_s;
  into.commands += s.commands;
  into.pending += s.pending;
}

nlohmann::json seconds_json(const StageSeconds& s) {
  return {{"device_s", s.device_s}, {"host_s", s.host_s()}, {"wall_s", s.wall_s}};
}

}  // namespace specbake::cl_util
