#include "kinds/atmosphere/bake/pass.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <stdexcept>
#include <variant>

#include "cl/buffers.hpp"
#include "core/parallel.hpp"
#include "kinds/atmosphere/bake/reference_widths.hpp"

namespace specbake::atmosphere {

using cl_util::Device;

int pass_width_for(std::size_t channels) {
  for (int w : kPassWidths)
    if (static_cast<std::size_t>(w) >= channels) return w;
  return kPassWidths[std::size(kPassWidths) - 1];
}

const char* to_string(Tex t) {
  switch (t) {
    case Tex::transmittance: return "transmittance";
    case Tex::delta_irradiance: return "delta_irradiance";
    case Tex::delta_rayleigh: return "delta_rayleigh";
    case Tex::delta_mie: return "delta_mie";
    case Tex::delta_multiple: return "delta_multiple";
    case Tex::density: return "density";
  }
  return "?";
}

namespace {

// Per-channel maximum (floored at 0) and mean of a [texels][w] texture, reduced in chunks of
// kSumChunk texels on the host's threads and combined in chunk order.
struct ChannelStats {
  std::vector<double> max, mean;
};
template <class T>
ChannelStats channel_stats(const std::vector<T>& v, int w) {
  const std::size_t n = v.size() / w, chunks = (n + kSumChunk - 1) / kSumChunk;
  std::vector<double> mx(chunks * w, 0.0), sum(chunks * w, 0.0);
  parallel_chunks(n, kSumChunk, [&](std::size_t first, std::size_t last, std::size_t k) {
    for (std::size_t i = first; i < last; ++i)
      for (int c = 0; c < w; ++c) {
        mx[k * w + c] = std::max(mx[k * w + c], static_cast<double>(v[i * w + c]));
        sum[k * w + c] += v[i * w + c];
      }
  });
  ChannelStats s{std::vector<double>(w, 0.0), std::vector<double>(w, 0.0)};
  for (std::size_t k = 0; k < chunks; ++k)
    for (int c = 0; c < w; ++c) {
      s.max[c] = std::max(s.max[c], mx[k * w + c]);
      s.mean[c] += sum[k * w + c];
    }
  for (int c = 0; c < w; ++c) s.mean[c] /= std::max<std::size_t>(n, 1);
  return s;
}

std::vector<double> inverse_rayleigh_phase(const Model& m);

// `to` = `from` converted to double, in chunks on the host's threads.
template <class S>
void copy_chunks(const std::vector<S>& from, std::vector<double>& to) {
  to.resize(from.size());
  parallel_chunks(from.size(), kSumChunk, [&](std::size_t first, std::size_t last, std::size_t) {
    std::copy(from.begin() + first, from.begin() + last, to.begin() + first);
  });
}


// The kernels' compile-time slice count NU_MAX (the private arrays and fixed-length loops of
// scattering_density) is the texture's NU, but never below 8. NVIDIA's OpenCL compiler (driver
// 580, H100) turns every texel of the density kernel into NaN when NU_MAX is 2..7 (NU_MAX 8 and
// 16 are right, and so is NU_MAX 4 built with -cl-opt-disable); PoCL is right for every NU_MAX.
// Slices past NU have a zero hat weight and are never read, so the texels are the same
// operations either way (bit-identical on PoCL; AtmosphereDevice.SmallSizesMatchDoubleReference
// and the other NU = 4 tests catch the NaNs on such a device).
constexpr int kNuMaxAtLeast = 8;

// LANES (atmosphere.cl): texels per work item of the single- and multiple-scattering row kernels,
// and suns side by side in the density's inner loops. On a CPU device 8, whose coordinate work
// the kernel compiler runs as 8-wide vector instructions (PoCL does not vectorise across work
// items there); elsewhere 1, one texel per work item and one sun at a time, as a GPU wants (and
// its private arrays stay small). The texels are the same operations either way.
std::size_t lanes(const cl_util::DeviceInfo& info) { return info.type == "cpu" ? 8 : 1; }

// Table shapes, from atmosphere.cl's macros (visible here through reference.hpp): ray samples
// [R][MU][SCATTERING_STEPS + 1][RAY_T + NCH], incidence [R][MU_S][density_theta][(2 NU + 1) NCH + INC_FIXED].
constexpr int kScatteringSteps = SCATTERING_STEPS, kRayFixed = RAY_T,
              kIncidenceFixed = INC_FIXED;
// A sky-view sample's entries after the transmittances (SKY_RAY_STRIDE − RAY_STRIDE).
constexpr int kSkyRayExtra = SKY_RAY_EXTRA;

// Parameter block, and the values the layout kernel must echo back.
struct Block {
  std::vector<unsigned char> bytes;
  std::vector<double> echo_reals;  // solar[0], albedo[NCH-1], absorption constant[1], rb, g, density_theta_power, density_phase_norm
  std::vector<int> echo_ints;      // transmittance_w, nu_size, sizeof
};

Block make_block(const Model& m, const Channels& ch, int width, bool dbl) {
  return with_width(width, [&](auto ref) {
    using W = decltype(ref);
    const auto a = W::parameters(m, ch);
    Block b;
    b.bytes = W::block(a, dbl);
    b.echo_reals = {a.solar_irradiance[0], a.ground_albedo[W::channels - 1], a.absorption_density.constant_term[1],
                    a.bottom_radius, a.mie_g, a.density_theta_power, a.density_phase_norm};
    b.echo_ints = {a.transmittance_w, a.nu_size, static_cast<int>(b.bytes.size())};
    return b;
  });
}

// An order's R,G,B additions (scattering, irradiance) over the passes so far, until their
// statistics are taken (and the buffer freed).
struct OrderSum {
  std::array<cl::Buffer, 2> rgb;
  std::array<std::optional<ChannelStats>, 2> stats;
  bool added(int which) const { return rgb[which]() != nullptr || stats[which].has_value(); }
};

// OrderRgb from an order's statistics (scattering, irradiance; absent: nothing added).
OrderRgb order_rgb_of(const ChannelStats* scattering, const ChannelStats* irradiance) {
  OrderRgb o;
  if (scattering) {
    o.scattering_max = scattering->max;
    o.scattering_mean = scattering->mean;
  }
  if (irradiance) {
    o.irradiance_max = irradiance->max;
    o.irradiance_mean = irradiance->mean;
  }
  return o;
}

// The device side of a backend's work: its program and parameter block, buffers, kernel
// launches (with their work-group sizes) and blocking reads, each recorded on the device's
// profiler.
class DeviceQueue {
 public:
  DeviceQueue(Device& dev, const Model& m, const Channels& ch, int width, bool dbl)
      : dev_(dev), width_(width), dbl_(dbl), lanes_(lanes(dev.info())), block_(make_block(m, ch, width, dbl)) {
    const std::string options = std::string("-DNCH=") + std::to_string(width) + " -DNU_MAX=" +
                                std::to_string(std::max(m.sizes.nu, kNuMaxAtLeast)) +
                                " -DLANES=" + std::to_string(lanes_) + (dbl ? " -DSPECBAKE_REAL_DOUBLE" : "");
    if (dbl && !dev.info().fp64) throw DeviceError("precision: double needs a device with cl_khr_fp64");
    program_ = dev.build(kProgram, options);
  }
  Device& dev() { return dev_; }
  const cl::Program& program() const { return program_; }
  const Block& block() const { return block_; }
  int width() const { return width_; }
  bool dbl() const { return dbl_; }
  std::size_t lane_count() const { return lanes_; }
  void use_block(Block b) { block_ = std::move(b); }

