#pragma once
// `sizes: auto` and `spectrum: auto`: the cheapest texture sizes and channel count whose bake meets
// the scene's tolerance against the path-traced truth (docs/atmosphere-method.md, "Settings chosen from
// the scene").
//
// Two searches over bakes, from half the default sizes (sizes: auto) and rgb (spectrum: auto),
// over the refinements: one axis group 1.5× finer (scattering r, μ, μ_s, ν; transmittance;
// irradiance), the density's θ nodes ×2, and the next channel count of the ladder rgb, 8, 12, 16,
// 24, 32, 48 wavelengths over 360–830 nm; costs are the bake_seconds model's (so the choice does
// not depend on timer noise).
// - Judged by CIEDE2000 (every try against one trace, the 48-wavelength reference):
//   model_search — cheap probes of each refinement measure what it does to every point's
//   displayed colour, a model adds those differences up, plans the cheapest settings it predicts
//   within kModelMargin of the tolerance, and bakes each plan to verify it. Its reference is
//   traced finer first where its own noise would hide the tolerance (kSearchNoise), and its first
//   round judges two point sets (kFirstRoundSets).
// - Judged by relative radiance (the truth at each try's own wavelengths): greedy_search — the
//   refinement that lowers the judged error most per predicted second is kept, step by step
//   (lazily, with plateaus crossed by applying a refinement two or three times); a search that
//   ends within a truth too noisy to judge it (kResolvable) searches on once with a finer truth.
// Both end when the tolerance is met, when nothing lowers the error (the rest is another cause:
// orders), when the error is within the truth's own p99 standard error (twilight at the walk
// cap), or at kMaxSearchSteps / kMaxCostFactor × the default sizes' cost. The truth is traced once
// (Memo); each try costs one bake and the lookups.
// The chosen settings are then judged at an independent point set of the same scene (held out).
// A p99 over n points is their ~n/100-th largest error (the second largest of 128), which moves
// between point sets: when the held-out set misses the tolerance the choice met, a second round
// searches again judged at all the sets so far, and a fresh set judges its choice (search_rounds).
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "core/text.hpp"
#include "job/kind.hpp"
#include "kinds/atmosphere/bake/bake.hpp"
#include "kinds/atmosphere/truth/scene_check.hpp"

