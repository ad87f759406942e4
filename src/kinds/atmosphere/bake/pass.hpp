#pragma once
// One precomputation pass (Bruneton's Algorithm 4.1) over up to a few channels
// (wavelengths): transmittance, direct irradiance, single scattering, then per order n ≥ 2
// the scattering density J_n, the indirect irradiance of order n − 1 and the multiple
// scattering of order n, accumulated exactly as the reference does:
//   irradiance += ΔE_{n−1} (indirect only; the direct sun is never added),
//   scattering  = single Rayleigh + Σ_n ΔS_n / P_R(ν_texel)   (ν clamped to its valid range),
//   single_mie  = single Mie,
// in the backend's Sums (on a device by kernels). The same driver runs the OpenCL kernels (DeviceBackend) or the double reference
// (host backend, reference.hpp) through the PassBackend interface.
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "cl/device.hpp"
#include "kinds/atmosphere/model/model.hpp"
#include "job/kind.hpp"

namespace specbake::atmosphere {

// Channel widths with a compiled reference path (and so a self-check).
// The OpenCL program of the atmosphere kernels (embedded path).
inline constexpr const char* kProgram = "kernels/atmosphere/kernels.cl";

// The stages of a pass, in the order they first run (paper Algorithm 4.1).
enum class PassStage {
  transmittance,        // T
  direct_irradiance,    // ΔE of the sun
  single_scattering,    // ΔS_R, ΔS_M
  scattering_density,   // ΔJ of order n
  indirect_irradiance,  // ΔE of order n − 1
  multiple_scattering,  // ΔS of order n
};
const char* to_string(PassStage s);

inline constexpr int kPassWidths[] = {3, 4, 8, 16};
int pass_width_for(std::size_t channels);  // smallest of kPassWidths ≥ channels, else the largest

enum class Tex { transmittance, delta_irradiance, delta_rayleigh, delta_mie, delta_multiple, density };
const char* to_string(Tex t);

enum class Sum { scattering, irradiance, single_mie };
const char* to_string(Sum s);

// Per order, the R,G,B maximum (floored at 0) and mean over texels of what it adds to the
// scattering and to the irradiance (empty: nothing added to the irradiance — the last order's light).
struct OrderRgb {
  std::vector<double> scattering_max, scattering_mean, irradiance_max, irradiance_mean;
};

// The sums of a bake (Algorithm 4.1's accumulation, the bundle's R,G,B textures, each order's
// statistics), kept by the backend where its textures are: on a device by kernels
// (kernels.cl, "The sums"), on the host in double (make_host_sums, their reference). run_pass
// calls them in this order per pass: begin_pass, single, then per order n ≥ 2 add_irradiance(n − 1)
// and add_scattering(n), then end_pass. The relative change of a sum is the largest
// |what was added| / sum over texels and channels where the sum exceeds kAutoFloor × the
// channel's maximum.
class Sums {
 public:
  virtual ~Sums() = default;
  // A pass begins; its channels map to R, G, B by to_rgb (3 × channels, R's weights first). In
  // the bake's last pass an order's R,G,B addition is complete as it comes: the device takes its
  // statistics then and frees it (it keeps one per order only while later passes will add to it).
  virtual void begin_pass(const std::vector<double>& to_rgb, bool last) = 0;
  // After single scattering: scattering ← ΔR, irradiance ← 0; order 1 adds to_rgb·ΔR.
  virtual void single() = 0;
  // irradiance += ΔE, the indirect irradiance of the light of `order`; its relative change.
  virtual double add_irradiance(int order) = 0;
  // add ← ΔS / P_R(ν of the texel), scattering += add, of `order`; its relative change.
  virtual double add_scattering(int order) = 0;
  // The pass ends: the bake's R,G,B textures += to_rgb·(scattering, irradiance, ΔM).
  virtual void end_pass() = 0;
  // The pass's sums in its channels, [texels][channels] (single_mie: ΔM).
  virtual void read_pass(Sum s, std::vector<double>& out) = 0;
  // The bake's R,G,B textures over the passes so far, [texels][3].
  virtual void read_rgb(Sum s, std::vector<double>& out) = 0;
  // What `order` added over the passes so far, in R,G,B.
  virtual OrderRgb order_rgb(int order) = 0;
};

class PassBackend;
// The sums in double on the host, from the backend's textures as read_into reads them.
std::unique_ptr<Sums> make_host_sums(PassBackend& b, const Model& m);

class PassBackend {
 public:
  virtual ~PassBackend() = default;
  virtual int channels() const = 0;
  virtual void transmittance() = 0;                   // T
  virtual void direct_irradiance() = 0;               // ΔE ← direct
  virtual void single_scattering() = 0;               // ΔR, ΔM
  virtual void scattering_density(int order) = 0;     // J ← f(T, ΔR, ΔM, ΔS, ΔE)
  virtual void indirect_irradiance(int order) = 0;    // ΔE ← indirect from scattering of `order`
  virtual void multiple_scattering() = 0;             // ΔS ← f(T, J)
  // [texels][channels()] into `out`, resized (its storage is reused when large enough)
  virtual void read_into(Tex t, std::vector<double>& out) = 0;
  std::vector<double> read(Tex t) {
    std::vector<double> out;
    read_into(t, out);
    return out;
  }
  // Texels ids[k] of t, [ids.size()][channels()], into `out`: a gather, so only those texels
  // leave the device (the self-checks' fetches).
  virtual void gather(Tex t, const std::vector<int>& ids, std::vector<double>& out) = 0;
  // Over every texel of t: per channel the largest |value| of its finite values, and how many
  // values (texel × channel) are NaN or ±inf (a reduction where the texture is).
  struct Scan {
    std::vector<double> max_abs;
    long long non_finite = 0;
  };
  virtual Scan scan(Tex t) = 0;
  // The bake's sums, kept where the textures are (below).
  virtual Sums& sums() = 0;
  // The channels of the next pass (same count): a backend serves every pass of a bake, so that
  // its sums over passes stay where they are.
  virtual void use_channels(const Channels& ch) = 0;
  // The sky-view table (Model::sky_view; atmosphere.cl, sky_view_texel): add_density_sum(n), called
  // after scattering_density(n), keeps J_sum = Σ J_n over the pass's orders (n = 2 starts it);
  // sky_view then computes the table of the pass's channels from T and J_sum into `out`,
  // [texels][2 · channels()] (radiance without single Mie, then single Mie without its phase).
  virtual void add_density_sum(int order) = 0;
  virtual void sky_view(int orders_used, std::vector<double>& out) = 0;
  // `orders_tail: geometric` (run_pass, around the last order's density): keep_density sets the
  // current J (the order before) aside; density_tail then makes J the density of every order from
  // the last on, geometric_tail(J, kept) per value (atmosphere.cl), and lets the kept one go.
  // The tail is not a stage of its own: the density's self-check sees J before it, the multiple
  // scattering's the tailed J it reads; the tests hold it to the double reference.
  virtual void keep_density() = 0;
  virtual void density_tail() = 0;
  // Where the backend's device commands are recorded (cl/timing.hpp); null: no device.
  virtual cl_util::Profiler* profiler() { return nullptr; }
  // Called between the slices of a long launch (a CPU device runs the scattering density one
  // altitude layer at a time): run_pass reports progress there, where a stop request (Ctrl-C)
  // lands instead of after the whole launch. It may throw; the launch then stops.
  std::function<void()> between_slices;
};

// The OpenCL backend: kernels built with NCH = width and float (or double) arithmetic.
std::unique_ptr<PassBackend> make_device_backend(cl_util::Device& dev, const Model& m, const Channels& ch, int width,
                                                 bool double_precision);
// The double-precision reference backend (threads over texels).
std::unique_ptr<PassBackend> make_host_backend(const Model& m, const Channels& ch, int width);

struct OrderStats {
  int order = 0;
  double relative = 0.0;  // the larger relative change of the scattering and irradiance sums (Sums)
};

// Seconds of one stage as cl_util::StageSeconds defines them: device_s from the profiling
// events of its commands, host_s = wall_s minus the time the host waited for the device.
struct StageTime {
  std::string stage;  // "transmittance", ..., "self_check" (the hooks), "sums" (the sums and reads between stages)
  int order = 0;
  cl_util::StageSeconds seconds;
};

struct PassResult {
  int width = 0;
  std::vector<StageTime> timings;  // in the order they ran
  std::vector<double> transmittance, direct_irradiance, irradiance, scattering, single_mie;
  std::vector<double> sky_view;  // [texels][2 · width] where the model has one (PassBackend::sky_view)
  std::vector<OrderStats> orders;  // 1..orders_used (order 1: single scattering)
  int orders_used = 0;
  bool converged = true;  // auto: the tolerance was met before the order cap
};

struct PassPlan {
  int orders = 4;           // fixed count, or the cap when auto
  bool auto_orders = false;
  double tolerance = 1e-3;
  std::vector<double> to_rgb;  // the pass's channels → R, G, B (Sums::begin_pass); empty: channel c → c
  bool last_pass = true;       // the bake's last pass (Sums::begin_pass)
  bool keep_textures = true;   // PassResult's textures read back at the end
  bool sky_view = false;       // the model's sky-view table into PassResult::sky_view
  // The orders beyond the last as a geometric series (`orders_tail: geometric`; fixed orders ≥ 3 here,
  // kMinTailOrders (4) in a config):
  // the last order's density becomes J_{≥n} before its multiple scattering and the sky-view sum,
  // and one more indirect irradiance (of the light of orders ≥ n) is added.
  bool tail = false;
};
inline constexpr int kMaxAutoOrders = 40;
// Texels whose accumulated value is below this fraction of their channel's maximum do not
// enter the relative change of `orders: auto` (0/0 in the dark).
inline constexpr double kAutoFloor = 1e-4;
// Elements per chunk of the host's sums over a texture (parallel_chunks: the same bytes whatever
// the thread count).
inline constexpr std::size_t kSumChunk = 1 << 14;

// Self-checks of one pass: after each stage, recomputes `count` texels of its output in double
// from the backend's own inputs and returns the largest |device − reference| / (|reference| +
// floor·max|device|), or +inf with the count when any value of the outputs, anywhere in the
// texture, is not finite. Only what a check recomputes leaves the device: the maxima and the
// non-finite count come from scans where the texture is (PassBackend::scan), and the sampled
// texels with exactly the input texels their recomputation reads from gathers
// (PassBackend::gather; texel_reads.hpp). run_pass calls it after every stage.
struct StageCheck {
  std::string stage;
  int order = 0;
  int texels = 0;
  double max_rel = 0.0;       // +inf when any value is not finite
  long long non_finite = 0;   // values (texel × channel) of the stage's outputs that are NaN or ±inf
};
class StageChecker {
 public:
  virtual ~StageChecker() = default;
  virtual StageCheck check(PassBackend& b, PassStage stage, int order) = 0;
};
std::unique_ptr<StageChecker> make_stage_checker(const Model& m, const Channels& ch, int width, int count,
                                                 double floor);

// Called with each stage's check when run_pass is given a checker.
using CheckHook = std::function<void(const StageCheck& check)>;

// Runs the pass, its sums in b.sums(); with a checker, checks every stage after it runs
// (reported through on_check).
PassResult run_pass(PassBackend& b, const PassPlan& plan, const Progress& progress,
                    double progress_from, double progress_to, StageChecker* checker = nullptr,
                    const CheckHook& on_check = {});

}  // namespace specbake::atmosphere
