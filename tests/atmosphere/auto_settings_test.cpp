// `sizes: auto` / `spectrum: auto` (auto_settings.hpp): the greedy search on synthetic errors
// (which refinement it keeps, plateaus, stops, caps), and from the CLI on a small scene (the
// record, the held-out check, the bundle at the chosen sizes, plan showing them).
#include <gtest/gtest.h>

#include <array>
#include <set>
#include <cmath>
#include <string>

#include "atmosphere/spec_of.hpp"
#include "kinds/atmosphere/search/auto_settings.hpp"
#include "support/testing.hpp"

namespace {

namespace t = specbake::testing;
namespace fs = std::filesystem;
using nlohmann::json;
using specbake::atmosphere::greedy_search;
using specbake::atmosphere::Refinement;

// A state of three "axes" (texel counts); cost = a·x + b·y + c·z; error = Σ k_i / n_i² (second-order
// interpolation error per axis) + a floor.
using S = std::array<int, 3>;

struct Model {
  std::array<double, 3> k{1.0, 1.0, 1.0}, price{1.0, 1.0, 1.0};
  double floor = 0.0;
  int evaluations = 0;
  double error(const S& s) const {
    double e = floor;
    for (int i = 0; i < 3; ++i) e += k[i] / (double(s[i]) * s[i]);
    return e;
  }
  double cost(const S& s) const { return price[0] * s[0] + price[1] * s[1] + price[2] * s[2]; }
};

std::vector<Refinement<S>> doubling(int limit = 1 << 20) {
  std::vector<Refinement<S>> r;
  for (int i = 0; i < 3; ++i)
    r.push_back({"axis" + std::to_string(i), [i, limit](S& s) {
                   s[i] *= 2;
                   return s[i] <= limit;
                 }});
  return r;
}

auto run(Model& m, double tolerance, double cap = 1e18, std::vector<Refinement<S>> refs = doubling(),
         bool lazy = true) {
  return greedy_search<S, int>(
      S{2, 2, 2}, refs, [&](const S& s) { return m.cost(s); },
      [&](const S& s, const std::string&) {
        ++m.evaluations;
        return std::pair<double, int>{m.error(s), m.evaluations};
      },
      [](const S& s) { return json(s); }, tolerance, cap, {}, {}, lazy);
}

// The refinements kept, step by step.
std::vector<std::string> path_of(const nlohmann::json& tries) {
  std::vector<std::string> p;
  for (const auto& t : tries)
    if (t.value("chosen", false)) p.push_back(t["refined"]);
  return p;
}

// The axis with the most error per unit of price is refined first; the search stops as soon as
// the tolerance is met, and what it returns meets it.
TEST(AutoSearch, RefinesTheAxisThatBuysTheMostErrorPerCost) {
  Model m;
  m.k = {16.0, 1.0, 1.0};  // axis 0 holds most of the error
  const auto out = run(m, 1.0);
  ASSERT_TRUE(out.met);
  EXPECT_LE(out.best.error, 1.0);
  // step 1 must pick axis 0: its gain 12 per 2 units of cost beats 0.1875 per 2
  bool found = false;
  for (const auto& tr : out.tries)
    if (tr["step"] == 1 && tr.value("chosen", false)) {
      found = true;
      EXPECT_EQ(tr["refined"], "axis0");
    }
  EXPECT_TRUE(found);
  // every try is recorded with its settings, predicted cost and error, in evaluation order
  EXPECT_EQ(static_cast<int>(out.tries.size()), out.evaluations);
  EXPECT_EQ(out.evaluations, m.evaluations);
  // the payload travels with the chosen state
  EXPECT_EQ(m.error(out.best.state), out.best.error);

  // with axis 0 priced 100×, the cheap axes go first although they hold less
  Model dear;
  dear.k = {16.0, 1.0, 1.0};
  dear.price = {100.0, 1.0, 1.0};
  const auto d = run(dear, 1e9);  // met at the start: nothing refined
  EXPECT_TRUE(d.met);
  EXPECT_EQ(d.evaluations, 1);
  const auto d2 = run(dear, 4.2);  // start 4.5: one cheap refinement (−0.1875 each) cannot reach 4.2
  for (const auto& tr : d2.tries)
    if (tr["step"] == 1 && tr.value("chosen", false)) EXPECT_NE(tr["refined"], "axis0") << tr;
}

// Lazy steps: where gains only shrink as the error falls (here each axis' error k/n² quarters
// with every doubling while its cost doubles), trying refinements in the order of their last
// rates and stopping when none left can beat the best makes the same choices as trying all of
// them, with fewer bakes; both meet the tolerance with the same state.
TEST(AutoSearch, LazyStepsChooseAsExhaustiveOnesWithFewerBakes) {
  for (const auto& [k, price] : std::vector<std::pair<std::array<double, 3>, std::array<double, 3>>>{
           {{16.0, 1.0, 1.0}, {1.0, 1.0, 1.0}}, {{4.0, 9.0, 1.0}, {1.0, 3.0, 0.5}}, {{1.0, 1.0, 1.0}, {1.0, 2.0, 4.0}}}) {
    Model lazy_m, full_m;
    lazy_m.k = full_m.k = k;
    lazy_m.price = full_m.price = price;
    const auto lazy = run(lazy_m, 0.05, 1e18, doubling(), true);
    const auto full = run(full_m, 0.05, 1e18, doubling(), false);
    ASSERT_TRUE(lazy.met && full.met);
    EXPECT_EQ(path_of(lazy.tries), path_of(full.tries));
    EXPECT_EQ(lazy.best.state, full.best.state);
    // the exhaustive search bakes 3 refinements a step; the lazy one all 3 in the first step only
    const int steps = static_cast<int>(path_of(full.tries).size());
    EXPECT_EQ(full.evaluations, 1 + 3 * steps);
    EXPECT_LT(lazy.evaluations, full.evaluations);
    EXPECT_LE(lazy.evaluations, 1 + 3 + 2 * (steps - 1)) << "at most two bakes a step after the first here";
  }
}

// A floor no refinement lowers ends the search with the reason, not a loop.
TEST(AutoSearch, AFloorStopsTheSearch) {
  Model m;
  m.floor = 0.5;
  const auto out = run(m, 0.4);
  EXPECT_FALSE(out.met);
  EXPECT_NE(out.stop.find("lowers the error"), std::string::npos) << out.stop;
  EXPECT_GT(out.best.error, 0.4);
  EXPECT_LT(out.best.error, 0.5 * 1.05);  // it refined until the gains fell under 1 %
}

// Within the measurement's own uncertainty no gain can be told from noise: the search stops
// there (the atmosphere's truth at twilight), instead of refining on noise.
TEST(AutoSearch, StopsAtTheMeasurementsResolution) {
  Model m;
  int evaluations = 0;
  auto out = greedy_search<S, int>(
      S{2, 2, 2}, doubling(), [&](const S& s) { return m.cost(s); },
      [&](const S& s, const std::string&) {
        ++evaluations;
        return std::pair<double, int>{m.error(s), 0};
      },
      [](const S& s) { return json(s); }, 1e-6, 1e18, [](const int&) { return 0.1; });
  EXPECT_FALSE(out.met);
  EXPECT_NE(out.stop.find("own uncertainty (0.1)"), std::string::npos) << out.stop;
  EXPECT_LE(out.best.error, 0.1);
  EXPECT_GT(out.best.error, 0.1 / 4);  // it stopped at the first step under 0.1, not later
}

// A refinement that first makes things worse (8 wavelengths against rgb) is crossed by applying it
// twice; one beyond the cost cap is not tried.
TEST(AutoSearch, PlateausAndCaps) {
  Model m;
  m.k = {1.0, 0.0, 0.0};
  int worse_then_better = 0;
  std::vector<Refinement<S>> refs{{"bumpy", [&](S& s) {
                                     ++worse_then_better;
                                     s[0] += 1;  // 2 → 3 is "worse" below, 3 → 4 better
                                     return true;
                                   }}};
  auto out = greedy_search<S, int>(
      S{2, 2, 2}, refs, [](const S& s) { return double(s[0]); },
      [&](const S& s, const std::string&) {
        const double e = s[0] == 3 ? 1.0 : 1.0 / (double(s[0]) * s[0]);
        return std::pair<double, int>{e, 0};
      },
      [](const S& s) { return json(s); }, 0.07, 1e9);
  ASSERT_TRUE(out.met) << out.tries.dump();
  EXPECT_EQ(out.tries[1]["refined"], "bumpy");
  EXPECT_EQ(out.tries[2]["refined"], "bumpy x2");
  EXPECT_TRUE(out.tries[2].value("chosen", false));

  Model capped;
  const auto c = run(capped, 1e-6, /*cap=*/12.0);  // start costs 6; one doubling costs 8; two, 10; three, 12
  EXPECT_FALSE(c.met);
  for (const auto& tr : c.tries) EXPECT_LE(tr["predicted_s"].get<double>(), 12.0);
}

// ---- The model search ----------------------------------------------------------------------
// A synthetic scene: per point p a 3-vector v_p = truth_p + Σ_a c_{p,a} / n_a^order over three
// texture-like axes (doubling, priced by their count), plus a ladder's per-level offsets (the
// spectrum: level 2 worse than level 1 at some points). The judged value is the p99 over the
// points of |v_p − truth_p| (nearest rank, as the scene check's).
using specbake::atmosphere::model_search;
using specbake::atmosphere::ModelEvaluation;
using V = std::array<double, 3>;
using S4 = std::array<int, 4>;  // three axes' counts, the ladder's level

struct PointScene {
  int n = 64;
  double order = 2.0, floor = 0.0;
  std::array<double, 3> price{1.0, 1.0, 1.0};
  std::vector<std::array<V, 3>> c;  // per point and axis
  std::vector<std::array<V, 4>> ladder;  // per point and level 0..3
  int evaluations = 0;
  explicit PointScene(unsigned seed, std::array<double, 3> scale = {40.0, 10.0, 3.0}) {
    std::uint32_t x = seed * 2654435761u + 1;
    auto u = [&] { return (x = x * 1664525u + 1013904223u) / 4294967296.0; };
    c.resize(n);
    ladder.resize(n);
    for (int p = 0; p < n; ++p) {
      for (int a = 0; a < 3; ++a)
        for (int k = 0; k < 3; ++k) c[p][a][k] = scale[a] * (2.0 * u() - 1.0) * (p % 7 == a ? 4.0 : 1.0);
      const double l0 = 6.0 * u(), l1 = 1.5 * u(), l2 = (p % 5 == 0 ? 3.0 : 0.4) * u(), l3 = 0.05 * u();
      const double lv[4] = {l0, l1, l2, l3};
      for (int l = 0; l < 4; ++l) ladder[p][l] = {lv[l], -0.5 * lv[l], 0.25 * lv[l]};
    }
  }
  std::vector<V> values(const S4& s) const {
    std::vector<V> v(n);
    for (int p = 0; p < n; ++p)
      for (int k = 0; k < 3; ++k) {
        double x = ladder[p][s[3]][k] + (k == 0 ? floor : 0.0);
        for (int a = 0; a < 3; ++a) x += c[p][a][k] / std::pow(double(s[a]), order);
        v[p][k] = x;  // truth_p = 0
      }
    return v;
  }
  static std::vector<double> errors(const std::vector<V>& v) {
    std::vector<double> e;
    for (const V& x : v) e.push_back(std::sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]));
    return e;
  }
  static double p99(const std::vector<V>& v) {
    return specbake::atmosphere::summarize_errors(errors(v)).p99;
  }
  double cost(const S4& s) const {
    return (price[0] * s[0] + price[1] * s[1] + price[2] * s[2]) * (1.0 + 0.5 * s[3]);
  }
};