namespace specbake::atmosphere {

inline constexpr int kMaxSearchSteps = 16;
inline constexpr double kMaxCostFactor = 16.0;     // × the predicted bake time of the default sizes
inline constexpr double kRefineFactor = 1.5;       // one axis group per step
inline constexpr int kMaxSearchDensityTheta = 64;  // the density's θ nodes: 16 or 32 → 64 at most
inline constexpr int kMaxReach = 3;                // refinements applied up to 3 times on a plateau
inline constexpr double kMinGain = 0.01;           // a refinement counts when it lowers the error by 1 %
inline constexpr int kSpectrumLadder[] = {8, 12, 16, 24, 32, 48};  // wavelengths after rgb
inline constexpr int kProbeWavelengths = 16;  // the model search probes the texture axes at 16 wavelengths

// Why a search stops before its next step (empty: it goes on): its step budget spent, or a best
// error the measurement cannot resolve (below it, gains cannot be told from noise).
template <class Payload>
std::string search_stop(int step, double best_error, const Payload& best,
                        const std::function<double(const Payload&)>& resolution) {
  if (step > kMaxSearchSteps) return "the search reached its " + std::to_string(kMaxSearchSteps) + " steps";
  if (resolution && best_error <= resolution(best))
    return "the error is within the measurement's own uncertainty (" + format_g(resolution(best)) +
           "): no gain can be measured";
  return {};
}

// The greedy search on its own, over any settings type (tests drive it with synthetic errors).
// `evaluate` bakes and judges a state (its error and a payload kept for the best state and the
// step's best candidate only); `cost` predicts what a state costs; `describe` records a state;
// `resolution` (optional) is the measurement's own uncertainty at a state: the search stops
// when the error is within it; `on_step` (optional) hears of each refinement kept; `lazy`
// (default) tries a step's refinements in the order of their last rates and stops trying once
// none left can beat the best (false: every refinement at every step, for comparison).
template <class State>
struct Refinement {
  std::string name;
  std::function<bool(State&)> apply;  // false: cannot (a limit)
  // For model_search: a level refines the axis's node spacing by `factor` (smooth: its error
  // modelled as ∝ spacing^kModelOrder), or is a step of a ladder whose every level is measured
  // (smooth = false: the spectrum, whose error need not fall monotonically).
  double factor = kRefineFactor;
  bool smooth = true;
};
template <class State, class Payload>
struct Evaluated {
  State state;
  std::string refined;  // "start", a refinement's name, or "name xK" (applied K times)
  double cost = 0.0, error = 0.0;
  Payload payload;
};
template <class State, class Payload>
struct SearchOutcome {
  Evaluated<State, Payload> best;
  nlohmann::json tries = nlohmann::json::array();  // {step, refined, settings, predicted_s, error, chosen?}
  bool met = false;
  std::string stop;  // why it ended short of the tolerance
  int evaluations = 0;
};

template <class State, class Payload>
SearchOutcome<State, Payload> greedy_search(
    const State& start, const std::vector<Refinement<State>>& refinements,
    const std::function<double(const State&)>& cost,
    const std::function<std::pair<double, Payload>(const State&, const std::string& label)>& evaluate,
    const std::function<nlohmann::json(const State&)>& describe, double tolerance, double cost_cap,
    const std::function<double(const Payload&)>& resolution = {},
    const std::function<void(int step, const Evaluated<State, Payload>& kept)>& on_step = {}, bool lazy = true) {
  SearchOutcome<State, Payload> out;
  std::vector<double> last_rate(refinements.size(), std::numeric_limits<double>::infinity());
  auto run = [&](const State& s, const std::string& label, int step) {
    Evaluated<State, Payload> e{s, label, cost(s), 0.0, Payload{}};
    auto [error, payload] = evaluate(s, label);
    e.error = error;
    e.payload = std::move(payload);
    ++out.evaluations;
    out.tries.push_back({{"step", step}, {"refined", label}, {"settings", describe(s)}, {"predicted_s", e.cost},
                         {"error", e.error}});
    return e;
  };
  out.best = run(start, "start", 0);
  for (int step = 1; !(out.best.error <= tolerance); ++step) {
    out.stop = search_stop(step, out.best.error, out.best.payload, resolution);
    if (!out.stop.empty()) break;
    std::optional<Evaluated<State, Payload>> chosen;
    double chosen_rate = 0.0;
    std::size_t chosen_try = 0;
    auto consider = [&](Evaluated<State, Payload> e, double rate) {
      if (!(e.error < (1.0 - kMinGain) * out.best.error)) return;
      if (!chosen || rate > chosen_rate) chosen_rate = rate, chosen = std::move(e), chosen_try = out.tries.size() - 1;
    };
    auto rate_of = [&](const Evaluated<State, Payload>& e) {
      return (out.best.error - e.error) / std::max(e.cost - out.best.cost, 1e-3 * out.best.cost);
    };
    // Lazily (lazy greedy): refinements in the order of what they bought per second when last
    // tried (untried ones first); once the best fresh rate of the step is at least every
    // untried refinement's last rate, none of them can beat it where gains only shrink as the
    // error falls, and the step ends. One that bought nothing last time is tried only when
    // nothing better gains, so a search still ends only after trying every refinement.
    std::vector<std::size_t> order(refinements.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    if (lazy)
      std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return last_rate[a] > last_rate[b]; });
    for (std::size_t i : order) {
      if (lazy && chosen && chosen_rate >= last_rate[i]) break;
      State s = out.best.state;
      if (!refinements[i].apply(s) || cost(s) > cost_cap) {
        last_rate[i] = -std::numeric_limits<double>::infinity();
        continue;
      }
      auto e = run(s, refinements[i].name, step);
      last_rate[i] = rate_of(e);
      consider(std::move(e), last_rate[i]);
    }
    // a plateau (8 wavelengths can be worse than rgb; one texel more may not move the p99) is
    // crossed by refining further: each refinement applied twice, then three times
    for (int reach = 2; reach <= kMaxReach && !chosen; ++reach)
      for (const auto& r : refinements) {
        State s = out.best.state;
        bool ok = true;
        for (int k = 0; k < reach && ok; ++k) ok = r.apply(s);
        if (!ok || cost(s) > cost_cap) continue;
        auto e = run(s, r.name + " x" + std::to_string(reach), step);
        const double rate = rate_of(e);
        consider(std::move(e), rate);
      }
    if (!chosen) {
      out.stop = "no refinement within the cost cap lowers the error by " + std::to_string(int(100 * kMinGain)) +
                 " % or more, even applied " + std::to_string(kMaxReach) + " times";
      break;
    }
    out.tries[chosen_try]["chosen"] = true;
    out.best = std::move(*chosen);
    if (on_step) on_step(step, out.best);
  }
  out.met = out.best.error <= tolerance;
  return out;
}