  cl::Buffer alloc(long long texels) { return alloc_reals(texels * width_); }
  cl::Buffer alloc_reals(long long n) {
    return cl::Buffer(dev_.context(), CL_MEM_READ_WRITE,
                      std::max<long long>(n, 1) * (dbl_ ? sizeof(double) : sizeof(float)));
  }
  void enqueue(cl::Kernel& k, long long n) { enqueue(k, cl::NDRange(static_cast<std::size_t>(n)), group_for(n)); }
  void enqueue(cl::Kernel& k, const cl::NDRange& global, const cl::NDRange& local,
               const cl::NDRange& offset = cl::NullRange) {
    cl::Event ev;
    dev_.queue().enqueueNDRangeKernel(k, offset, global, local, nullptr, &ev);
    dev_.profiler().record(ev);
    dev_.profiler().wait([&] { dev_.queue().finish(); });
  }
  // Runs kernel `name` over n work items with the parameter block, then `args` in order
  // (device buffers, or the scattering order as an int).
  using Args = std::initializer_list<std::variant<cl::Buffer*, int>>;
  void launch(const char* name, long long n, Args args) {
    cl_util::checked(name, [&] {
      cl::Kernel k = kernel(name, args);
      enqueue(k, n);
      return 0;
    });
  }
  // launch(), in slices of `slice` work items (rounded up to the launch's work group) from
  // increasing global offsets on a CPU device, `between` called after each slice but the last;
  // one launch elsewhere (a GPU runs it in milliseconds and wants it whole). The work groups are
  // the unsliced launch's, and every work item writes its own texel: the same values.
  void launch_sliced(const char* name, long long n, long long slice, const std::function<void()>& between, Args args) {
    const cl::NDRange group = group_for(n);
    if (dev_.info().type != "cpu" || slice >= n || group.dimensions() == 0) {
      launch(name, n, args);
      return;
    }
    const long long g = static_cast<long long>(group[0]);
    slice = (slice + g - 1) / g * g;
    cl_util::checked(name, [&] {
      cl::Kernel k = kernel(name, args);
      for (long long at = 0; at < n; at += slice) {
        const long long count = std::min(slice, n - at);
        enqueue(k, cl::NDRange(static_cast<std::size_t>(count)), group, cl::NDRange(static_cast<std::size_t>(at)));
        if (between && at + count < n) between();
      }
      return 0;
    });
  }
  void zero(cl::Buffer& b, long long n) {
    cl::Event ev;
    if (dbl_) dev_.queue().enqueueFillBuffer(b, 0.0, 0, n * sizeof(double), nullptr, &ev);
    else dev_.queue().enqueueFillBuffer(b, 0.0f, 0, n * sizeof(float), nullptr, &ev);
    dev_.profiler().record(ev);
  }
  void copy(const cl::Buffer& from, cl::Buffer& to, long long n) {
    cl::Event ev;
    dev_.queue().enqueueCopyBuffer(from, to, 0, 0, n * (dbl_ ? sizeof(double) : sizeof(float)), nullptr, &ev);
    dev_.profiler().record(ev);
  }
  // n reals of a buffer into `out` as double (float buffers through a staging copy kept between reads).
  void read_reals(const cl::Buffer& b, long long n, std::vector<double>& out) {
    out.resize(n);
    if (dbl_) {
      read_buffer(b, n * sizeof(double), out.data());
    } else {
      staging_.resize(n);
      read_buffer(b, n * sizeof(float), staging_.data());
      copy_chunks(staging_, out);
    }
  }
  // A blocking read, recorded with its wait.
  void read_buffer(const cl::Buffer& b, std::size_t bytes, void* to) {
    cl::Event ev;
    dev_.profiler().wait([&] { dev_.queue().enqueueReadBuffer(b, CL_TRUE, 0, bytes, to, nullptr, &ev); });
    dev_.profiler().record(ev);
  }
  // The device must read the parameter block exactly as the host wrote it.
  void check_layout() {
    cl_util::checked("atmosphere_layout", [&] {
      cl::Buffer reals(dev_.context(), CL_MEM_READ_WRITE, 6 * (dbl_ ? sizeof(double) : sizeof(float)));
      cl::Buffer ints(dev_.context(), CL_MEM_READ_WRITE, 3 * sizeof(int));
      cl::Kernel k(program_, "atmosphere_layout");
      k.setArg(0, block_.bytes.size(), block_.bytes.data());
      k.setArg(1, reals);
      k.setArg(2, ints);
      enqueue(k, 1);
      std::vector<double> r(6);
      if (dbl_) {
        read_buffer(reals, 6 * sizeof(double), r.data());
      } else {
        std::vector<float> f(6);
        read_buffer(reals, 6 * sizeof(float), f.data());
        std::copy(f.begin(), f.end(), r.begin());
      }
      std::vector<int> iv(3);
      read_buffer(ints, 3 * sizeof(int), iv.data());
      for (int i = 0; i < 6; ++i) {
        const double want = dbl_ ? block_.echo_reals[i] : static_cast<float>(block_.echo_reals[i]);
        if (r[i] != want)
          throw DeviceError("atmosphere parameter block: the device reads real #" + std::to_string(i) + " as " +
                            std::to_string(r[i]) + ", the host wrote " + std::to_string(want));
      }
      if (iv != block_.echo_ints)
        throw DeviceError("atmosphere parameter block: the device's layout (" + std::to_string(iv[2]) +
                          " bytes) differs from the host's (" + std::to_string(block_.echo_ints[2]) + " bytes)");
      return 0;
    });
  }

 private:
  // Work items per group for a kernel over n items. PoCL's CPU device runs a work group on one
  // thread and keeps a copy of each item's private arrays on that thread's stack where they live
  // across its work-item loop; left to choose, it takes the largest divisor of n up to 4096, and
  // the density's incidence table (16 channels, NU = 20, scattering 16 × · × 54: 3456 items of
  // ~2.8 KB) overran the 8 MiB stack and crashed the process. On a CPU device the group is the
  // largest divisor of n up to kCpuGroupLimit (the largest kernel, the density at NU = 64 and 16
  // channels, holds ~35 KB per item: 2.2 MiB a group); on other devices the driver chooses. The
  // kernels share nothing within a group, so the results do not depend on it.
  // Kernel `name` with the parameter block, then `args` in order (device buffers, or an int).
  cl::Kernel kernel(const char* name, Args args) const {
    cl::Kernel k(program_, name);
    k.setArg(0, block_.bytes.size(), block_.bytes.data());
    cl_uint i = 1;
    for (const auto& a : args) {
      if (const auto* b = std::get_if<cl::Buffer*>(&a)) k.setArg(i++, **b);
      else k.setArg(i++, std::get<int>(a));
    }
    return k;
  }
  cl::NDRange group_for(long long n) const {
    if (dev_.info().type != "cpu") return cl::NullRange;
    long long g = std::min<long long>(kCpuGroupLimit, n);
    while (g > 1 && n % g != 0) --g;
    return cl::NDRange(static_cast<std::size_t>(g));
  }
  static constexpr long long kCpuGroupLimit = 64;