std::vector<Refinement<S4>> scene_refinements(int limit = 1 << 12) {
  std::vector<Refinement<S4>> r;
  for (int i = 0; i < 3; ++i)
    r.push_back({"axis" + std::to_string(i),
                 [i, limit](S4& s) {
                   s[i] *= 2;
                   return s[i] <= limit;
                 },
                 2.0});
  r.push_back({"ladder", [](S4& s) { return ++s[3] <= 3; }, 1.0, false});
  return r;
}

auto model_run(PointScene& m, double tolerance, double cap = 1e18) {
  return model_search<S4, int, V>(
      S4{2, 2, 2, 0}, scene_refinements(), [&](const S4& s) { return m.cost(s); },
      [&](const S4& s, const std::string&) {
        ++m.evaluations;
        const std::vector<V> v = m.values(s);
        return ModelEvaluation<int, V>{v, PointScene::p99(v), m.evaluations};
      },
      &PointScene::errors, &PointScene::p99, [](const S4& s) { return json(s); }, tolerance, cap);
}

// The cheapest state of the grid (each axis 2..2^12 by doublings, the ladder 0..3) that meets the
// tolerance, by brute force.
double cheapest_met(const PointScene& m, double tolerance) {
  double best = 1e300;
  for (int a = 2; a <= 4096; a *= 2)
    for (int b = 2; b <= 4096; b *= 2)
      for (int c = 2; c <= 4096; c *= 2)
        for (int l = 0; l <= 3; ++l) {
          const S4 s{a, b, c, l};
          if (m.cost(s) < best && PointScene::p99(m.values(s)) <= tolerance) best = m.cost(s);
        }
  return best;
}