// The model search: fewer and cheaper bakes than the greedy one where the judged value is a
// function of per-point values that refinements move additively (the displayed colours of the
// scene's points: each texture axis's interpolation error, the density's quadrature error and the
// spectrum's sampling error are, to leading order, separate terms of a point's colour).
//
// 1. Probes: the start, and each refinement applied once (cheap bakes at the start's sizes; a
//    smooth axis with the ladders at `probe_levels`, where its difference is measured in the
//    colours it will be used in). For a smooth axis the difference one level made, D_a, fixes the model
//    v(l) = v(l0) + D_a · (φ(l) − φ(l0)), φ(l) = (1 − f^(−k·l)) / (1 − f^(−k)), k = kModelOrder
//    (bilinear interpolation and the density's rule converge as h²); a ladder's (spectrum) every
//    level is probed at the start's other settings when the planner first considers it.
// 2. Plan: from the anchor (the last verified bake), refine the modelled colours greedily by
//    what each step lowers the mean of the worst modelled errors (the p99's points and
//    kTailExtra more) per second of predicted cost, until the modelled p99 is at most m·T
//    (m = kModelMargin), each smooth axis at most kModelReach levels past the anchor (the
//    model extrapolates from one measured level).
// 3. Verify: bake and judge the plan. Within m·T: done. Otherwise the plan becomes the anchor
//    (its measured colours replace the model's there) and the next plan starts from it; a plan
//    that bought less than kMinGain of the error ends the search (probing again at a large anchor
//    would cost a large bake per axis).
// The choice: the cheapest bake within m·T, else the cheapest within T (met), else the lowest error.
// The stops are the greedy search's: a bake within m·T (a p99 moves between point sets, so one
// just under T at its points may miss it at held-out ones; a search that stops otherwise with its
// best within T has met it too), within `resolution`, nothing lowers the error, the cost cap,
// kMaxSearchSteps verifications. Every bake is a try in the record; a verification
// carries the error the model predicted for it.
inline constexpr double kModelOrder = 2.0;
inline constexpr double kModelMargin = 0.8;
inline constexpr int kModelReach = 2;        // a plan moves a smooth axis at most 2 levels past its anchor
inline constexpr std::size_t kTailExtra = 2;  // the plan's objective: the p99's points and 2 more
inline constexpr double kAimCostFactor = 2.0;  // once met, a plan within the margin costs at most 2× the met bake
template <class Value>
using PointValues = std::vector<Value>;
template <class Payload, class Value>
struct ModelEvaluation {
  PointValues<Value> values;  // per point, what the model adds up (a displayed colour)
  double error = 0.0;         // the judged value of `values`
  Payload payload;
};
template <class State, class Payload, class Value>
SearchOutcome<State, Payload> model_search(
    const State& start, const std::vector<Refinement<State>>& refinements,
    const std::function<double(const State&)>& cost,
    const std::function<ModelEvaluation<Payload, Value>(const State&, const std::string& label)>& evaluate,
    const std::function<std::vector<double>(const PointValues<Value>&)>& point_errors,
    const std::function<double(const PointValues<Value>&)>& judged,
    const std::function<nlohmann::json(const State&)>& describe, double tolerance, double cost_cap,
    const std::function<double(const Payload&)>& resolution = {},
    const std::function<void(int step, const Evaluated<State, Payload>& kept)>& on_step = {},
    const std::vector<int>& probe_levels = {}) {
  using Values = PointValues<Value>;
  const std::size_t R = refinements.size();
  SearchOutcome<State, Payload> out;
  std::vector<int> zero(R, 0);
  // the state at `levels`: each refinement applied that many times to the start, in order
  auto state_at = [&](const std::vector<int>& levels) -> std::optional<State> {
    State s = start;
    for (std::size_t i = 0; i < R; ++i)
      for (int k = 0; k < levels[i]; ++k)
        if (!refinements[i].apply(s)) return std::nullopt;
    return s;
  };
  auto label_of = [&](const std::vector<int>& levels) {
    std::string l;
    for (std::size_t i = 0; i < R; ++i)
      if (levels[i] > 0) l += (l.empty() ? "" : ", ") + refinements[i].name + (levels[i] > 1 ? " x" + std::to_string(levels[i]) : "");
    return l.empty() ? std::string("start") : l;
  };
  bool have_best = false;
  std::size_t out_points = 0;
  // one bake: recorded as a try, its payload kept when it is the choice so far
  auto run = [&](const State& s, const std::string& label, int step, double predicted_error) {
    ModelEvaluation<Payload, Value> e = evaluate(s, label);
    ++out.evaluations;
    if (out.evaluations > 1 && e.values.size() != out_points)
      throw std::logic_error("model_search: a try judged " + std::to_string(e.values.size()) + " points, not " +
                             std::to_string(out_points));
    out_points = e.values.size();
    const double c = cost(s);
    nlohmann::json t = {{"step", step}, {"refined", label}, {"settings", describe(s)}, {"predicted_s", c}, {"error", e.error}};
    if (std::isfinite(predicted_error)) t["predicted_error"] = predicted_error;
    out.tries.push_back(t);
    // the choice: the cheapest bake within the aim, else the cheapest within the tolerance, else
    // the lowest error
    const auto tier = [&](double error) { return error <= kModelMargin * tolerance ? 0 : error <= tolerance ? 1 : 2; };
    const bool better = !have_best || tier(e.error) < tier(out.best.error) ||
                        (tier(e.error) == tier(out.best.error) &&
                         (tier(e.error) < 2 ? c < out.best.cost
                                            : (e.error < out.best.error || (e.error == out.best.error && c < out.best.cost))));
    if (better) {
      out.best = {s, label, c, e.error, std::move(e.payload)};
      have_best = true;
    }
    return std::make_pair(std::move(e.values), e.error);
  };
  // (not a structured binding: the lambdas below capture v0, which C++17 and clang do not allow)
  auto started = run(start, "start", 0, std::nan(""));
  const Values v0 = std::move(started.first);
  const double e0 = started.second;
  if (e0 <= kModelMargin * tolerance) {
    out.met = true;
    return out;
  }
  const std::size_t n = v0.size();
  auto plus = [&](Values& v, const Values& a, const Values& b, double w) {  // v += w (a − b)
    for (std::size_t p = 0; p < n; ++p)
      for (std::size_t c = 0; c < v[p].size(); ++c) v[p][c] += w * (a[p][c] - b[p][c]);
  };
  auto phi = [&](std::size_t i, int l) {
    const double q = std::pow(refinements[i].factor, -kModelOrder);
    return (1.0 - std::pow(q, l)) / (1.0 - q);
  };
  // smooth axes: D[i], the values one level moved, at phi's normalisation; ladders: the values at
  // each level, measured at the start's other settings
  std::vector<std::optional<Values>> D(R);
  std::vector<std::map<int, Values>> ladder(R);  // a map: the pointers ladder_at returns stay valid
  std::vector<bool> unusable(R, false);  // a limit or the cost cap at the probe
  struct Anchor {
    std::vector<int> levels;
    Values values;
    double error;
  } anchor{zero, v0, e0};
  int step = 1;
  // done: the best bake is within the plan's aim (a p99 moves between point sets: one just under
  // the tolerance at its points often misses it at the held-out ones); met: within the tolerance
  const double aim = kModelMargin * tolerance;
  auto met_now = [&] { return out.best.error <= aim; };
  // probe a smooth axis one level past `at` (the first probes' base): D from the difference that
  // level made there
  auto probe_smooth = [&](std::size_t i, const Anchor& at) {
    std::vector<int> l = at.levels;
    ++l[i];
    const std::optional<State> s = state_at(l);
    if (!s || cost(*s) > cost_cap) {
      if (at.levels[i] == 0) unusable[i] = true;
      return;
    }
    auto [v, e] = run(*s, at.levels == zero ? refinements[i].name
                                            : refinements[i].name + " (probed at " + label_of(at.levels) + ")",
                      step, std::nan(""));
    Values d(n, Value{});
    plus(d, v, at.values, 1.0 / (phi(i, l[i]) - phi(i, at.levels[i])));
    D[i] = std::move(d);
  };
  // a ladder's level at the start's other settings
  auto ladder_at = [&](std::size_t i, int level) -> const Values* {
    if (level == 0) return &v0;
    auto it = ladder[i].find(level);
    if (it == ladder[i].end()) {
      std::vector<int> l = zero;
      l[i] = level;
      const std::optional<State> s = state_at(l);
      if (!s || cost(*s) > cost_cap) return nullptr;
      it = ladder[i].emplace(level, run(*s, refinements[i].name + (level > 1 ? " x" + std::to_string(level) : ""), step,
                                        std::nan("")).first).first;
    }
    return &it->second;
  };
  // the first probes: every ladder's next level at the start; every smooth axis one level past
  // the start with the ladders at probe_levels (the spectrum the scene will likely need: an axis's
  // difference in colour is then measured where it will be used)
  for (std::size_t i = 0; i < R && !met_now(); ++i)
    if (!refinements[i].smooth) ladder_at(i, 1);
  Anchor base = anchor;
  for (std::size_t i = 0; i < R && !met_now(); ++i)
    if (!refinements[i].smooth && i < probe_levels.size() && probe_levels[i] > 0)
      if (const Values* v = ladder_at(i, probe_levels[i])) {
        // one ladder off its start level: its measured level is the base (several: not supported)
        if (base.levels != zero) throw std::logic_error("model_search: probe_levels moves more than one ladder");
        base.levels[i] = probe_levels[i];
        base.values = *v;
      }
  for (std::size_t i = 0; i < R && !met_now(); ++i)
    if (refinements[i].smooth) probe_smooth(i, base);
  if (met_now()) {
    out.met = true;
    return out;
  }
  // (a probe within the tolerance but not the aim: the plans go on from the start)
  // the modelled values at `levels` (nothing: a smooth axis moved that has no D, a ladder level
  // beyond its limit)
  auto model = [&](const std::vector<int>& levels) -> std::optional<Values> {
    Values v = anchor.values;
    for (std::size_t i = 0; i < R; ++i) {
      if (levels[i] == anchor.levels[i]) continue;
      if (refinements[i].smooth) {
        if (!D[i]) return std::nullopt;
        Values zero_v(n, Value{});
        plus(v, *D[i], zero_v, phi(i, levels[i]) - phi(i, anchor.levels[i]));
      } else {
        const Values* a = ladder_at(i, levels[i]);
        const Values* b = ladder_at(i, anchor.levels[i]);
        if (!a || !b) return std::nullopt;
        plus(v, *a, *b, 1.0);
      }
    }
    return v;
  };
  // the plan's objective: the mean of the largest errors — those at and above the p99's rank and
  // kTailExtra more — which the p99 cannot fall under and which, unlike the p99 alone, moves
  // when any of the worst points improves
  auto tail = [&](const Values& v) {
    std::vector<double> e;
    for (double x : point_errors(v))
      if (std::isfinite(x)) e.push_back(x);
    if (e.empty()) return 0.0;
    const std::size_t rank = static_cast<std::size_t>(std::ceil(0.99 * static_cast<double>(e.size())));
    const std::size_t m = std::min(e.size(), e.size() - rank + 1 + kTailExtra);
    std::partial_sort(e.begin(), e.begin() + m, e.end(), std::greater<double>());
    double s = 0.0;
    for (std::size_t k = 0; k < m; ++k) s += e[k];
    return s / static_cast<double>(m);
  };
  for (;; ++step) {
    out.stop = search_stop(step, out.best.error, out.best.payload, resolution);
    if (!out.stop.empty()) break;
    // plan: greedy on the model from the anchor
    std::vector<int> levels = anchor.levels;
    Values pv = anchor.values;
    double pj = tail(pv), pc = cost(*state_at(levels));
    for (int guard = 0; guard < 64 && judged(pv) > aim; ++guard) {
      std::optional<std::vector<int>> pick;
      Values pick_v;
      double pick_rate = 0.0, pick_j = 0.0, pick_c = 0.0;
      for (std::size_t i = 0; i < R; ++i) {
        if (unusable[i]) continue;
        // a smooth axis one level on, within the model's trust region; a ladder any level on
        // (a level worse than the last can precede a better one: 8 wavelengths against rgb)
        const int most = refinements[i].smooth ? std::min(levels[i] + 1, anchor.levels[i] + kModelReach)
                                               : std::numeric_limits<int>::max();
        for (int to = levels[i] + 1; to <= most; ++to) {
          std::vector<int> l = levels;
          l[i] = to;
          const std::optional<State> s = state_at(l);
          if (!s) break;
          const double c = cost(*s);
          if (c > cost_cap) break;
          std::optional<Values> v = model(l);
          if (!v) break;
          const double j = tail(*v);
          const double rate = (pj - j) / std::max(c - pc, 1e-3 * pc);
          if (j < pj && (!pick || rate > pick_rate)) pick = l, pick_v = std::move(*v), pick_rate = rate, pick_j = j, pick_c = c;
        }
      }
      if (!pick) break;
      levels = *pick, pv = std::move(pick_v), pj = pick_j, pc = pick_c;
      spdlog::trace("auto: plan {}: modelled p99 {:.4g}, tail {:.4g}, predicted {:.3g} s", label_of(levels),
                    judged(pv), pj, pc);
    }
    if (met_now()) break;  // a ladder level the plan probed met the tolerance
    // a plan the model says buys less than kMinGain of the error is not worth its bake
    if (!(judged(pv) < (1.0 - kMinGain) * anchor.error)) levels = anchor.levels;
    if (levels == anchor.levels) {
      out.stop = "no refinement within the cost cap lowers the modelled error from " + label_of(anchor.levels);
      break;
    }
    // met already: the margin is bought only where it is cheap (a plan over kAimCostFactor × the
    // met bake's cost is not baked: a second round at more points pins the p99 better for less)
    if (out.best.error <= tolerance && pc > kAimCostFactor * out.best.cost) {
      out.stop = "met; the plan within the margin (" + label_of(levels) + ", predicted " + format_g(pc) +
                 " s) costs over " + format_g(kAimCostFactor) + "x the met bake";
      break;
    }
    const double predicted = judged(pv);
    const State s = *state_at(levels);
    auto [v, e] = run(s, label_of(levels), step, predicted);
    out.tries.back()["model"] = true;
    spdlog::info("auto: plan {} baked: p99 {} (the model said {})", label_of(levels), format_g(e), format_g(predicted));
    const bool gained = e < (1.0 - kMinGain) * anchor.error;
    anchor = {levels, std::move(v), e};
    if (on_step) on_step(step, out.best);
    if (met_now()) break;
    if (!gained) {  // the refinements the model trusts have stopped paying where it extrapolates
      out.stop = "the model's plan (" + label_of(anchor.levels) + ") lowered the error by under " +
                 std::to_string(int(100 * kMinGain)) + " %";
      break;
    }
  }
  out.met = out.best.error <= tolerance;
  if (out.met) out.stop.clear();
  return out;
}