  Device& dev_;
  int width_;
  bool dbl_;
  std::size_t lanes_;  // LANES: texels per work item of the row kernels, suns side by side in the density
  Block block_;
  cl::Program program_;
  std::vector<float> staging_;
};

// Work items of a texture scan (each takes every kScanItems-th texel): enough for a GPU's
// lanes, few enough that the partial maxima are a small read.
constexpr long long kScanItems = 4096;

// A pass's textures on the device, [texels][width] each.
struct DeviceTextures {
  cl::Buffer T, dE, dR, dM, dS, J;
};

// The sums, by kernels where the textures are (kernels.cl, "The sums"): the pass's scattering
// and irradiance, each order's R,G,B additions over the passes, and the bake's R,G,B textures.
class DeviceSums final : public Sums {
 public:
  DeviceSums(DeviceQueue& q, DeviceTextures& tex, const Model& m)
      : q_(q), tex_(tex), model_(m), n_e_(1LL * m.sizes.irradiance_w * m.sizes.irradiance_h),
        n_s_(m.sizes.scattering_texels()), width_(q.width()) {}

  void begin_pass(const std::vector<double>& to_rgb, bool last) override {
    if (!S_()) allocate_sums();
    to_rgb_ = cl_util::upload_real(q_.dev(), to_rgb, q_.dbl());
    last_pass_ = last;
  }
  void single() override {
    cl_util::checked("atmosphere sums", [&] {
      q_.copy(tex_.dR, S_, n_s_ * width_);
      q_.zero(E_, n_e_ * width_);
      return 0;
    });
    add_order(1, 0, tex_.dR, n_s_);
  }
  double add_irradiance(int order) override {
    q_.launch("add_values", n_e_ * width_, {&tex_.dE, static_cast<int>(n_e_ * width_), &E_});
    add_order(order, 1, tex_.dE, n_e_);
    return relative_change(tex_.dE, E_, n_e_);
  }
  double add_scattering(int order) override {
    if (!inverse_phase_())  // 1/P_R(ν) of every texel, decoded in double (as the host's reference does)
      inverse_phase_ = cl_util::upload_real(q_.dev(), inverse_rayleigh_phase(model_), q_.dbl());
    q_.launch("add_multiple_scattering", n_s_, {&tex_.dS, &inverse_phase_, &S_, &add_});
    add_order(order, 0, add_, n_s_);
    return relative_change(add_, S_, n_s_);
  }
  void end_pass() override {
    add_rgb(S_, n_s_, rgb_[0], !rgb_written_);
    add_rgb(E_, n_e_, rgb_[1], !rgb_written_);
    add_rgb(tex_.dM, n_s_, rgb_[2], !rgb_written_);
    rgb_written_ = true;
  }
  void read_pass(Sum s, std::vector<double>& out) override {
    cl_util::checked("reading an atmosphere sum", [&] {
      if (s == Sum::scattering) q_.read_reals(S_, n_s_ * width_, out);
      else if (s == Sum::irradiance) q_.read_reals(E_, n_e_ * width_, out);
      else q_.read_reals(tex_.dM, n_s_ * width_, out);
      return 0;
    });
  }
  void read_rgb(Sum s, std::vector<double>& out) override {
    cl_util::checked("reading an atmosphere sum", [&] {
      q_.read_reals(rgb_[static_cast<int>(s)], 3 * (s == Sum::irradiance ? n_e_ : n_s_), out);
      return 0;
    });
  }
  OrderRgb order_rgb(int order) override {
    const auto it = orders_.find(order);
    if (it == orders_.end()) return {};
    OrderSum& sum = it->second;
    for (int which : {0, 1})
      if (sum.added(which) && !sum.stats[which]) finish(sum, which);
    return order_rgb_of(sum.stats[0] ? &*sum.stats[0] : nullptr, sum.stats[1] ? &*sum.stats[1] : nullptr);
  }

 private:
  // The sums' buffers, on a pass's first use (a backend that only computes T needs none).
  void allocate_sums() {
    cl_util::checked("allocating the atmosphere sums", [&] {
      S_ = q_.alloc(n_s_);
      E_ = q_.alloc(n_e_);
      add_ = q_.alloc(n_s_);
      rgb_[0] = q_.alloc_reals(3 * n_s_);
      rgb_[1] = q_.alloc_reals(3 * n_e_);
      rgb_[2] = q_.alloc_reals(3 * n_s_);
      return 0;
    });
  }
  // rgb ([texels][3]) += to_rgb · x ([texels][width]), or = where first.
  void add_rgb(cl::Buffer& x, long long texels, cl::Buffer& rgb, bool first) {
    q_.launch("add_rgb", texels, {&x, &to_rgb_, static_cast<int>(texels), first ? 1 : 0, &rgb});
  }
  // What `order` adds ([texels][width]) into its R,G,B sum over passes (which: 0 scattering, 1
  // irradiance); in the last pass the sum is complete: its statistics are taken and it is freed.
  void add_order(int order, int which, cl::Buffer& x, long long texels) {
    OrderSum& sum = orders_[order];
    const bool first = !sum.added(which);
    if (first)
      cl_util::checked("allocating an order's sums", [&] {
        sum.rgb[which] = q_.alloc_reals(3 * texels);
        return 0;
      });
    add_rgb(x, texels, sum.rgb[which], first);
    if (last_pass_) finish(sum, which);
  }
  void finish(OrderSum& sum, int which) {
    sum.stats[which] = stats(sum.rgb[which], which == 0 ? n_s_ : n_e_, 3);
    sum.rgb[which] = cl::Buffer();
  }
  // Per channel max (floored at 0) and mean of x ([texels][channels]): partial results of
  // kScanItems work items, combined on the host in item order.
  ChannelStats stats(cl::Buffer& x, long long texels, int channels) {
    const int items = static_cast<int>(std::min<long long>(texels, kScanItems));
    ChannelStats st{std::vector<double>(channels, 0.0), std::vector<double>(channels, 0.0)};
    cl_util::checked("atmosphere sums", [&] {
      cl::Buffer mx = q_.alloc_reals(1LL * items * channels), sum = q_.alloc_reals(1LL * items * channels);
      q_.launch("channel_stats_partial", items, {&x, static_cast<int>(texels), channels, &mx, &sum});
      std::vector<double> m, t;
      q_.read_reals(mx, 1LL * items * channels, m);
      q_.read_reals(sum, 1LL * items * channels, t);
      for (int g = 0; g < items; ++g)
        for (int c = 0; c < channels; ++c) {
          st.max[c] = std::max(st.max[c], m[1LL * g * channels + c]);
          st.mean[c] += t[1LL * g * channels + c];
        }
      for (double& v : st.mean) v /= static_cast<double>(std::max<long long>(texels, 1));
      return 0;
    });
    return st;
  }
  // The largest |add| / sum where the sum exceeds kAutoFloor × its channel's maximum (Sums).
  double relative_change(cl::Buffer& add, cl::Buffer& sum, long long texels) {
    std::vector<double> floor = stats(sum, texels, width_).max;
    for (double& f : floor) f *= kAutoFloor;
    const int items = static_cast<int>(std::min<long long>(texels, kScanItems));
    double out = 0.0;
    cl_util::checked("atmosphere sums", [&] {
      cl::Buffer fl = cl_util::upload_real(q_.dev(), floor, q_.dbl()), partial = q_.alloc_reals(items);
      q_.launch("relative_change_partial", items, {&add, &sum, &fl, static_cast<int>(texels), &partial});
      std::vector<double> r;
      q_.read_reals(partial, items, r);
      for (double v : r) out = std::max(out, v);
      return 0;
    });
    return out;
  }

