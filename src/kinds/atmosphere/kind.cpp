// The atmosphere kind's entry in the kind table.
#include "kinds/atmosphere/kind.hpp"

#include <algorithm>
#include <cstdio>

#include "atmosphere/limits.h"
#include "kinds/atmosphere/atmosphere_job.hpp"
#include "kinds/atmosphere/model/model.hpp"
#include "kinds/atmosphere/truth/truth.hpp"

namespace specbake::atmosphere {

namespace {

MemoryEstimate device_memory(const AtmosphereSpec& s) {
  // One pass of w channels (channels_per_pass) keeps six 4D textures on the device (the two
  // single-scattering deltas, the multiple-scattering delta, the density, the pass's scattering
  // sum and an order's addition to it), a ray-sample table per (r, mu) texel row
  // (SCATTERING_STEPS + 1 samples of RAY_FIXED + w values) and a density incidence table per
  // (r, mu_s) (density_theta directions of (2·nu + 1)·w + INC_FIXED values), plus the
  // small 2D textures; the sums over passes (pass.hpp's Sums) add the bundle's two R,G,B 4D
  // textures, 1/P_R per texel and each order's R,G,B addition while later passes add to it (all
  // orders' with several passes: the order count, or for `orders: auto` its cap; one at a time
  // with one pass).
  const std::uint64_t w = channels_per_pass(s);
  const std::uint64_t real = s.double_precision ? 8 : 4;
  const std::uint64_t texels = std::uint64_t(s.scattering_r) * s.scattering_mu * s.scattering_mu_s * s.scattering_nu;
  const std::uint64_t texture = texels * w * real;
  const std::uint64_t rays = std::uint64_t(s.scattering_r) * s.scattering_mu * (SCATTERING_STEPS + 1) * (RAY_FIXED + w) * real;
  const std::uint64_t incidence = std::uint64_t(s.scattering_r) * s.scattering_mu_s * s.density_theta *
                                  ((2 * s.scattering_nu + 1) * w + INC_FIXED) * real;
  const std::uint64_t channels = s.spectral ? s.count : 3, passes = (channels + w - 1) / w;
  const std::uint64_t orders_kept = passes > 1 ? std::uint64_t(s.orders.value_or(kMaxAutoOrders)) : 1;
  const std::uint64_t sums = texels * real * (2 * 3 + 1 + 3 * orders_kept);
  // Host: the bundle's R,G,B textures in double (scattering and single Mie) and the float32
  // staging of their reads, 1/P_R per texel in double, the 2D textures likewise, the encoded files
  // (float32 + EXR) of the 4D textures; with `store: radiance` a pass's textures read in double.
  const std::uint64_t t2d = std::uint64_t(s.transmittance_mu) * s.transmittance_r +
                            std::uint64_t(s.irradiance_mu_s) * s.irradiance_r;
  std::uint64_t host = texels * 8 * (2 * 3 + 1) + texels * 4 * 3 + t2d * 8 * (3 * 3 + 4 * w) +
                       texels * 3 * 4 * 4 + (std::uint64_t{1} << 26);
  if (s.store_radiance) host += texels * 8 * 3 * w;
  // store: radiance: the float32 textures at every wavelength, and their files (.bin, the Spectral
  // OpenEXR and its pixel copy, KTX2), all alive until the bundle is written
  if (s.store_radiance)
    host += (2 * texels + t2d) * std::uint64_t(s.count) * 4 * (s.ktx2.enabled ? 5 : 4);
  // The scene check: its traces (the bake's channels, then the 48-wavelength reference) one
  // after the other, counted as if alive beside the bake's buffers.
  TruthMemory check;
  if (s.scene.check) {
    const std::size_t points = static_cast<std::size_t>(s.scene.points);
    const TruthMemory a = truth_memory(points, s.spectral ? s.count : 3), b = truth_memory(points, 48);
    check = {std::max(a.host, b.host), std::max(a.device, b.device), std::max(a.largest_buffer, b.largest_buffer)};
  }
  // The sky-view table (where the scene has one): the density summed over orders (one more 4D
  // texture), its values (2·w per texel), its rays' samples; on the host its R,G,B sums in double
  // and the pass's values read back.
  const SkyView v = sky_view_of(s);
  const std::uint64_t table = std::uint64_t(v.texels()) * 2 * w * real,
                      table_rays = std::uint64_t(v.altitude) * v.view * (SCATTERING_STEPS + 1) * (RAY_FIXED + w) * real,
                      table_device = v.on() ? texture + table + table_rays : 0;
  host += std::uint64_t(v.texels()) * 8 * (2 * 3 + 2 * w);
  // orders_tail: the order before the last one's density, kept while that is computed
  const std::uint64_t tail = takes_geometric_tail(s) ? texture : 0;
  return MemoryEstimate{6 * texture + tail + sums + rays + incidence + table_device + (std::uint64_t{1} << 24) + check.device,
                        std::max({texture, rays, incidence, table, check.largest_buffer}), host + check.host};
}

}  // namespace

Kind kind() {
  Kind k = Kind::of<AtmosphereSpec>("atmosphere", "Bruneton 2017 precomputed atmospheric scattering LUTs, all orders", parse_spec, plan, bake);
  k.cost_s = [](const JobSpec& j) { return estimated_seconds(j.as<AtmosphereSpec>()); };
  k.kept_cost_s = [](const JobSpec& j, JobContext& ctx) { return kept_estimated_seconds(j.as<AtmosphereSpec>(), ctx); };
  k.memory = [](const JobSpec& j) { return device_memory(j.as<AtmosphereSpec>()); };
  k.programs = {kProgram, kTruthProgram};
  k.truth_records = {"vs_path_traced"};
  k.describe = [](const nlohmann::json& p) {
    std::string s;
    const auto& w = p.value("wavelengths_nm", nlohmann::json::array());
    s += w.size() == 3 ? "rgb" : std::to_string(w.size()) + " wavelengths";
    if (p.value("store", "") == "luminance and radiance") s += " (radiance stored)";
    const nlohmann::json orders = p.contains("orders") ? p["orders"].value("used", nlohmann::json()) : nlohmann::json();
    const nlohmann::json requested = p.value("orders_requested", nlohmann::json("?"));
    s += ", orders " + (orders.is_number() ? orders.dump()
                                           : requested.is_string() ? requested.get<std::string>() : requested.dump());
    // parameters.orders_tail: "none", or what the tail is (plan's parameters, before orders.used exists)
    if (p.value("orders_tail", std::string("none")) != "none") s += " + geometric tail";
    if (p.contains("sizes") && p["sizes"].contains("scattering")) {
      const auto& sc = p["sizes"]["scattering"];
      s += ", scattering " + std::to_string(sc.value("r", 0)) + "x" + std::to_string(sc.value("mu", 0)) + "x" +
           std::to_string(sc.value("mu_s", 0)) + "x" + std::to_string(sc.value("nu", 0));
      std::string baked;
      for (const char* axis : {"mu_s", "nu"})
        if (const std::string key = std::string(axis) + "_baked"; sc.contains(key) && sc[key].is_object())
          baked += (baked.empty() ? "" : ", ") + std::string(axis) + " " + std::to_string(sc[key].value(axis, 0));
      if (!baked.empty()) s += " (" + baked + " baked)";
    }
    if (p.contains("sky_view") && p["sky_view"].is_object()) {
      const auto& n = p["sky_view"]["nodes"];
      s += ", sky view " + std::to_string(n.value("altitude", 0)) + "x" + std::to_string(n.value("sun", 0)) + "x" +
           std::to_string(n.value("view", 0)) + "x" + std::to_string(n.value("azimuth", 0));
    }
    s += ", " + p.value("precision", "float32");
    if (p.contains("auto") && p["auto"].is_object()) {
      const auto& a = p["auto"];
      char b[160];
      std::snprintf(b, sizeof b, ", auto: %s after %zu tries (predicted bake %.0f s; default sizes %.0f s)",
                    a.value("met", false) ? "met" : "NOT met", a.value("tries", nlohmann::json::array()).size(),
                    a.value("chosen_predicted_s", 0.0),
                    a.contains("compared_predicted_s") ? a["compared_predicted_s"].value("default_sizes", 0.0) : 0.0);
      s += b;
    }
    if (p.contains("scene_check") && p["scene_check"].is_object())
      s += ", scene check " + std::to_string(p["scene_check"].value("points", 0)) + " points";
    return s;
  };
  return k;
}

}  // namespace specbake::atmosphere