// Rounds of search and validation over a scene of n points: round k (from `sets`: the first
// round judges that many point sets) searches (from the previous round's choice) judged at the
// points [0, k·n) and is held out at [k·n, (k + 1)·n). Another round
// follows when a round met the tolerance at its points and missed it at the held-out ones (up to
// kMaxRounds such widenings), or when a round ended short of the tolerance and `sharpen`
// (optional) made the measurement finer: that round is searched again at the same
// points, without a held-out check of its own. `search(judged, previous)` runs a round (previous:
// null in the first), `met` says whether it met the tolerance, `hold_out(found, first)` judges it at
// [first, first + n) and says whether that passed, `sharpen(found)` refines the measurement for the
// rounds after it and says whether it could. Returns the rounds in order; the last holds the choice.
inline constexpr int kMaxRounds = 2;
// A search that ends short of the tolerance while the truth's own p99 standard error is at least
// kResolvable × the tolerance could not have told a bake that meets it from one that does not:
// a default relative_se is then divided by kTruthSharpening (once: 4× the walks) and the search
// goes on from its choice.
inline constexpr double kResolvable = 0.5;
inline constexpr double kTruthSharpening = 2.0;
// Before a search judged by CIEDE2000 against the reference (config's relative_se left at its
// default): a reference whose own p99 se is over kSearchNoise × the tolerance is traced finer
// first, its relative_se scaled to bring the se there, by at most kMaxUpfrontSharpening (6.25×
// the walks).
inline constexpr double kSearchNoise = 0.4;
inline constexpr double kMaxUpfrontSharpening = 0.4;
// A search judged by CIEDE2000 judges its first round at two point sets (2n points): a p99 over n
// = 128 points is their second largest and moved by ~0.2 ΔE between sets, so a choice that met
// it at one set missed it at the next (and a second round re-probed every axis at the choice's
// sizes); at 2n the plan cannot fit one set's few worst points, and the reference's trace of the
// second set costs less than a bake there.
inline constexpr int kFirstRoundSets = 2;
template <class Found>
std::vector<Found> search_rounds(int n, const std::function<Found(int judged, const Found* previous)>& search,
                                 const std::function<bool(const Found&)>& met,
                                 const std::function<bool(Found&, int first)>& hold_out,
                                 const std::function<bool(const Found&)>& sharpen = {}, int sets = 1) {
  std::vector<Found> rounds;
  for (int k = sets;;) {
    Found f = search(k * n, rounds.empty() ? nullptr : &rounds.back());
    const bool searched_ok = met(f);
    if (!searched_ok && sharpen && sharpen(f)) {
      rounds.push_back(std::move(f));
      continue;
    }
    const bool passed = hold_out(f, k * n);
    rounds.push_back(std::move(f));
    if (!searched_ok || passed || k == sets + kMaxRounds - 1) break;
    ++k;
  }
  return rounds;
}