  DeviceQueue& q_;
  DeviceTextures& tex_;
  const Model& model_;
  long long n_e_, n_s_;
  int width_;
  // the pass's scattering and irradiance, an order's scattering addition, the channels → R,G,B
  // weights, the bake's R,G,B textures (as Sum numbers them) and per order its R,G,B additions
  // (scattering, irradiance; whether each is there yet)
  cl::Buffer S_, E_, add_, to_rgb_, inverse_phase_;  // null until first used
  std::array<cl::Buffer, 3> rgb_;
  bool rgb_written_ = false;  // by a pass's end
  std::map<int, OrderSum> orders_;
  bool last_pass_ = true;
};

// A pass on an OpenCL device: the stages' kernels over the pass's textures, their reads, and the
// sums over passes (DeviceSums).
class DeviceBackend final : public PassBackend {
 public:
  DeviceBackend(Device& dev, const Model& m, const Channels& ch, int width, bool dbl)
      : q_(dev, m, ch, width, dbl), model_(m), sizes_(m.sizes), width_(width), sums_(q_, tex_, model_) {
    n_t_ = 1LL * sizes_.transmittance_w * sizes_.transmittance_h;
    n_e_ = 1LL * sizes_.irradiance_w * sizes_.irradiance_h;
    n_s_ = sizes_.scattering_texels();
    allocate();
    q_.check_layout();
    // the density's phase factors: geometry and the phase functions only, the same for every pass
    q_.launch("density_phase_table", 1LL * sizes_.r * sizes_.mu, {&phase_factors_});
    row_group_ = choose_row_group();
    spdlog::debug("atmosphere: LANES {} (texels per work item of single and multiple scattering, suns side by side "
                  "in the density); multiple scattering {} ({} B of local memory per row, {} B on the device)",
                  q_.lane_count(),
                  row_group_ ? "in work groups of " + std::to_string(row_group_) + " per (mu, r) row" : "per texel",
                  row_columns_bytes(), q_.dev().info().local_mem_bytes);
  }
  int channels() const override { return width_; }

  void transmittance() override { q_.launch("transmittance_texture", n_t_, {&tex_.T}); }
  void direct_irradiance() override { q_.launch("direct_irradiance_texture", n_e_, {&tex_.T, &tex_.dE}); }
  // The ray-sample table depends on T only: built here, reused by every multiple_scattering().
  void single_scattering() override {
    q_.launch("ray_sample_table", 1LL * sizes_.r * sizes_.mu * (kScatteringSteps + 1), {&tex_.T, &rays_});
    q_.launch("single_scattering_texture", row_chunks(), {&tex_.T, &rays_, &tex_.dR, &tex_.dM});
  }
  void scattering_density(int order) override {
    q_.launch("density_incidence_table", 1LL * sizes_.r * sizes_.mu_s * model_.density_theta,
              {&tex_.T, &tex_.dR, &tex_.dM, &tex_.dS, order, &incidence_});
    q_.launch_sliced("scattering_density_texture", 1LL * sizes_.r * sizes_.mu * sizes_.mu_s,
                     1LL * sizes_.mu * sizes_.mu_s, between_slices,
                     {&incidence_, &phase_factors_, &tex_.dE, order, &tex_.J});
  }
  void indirect_irradiance(int order) override {
    q_.launch("indirect_irradiance_texture", n_e_, {&tex_.dR, &tex_.dM, &tex_.dS, order, &tex_.dE});
  }
  // One work group per (μ, r) row sharing its column blends in local memory
  // (multiple_scattering_texture), or, where the device's local memory cannot hold a row's
  // columns, one work item per texel (multiple_scattering_texels): the same operations.
  void multiple_scattering() override {
    if (row_group_ == 0) {
      q_.launch("multiple_scattering_texels", n_s_, {&rays_, &tex_.J, &tex_.dS});
      return;
    }
    cl_util::checked("multiple_scattering_texture", [&] {
      cl::Kernel k(q_.program(), "multiple_scattering_texture");
      k.setArg(0, q_.block().bytes.size(), q_.block().bytes.data());
      k.setArg(1, rays_);
      k.setArg(2, tex_.J);
      k.setArg(3, tex_.dS);
      k.setArg(4, cl::Local(row_columns_bytes()));
      const std::size_t rows = static_cast<std::size_t>(sizes_.r) * sizes_.mu;
      q_.enqueue(k, cl::NDRange(rows * row_group_), cl::NDRange(row_group_));
      return 0;
    });
  }

