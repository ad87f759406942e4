#include "kinds/atmosphere/search/auto_settings.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "atmosphere/limits.h"
#include "core/hash.hpp"
#include "core/text.hpp"
#include "core/version.hpp"
#include "io/result_store.hpp"
#include "kinds/atmosphere/bake/pass.hpp"
#include "kinds/atmosphere/model/scene.hpp"
#include "kinds/atmosphere/truth/truth.hpp"

namespace specbake::atmosphere {

using nlohmann::json;

namespace {

int finer(int v, bool even) {
  int f = static_cast<int>(std::ceil(v * kRefineFactor));
  if (even) f += f % 2;
  return std::max(f, v + (even ? 2 : 1));
}

}  // namespace

std::vector<Refinement<AtmosphereSpec>> search_refinements(const AtmosphereSpec& spec) {
  std::vector<Refinement<AtmosphereSpec>> out;
  auto axis = [&](const char* name, std::vector<int AtmosphereSpec::*> fields, bool even) {
    out.push_back({name, [fields, even](AtmosphereSpec& s) {
                     for (auto f : fields) s.*f = finer(s.*f, even && f == &AtmosphereSpec::scattering_mu);
                     return sizes_within_limits(s);
                   }});
  };
  if (spec.auto_sizes) {
    axis("scattering.r", {&AtmosphereSpec::scattering_r}, false);
    axis("scattering.mu", {&AtmosphereSpec::scattering_mu}, true);
    axis("scattering.mu_s", {&AtmosphereSpec::scattering_mu_s}, false);
    axis("scattering.nu", {&AtmosphereSpec::scattering_nu}, false);
    axis("transmittance", {&AtmosphereSpec::transmittance_mu, &AtmosphereSpec::transmittance_r}, false);
    axis("irradiance", {&AtmosphereSpec::irradiance_mu_s, &AtmosphereSpec::irradiance_r}, false);
    // the scattering density's sphere rule: twice the θ nodes (a quadrature, not a texture: it
    // costs compute, no memory), unless the config fixed them
    if (!spec.density_theta_given)
      out.push_back({"quadrature.density_theta",
                   [](AtmosphereSpec& s) {
                     s.density_theta *= 2;
                     return s.density_theta <= kMaxSearchDensityTheta;
                   },
                   2.0});
  }
  if (spec.auto_spectrum)
    out.push_back({"spectrum", [](AtmosphereSpec& s) {
                     const int now = s.spectral ? s.count : 3;
                     for (int n : kSpectrumLadder)
                       if (n > now) {
                         s.spectral = true;
                         s.min_nm = 360.0;
                         s.max_nm = 830.0;
                         s.count = n;
                         return true;
                       }
                     return false;
                   },
                   1.0, false});
  return out;
}

namespace {

// The record's rule: what a search judged by CIEDE2000 does (model_search), and one judged by
// relative radiance (greedy_search); the rounds' rule follows either.
constexpr const char* kRounds =
    " When a search ends short of the tolerance with the truth's own p99 standard error at least half the tolerance "
    "and the config left scene.relative_se at its default, it searches on with relative_se halved (once). The choice "
    "is then judged at the next n points of the scene (held out); when they miss the tolerance the round met, a "
    "second round searches again judged at all the points so far (the model search from its start again, its probes "
    "being cheap there; the greedy one on from the choice) and a fresh set of n points judges its choice. A try whose "
    "settings an earlier try baked is judged from that bake (bake_reused), not baked again";
const std::string kModelRule =
    std::string("model: from half the default sizes and rgb, bake the start and each refinement once (one axis group "
                "x1.5, the density's theta nodes x2 up to 64 unless the config gives them; the spectrum's next count "
                "of rgb, 8, 12, 16, 24, 32, 48 when the plan first reaches it) and model every point's displayed colour "
                "as the start's plus each refinement's difference, a texture axis's or the density's scaled as a "
                "second-order discretisation error (h^2), the spectrum's as measured; plan on the model (greedy: the "
                "refinement that lowers the mean of the worst points' CIEDE2000 (the p99's and 2 more) most per "
                "second of predicted bake time, each texture axis at most 2 levels past the last bake, until the "
                "modelled p99 is at most 0.8 x the tolerance) and bake the plan to "
                "verify it against the 48-wavelength reference; a plan that misses becomes the anchor of the next; "
                "stop when a bake is within 0.8 x the tolerance (a p99 moves between point sets), when a bake "
                "met the tolerance and the next plan would cost over 2x it, when a plan lowered the error by "
                "under 1 %, when no plan lowers the modelled error, when the error is within "
                "the truth's own p99 standard error, after 16 plans, or beyond 16x the default sizes' predicted "
                "time. The choice: the cheapest bake within 0.8 x the tolerance, else the cheapest within it "
                "(met), else the lowest error. A default relative_se whose reference's own p99 standard error is "
                "over 0.4 x the tolerance is scaled down first (to at most 0.4 of it), and the first round judges "
                "two point sets (2n points).") +
    kRounds;
const std::string kGreedyRule =
    std::string("greedy: from half the default sizes and rgb, bake refinements (one axis group x1.5, the density's "
                "theta nodes x2 up to 64 unless the config gives them, or the next channel count of rgb, 8, 12, 16, "
                "24, 32, 48) and keep the one that lowers the judged error most per second of predicted bake time (a "
                "gain under 1 % does not count; the first step bakes every refinement, later ones try them in the "
                "order of their last gain per second and stop once none untried can beat the best; on a plateau each "
                "refinement is tried applied twice, then three times; each try judged against the truth at its own "
                "wavelengths); stop when the tolerance is met, when nothing lowers the error, when the error is "
                "within the truth's own p99 standard error, after 16 steps, or beyond 16x the default sizes' "
                "predicted time.") +
    kRounds;

// The truth's own p99 standard error over the scene in `measure` ("de2000", "relative"); 0 without.
double se_p99(const SceneCheck& c, const char* measure) {
  const json& d = c.record.details;
  if (!d.contains("standard_error") || !d["standard_error"].contains(measure)) return 0.0;
  return d["standard_error"][measure].value("p99", 0.0);
}

// ", the truth's own p99 standard error X ΔE": a floor no bake goes under at the scene's points.
std::string truth_noise(const SceneCheck& c) {
  const double se = se_p99(c, "de2000");
  if (!(se > 0.0)) return "";
  return "; the truth's own p99 standard error is " + format_g(se) +
         " CIEDE2000 (a lower scene.relative_se lowers it until the walk cap binds, as it does at twilight points;"
         " a scene without twilight is judged finer)";
}

// The scene's tolerance in the judged measure.
double judged_tolerance(const AtmosphereSpec& spec) {
  return spec.scene.tolerance_relative ? *spec.scene.tolerance_relative : *spec.scene.tolerance_de2000;
}

// The search's start with the default sizes (or the given ones): the cost cap's scale and the
// record's comparison.
AtmosphereSpec default_sizes_of(const AtmosphereSpec& spec) {
  AtmosphereSpec defaults = search_start(spec);
  if (spec.auto_sizes) set_scene_default_sizes(defaults);
  return defaults;
}

// The truth's own p99 standard error over the scene, in the judged measure.
double truth_se_p99(const SceneCheck& c, const AtmosphereSpec& spec) {
  return se_p99(c, spec.scene.tolerance_relative ? "relative" : "de2000");
}

double p99_of(const SceneCheck& c, const char* part) {
  const json& d = c.record.details;
  if (!d.contains("parts") || !d["parts"].contains(part)) return std::nan("");
  return d["parts"][part]["de2000"].value("p99", std::nan(""));
}

}  // namespace

double predicted_bake_seconds(const AtmosphereSpec& spec) {
  AtmosphereSpec s = spec;
  s.scene.check = false;
  return bake_seconds(s);
}

json settings_json(const AtmosphereSpec& s) {
  return {{"sizes", {{"transmittance", {s.transmittance_mu, s.transmittance_r}},
                     {"irradiance", {s.irradiance_mu_s, s.irradiance_r}},
                     {"scattering", {{"r", s.scattering_r}, {"mu", s.scattering_mu}, {"mu_s", s.scattering_mu_s},
                                     {"nu", s.scattering_nu}}}}},
          {"spectrum", s.spectral ? json{{"min_nm", s.min_nm}, {"max_nm", s.max_nm}, {"count", s.count}} : json("rgb")},
          {"quadrature", {{"density_theta", s.density_theta}}}};
}

AtmosphereSpec with_settings(const AtmosphereSpec& spec, const json& settings) {
  AtmosphereSpec s = spec;
  s.auto_sizes = s.auto_spectrum = false;
  try {
    const json& z = settings.at("sizes");
    s.transmittance_mu = z.at("transmittance").at(0).get<int>();
    s.transmittance_r = z.at("transmittance").at(1).get<int>();
    s.irradiance_mu_s = z.at("irradiance").at(0).get<int>();
    s.irradiance_r = z.at("irradiance").at(1).get<int>();
    const json& sc = z.at("scattering");
    s.scattering_r = sc.at("r").get<int>();
    s.scattering_mu = sc.at("mu").get<int>();
    s.scattering_mu_s = sc.at("mu_s").get<int>();
    s.scattering_nu = sc.at("nu").get<int>();
    const json& sp = settings.at("spectrum");
    s.spectral = sp.is_object();
    if (s.spectral) {
      s.min_nm = sp.at("min_nm").get<double>();
      s.max_nm = sp.at("max_nm").get<double>();
      s.count = sp.at("count").get<int>();
    } else if (sp != "rgb") {
      throw std::runtime_error("spectrum is neither \"rgb\" nor {min_nm, max_nm, count}");
    }
    if (settings.contains("quadrature")) s.density_theta = settings["quadrature"].at("density_theta").get<int>();
  } catch (const json::exception& e) {
    throw std::runtime_error(std::string("settings record: ") + e.what());
  }
  if (!sizes_within_limits(s) || s.scattering_mu % 2 != 0 || (s.spectral && s.count < 1) || s.density_theta < 4 ||
      s.density_theta > DENSITY_THETA_MAX || s.density_theta % 2 != 0)
    throw std::runtime_error("settings record: sizes, spectrum or density_theta out of range");
  return s;
}

AtmosphereSpec search_start(const AtmosphereSpec& spec) {
  AtmosphereSpec start = spec;
  start.auto_sizes = start.auto_spectrum = false;
  if (spec.auto_sizes) {  // half the scene's default sizes
    set_scene_default_sizes(start);
    scale_sizes(start, 0.5);
  }
  if (spec.auto_spectrum) start.spectral = false;
  return start;
}

namespace {

// The choice judged at the held-out points [first, first + n): by its judged value alone where
// that is the reference's (what the hold-out decides; the truth at the choice's own wavelengths
// would cost a trace of its own there), by the whole check otherwise.
SceneCheck held_out_check(const AtmosphereSpec& probe, const Baked& baked, cl_util::Device& dev,
                          const Progress& progress, Memo& memo, int first) {
  return judged_by_reference_alone(probe) ? judge_scene(probe, baked.luts, dev, progress, &memo, first)
                                          : check_scene(probe, baked.luts, baked.orders_used, dev, progress, &memo, first);
}

// Progress of a check after the tries (where the next try's would go).
Progress progress_of_check(const Progress& progress, int tries) {
  return [&progress, tries](std::string_view, double frac) {
    const double base = 1.0 - std::pow(0.9, tries), next = 1.0 - std::pow(0.9, tries + 1);
    progress("auto: the choice's scene check", base + (next - base) * frac);
  };
}

// The bakes of a search's tries by their settings, kept across its rounds: a later round judges
// more points but bakes the same probes (the model search starts each round from the same
// start), and a bake does not depend on where it is judged. Kept while the tables held stay
// within kKeptBakesBytes (the probes are small; a large plan's bake is kept when it fits).
inline constexpr std::size_t kKeptBakesBytes = std::size_t(512) << 20;
struct KeptBakes {
  std::map<std::string, Baked> by_settings;
  std::size_t bytes = 0;
  static std::size_t size_of(const Baked& b) {
    const Luts& l = b.luts;
    const SpectralLuts& r = b.radiance;
    return sizeof(double) * (l.transmittance.size() + l.irradiance.size() + l.scattering.size() + l.single_mie.size() +
                             l.sky_view.size() + l.sky_view_mie.size()) +
           sizeof(float) * (r.transmittance.size() + r.irradiance.size() + r.scattering.size() + r.single_mie.size());
  }
  const Baked* find(const std::string& key) const {
    auto it = by_settings.find(key);
    return it == by_settings.end() ? nullptr : &it->second;
  }
  void keep(const std::string& key, const Baked& b) {
    const std::size_t n = size_of(b);
    if (bytes + n > kKeptBakesBytes || by_settings.count(key)) return;
    by_settings.emplace(key, b);
    bytes += n;
  }
};

// One round of the search: from `start`, every state judged at start.scene.points points.
// `tries` counts the evaluations of all rounds (progress and the log number them).
AutoSearch search_round(const AtmosphereSpec& spec, const AtmosphereSpec& start, int round, int& tries,
                        cl_util::Device& dev, const Progress& progress, Memo& memo, KeptBakes& kept_bakes) {
  const std::vector<Refinement<AtmosphereSpec>> steps = search_refinements(spec);
  const double tolerance = judged_tolerance(spec);
  const double cost_cap = kMaxCostFactor * predicted_bake_seconds(default_sizes_of(spec));

  struct Payload {
    Baked baked;
    SceneCheck check;
  };
  std::vector<json> measured;  // per evaluation, in order: measured bake seconds and the parts' p99
  const std::function<std::pair<double, Payload>(const AtmosphereSpec&, const std::string&)> evaluate =
      [&](const AtmosphereSpec& s, const std::string& refined) {
        const double base = 1.0 - std::pow(0.9, tries), next = 1.0 - std::pow(0.9, tries + 1);
        auto part = [&](double from, double to) {
          return [&, from, to](std::string_view, double f) {
            progress("auto: try " + std::to_string(tries + 1) + " (" + refined + ")",
                     base + (next - base) * (from + (to - from) * f));
          };
        };
        const auto t0 = std::chrono::steady_clock::now();
        Payload p;
        const std::string key = settings_json(s).dump();
        const Baked* earlier = kept_bakes.find(key);
        if (earlier) {
          p.baked = *earlier;
        } else {
          p.baked = bake_luts(s, dev, part(0.0, 0.8), 24);
          kept_bakes.keep(key, p.baked);
        }
        const double bake_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        // a try needs only the judged value: against the spectral reference alone where that is the
        // judged measure (one trace per point set serves every try); the choice gets the full check
        p.check = judged_by_reference_alone(s)
                      ? judge_scene(s, p.baked.luts, dev, part(0.8, 1.0), &memo)
                      : check_scene(s, p.baked.luts, p.baked.orders_used, dev, part(0.8, 1.0), &memo);
        ++tries;
        spdlog::debug("atmosphere: auto try {} (round {}, {}): predicted {:.1f} s, {} {:.1f} s, error {:.4g}", tries, round,
                      refined, predicted_bake_seconds(s), earlier ? "an earlier round's bake, judged in" : "baked in",
                      bake_s, p.check.record.value);
        json parts = json::object();
        for (const char* name : {"lut_discretisation", "order_truncation", "spectral_sampling"})
          if (const double v = p99_of(p.check, name); std::isfinite(v)) parts[name] = v;
        measured.push_back({{"bake_s", earlier ? 0.0 : bake_s}, {"parts_p99_de2000", parts}});
        if (earlier) measured.back()["bake_reused"] = true;
        const double error = p.check.record.value;
        return std::pair<double, Payload>{error, std::move(p)};
      };
  const auto describe = [](const AtmosphereSpec& s) { return settings_json(s); };
  const auto predicted_cost = [](const AtmosphereSpec& s) { return predicted_bake_seconds(s); };
  const auto resolution = [&](const Payload& p) { return truth_se_p99(p.check, spec); };
  const auto kept = [&](int step, const Evaluated<AtmosphereSpec, Payload>& k) {
    spdlog::info("atmosphere: auto round {} step {}: {} -> error {} (predicted bake {:.1f} s)", round, step, k.refined,
                 format_g(k.error), k.cost);
  };
  // Judged by CIEDE2000 against the reference alone: the model search over the points' displayed
  // colours. Judged by relative radiance (the truth at each try's own wavelengths): the greedy one.
  SearchOutcome<AtmosphereSpec, Payload> found;
  if (judged_by_reference_alone(start)) {
    JudgedColours judged_at;  // the reference's colours at the round's points (every try's the same)
    const std::function<ModelEvaluation<Payload, Vec3>(const AtmosphereSpec&, const std::string&)>
        model_evaluate = [&](const AtmosphereSpec& s, const std::string& refined) {
          auto [error, p] = evaluate(s, refined);
          if (judged_at.shown_ref.empty()) judged_at = p.check.colours;
          std::vector<Vec3> values = p.check.colours.shown_lut;
          return ModelEvaluation<Payload, Vec3>{std::move(values), error, std::move(p)};
        };
    // the texture axes are probed at kProbeWavelengths when the spectrum is searched from fewer
    // (rgb's colours move otherwise than a spectrum's), at the start's spectrum otherwise
    std::vector<int> probe_levels(steps.size(), 0);
    for (std::size_t i = 0; i < steps.size(); ++i)
      if (steps[i].name == "spectrum") {
        AtmosphereSpec s = start;
        for (int level = 1; steps[i].apply(s); ++level)
          if (s.count >= kProbeWavelengths) {
            if (!start.spectral || start.count < kProbeWavelengths) probe_levels[i] = level;
            break;
          }
      }
    found = model_search<AtmosphereSpec, Payload, Vec3>(
        start, steps, predicted_cost, model_evaluate,
        [&](const std::vector<Vec3>& v) { return judged_at.errors(v); },
        [&](const std::vector<Vec3>& v) { return judged_at.p99(v); }, describe, tolerance, cost_cap, resolution, kept,
        probe_levels);
  } else {
    found = greedy_search<AtmosphereSpec, Payload>(start, steps, predicted_cost, evaluate, describe, tolerance, cost_cap,
                                                   resolution, kept);
  }
  for (std::size_t i = 0; i < found.tries.size() && i < measured.size(); ++i) {
    found.tries[i].update(measured[i]);
    found.tries[i]["round"] = round;
  }
  AutoSearch out;
  out.met = found.met;
  out.resolved = found.best.state;
  out.baked = std::move(found.best.payload.baked);
  out.check = std::move(found.best.payload.check);
  if (out.check.record.details.contains("judged_only"))  // the choice's whole record: its parts, per-point file
    out.check = check_scene(out.resolved, out.baked.luts, out.baked.orders_used, dev, progress_of_check(progress, tries),
                            &memo);
  out.unresolved = !found.met && truth_se_p99(out.check, spec) >= kResolvable * tolerance;
  const std::string stop = found.stop;
  json tries_j = found.tries;
  if (!out.met) {
    const std::string largest = [&] {
      std::string name;
      double v = -1;
      for (const char* p : {"lut_discretisation", "order_truncation", "spectral_sampling"})
        if (const double x = p99_of(out.check, p); std::isfinite(x) && x > v) v = x, name = p;
      return name;
    }();
    out.failure = std::string(spec.auto_sizes ? "sizes" : "spectrum") +
                  (spec.auto_sizes && spec.auto_spectrum ? " and spectrum" : "") + ": auto did not meet the scene's tolerance " +
                  format_g(tolerance) + ": " + stop + "; the best of " + std::to_string(tries) +
                  " tries reached " + format_g(out.check.record.value) + " (" + out.check.record.unit + ")" +
                  (largest.empty() ? "" : ", its largest cause " + largest) + truth_noise(out.check) +
                  " (-v logs every try; a sweep or a bake with the error's cause fixed shows the rest)";
  }
  out.record = {{"tries", tries_j}, {"met", out.met}};
  if (!stop.empty()) out.record["stopped"] = stop;
  return out;
}

}  // namespace

AutoSearch search_settings(const AtmosphereSpec& spec, cl_util::Device& dev, const Progress& progress, Memo& memo) {
  const int n = spec.scene.points;
  int tries = 0, round = 0;
  // the truth's target standard error: the scene's, halved once when a search ends short of the
  // tolerance with the truth's own p99 standard error at least kResolvable of it and the config
  // left relative_se at its default (kTruthSharpening)
  double relative_se = spec.scene.relative_se;
  bool sharpened = false;
  // A search judged against the 48-wavelength reference alone compares every try with the same
  // trace, so the reference's own noise sits in every judged p99: traced at the default
  // relative_se its p99 se may be most of the tolerance (the default ground scene at ΔE ≤ 1:
  // 0.85), and no bake could be seen to meet it. Before the first try, such a reference is traced
  // finer, once: relative_se scaled by kSearchNoise·T / se (se ∝ relative_se), at most to
  // kMaxUpfrontSharpening of it.
  if (!spec.scene.relative_se_given && spec.scene.tolerance_de2000) {
    AtmosphereSpec probe = search_start(spec);
    if (judged_by_reference_alone(probe)) {
      const double se = reference_se_p99(probe, dev, [&](std::string_view, double f) {
        progress("auto: the truth's precision", 0.02 * f);
      }, &memo);
      const double tolerance = *spec.scene.tolerance_de2000;
      if (se > kSearchNoise * tolerance) {
        const double factor = std::max(kMaxUpfrontSharpening, kSearchNoise * tolerance / se);
        relative_se = std::stod(format_g(relative_se * factor, 2));
        sharpened = true;
        spdlog::info("atmosphere: auto: the reference's own p99 standard error is {} CIEDE2000 at relative_se {} "
                     "(over {} x the tolerance {}); searching with relative_se {}",
                     format_g(se), format_g(spec.scene.relative_se), format_g(kSearchNoise), format_g(tolerance),
                     format_g(relative_se));
      }
    }
  }
  KeptBakes kept_bakes;
  std::vector<AutoSearch> rounds = search_rounds<AutoSearch>(
      n,
      [&](int judged, const AutoSearch* previous) {
        // the model search probes at the start's sizes in every round (cheap bakes; at the choice's
        // sizes each probe would cost a bake of the choice), the greedy one goes on from the choice
        AtmosphereSpec start = previous && !judged_by_reference_alone(spec) ? previous->resolved : search_start(spec);
        start.scene.points = judged;
        start.scene.relative_se = relative_se;
        AtmosphereSpec judged_spec = spec;
        judged_spec.scene.points = judged;
        judged_spec.scene.relative_se = relative_se;
        return search_round(judged_spec, start, ++round, tries, dev, progress, memo, kept_bakes);
      },
      [](const AutoSearch& f) { return f.met; },
      [&](AutoSearch& f, int first) {
        AtmosphereSpec probe = f.resolved;
        probe.scene.points = n;
        f.held_out = held_out_check(probe, f.baked, dev, [&](std::string_view, double frac) {
          const double base = 1.0 - std::pow(0.9, tries), next = 1.0 - std::pow(0.9, tries + 1);
          progress("auto: held-out check of round " + std::to_string(round), base + (next - base) * frac);
        }, memo, first);
        f.held_out_first = first;
        return f.held_out.record.passed;
      },
      [&](const AutoSearch& f) {
        if (!f.unresolved || sharpened || spec.scene.relative_se_given) return false;
        sharpened = true;
        relative_se /= kTruthSharpening;
        spdlog::info("atmosphere: auto: stopped at {} with the truth's own p99 standard error {} at relative_se {}; "
                     "searching on with relative_se {} ({}x the walks)",
                     format_g(f.check.record.value), format_g(truth_se_p99(f.check, spec)),
                     format_g(relative_se * kTruthSharpening), format_g(relative_se),
                     format_g(kTruthSharpening * kTruthSharpening));
        return true;
      },
      judged_by_reference_alone(search_start(spec)) ? kFirstRoundSets : 1);

  const double tolerance = judged_tolerance(spec);
  const AtmosphereSpec defaults = default_sizes_of(spec);
  json tries_j = json::array(), rounds_j = json::array();
  for (std::size_t k = 0; k < rounds.size(); ++k) {
    const AutoSearch& r = rounds[k];
    for (const json& tj : r.record["tries"]) tries_j.push_back(tj);
    json rj = {{"round", k + 1},
               {"judged_points", {0, r.resolved.scene.points}},
               {"truth_relative_se", r.resolved.scene.relative_se},
               {"met", r.met},
               {"error", r.check.record.value},
               {"chosen", settings_json(r.resolved)}};
    if (r.held_out_first >= 0) {
      rj["held_out_points"] = {r.held_out_first, r.held_out_first + n};
      rj["held_out_error"] = r.held_out.record.value;
      rj["held_out_passed"] = r.held_out.record.passed;
    } else {
      rj["searched_again"] = "with a finer truth (relative_se / " + format_g(kTruthSharpening) + ")";
    }
    if (r.record.contains("stopped")) rj["stopped"] = r.record["stopped"];
    rounds_j.push_back(rj);
  }
  std::vector<std::string> searched;
  if (spec.auto_sizes) searched.push_back("sizes");
  if (spec.auto_spectrum) searched.push_back("spectrum");
  const json stopped = rounds.back().record.value("stopped", json());
  AutoSearch out = std::move(rounds.back());
  // the choice keeps the scene as the config gives it: its rounds' point sets are in the record
  out.resolved.scene.points = n;
  out.record = {
      {"searched", searched},
      {"tolerance", tolerance},
      {"measure", out.check.record.unit},
      {"rule", judged_by_reference_alone(search_start(spec)) ? kModelRule : kGreedyRule},
      {"start", settings_json(search_start(spec))},
      {"tries", tries_j},
      {"rounds", rounds_j},
      {"chosen", settings_json(out.resolved)},
      {"chosen_predicted_s", predicted_bake_seconds(out.resolved)},
      {"met", out.met},
      {"compared_predicted_s", {{"default_sizes", predicted_bake_seconds(defaults)},
                                {"sizes_200_percent", [&] {
                                   AtmosphereSpec twice = defaults;
                                   scale_sizes(twice, 2.0);
                                   return predicted_bake_seconds(twice);
                                 }()}}}};
  if (!stopped.is_null()) out.record["stopped"] = stopped;
  return out;
}

// ---- Kept searches -------------------------------------------------------------------------

std::string search_key(const AtmosphereSpec& spec, cl_util::Device& dev) {
  const json searched = {{"sizes", spec.auto_sizes},
                         {"spectrum", spec.auto_spectrum},
                         {"relative_se_given", spec.scene.relative_se_given}};
  return std::string("atmosphere.search/") + parameters_json(spec).dump() + "/scene " + scene_json(spec.scene).dump() +
         "/searched " + searched.dump() + "/bake " + sha256_hex(expanded_program(kProgram)) + "/truth " +
         sha256_hex(expanded_program(kTruthProgram)) + "/host " + kHostSources + "/device " +
         device_identity(dev.info()).dump() + "/version " + kVersion;
}

namespace {

std::string kept_bytes(const KeptSearch& k) {
  const json j = {{"chosen", k.chosen},
                  {"judged_points", k.judged_points},
                  {"relative_se", k.relative_se},
                  {"held_out_first", k.held_out_first},
                  {"met", k.met},
                  {"unresolved", k.unresolved},
                  {"failure", k.failure},
                  {"record", k.record}};
  const std::vector<std::uint8_t> cbor = json::to_cbor(j);
  return std::string(cbor.begin(), cbor.end());
}

KeptSearch kept_from_bytes(const std::string& bytes) {
  const json j = json::from_cbor(bytes);
  KeptSearch k;
  k.chosen = j.at("chosen");
  k.judged_points = j.at("judged_points").get<int>();
  k.relative_se = j.at("relative_se").get<double>();
  k.held_out_first = j.at("held_out_first").get<int>();
  k.met = j.at("met").get<bool>();
  k.unresolved = j.at("unresolved").get<bool>();
  k.failure = j.at("failure").get<std::string>();
  k.record = j.at("record");
  if (k.judged_points < 1 || !(k.relative_se > 0.0) || !k.record.is_object())
    throw std::runtime_error("a search record out of range");
  return k;
}

// The kept choice baked once and judged where its search judged it, with the same truths (kept
// beside it): the same bytes as the search's own bake of it on the same device.
AutoSearch replay(const AtmosphereSpec& spec, const KeptSearch& k, cl_util::Device& dev, const Progress& progress,
                  Memo& memo) {
  AutoSearch out;
  out.resolved = with_settings(spec, k.chosen);
  out.resolved.scene.relative_se = k.relative_se;
  out.baked = bake_luts(out.resolved, dev, [&](std::string_view what, double f) {
    progress("auto: the kept choice, " + std::string(what), 0.8 * f);
  }, 24);
  AtmosphereSpec judged = out.resolved;
  judged.scene.points = k.judged_points;
  out.check = check_scene(judged, out.baked.luts, out.baked.orders_used, dev, [&](std::string_view, double f) {
    progress("auto: the choice's scene check", 0.8 + 0.15 * f);
  }, &memo);
  out.held_out_first = k.held_out_first;
  if (k.held_out_first >= 0)
    out.held_out = held_out_check(out.resolved, out.baked, dev,
                                  [&](std::string_view, double f) { progress("auto: held-out check", 0.95 + 0.05 * f); },
                                  memo, k.held_out_first);
  out.met = k.met;
  out.unresolved = k.unresolved;
  out.failure = k.failure;
  out.record = k.record;
  out.record["reused"] = k.entry;
  const json& rounds = k.record.value("rounds", json::array());
  const double searched = rounds.empty() ? std::nan("") : rounds.back().value("error", std::nan(""));
  if (!(out.check.record.value == searched))
    spdlog::warn("atmosphere: auto: the kept choice judges {} where its search judged {} (a bake that differs "
                 "from the search's: another device state or driver?)",
                 format_g(out.check.record.value), format_g(searched));
  return out;
}

}  // namespace

std::optional<KeptSearch> find_kept_search(const AtmosphereSpec& spec, cl_util::Device& dev, Memo& memo) {
  if (!memo.store) return std::nullopt;
  const std::string key = search_key(spec, dev);
  const std::optional<std::string> bytes = memo.store->get(key);
  if (!bytes) return std::nullopt;
  const std::string name = ResultStore::name_of(key);
  try {
    KeptSearch k = kept_from_bytes(*bytes);
    with_settings(spec, k.chosen);  // readable
    k.entry = name;
    return k;
  } catch (const std::exception& e) {
    spdlog::warn("{}: not used ({}); searching again", (memo.store->dir() / name).string(), e.what());
    return std::nullopt;
  }
}

AutoSearch kept_search_settings(const AtmosphereSpec& spec, cl_util::Device& dev, const Progress& progress, Memo& memo) {
  if (std::optional<KeptSearch> k = find_kept_search(spec, dev, memo)) {
    spdlog::info("atmosphere: auto: the search kept in {} chose {}; baking it without searching again",
                 (memo.store->dir() / k->entry).string(), k->chosen.dump());
    memo.store_used.insert(k->entry);
    return replay(spec, *k, dev, progress, memo);
  }
  AutoSearch found = search_settings(spec, dev, progress, memo);
  if (memo.store) {
    KeptSearch k;
    k.chosen = settings_json(found.resolved);
    const json& rounds = found.record.at("rounds");
    k.judged_points = rounds.back().at("judged_points").at(1).get<int>();
    k.relative_se = found.resolved.scene.relative_se;
    k.held_out_first = found.held_out_first;
    k.met = found.met;
    k.unresolved = found.unresolved;
    k.failure = found.failure;
    k.record = found.record;
    const std::string key = search_key(spec, dev);
    if (memo.store->put(key, kept_bytes(k))) {
      k.entry = ResultStore::name_of(key);
      memo.store_used.insert(k.entry);
      found.record["kept"] = k.entry;
    }
  }
  return found;
}

}  // namespace specbake::atmosphere