struct AutoSearch {
  AtmosphereSpec resolved;   // the spec with the chosen sizes and spectrum (auto flags cleared)
  Baked baked;               // its bake (self-checked, as a plain bake is)
  SceneCheck check;          // its scene check at the points its round judged ([0, k·n))
  SceneCheck held_out;       // and at the round's held-out points [k·n, (k + 1)·n)
  int held_out_first = -1;   // k·n (-1: not held out — a round searched again with a finer truth)
  bool met = false;          // the tolerance was met at the judged points
  bool unresolved = false;   // it ended short of the tolerance with a truth too noisy to judge it (kResolvable)
  std::string failure;       // why the search stopped short, when it did
  nlohmann::json record;     // start, rule, every try (settings, predicted and measured seconds, error, parts), chosen
};

// Predicted bake seconds of a spec without its scene check (2-core CPU scale).
double predicted_bake_seconds(const AtmosphereSpec& spec);

// Where the search starts: half the scene's default sizes (sizes: auto; set_scene_default_sizes),
// rgb (spectrum: auto).
AtmosphereSpec search_start(const AtmosphereSpec& spec);
// A rough wall time of a search: kTypicalTries bakes of its start (`plan`'s estimate before the
// search runs; the tries grow as the search refines, the start's scene check is traced once).
inline constexpr double kTypicalTries = 20.0;