  void read_into(Tex t, std::vector<double>& out) override {
    cl_util::checked("reading an atmosphere texture", [&] {
      q_.read_reals(buffer(t), texels(t) * width_, out);
      return 0;
    });
  }
  void gather(Tex t, const std::vector<int>& ids, std::vector<double>& out) override {
    out.clear();
    if (ids.empty()) return;
    cl_util::checked("gathering atmosphere texels", [&] {
      const int n = static_cast<int>(ids.size());
      cl::Buffer at(q_.dev().context(), CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, ids.size() * sizeof(int),
                    const_cast<int*>(ids.data()));
      cl::Buffer values = q_.alloc_reals(1LL * n * width_);
      q_.launch("gather_texels", n, {&buffer(t), &at, n, &values});
      q_.read_reals(values, 1LL * n * width_, out);
      return 0;
    });
  }
  Scan scan(Tex t) override {
    Scan s{std::vector<double>(width_, 0.0), 0};
    cl_util::checked("scanning an atmosphere texture", [&] {
      const long long n = texels(t);
      const int items = static_cast<int>(std::min<long long>(n, kScanItems));
      cl::Buffer max_abs = q_.alloc_reals(1LL * items * width_);
      cl::Buffer bad(q_.dev().context(), CL_MEM_READ_WRITE, items * sizeof(int));
      q_.launch("scan_texture", items, {&buffer(t), static_cast<int>(n), &max_abs, &bad});
      std::vector<double> m;
      q_.read_reals(max_abs, 1LL * items * width_, m);
      std::vector<int> b(items);
      q_.read_buffer(bad, items * sizeof(int), b.data());
      for (int g = 0; g < items; ++g) {
        s.non_finite += b[g];
        for (int c = 0; c < width_; ++c) s.max_abs[c] = std::max(s.max_abs[c], m[1LL * g * width_ + c]);
      }
      return 0;
    });
    return s;
  }
  void add_density_sum(int order) override {
    const long long n = n_s_ * width_;
    if (order == 2) {
      if (J_sum_() == nullptr) J_sum_ = q_.alloc(n_s_);
      q_.copy(tex_.J, J_sum_, n);
    } else {
      q_.launch("add_values", n, {&tex_.J, static_cast<int>(n), &J_sum_});
    }
  }
  void keep_density() override {
    if (J_prev_() == nullptr) J_prev_ = q_.alloc(n_s_);
    q_.copy(tex_.J, J_prev_, n_s_ * width_);
  }
  void density_tail() override {
    const long long n = n_s_ * width_;
    q_.launch("density_tail", n, {&J_prev_, static_cast<int>(n), &tex_.J});
    J_prev_ = cl::Buffer();
  }
  void sky_view(int orders_used, std::vector<double>& out) override {
    const SkyView& v = model_.sky_view;
    cl_util::checked("sky_view_texture", [&] {
      cl::Buffer grid = cl_util::upload_real(q_.dev(),
                                             {v.altitude_min_km, v.altitude_max_km, v.sun_min_deg * M_PI / 180.0,
                                              v.sun_max_deg * M_PI / 180.0},
                                             q_.dbl());
      cl::Buffer values = q_.alloc(2 * v.texels());
      cl::Buffer samples =
          q_.alloc_reals(1LL * v.altitude * v.view * (kScatteringSteps + 1) * (kRayFixed + width_ + kSkyRayExtra));
      cl::Buffer& J = orders_used > 1 ? J_sum_ : tex_.J;
      q_.launch("sky_view_ray_samples", 1LL * v.altitude * v.view * (kScatteringSteps + 1),
                {&tex_.T, &grid, v.altitude, v.view, &samples});
      q_.launch("sky_view_texture", v.texels(),
                {&tex_.T, &J, orders_used > 1 ? 1 : 0, v.geometric_density ? 1 : 0, &grid, &samples, v.altitude, v.sun, v.view, v.azimuth,
                 &values});
      q_.read_reals(values, 2 * v.texels() * width_, out);
      return 0;
    });
  }
  cl_util::Profiler* profiler() override { return &q_.dev().profiler(); }
  Sums& sums() override { return sums_; }
  void use_channels(const Channels& ch) override { q_.use_block(make_block(model_, ch, width_, q_.dbl())); }

 private:
  // The pass's textures and the tables of the scattering stages: ray samples
  // [R][MU][SCATTERING_STEPS + 1][RAY_T + NCH], incidence [R][MU_S][density_theta][(2 NU + 1) NCH + INC_FIXED],
  // the density's phase factors [R][MU][2].
  void allocate() {
    const long long n_ray = 1LL * sizes_.r * sizes_.mu * (kScatteringSteps + 1) * (kRayFixed + width_);
    const long long n_inc =
        1LL * sizes_.r * sizes_.mu_s * model_.density_theta * (2 * sizes_.nu * width_ + width_ + kIncidenceFixed);
    cl_util::checked("allocating atmosphere textures", [&] {
      rays_ = q_.alloc_reals(n_ray);
      incidence_ = q_.alloc_reals(n_inc);
      phase_factors_ = q_.alloc_reals(2LL * sizes_.r * sizes_.mu);
      tex_.T = q_.alloc(n_t_);
      tex_.dE = q_.alloc(n_e_);
      tex_.dR = q_.alloc(n_s_);
      tex_.dM = q_.alloc(n_s_);
      tex_.dS = q_.alloc(n_s_);
      tex_.J = q_.alloc(n_s_);
      return 0;
    });
  }
  long long texels(Tex t) const {
    if (t == Tex::transmittance) return n_t_;
    if (t == Tex::delta_irradiance) return n_e_;
    return n_s_;
  }
  cl::Buffer& buffer(Tex t) {
    switch (t) {
      case Tex::transmittance: return tex_.T;
      case Tex::delta_irradiance: return tex_.dE;
      case Tex::delta_rayleigh: return tex_.dR;
      case Tex::delta_mie: return tex_.dM;
      case Tex::delta_multiple: return tex_.dS;
      case Tex::density: return tex_.J;
    }
    return tex_.T;
  }
  // Work items of a kernel that takes LANES texels of a (mu, r) row per item.
  long long row_chunks() const {
    const long long row = 1LL * sizes_.nu * sizes_.mu_s, lanes = static_cast<long long>(q_.lane_count());
    return 1LL * sizes_.r * sizes_.mu * ((row + lanes - 1) / lanes);
  }
  std::size_t row_columns_bytes() const {
    return static_cast<std::size_t>(sizes_.nu) * sizes_.mu_s * width_ * (q_.dbl() ? sizeof(double) : sizeof(float));
  }
  // Work-group size of the row kernel: the row's width over the texels per item, or the most
  // the kernel allows (items then take several rounds); 0 when the device's local memory cannot
  // hold the columns.
  std::size_t choose_row_group() {
    return cl_util::checked("sizing multiple_scattering_texture", [&]() -> std::size_t {
      cl::Kernel k(q_.program(), "multiple_scattering_texture");
      Device& dev = q_.dev();
      const cl::Device d = dev.context().getInfo<CL_CONTEXT_DEVICES>().front();
      const std::size_t most = k.getWorkGroupInfo<CL_KERNEL_WORK_GROUP_SIZE>(d);
      const unsigned long long fixed = k.getWorkGroupInfo<CL_KERNEL_LOCAL_MEM_SIZE>(d);
      if (fixed + row_columns_bytes() > dev.info().local_mem_bytes) return 0;
      const std::size_t row = static_cast<std::size_t>(sizes_.nu) * sizes_.mu_s;
      return std::min({most, dev.info().max_work_group_size, (row + q_.lane_count() - 1) / q_.lane_count()});
    });
  }