// Where the model is the scene's own law (second order, separate axes), the search meets the
// tolerance with its probes and one or two verifying bakes, and what it chooses costs little more
// than the cheapest state that meets it (the greedy plan on the model is not exhaustive, and it
// aims at 0.8 of the tolerance: within 2× here). Every bake is a recorded try; a verification
// carries the error the model predicted, which is exact here up to rounding.
TEST(ModelSearch, MeetsAToleranceWithItsProbesAndAFewVerifyingBakes) {
  for (unsigned seed : {1u, 2u, 3u, 4u}) {
    PointScene m(seed);
    const double tolerance = 0.2;  // the ladder's last level leaves up to 0.06
    const auto out = model_run(m, tolerance);
    ASSERT_TRUE(out.met) << "seed " << seed << ": " << out.stop << "\n" << out.tries.dump();
    // exact predictions reach the plan's aim: 0.8 of the tolerance (the held-out points' margin)
    EXPECT_LE(out.best.error, specbake::atmosphere::kModelMargin * tolerance);
    EXPECT_EQ(PointScene::p99(m.values(out.best.state)), out.best.error);
    EXPECT_EQ(out.evaluations, m.evaluations);
    EXPECT_EQ(static_cast<int>(out.tries.size()), out.evaluations);
    // the start, three axis probes, the ladder's levels as the plan reaches them (≤ 3), and
    // verifications: exact predictions, but a plan moves an axis at most kModelReach (2)
    // doublings past the last bake and the worst axis needs 5 (n ≥ 40 for c ≤ 160 under 0.1)
    int verified = 0;
    for (const auto& t : out.tries)
      if (t.value("model", false)) {
        ++verified;
        EXPECT_NEAR(t["predicted_error"].get<double>(), t["error"].get<double>(), 1e-9 * t["error"].get<double>() + 1e-12)
            << t;
      }
    EXPECT_GE(verified, 1);
    EXPECT_LE(verified, 3) << out.tries.dump();
    EXPECT_LE(out.evaluations, 1 + 3 + 3 + verified) << out.tries.dump();
    EXPECT_LE(out.best.cost, 2.0 * cheapest_met(m, tolerance)) << out.tries.dump();
  }
}