// Runs the search's rounds with their held-out checks (spec.auto_sizes and/or spec.auto_spectrum
// set). `memo` keeps the traces.
AutoSearch search_settings(const AtmosphereSpec& spec, cl_util::Device& dev, const Progress& progress, Memo& memo);

// What the search may refine from `spec` (sizes: auto: each texture's axis group ×1.5 and,
// unless the config gives `quadrature: {density_theta}`, the density's θ nodes ×2 up to
// kMaxSearchDensityTheta; spectrum: auto: the next count of kSpectrumLadder).
std::vector<Refinement<AtmosphereSpec>> search_refinements(const AtmosphereSpec& spec);

// The sizes, spectrum and density θ nodes of a spec as the manifest reports them.
nlohmann::json settings_json(const AtmosphereSpec& spec);
// `spec` with the sizes, spectrum and density θ nodes of a settings_json record (auto flags
// cleared); throws std::runtime_error on a record it cannot read.
AtmosphereSpec with_settings(const AtmosphereSpec& spec, const nlohmann::json& settings);

// A search's outcome as the result store keeps it: what `run` needs to bake the choice once and
// judge it at the same points with the same (kept) truths, instead of searching again.
struct KeptSearch {
  nlohmann::json chosen;        // settings_json of the choice
  int judged_points = 0;        // the last round's judged points [0, judged_points)
  double relative_se = 0.0;     // the last round's truth (a default relative_se may have been halved)
  int held_out_first = -1;      // its held-out points [first, first + n); -1: none
  bool met = false, unresolved = false;
  std::string failure;
  nlohmann::json record;        // parameters.auto as the search wrote it
  std::string entry;            // the store's file name it was read from or written to
};
// The key of a spec's search: everything a search depends on — the atmosphere, orders,
// quadratures and scene with its tolerance (parameters_json, scene_json), which axes are searched,
// the bake's and the tracer's expanded programs, the atmosphere's host sources (kHostSources), the
// device and its build options, the tool's version.
std::string search_key(const AtmosphereSpec& spec, cl_util::Device& dev);
// The search kept under search_key in `memo.store`, or nothing (none, or unreadable: logged).
std::optional<KeptSearch> find_kept_search(const AtmosphereSpec& spec, cl_util::Device& dev, Memo& memo);
// search_settings through `memo.store`: a search kept by an earlier `plan` or `run` is replayed —
// its choice baked once and judged at the same points (their truths kept too) — and a search made
// here is kept (its record's `kept` names the entry; a replay's says `reused`).
AutoSearch kept_search_settings(const AtmosphereSpec& spec, cl_util::Device& dev, const Progress& progress, Memo& memo);

}  // namespace specbake::atmosphere