  DeviceQueue q_;
  Model model_;
  Sizes sizes_;
  int width_;
  long long n_t_ = 0, n_e_ = 0, n_s_ = 0;
  std::size_t row_group_ = 0;
  DeviceTextures tex_;
  cl::Buffer rays_, incidence_, phase_factors_, J_sum_, J_prev_;
  DeviceSums sums_;
};

// max over texels of |add| / acc, where acc exceeds kAutoFloor × its channel's maximum.
double relative_change(const std::vector<double>& add, const std::vector<double>& acc, int w) {
  const std::vector<double> floor = [&] {
    std::vector<double> f = channel_stats(acc, w).max;
    for (double& x : f) x *= kAutoFloor;
    return f;
  }();
  const std::size_t n = acc.size() / w;
  std::vector<double> rel((n + kSumChunk - 1) / kSumChunk, 0.0);
  parallel_chunks(n, kSumChunk, [&](std::size_t first, std::size_t last, std::size_t k) {
    for (std::size_t i = first; i < last; ++i)
      for (int c = 0; c < w; ++c) {
        const double a = acc[i * w + c];
        if (a > floor[c] && a > 0.0) rel[k] = std::max(rel[k], std::fabs(add[i * w + c]) / a);
      }
  });
  double out = 0.0;
  for (double r : rel) out = std::max(out, r);
  return out;
}

// 1 / P_R(ν) for every texel of the scattering texture: the slice's own ν (phase_nu_slice), or ν as
// the texel decodes it, clamped to the (μ, μ_s) column's feasible range (scattering_nu_of_slice, the
// reference's). The lookup multiplies by P_R of the view's ν, which lies between the slices around
// it: with the clamped ν, a texel whose slices all clamp (μ_s = 1, where every ν is μ) comes back
// scaled by P_R(ν_view)/P_R(μ) — up to 1.47× — and the coarse μ_s texels of a high sun blend it in
// (docs/atmosphere-method.md, "Daylight").
std::vector<double> inverse_rayleigh_phase(const Model& m) {
  const auto a = ref3::make_parameters(m, Channels{});
  const Sizes& s = m.sizes;
  const int wd = s.scattering_width();
  std::vector<double> out(s.scattering_texels());
  parallel_for(1LL * s.r * s.mu, [&](long long row) {  // row = z·MU + y
    const int y = static_cast<int>(row % s.mu), z = static_cast<int>(row / s.mu);
    for (int i = 0; i < s.mu_s; ++i) {
      double h, mu, mu_s, nu;
      int ground;
      ref3::scattering_params_from_texel(&a, i, y, z, &h, &mu, &mu_s, &nu, &ground);
      for (int k = 0; k < s.nu; ++k)
        out[row * wd + k * s.mu_s + i] =
            1.0 / ref3::rayleigh_phase(m.phase_nu_slice ? ref3::scattering_u_nu_of_slice(&a, k) * 2.0 - 1.0
                                                        : ref3::scattering_nu_of_slice(&a, k, mu, mu_s));
    }
  });
  return out;
}

// x ([texels][w]) → R,G,B ([texels][3]) by W (3 × w), added into rgb (sized on first use).
void add_rgb(const std::vector<double>& x, int w, const std::vector<double>& W, std::vector<double>& rgb) {
  const std::size_t n = x.size() / w;
  if (rgb.empty()) rgb.assign(3 * n, 0.0);
  parallel_chunks(n, kSumChunk, [&](std::size_t first, std::size_t last, std::size_t) {
    for (std::size_t t = first; t < last; ++t)
      for (int k = 0; k < 3; ++k) {
        double v = 0.0;
        for (int c = 0; c < w; ++c) v += W[k * w + c] * x[t * w + c];
        rgb[3 * t + k] += v;
      }
  });
}

// The identity on the first three channels (PassPlan::to_rgb left empty).
std::vector<double> first_three(int w) {
  std::vector<double> W(3 * w, 0.0);
  for (int k = 0; k < 3 && k < w; ++k) W[k * w + k] = 1.0;
  return W;
}

// Sums in double on the host, from the backend's textures (the reference of the device's).
class HostSums final : public Sums {
 public:
  HostSums(PassBackend& b, const Model& m) : b_(b), m_(m), w_(b.channels()) {}
  void begin_pass(const std::vector<double>& to_rgb, bool) override { W_ = to_rgb; }
  void single() override {
    b_.read_into(Tex::delta_rayleigh, scattering_);
    irradiance_.assign(static_cast<std::size_t>(m_.sizes.irradiance_w) * m_.sizes.irradiance_h * w_, 0.0);
    add_rgb(scattering_, w_, W_, orders_[1][0]);
  }
  double add_irradiance(int order) override {
    b_.read_into(Tex::delta_irradiance, add_);
    for (std::size_t i = 0; i < add_.size(); ++i) irradiance_[i] += add_[i];
    add_rgb(add_, w_, W_, orders_[order][1]);
    return relative_change(add_, irradiance_, w_);
  }
  double add_scattering(int order) override {
    if (inv_phase_.empty()) inv_phase_ = inverse_rayleigh_phase(m_);
    b_.read_into(Tex::delta_multiple, add_);
    for (std::size_t i = 0; i < add_.size(); ++i) {
      add_[i] *= inv_phase_[i / w_];
      scattering_[i] += add_[i];
    }
    add_rgb(add_, w_, W_, orders_[order][0]);
    return relative_change(add_, scattering_, w_);
  }
  void end_pass() override {
    add_rgb(scattering_, w_, W_, rgb_[0]);
    add_rgb(irradiance_, w_, W_, rgb_[1]);
    b_.read_into(Tex::delta_mie, add_);
    add_rgb(add_, w_, W_, rgb_[2]);
  }
  void read_pass(Sum s, std::vector<double>& out) override {
    if (s == Sum::scattering) out = scattering_;
    else if (s == Sum::irradiance) out = irradiance_;
    else b_.read_into(Tex::delta_mie, out);
  }
  void read_rgb(Sum s, std::vector<double>& out) override { out = rgb_[static_cast<int>(s)]; }
  OrderRgb order_rgb(int order) override {
    const auto& x = orders_[order];
    const ChannelStats s = channel_stats(x[0], 3), e = channel_stats(x[1], 3);
    return order_rgb_of(x[0].empty() ? nullptr : &s, x[1].empty() ? nullptr : &e);
  }

 private:
  PassBackend& b_;
  Model m_;
  int w_;
  std::vector<double> W_, scattering_, irradiance_, add_, inv_phase_;
  std::array<std::vector<double>, 3> rgb_;                     // as Sum numbers them
  std::map<int, std::array<std::vector<double>, 2>> orders_;   // per order: scattering, irradiance (R,G,B)
};

// The textures a stage reads and writes, as the reference recomputes them.
struct StageTextures {
  std::vector<Tex> inputs, outputs;
};
StageTextures textures_of(PassStage stage, int order) {
  switch (stage) {
    case PassStage::transmittance: return {{}, {Tex::transmittance}};
    case PassStage::direct_irradiance: return {{Tex::transmittance}, {Tex::delta_irradiance}};
    case PassStage::single_scattering: return {{Tex::transmittance}, {Tex::delta_rayleigh, Tex::delta_mie}};
    case PassStage::scattering_density:
      // order 2 reads single scattering, later orders the previous multiple order
      if (order == 2)
        return {{Tex::transmittance, Tex::delta_irradiance, Tex::delta_rayleigh, Tex::delta_mie}, {Tex::density}};
      return {{Tex::transmittance, Tex::delta_irradiance, Tex::delta_multiple}, {Tex::density}};
    case PassStage::indirect_irradiance:
      if (order == 1) return {{Tex::delta_rayleigh, Tex::delta_mie}, {Tex::delta_irradiance}};
      return {{Tex::delta_multiple}, {Tex::delta_irradiance}};
    case PassStage::multiple_scattering: return {{Tex::transmittance, Tex::density}, {Tex::delta_multiple}};
  }
  return {};
}

template <class HB>
class HostStageChecker final : public StageChecker {
 public:
  HostStageChecker(const Model& m, const Channels& ch, int count, double floor)
      : h_(m, ch), count_(count), floor_(floor) {}