// Where the scene's error falls as h (first order) and the model assumes h², the model overrates
// each refinement; verifying bakes correct it (each verified bake becomes the anchor, and a plan
// that bought too little re-probes the axes there), and the search still meets the tolerance.
TEST(ModelSearch, AWrongOrderIsCorrectedByItsVerifyingBakes) {
  PointScene m(7, {4.0, 1.0, 0.3});
  m.order = 1.0;
  const auto out = model_run(m, 0.2);
  ASSERT_TRUE(out.met) << out.stop << "\n" << out.tries.dump();
  EXPECT_LE(out.best.error, 0.2);
  EXPECT_LE(out.evaluations, 40) << out.tries.dump();
}

// A floor no refinement lowers ends the search with its reason after a bounded number of bakes;
// the cost cap bounds every try; a start that meets the tolerance is the only bake.
TEST(ModelSearch, AFloorACapAndAStartThatMeets) {
  PointScene floored(3);
  floored.floor = 0.5;
  const auto f = model_run(floored, 0.1);
  EXPECT_FALSE(f.met);
  EXPECT_NE(f.stop.find("lowers the modelled error"), std::string::npos) << f.stop;
  EXPECT_LE(f.evaluations, 24);
  EXPECT_GE(f.best.error, 0.5 - 1e-9);

  PointScene capped(3);
  const auto c = model_run(capped, 1e-6, /*cap=*/40.0);
  EXPECT_FALSE(c.met);
  for (const auto& t : c.tries) EXPECT_LE(t["predicted_s"].get<double>(), 40.0) << t;

  PointScene easy(3);
  const auto e = model_run(easy, 1e9);
  EXPECT_TRUE(e.met);
  EXPECT_EQ(e.evaluations, 1);
}

// From the CLI: a scene the start already meets bakes once at half the default sizes; the record,
// the held-out check and the bundle's textures follow the chosen sizes; plan shows them.
// Rounds: a choice that misses the tolerance at the held-out points is searched on, judged at
// both point sets, and judged again at a fresh set; one that passes, or a search that did not
// meet the tolerance, ends the rounds. Found = {round, judged points, the held-out set's first point}.
struct Round {
  int judged = 0, first = -1;
  bool met = true;
};
std::vector<Round> rounds_with(int n, std::vector<bool> met, std::vector<bool> passes) {
  std::size_t k = 0;
  return specbake::atmosphere::search_rounds<Round>(
      n,
      [&](int judged, const Round* previous) {
        EXPECT_EQ(previous == nullptr, judged == n);  // the second round starts from the first's choice
        return Round{judged, -1, met.at(k)};
      },
      [](const Round& r) { return r.met; },
      [&](Round& r, int first) {
        r.first = first;
        return static_cast<bool>(passes.at(k++));
      });
}

TEST(AutoSearch, AHeldOutMissSearchesOnAtBothPointSetsAndHoldsOutAFreshSet) {
  const auto again = rounds_with(128, {true, true}, {false, true});
  ASSERT_EQ(again.size(), 2u);
  EXPECT_EQ(again[0].judged, 128);  // [0, n)
  EXPECT_EQ(again[0].first, 128);   // held out [n, 2n)
  EXPECT_EQ(again[1].judged, 256);  // [0, 2n): both sets the first round saw
  EXPECT_EQ(again[1].first, 256);   // a fresh [2n, 3n)

  const auto passed = rounds_with(128, {true}, {true});
  ASSERT_EQ(passed.size(), 1u);
  EXPECT_EQ(passed[0].first, 128);

  // a search short of the tolerance at its own points is not searched again: the held-out check
  // is reported, and the rounds end
  const auto short_of_it = rounds_with(64, {false}, {false});
  ASSERT_EQ(short_of_it.size(), 1u);
  EXPECT_EQ(short_of_it[0].first, 64);

  // a first round judged at two sets: [0, 2n), held out at [2n, 3n); the next at [0, 3n)
  std::size_t k = 0;
  std::vector<bool> held{false, true};
  const auto two = specbake::atmosphere::search_rounds<Round>(
      32, [&](int judged, const Round*) { return Round{judged, -1, true}; }, [](const Round& r) { return r.met; },
      [&](Round& r, int first) {
        r.first = first;
        return static_cast<bool>(held.at(k++));
      },
      {}, 2);
  ASSERT_EQ(two.size(), 2u);
  EXPECT_EQ(two[0].judged, 64);
  EXPECT_EQ(two[0].first, 64);
  EXPECT_EQ(two[1].judged, 96);
  EXPECT_EQ(two[1].first, 96);

  // at most kMaxRounds rounds, whatever the held-out sets say
  const auto capped = rounds_with(16, {true, true, true}, {false, false, false});
  EXPECT_EQ(capped.size(), static_cast<std::size_t>(specbake::atmosphere::kMaxRounds));
  EXPECT_EQ(capped.back().first, 16 * specbake::atmosphere::kMaxRounds);
}

