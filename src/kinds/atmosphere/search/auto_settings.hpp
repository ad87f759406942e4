#pragma once
// `sizes: auto` and `spectrum: auto`: the cheapest texture sizes and channel count whose bake meets
// the scene's tolerance against the path-traced truth (docs/atmosphere-method.md, "Settings chosen from
// the scene").
//
// A greedy search over bakes. It starts at half the default sizes (sizes: auto) and rgb
// (spectrum: auto). While the bake misses the tolerance, refinements are baked and judged at the
// scene's points: one axis group 1.5× finer (scattering r, μ, μ_s, ν; transmittance; irradiance)
// and the next channel count of the ladder rgb, 8, 12, 16, 24, 32, 48 wavelengths over 360–830 nm.
// The refinement that lowers the judged error most per second of predicted bake time (the cost
// model of bake_seconds, so the choice does not depend on timer noise) is kept; one that
// lowers the error by less than kMinGain of it does not count. The first step bakes every
// refinement; later steps try them in the order of what they bought when last tried and stop
// once the best fresh gain per second is at least every untried one's last (lazy greedy: the
// same choice as trying all where gains only shrink as the error falls, in ~2 bakes a step
// instead of 7). When none lowers it, each is
// tried applied twice, then three times (a plateau: 8 wavelengths can be
// worse than rgb). The search ends when the tolerance is met, when nothing lowers the error
// (the rest is another cause: orders), when the error is within the truth's own p99 standard
// error (no gain can be measured there: twilight at the walk cap), or at kMaxSearchSteps /
// kMaxCostFactor × the default sizes' cost. The truth is traced once (Memo); each try costs one bake and the lookups.
// A search that ends short of the tolerance with a truth too noisy to judge it (kResolvable)
// searches on with a finer truth when the config left relative_se at its default.
// The chosen settings are then judged at an independent point set of the same scene (held out).
// A p99 over n points is their ~n/100-th largest error (the second largest of 128), which moves
// between point sets: when the held-out set misses the tolerance the choice met, a second round
// searches on from it judged at both sets (2n points), and a fresh set judges its choice
// (search_rounds).
#include <algorithm>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

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
    if (step > kMaxSearchSteps) {
      out.stop = "the search reached its " + std::to_string(kMaxSearchSteps) + " steps";
      break;
    }
    // below what the measurement resolves, gains cannot be told from noise
    if (resolution && out.best.error <= resolution(out.best.payload)) {
      out.stop = "the error is within the measurement's own uncertainty (" + format_g(resolution(out.best.payload)) +
                 "): no gain can be measured";
      break;
    }
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

// Rounds of search and validation over a scene of n points: round k searches (from the previous
// round's choice) judged at the points [0, k·n) and is held out at [k·n, (k + 1)·n). Another round
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
template <class Found>
std::vector<Found> search_rounds(int n, const std::function<Found(int judged, const Found* previous)>& search,
                                 const std::function<bool(const Found&)>& met,
                                 const std::function<bool(Found&, int first)>& hold_out,
                                 const std::function<bool(const Found&)>& sharpen = {}) {
  std::vector<Found> rounds;
  for (int k = 1;;) {
    Found f = search(k * n, rounds.empty() ? nullptr : &rounds.back());
    const bool searched_ok = met(f);
    if (!searched_ok && sharpen && sharpen(f)) {
      rounds.push_back(std::move(f));
      continue;
    }
    const bool passed = hold_out(f, k * n);
    rounds.push_back(std::move(f));
    if (!searched_ok || passed || k == kMaxRounds) break;
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