  StageCheck check(PassBackend& b, PassStage stage, int order) override {
    const int w = b.channels();
    const StageTextures io = textures_of(stage, order);
    // per output and channel the largest |value| and the values that are not finite, over the
    // whole texture where it is
    std::vector<double> scale;
    long long non_finite = 0;
    for (Tex t : io.outputs) {
      const PassBackend::Scan sc = b.scan(t);
      scale.insert(scale.end(), sc.max_abs.begin(), sc.max_abs.end());
      non_finite += sc.non_finite;
    }
    const long long n = h_.texels(io.outputs[0]);
    StageCheck r{to_string(stage), order, static_cast<int>(std::min<long long>(count_, n)), 0.0, non_finite};
    if (non_finite > 0) r.max_rel = std::numeric_limits<double>::infinity();
    else r.max_rel = sampled_error(b, stage, order, io, w, n, scale, r.texels);
    return r;
  }

 private:
  // The largest relative error of `texels` texels spread over the texture, recomputed in double
  // from the input texels the recomputation reads, gathered from the device.
  double sampled_error(PassBackend& b, PassStage stage, int order, const StageTextures& io, int w, long long n,
                       const std::vector<double>& scale, int texels) {
    std::vector<int> ids(texels);
    for (int k = 0; k < texels; ++k)  // spread over the texture: a fixed multiplicative stride
      ids[k] = static_cast<int>((k * 2654435761LL + 12345) % n);
    // The inputs at full size, for the lookups' arithmetic (memory only where texels are put).
    std::array<const double*, TexelReads::kTextures> bases{};
    for (Tex t : io.inputs) {
      h_.texture(t).resize(static_cast<std::size_t>(h_.texels(t)) * w);
      bases[static_cast<int>(t)] = h_.texture(t).data();
    }
    // Which input texels each recomputation reads (on whatever the copies hold: the coordinates
    // of a lookup do not depend on the values) ...
    std::vector<TexelReads> reads(texels, TexelReads(bases, w));
    std::vector<double> want(static_cast<std::size_t>(texels) * 2 * w);
    parallel_for(texels, [&](long long k) {
      TexelReads::Scope scope(reads[k]);
      h_.texel(stage, order, ids[k], &want[k * 2 * w]);
    });
    // ... fetched from the device, every input texel once, into the copies ...
    std::vector<std::array<std::vector<long long>, TexelReads::kTextures>> read_by(texels);
    for (int k = 0; k < texels; ++k) read_by[k] = reads[k].sorted();
    std::vector<double> values;
    long long gathered = 0;
    for (Tex t : io.inputs) {
      std::vector<long long> all;
      for (const auto& rd : read_by) all.insert(all.end(), rd[static_cast<int>(t)].begin(), rd[static_cast<int>(t)].end());
      std::sort(all.begin(), all.end());
      all.erase(std::unique(all.begin(), all.end()), all.end());
      const std::vector<int> at(all.begin(), all.end());
      b.gather(t, at, values);
      gathered += static_cast<long long>(at.size());
      HostTexture& copy = h_.texture(t);
      for (std::size_t i = 0; i < at.size(); ++i)
        for (int c = 0; c < w; ++c) copy[static_cast<std::size_t>(at[i]) * w + c] = values[i * w + c];
    }
    // ... and the sampled texels of the outputs.
    std::vector<std::vector<double>> got;
    for (Tex t : io.outputs) {
      got.emplace_back();
      b.gather(t, ids, got.back());
    }
    spdlog::debug("atmosphere: self-check of {} (order {}): {} texels gathered", to_string(stage), order,
                  gathered + static_cast<long long>(ids.size() * io.outputs.size()));
    // The recomputations on the fetched values, which must read the same texels.
    const int k_out = static_cast<int>(io.outputs.size());
    std::vector<double> errs(texels, 0.0);
    std::vector<char> same(texels, 1);
    parallel_for(texels, [&](long long k) {
      TexelReads again(bases, w);
      {
        TexelReads::Scope scope(again);
        h_.texel(stage, order, ids[k], &want[k * 2 * w]);
      }
      same[k] = again.sorted() == read_by[k];
      double e = 0.0;
      for (int o = 0; o < k_out; ++o)
        for (int c = 0; c < w; ++c) {
          const double ref = want[k * 2 * w + o * w + c], dev = got[o][k * w + c];
          e = std::max(e, std::fabs(dev - ref) / (std::fabs(ref) + floor_ * scale[o * w + c] + 1e-300));
        }
      errs[k] = e;
    });
    if (std::find(same.begin(), same.end(), 0) != same.end())
      throw std::logic_error(std::string("self-check of ") + to_string(stage) +
                             ": the recomputation read other texels on the fetched values than before");
    double worst = 0.0;
    for (double e : errs) worst = std::max(worst, e);
    return worst;
  }

  HB h_;
  int count_;
  double floor_;
};

}  // namespace

std::unique_ptr<PassBackend> make_device_backend(Device& dev, const Model& m, const Channels& ch, int width,
                                                 bool double_precision) {
  return std::make_unique<DeviceBackend>(dev, m, ch, width, double_precision);
}

std::unique_ptr<PassBackend> make_host_backend(const Model& m, const Channels& ch, int width) {
  return with_width(width, [&](auto ref) -> std::unique_ptr<PassBackend> {
    return std::make_unique<typename decltype(ref)::Backend>(m, ch);
  });
}

std::unique_ptr<Sums> make_host_sums(PassBackend& b, const Model& m) { return std::make_unique<HostSums>(b, m); }

const char* to_string(Sum s) {
  switch (s) {
    case Sum::scattering: return "scattering";
    case Sum::irradiance: return "irradiance";
    case Sum::single_mie: return "single_mie";
  }
  return "?";
}

std::unique_ptr<StageChecker> make_stage_checker(const Model& m, const Channels& ch, int width, int count,
                                                 double floor) {
  return with_width(width, [&](auto ref) -> std::unique_ptr<StageChecker> {
    return std::make_unique<HostStageChecker<typename decltype(ref)::Backend>>(m, ch, count, floor);
  });
}

const char* to_string(PassStage s) {
  switch (s) {
    case PassStage::transmittance: return "transmittance";
    case PassStage::direct_irradiance: return "direct_irradiance";
    case PassStage::single_scattering: return "single_scattering";
    case PassStage::scattering_density: return "scattering_density";
    case PassStage::indirect_irradiance: return "indirect_irradiance";
    case PassStage::multiple_scattering: return "multiple_scattering";
  }
  return "?";
}

namespace {

// The times of a pass: every moment belongs to one stage, a timed stage, a hook ("self_check")
// or the work in between ("sums": the sums' kernels on a device, on the host's threads for the
// host backend, and reads; with the order of the stage after it).
class PassTimeline {
 public:
  explicit PassTimeline(PassBackend& b) : prof_(b.profiler() ? *b.profiler() : own_), gap_(std::in_place, prof_, "sums", 0) {}