// A round that ends short of the tolerance with a measurement too noisy to judge it is searched again at the same points when the
// measurement can be made finer (no held-out check in between); one that cannot ends the rounds
// with its held-out check, as a round short of the tolerance does.
TEST(AutoSearch, ARoundWithinTheTruthsNoiseIsSearchedAgainWithAFinerTruth) {
  struct Found {
    int judged = 0, first = -1;
    bool met = false, unresolved = false;
  };
  // per search: met?, unresolved?; sharpening allowed once
  auto run = [](std::vector<std::pair<bool, bool>> results, std::vector<bool> passes, bool can_sharpen) {
    std::size_t s = 0, h = 0;
    bool sharpened = false;
    auto rounds = specbake::atmosphere::search_rounds<Found>(
        64,
        [&](int judged, const Found*) {
          const auto [met, unresolved] = results.at(s++);
          return Found{judged, -1, met, unresolved};
        },
        [](const Found& f) { return f.met; },
        [&](Found& f, int first) {
          f.first = first;
          return static_cast<bool>(passes.at(h++));
        },
        [&](const Found& f) {
          if (!f.unresolved || sharpened || !can_sharpen) return false;
          return sharpened = true;
        });
    EXPECT_EQ(s, results.size());
    EXPECT_EQ(h, passes.size());
    return rounds;
  };
  // unresolved, sharpened, then met and held out
  auto r = run({{false, true}, {true, false}}, {true}, true);
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[0].judged, 64);
  EXPECT_EQ(r[0].first, -1);  // not held out
  EXPECT_EQ(r[1].judged, 64);  // the same points, a finer truth
  EXPECT_EQ(r[1].first, 64);
  // sharpened, met, missed at the held-out points: widened to 2n, then a fresh set
  r = run({{false, true}, {true, false}, {true, false}}, {false, true}, true);
  ASSERT_EQ(r.size(), 3u);
  EXPECT_EQ(r[2].judged, 128);
  EXPECT_EQ(r[2].first, 128);
  // unresolved twice: sharpened once only, the second ends the rounds with its held-out check
  r = run({{false, true}, {false, true}}, {false}, true);
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[1].first, 64);
  // a truth the config fixed (relative_se given) is not sharpened
  r = run({{false, true}}, {false}, false);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].first, 64);
}

// sizes: auto also refines the scattering density's θ nodes (×2, from the scene's default: 16,
// or 32 where the sun goes below −6°, up to 64), unless the config gives them; the choice's
// record carries them and reads back.
TEST(AutoSettings, TheDensitysThetaNodesAreASearchAxisUnlessTheConfigGivesThem) {
  using specbake::AtmosphereSpec;
  using specbake::atmosphere::search_refinements;
  using specbake::atmosphere::search_start;
  auto named = [](const AtmosphereSpec& spec, const std::string& name) -> const Refinement<AtmosphereSpec>* {
    static std::vector<Refinement<AtmosphereSpec>> keep;
    keep = search_refinements(spec);
    for (const auto& r : keep)
      if (r.name == name) return &r;
    return nullptr;
  };
  const std::string scene = "    scene: {tolerance_de2000: 1}\n";
  const AtmosphereSpec day = t::spec_of("    sizes: auto\n" + scene);
  const auto* theta = named(day, "quadrature.density_theta");
  ASSERT_NE(theta, nullptr);
  AtmosphereSpec s = search_start(day);
  EXPECT_EQ(s.density_theta, 16);
  EXPECT_TRUE(theta->apply(s));
  EXPECT_EQ(s.density_theta, 32);
  EXPECT_TRUE(theta->apply(s));
  EXPECT_EQ(s.density_theta, 64);
  EXPECT_FALSE(theta->apply(s));  // 128: past the search's limit

  const AtmosphereSpec deep =
      t::spec_of("    sizes: auto\n    scene: {tolerance_de2000: 1, sun_elevation_deg: [-12, 0]}\n");
  EXPECT_EQ(search_start(deep).density_theta, 32);
  // and from half the scene's default μ_s texels: 64 where the sun goes below the horizon (the
  // default scene, sun −6…90°, too), 32 in daylight
  EXPECT_EQ(search_start(deep).scattering_mu_s, 32);
  EXPECT_EQ(search_start(day).scattering_mu_s, 32);
  EXPECT_EQ(search_start(t::spec_of("    sizes: auto\n    scene: {tolerance_de2000: 1, sun_elevation_deg: [0, 90]}\n"))
                .scattering_mu_s,
            16);
  EXPECT_NE(named(deep, "quadrature.density_theta"), nullptr);

  EXPECT_EQ(named(t::spec_of("    sizes: auto\n    quadrature: {density_theta: 24}\n" + scene),
                  "quadrature.density_theta"),
            nullptr);
  EXPECT_EQ(named(t::spec_of("    spectrum: auto\n" + scene), "quadrature.density_theta"), nullptr);

  AtmosphereSpec chosen = search_start(day);
  chosen.density_theta = 64;
  const json record = specbake::atmosphere::settings_json(chosen);
  EXPECT_EQ(record["quadrature"]["density_theta"], 64);
  EXPECT_EQ(specbake::atmosphere::with_settings(day, record).density_theta, 64);
  json odd = record;
  odd["quadrature"]["density_theta"] = 5;
  EXPECT_THROW(specbake::atmosphere::with_settings(day, odd), std::runtime_error);
}

// The search's finer truth, on the device: a tolerance far below the reference's noise has the
// search (by CIEDE2000, the config's relative_se left at its default) trace the reference finer
// before its first try; a relative_se the config gives is kept.
TEST(AutoSettingsDevice, AReferenceTooNoisyForTheToleranceIsTracedFinerBeforeTheSearch) {
  const std::string job =
      "    orders: 2\n"
      "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 5, mu: 16, mu_s: 8, nu: 4}}\n"
      "    spectrum: auto\n"
      "    scene: {points: 6, sun_elevation_deg: [20, 60], tolerance_de2000: 0.001";
  const auto quiet = [](std::string_view, double) {};
  specbake::Memo memo;
  const specbake::atmosphere::AutoSearch a =
      specbake::atmosphere::search_settings(t::spec_of(job + "}\n"), t::shared_device(), quiet, memo);
  const json& r = a.record["rounds"];
  // the reference's se at relative_se 0.01 is far over 0.4 × 0.001 ΔE: relative_se × 0.4 (the
  // most the first sharpening takes) before the first try, one round, no sharpening after it
  ASSERT_EQ(r.size(), 1u) << r.dump();
  EXPECT_DOUBLE_EQ(r[0]["truth_relative_se"].get<double>(),
                   0.01 * specbake::atmosphere::kMaxUpfrontSharpening);
  EXPECT_EQ(r[0]["judged_points"], (json{0, 12}));
  EXPECT_EQ(r[0]["held_out_points"], (json{12, 18}));
  EXPECT_FALSE(a.met);
  EXPECT_EQ(a.held_out_first, 12);
  for (const json& tj : a.record["tries"]) EXPECT_EQ(tj["round"], 1) << tj.dump();

  specbake::Memo memo_given;
  const specbake::atmosphere::AutoSearch given = specbake::atmosphere::search_settings(
      t::spec_of(job + ", relative_se: 0.01}\n"), t::shared_device(), quiet, memo_given);
  ASSERT_EQ(given.record["rounds"].size(), 1u) << given.record["rounds"].dump();
  EXPECT_EQ(given.record["rounds"][0]["truth_relative_se"], 0.01);
}

// A later round does not bake again what an earlier one baked: a greedy search (judged by
// relative radiance) that ends within its truth's noise searches on from its choice with a finer
// truth, and that round's start is the first round's choice — judged again at the finer truth from
// the kept bake (its try records bake_reused and no bake seconds), with the same error a fresh bake
// of it would give where the truth is the same (the bake is deterministic on a device).
TEST(AutoSettingsDevice, ALaterRoundJudgesTheBakesOfEarlierOnesWithoutBakingThemAgain) {
  const std::string job =
      "    orders: 2\n"
      "    sizes: auto\n"
      "    scene: {points: 6, sun_elevation_deg: [20, 60], tolerance_relative: 0.0001}\n";
  const auto quiet = [](std::string_view, double) {};
  specbake::Memo memo;
  const specbake::atmosphere::AutoSearch a =
      specbake::atmosphere::search_settings(t::spec_of(job), t::shared_device(), quiet, memo);
  const json& rounds = a.record["rounds"];
  ASSERT_EQ(rounds.size(), 2u) << rounds.dump();
  ASSERT_TRUE(rounds[0].contains("searched_again")) << rounds[0].dump();
  std::vector<json> first, second;
  for (const json& tj : a.record["tries"]) (tj["round"] == 1 ? first : second).push_back(tj);
  ASSERT_FALSE(first.empty());
  ASSERT_FALSE(second.empty());
  EXPECT_EQ(second.front()["settings"], rounds[0]["chosen"]);
  EXPECT_EQ(second.front()["bake_reused"], true) << second.front().dump();
  EXPECT_EQ(second.front()["bake_s"], 0.0);
  // every try whose settings an earlier try baked reused that bake; the others baked
  std::set<std::string> baked;
  for (const json& tj : a.record["tries"]) {
    const std::string settings = tj["settings"].dump();
    EXPECT_EQ(tj.value("bake_reused", false), baked.count(settings) == 1) << tj.dump();
    baked.insert(settings);
  }
}