  // Runs f as stage `stage` of `order`, closing the gap before it.
  template <class F>
  void stage(const std::string& stage, int order, F&& f) {
    close_gap(order);
    {
      cl_util::Profiler::Stage st(prof_, stage, order);
      f();
      records_.push_back(st.close());
    }
    logged_.push_back(records_.back()->pending == 0);  // the stage's commands are done: log now
    if (logged_.back()) log(*records_.back());
    gap_.emplace(prof_, "sums", order);
  }

  // The pass's stages, once its last gap (of `order`) is closed and the device's times are in.
  std::vector<StageTime> finish(int order) {
    close_gap(order);
    prof_.settle();  // times of commands still running when their stage closed
    std::vector<StageTime> out;
    for (std::size_t i = 0; i < records_.size(); ++i) {
      const cl_util::StageSeconds& s = *records_[i];
      if (!logged_[i]) log(s);
      if (s.stage == "sums" && s.wall_s == 0.0 && s.commands == 0) continue;
      out.push_back({s.stage, s.order, s});
    }
    return out;
  }

 private:
  void close_gap(int order) {
    gap_->record()->order = order;
    records_.push_back(gap_->close());
    logged_.push_back(true);
    gap_.reset();
  }
  static void log(const cl_util::StageSeconds& s) {
    spdlog::debug("atmosphere: {} (order {}): device {:.3f} s, host {:.3f} s (wall {:.3f} s)", s.stage, s.order,
                  s.device_s, s.host_s(), s.wall_s);
  }

  cl_util::Profiler own_;  // the host backend enqueues nothing: device_s stays 0
  cl_util::Profiler& prof_;
  std::vector<cl_util::Profiler::Record> records_;
  std::vector<bool> logged_;
  std::optional<cl_util::Profiler::Stage> gap_;
};

// The pass's share [p0, p1] of the job's progress, by the rough relative cost of its stages.
class PassProgress {
 public:
  PassProgress(const Progress& progress, const PassPlan& plan, int cap, double p0, double p1)
      : progress_(progress), p0_(p0), p1_(p1), total_(0.12 + 0.72 * std::max(0, (plan.auto_orders ? 6 : cap) - 1)) {}
  void step(const std::string& stage, double cost) {
    done_ += cost;
    progress_(stage, p0_ + (p1_ - p0_) * std::min(1.0, done_ / total_));
  }
  // Within a stage: the fraction so far, under the stage's name.
  void within(const std::string& stage) const { progress_(stage, p0_ + (p1_ - p0_) * std::min(1.0, done_ / total_)); }

 private:
  const Progress& progress_;
  double p0_, p1_, total_, done_ = 0.0;
};

}  // namespace

PassResult run_pass(PassBackend& b, const PassPlan& plan, const Progress& progress,
                    double p0, double p1, StageChecker* checker, const CheckHook& on_check) {
  const int w = b.channels();
  const int cap = plan.auto_orders ? kMaxAutoOrders : plan.orders;
  PassProgress steps(progress, plan, cap, p0, p1);
  struct NoSlicesAfter {  // the hook refers to this frame: gone with it, however run_pass ends
    PassBackend& b;
    ~NoSlicesAfter() { b.between_slices = nullptr; }
  } no_slices_after{b};
  PassResult r;
  r.width = w;
  PassTimeline timeline(b);
  auto hook = [&](PassStage stage, int order) {
    if (!checker) return;
    timeline.stage("self_check", order, [&] {
      const StageCheck c = checker->check(b, stage, order);
      if (on_check) on_check(c);
    });
  };
  auto timed = [&](PassStage what, int order, auto&& f) {
    timeline.stage(to_string(what), order, f);
    hook(what, order);
  };
  Sums& sums = b.sums();
  sums.begin_pass(plan.to_rgb.empty() ? first_three(w) : plan.to_rgb, plan.last_pass);

  timed(PassStage::transmittance, 0, [&] { b.transmittance(); });
  timed(PassStage::direct_irradiance, 0, [&] { b.direct_irradiance(); });
  if (plan.keep_textures) {
    b.read_into(Tex::transmittance, r.transmittance);
    b.read_into(Tex::delta_irradiance, r.direct_irradiance);
  }
  steps.step("transmittance", 0.02);
  timed(PassStage::single_scattering, 1, [&] { b.single_scattering(); });
  sums.single();
  steps.step("single scattering", 0.1);
  r.orders.push_back({1, 1.0});
  r.orders_used = 1;
  r.converged = !plan.auto_orders;
  const bool tail = plan.tail && !plan.auto_orders && cap >= 3;
  for (int n = 2; n <= cap; ++n) {
    const std::string density = "order " + std::to_string(n) + ": scattering density";
    b.between_slices = [&] { steps.within(density); };
    if (tail && n == cap) b.keep_density();
    timed(PassStage::scattering_density, n, [&] { b.scattering_density(n); });
    if (tail && n == cap) timeline.stage("density_tail", n, [&] { b.density_tail(); });
    if (plan.sky_view) timeline.stage("sky_view", n, [&] { b.add_density_sum(n); });
    steps.step(density, 0.55);
    timed(PassStage::indirect_irradiance, n - 1, [&] { b.indirect_irradiance(n - 1); });
    const double rel_e = sums.add_irradiance(n - 1);
    steps.step("order " + std::to_string(n) + ": indirect irradiance", 0.02);
    timed(PassStage::multiple_scattering, n, [&] { b.multiple_scattering(); });
    const double rel_s = sums.add_scattering(n);
    r.orders.push_back({n, std::max(rel_s, rel_e)});
    r.orders_used = n;
    steps.step("order " + std::to_string(n) + ": multiple scattering", 0.15);
    spdlog::debug("atmosphere: order {} adds at most {:.3e} (relative)", n, r.orders.back().relative);
    if (plan.auto_orders && r.orders.back().relative < plan.tolerance) {
      r.converged = true;
      break;
    }
  }
  if (tail) {  // the irradiance of the light of orders ≥ cap, from its multiple scattering
    timed(PassStage::indirect_irradiance, cap, [&] { b.indirect_irradiance(cap); });
    r.orders.back().relative = std::max(r.orders.back().relative, sums.add_irradiance(cap));
  }
  if (plan.sky_view) {
    timeline.stage("sky_view", 0, [&] { b.sky_view(r.orders_used, r.sky_view); });
  }
  sums.end_pass();
  if (plan.keep_textures) {
    sums.read_pass(Sum::scattering, r.scattering);
    sums.read_pass(Sum::irradiance, r.irradiance);
    sums.read_pass(Sum::single_mie, r.single_mie);
  }
  r.timings = timeline.finish(r.orders_used);
  return r;
}

}  // namespace specbake::atmosphere