TEST(AutoSettingsCli, PlanReportsASearchThatFailsAsFailed) {
  t::TempDir tmp;
  const std::string job =
      "specbake: 1\noutput: out\njobs:\n  - name: sky\n    kind: atmosphere\n    orders: 2\n"
      "    sizes: {transmittance: [32, 8], irradiance: [16, 4], scattering: {r: 5, mu: 16, mu_s: 8, nu: 4}}\n"
      "    spectrum: auto\n"
      "    scene: {points: 6, relative_se: 0.1, sun_elevation_deg: [20, 60], tolerance_de2000: 0.001}\n";
  t::write_file(tmp / "c.yaml", job);
  auto p = t::run_cli({"plan", (tmp / "c.yaml").string(), "--report", (tmp / "r.json").string()}, tmp.path());
  EXPECT_EQ(p.exit_code, 1) << p.out << p.err;
  EXPECT_NE(p.out.find("0 planned, 1 failed"), std::string::npos) << p.out;
  EXPECT_NE(p.out.find("sky: failed: spectrum: auto did not meet the scene's tolerance"), std::string::npos) << p.out;
  const json r = t::read_json(tmp / "r.json");
  EXPECT_EQ(r["jobs"][0]["status"], "failed");
  EXPECT_EQ(r["jobs"][0]["exit_code"], 1);
  EXPECT_FALSE(r["jobs"][0]["parameters"]["auto"]["met"].get<bool>()) << r.dump();
  EXPECT_FALSE(r["jobs"][0]["parameters"]["auto"]["tries"].empty());
  EXPECT_FALSE(fs::exists(tmp / "out" / "sky"));  // no bundle (the search is kept in out/.results)

  t::write_file(tmp / "c.yaml", job + "    tolerance_advisory: true\n");
  p = t::run_cli({"plan", (tmp / "c.yaml").string()}, tmp.path());
  EXPECT_EQ(p.exit_code, 0) << p.out << p.err;
  EXPECT_NE(p.out.find("1 planned, 0 failed"), std::string::npos) << p.out;
}

TEST(AutoSettingsCli, MetAtTheStartBakesHalfTheDefaultSizes) {
  t::TempDir tmp;
  t::write_file(tmp / "c.yaml",
                "specbake: 1\noutput: out\njobs:\n  - name: sky\n    kind: atmosphere\n    orders: 2\n"
                "    sizes: auto\n    spectrum: auto\n"
                "    scene: {points: 8, relative_se: 0.1, sun_elevation_deg: [20, 60], tolerance_de2000: 100}\n");
  const auto p = t::run_cli({"plan", (tmp / "c.yaml").string(), "-v"}, tmp.path());
  ASSERT_EQ(p.exit_code, 0) << p.out << p.err;
  EXPECT_NE(p.out.find("scattering 16x64x16x4"), std::string::npos) << p.out;  // the resolved sizes
  EXPECT_FALSE(fs::exists(tmp / "out" / "sky"));  // no bundle (the search is kept in out/.results)

  const auto r = t::run_cli({"run", (tmp / "c.yaml").string()}, tmp.path());
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const json m = t::read_json(tmp / "out" / "sky" / "latest" / "manifest.json");
  EXPECT_EQ(m["config"]["sizes"], "auto");
  EXPECT_EQ(m["config"]["spectrum"], "auto");
  const json& a = m["parameters"]["auto"];
  EXPECT_TRUE(a["met"].get<bool>());
  ASSERT_EQ(a["tries"].size(), 1u);
  EXPECT_EQ(a["chosen"]["spectrum"], "rgb");
  EXPECT_EQ(a["chosen"]["sizes"]["scattering"], (json{{"r", 16}, {"mu", 64}, {"mu_s", 16}, {"nu", 4}}));
  EXPECT_EQ(a["chosen"]["sizes"]["transmittance"], (json{128, 32}));
  EXPECT_EQ(a["tries"][0]["error"].get<double>(), m["accuracy"][0]["value"].get<double>());
  EXPECT_EQ(m["accuracy"][0]["name"], "vs_path_traced");
  EXPECT_EQ(m["accuracy"][1]["name"], "vs_path_traced_held_out");
  EXPECT_EQ(m["accuracy"][1]["details"]["first_point"], 16);
  // one round, judged (by CIEDE2000) at two point sets [0, 16), held out at [16, 24), which passed
  ASSERT_EQ(a["rounds"].size(), 1u);
  EXPECT_EQ(a["rounds"][0]["judged_points"], (json{0, 16}));
  EXPECT_EQ(a["rounds"][0]["held_out_points"], (json{16, 24}));
  EXPECT_TRUE(a["rounds"][0]["held_out_passed"].get<bool>());
  EXPECT_EQ(a["rounds"][0]["held_out_error"].get<double>(), m["accuracy"][1]["value"].get<double>());
  EXPECT_EQ(a["tries"][0]["round"], 1);
  // the held-out points are other points: another error
  EXPECT_NE(m["accuracy"][1]["value"].get<double>(), m["accuracy"][0]["value"].get<double>());
  // the textures have the chosen sizes: scattering [r][mu][nu*mu_s][3]
  bool seen = false;
  for (const auto& f : m["files"])
    if (f["path"] == "scattering.bin") {
      seen = true;
      EXPECT_EQ(f["shape"], (json{16, 64, 64, 3})) << f;
    }
  EXPECT_TRUE(seen);
}

// `plan` keeps its search in the output's result store and `run` bakes the kept choice without
// searching again (one bake, the same judged error: the same bytes on the same device); a plan
// after that shows the kept search without baking; a change the search depends on (here the
// tolerance) searches again.
TEST(AutoSettingsCli, RunBakesThePlansKeptSearchWithoutSearchingAgain) {
  t::TempDir tmp;
  const std::string job =
      "specbake: 1\noutput: out\njobs:\n  - name: sky\n    kind: atmosphere\n    orders: 2\n"
      "    sizes: auto\n    spectrum: auto\n    previews: none\n";
  t::write_file(tmp / "c.yaml",
                job + "    scene: {points: 8, relative_se: 0.1, sun_elevation_deg: [20, 60], tolerance_de2000: 100}\n");
  auto p = t::run_cli({"plan", (tmp / "c.yaml").string(), "-v", "--report", (tmp / "p.json").string()}, tmp.path());
  ASSERT_EQ(p.exit_code, 0) << p.out << p.err;
  const json planned = t::read_json(tmp / "p.json")["jobs"][0]["parameters"]["auto"];
  // the estimate is what `run` then costs: the kept choice's bake, not a search
  const json estimate = t::read_json(tmp / "p.json")["jobs"][0]["estimate"];
  EXPECT_EQ(estimate["basis"], "2-core CPU model of the kept search's choice") << estimate;
  ASSERT_TRUE(planned.contains("kept")) << planned.dump();
  EXPECT_FALSE(planned.contains("reused"));
  const std::string entry = planned["kept"];
  EXPECT_TRUE(fs::exists(tmp / "out" / ".results" / entry));
  EXPECT_FALSE(fs::exists(tmp / "out" / "sky"));  // plan publishes no bundle

  const auto r = t::run_cli({"run", (tmp / "c.yaml").string(), "-v"}, tmp.path());
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.err.find("without searching again"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("auto try"), std::string::npos) << r.err;  // no try baked
  const json m = t::read_json(tmp / "out" / "sky" / "latest" / "manifest.json");
  const json& a = m["parameters"]["auto"];
  EXPECT_EQ(a["reused"], entry);
  EXPECT_EQ(a["tries"], planned["tries"]);
  EXPECT_EQ(a["chosen"], planned["chosen"]);
  // the choice judged where the search judged it, with the kept truths: the same error
  EXPECT_EQ(m["accuracy"][0]["value"].get<double>(), planned["rounds"][0]["error"].get<double>());
  EXPECT_EQ(m["accuracy"][1]["value"].get<double>(), planned["rounds"][0]["held_out_error"].get<double>());
  bool listed = false;
  for (const auto& e : m["results_kept"]) listed = listed || e == entry;
  EXPECT_TRUE(listed) << m["results_kept"];  // so `gc` keeps it

  p = t::run_cli({"plan", (tmp / "c.yaml").string(), "-v", "--report", (tmp / "p.json").string()}, tmp.path());
  ASSERT_EQ(p.exit_code, 0) << p.out << p.err;
  EXPECT_EQ(t::read_json(tmp / "p.json")["jobs"][0]["parameters"]["auto"]["reused"], entry);
  EXPECT_EQ(p.err.find("auto try"), std::string::npos) << p.err;
  // an up-to-date bundle is planned from its manifest: without the kept search (another tool's
  // key, or removed), plan does not search again for a bundle run would skip
  fs::remove_all(tmp / "out" / ".results");
  p = t::run_cli({"plan", (tmp / "c.yaml").string(), "-v", "--report", (tmp / "p.json").string()}, tmp.path());
  ASSERT_EQ(p.exit_code, 0) << p.out << p.err;
  EXPECT_EQ(p.err.find("auto try"), std::string::npos) << p.err;
  EXPECT_NE(p.out.find("up to date"), std::string::npos) << p.out;
  EXPECT_EQ(t::read_json(tmp / "p.json")["jobs"][0]["parameters"]["auto"]["chosen"], planned["chosen"]);
  EXPECT_FALSE(fs::exists(tmp / "out" / ".results" / entry));

  t::write_file(tmp / "c.yaml",
                job + "    scene: {points: 8, relative_se: 0.1, sun_elevation_deg: [20, 60], tolerance_de2000: 90}\n");
  p = t::run_cli({"plan", (tmp / "c.yaml").string(), "-v", "--report", (tmp / "p.json").string()}, tmp.path());
  ASSERT_EQ(p.exit_code, 0) << p.out << p.err;
  const json again = t::read_json(tmp / "p.json")["jobs"][0]["parameters"]["auto"];
  EXPECT_FALSE(again.contains("reused")) << again.dump();
  EXPECT_NE(again["kept"], entry);
  EXPECT_NE(p.err.find("auto try"), std::string::npos) << p.err;
}

}  // namespace
