// `bsn tune`'s optimiser and runner: ranges and their errors, Nez's criterion, the Halton + pattern search against
// an exhaustive grid on simulated recordings, and the two-thread evaluation.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "bsn/config/body_config.hpp"
#include "bsn/eval/tune_runner.hpp"
#include "bsn/eval/tuning.hpp"
#include "bsn/fusion/mekf_filter.hpp"
#include "bsn/sim/scenario_file.hpp"

namespace bsn::eval {
namespace {

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(ParamRange, ParsesLinearAndLog) {
  const ParamRange a = parse_param_range("sigma_a=0.1:10:log");
  EXPECT_EQ(a.name, "sigma_a");
  EXPECT_TRUE(a.log);
  EXPECT_DOUBLE_EQ(a.value_at(0.0), 0.1);
  EXPECT_NEAR(a.value_at(0.5), 1.0, 1e-12);  // geometric middle
  EXPECT_NEAR(a.value_at(1.0), 10.0, 1e-12);
  const ParamRange b = parse_param_range("zeta=0:4");
  EXPECT_FALSE(b.log);
  EXPECT_DOUBLE_EQ(b.value_at(0.25), 1.0);
}

TEST(ParamRange, BadRangesNameTheParameter) {
  for (const char* bad : {"sigma_a=1:1", "sigma_a=2:1", "sigma_a=nan:1", "sigma_a=0:1:log", "sigma_a=1", "sigma_a=x:2",
                          "sigma_a=1:inf", "sigma_a=1:2:cubic"}) {
    const std::string e = error_of([&] { (void)parse_param_range(bad); });
    EXPECT_NE(e.find("sigma_a"), std::string::npos) << bad << ": " << e;
  }
  EXPECT_NE(error_of([] { (void)parse_param_range("sigma_a=2:1"); }).find("inverted"), std::string::npos);
  EXPECT_NE(error_of([] { (void)parse_param_range("=1:2"); }), "");
}

TEST(ParamRange, FilterJudgesNamesAndValues) {
  const fusion::FilterSpec mekf{"mekf", {}};
  EXPECT_NO_THROW(check_param_ranges(mekf, default_param_ranges("mekf")));
  EXPECT_NO_THROW(check_param_ranges({"seel_ruppin", {}}, default_param_ranges("seel_ruppin")));
  const std::string unknown = error_of([&] { check_param_ranges(mekf, {{"tau_acc_s", 0.1, 1.0, true}}); });
  EXPECT_NE(unknown.find("has no parameter 'tau_acc_s'"), std::string::npos) << unknown;
  const std::string twice = error_of([&] {
    check_param_ranges(mekf, {{"sigma_a", 0.1, 1.0, true}, {"sigma_a", 0.1, 2.0, true}});
  });
  EXPECT_NE(twice.find("sigma_a"), std::string::npos);
  // A value the filter refuses (negative sigma) at a range end.
  const std::string refused = error_of([&] { check_param_ranges(mekf, {{"sigma_m", -1.0, 1.0, false}}); });
  EXPECT_NE(refused.find("sigma_m"), std::string::npos) << refused;
  EXPECT_NE(error_of([&] { check_param_ranges(mekf, {}); }), "");
}

TEST(Criterion, NezIsMeanPlusSampleStandardDeviation) {
  const std::vector<double> rmse = {1.0, 2.0, 3.0};  // mean 2, SD (n-1) 1
  EXPECT_DOUBLE_EQ(criterion_value(Criterion::kNez, rmse), 3.0);
  EXPECT_DOUBLE_EQ(criterion_value(Criterion::kRmse, rmse), 2.0);
  EXPECT_DOUBLE_EQ(criterion_value(Criterion::kNez, std::vector<double>{2.5}), 2.5);
  const std::vector<double> diverged = {1.0, std::numeric_limits<double>::quiet_NaN()};
  EXPECT_EQ(criterion_value(Criterion::kNez, diverged), std::numeric_limits<double>::infinity());
  EXPECT_EQ(criterion_value(Criterion::kRmse, std::vector<double>{}), std::numeric_limits<double>::infinity());
  EXPECT_EQ(parse_criterion("nez"), Criterion::kNez);
  EXPECT_THROW((void)parse_criterion("mae"), std::invalid_argument);
}

TEST(Optimiser, HaltonPointsAreTheRadicalInverses) {
  EXPECT_DOUBLE_EQ(halton_point(1, 2)[0], 0.5);
  EXPECT_DOUBLE_EQ(halton_point(2, 2)[0], 0.25);
  EXPECT_DOUBLE_EQ(halton_point(3, 2)[0], 0.75);
  EXPECT_NEAR(halton_point(1, 2)[1], 1.0 / 3.0, 1e-15);
  EXPECT_NEAR(halton_point(5, 2)[1], 7.0 / 9.0, 1e-15);
}

TEST(Optimiser, FindsTheMinimumOfABowlToTheFinalStep) {
  const std::vector<double> target = {0.3, 0.81, 0.55};
  std::size_t calls = 0;
  const BatchObjective f = [&](const std::vector<std::vector<double>>& pts) {
    std::vector<double> out;
    for (const auto& p : pts) {
      double s = 0.0;
      for (std::size_t d = 0; d < p.size(); ++d) s += (d + 1.0) * (p[d] - target[d]) * (p[d] - target[d]);
      out.push_back(s);
      ++calls;
    }
    return out;
  };
  OptimiserOptions o;
  o.min_step = 1.0 / 256.0;
  const OptimiserResult r = minimise(3, f, o);
  EXPECT_EQ(r.evaluations, calls);  // each distinct point once
  EXPECT_LE(r.evaluations, o.max_evaluations);
  EXPECT_LT(r.final_step, o.min_step);
  // Converged: on a separable bowl the pattern search ends within one final lattice step of the minimum.
  for (std::size_t d = 0; d < 3; ++d) EXPECT_NEAR(r.unit[d], target[d], 2.0 * o.min_step) << d;
}

TEST(Optimiser, NanCountsAsWorstAndBudgetHolds) {
  const BatchObjective f = [](const std::vector<std::vector<double>>& pts) {
    std::vector<double> out;
    for (const auto& p : pts) out.push_back(p[0] > 0.5 ? std::numeric_limits<double>::quiet_NaN() : 1.0 - p[0]);
    return out;
  };
  OptimiserOptions o;
  o.max_evaluations = 30;
  const OptimiserResult r = minimise(1, f, o);
  EXPECT_LE(r.evaluations, 30u);
  EXPECT_LE(r.unit[0], 0.5);
  EXPECT_TRUE(std::isfinite(r.value));
}

// Short simulated recordings of Nez's scenarios (Opal-like sensor noise), 40 s of which 30 s random motion.
TuneRecording nez_recording(const std::string& scenario, double seconds) {
  sim::ScenarioSpec spec = sim::load_scenario(std::string(BSN_SCENARIO_DIR) + "/" + scenario + ".yaml");
  spec.duration_s = seconds;
  return {scenario, simulate_recording(spec), {}};
}

// The optimiser against the exhaustive grid at the same resolution (Nez's method, 9 log-spaced values per
// parameter here): it must land within 5 % of the grid's optimum, with fewer evaluations.
TEST(Optimiser, WithinFivePercentOfTheExhaustiveGridOnSimulatedRecordings) {
  const TuneRecording slow = nez_recording("nez_slow", 40.0);
  const TuneRecording inter = nez_recording("nez_intermediate", 40.0);
  const fusion::FilterSpec base{"mekf", {}};
  const std::vector<ParamRange> ranges = {{"sigma_g", 1e-4, 1.0, true}, {"sigma_a", 1e-2, 100.0, true}};
  constexpr int kGrid = 9;
  std::vector<std::vector<double>> grid_values;
  for (int i = 0; i < kGrid; ++i) {
    for (int j = 0; j < kGrid; ++j) {
      grid_values.push_back({ranges[0].value_at(i / (kGrid - 1.0)), ranges[1].value_at(j / (kGrid - 1.0))});
    }
  }
  struct Case {
    std::vector<const TuneRecording*> recs;
    Criterion criterion;
  };
  const std::vector<Case> cases = {
      {{&slow}, Criterion::kRmse}, {{&inter}, Criterion::kRmse}, {{&slow, &inter}, Criterion::kNez}};
  for (const Case& c : cases) {
    const auto table = rmse_table(base, ranges, grid_values, c.recs, 2);
    double grid_best = std::numeric_limits<double>::infinity();
    for (const auto& row : table) grid_best = std::min(grid_best, criterion_value(c.criterion, row));
    ASSERT_TRUE(std::isfinite(grid_best));

    TuneSetup setup;
    setup.base = base;
    setup.ranges = ranges;
    setup.criterion = c.criterion;
    setup.fit = c.recs;
    setup.options.global_points = 12;
    setup.options.initial_step = 0.25;
    setup.options.min_step = 1.0 / (kGrid - 1.0);  // the grid's resolution
    const TuneResult r = tune(setup);
    EXPECT_LE(r.fit_criterion, 1.05 * grid_best) << c.recs.front()->name << " " << criterion_name(c.criterion);
    EXPECT_LT(r.optimiser.evaluations, grid_values.size());
    // The identified set is at least as good as the filter's defaults on the recordings it was fitted on.
    EXPECT_LE(r.fit_criterion, r.base_fit_criterion);
  }
}

TEST(TuneRunner, TwoThreadsGiveTheSameTableAsOne) {
  const TuneRecording rec = nez_recording("nez_intermediate", 15.0);
  const std::vector<ParamRange> ranges = {{"sigma_a", 0.1, 10.0, true}};
  const std::vector<std::vector<double>> values = {{0.1}, {1.0}, {10.0}};
  const auto one = rmse_table({"mekf", {}}, ranges, values, {&rec, &rec}, 1);
  const auto two = rmse_table({"mekf", {}}, ranges, values, {&rec, &rec}, 2);
  EXPECT_EQ(one, two);  // filters are deterministic: bit-identical whichever thread ran them
  for (const auto& row : one) {
    for (const double v : row) EXPECT_TRUE(std::isfinite(v));
  }
}

TEST(TuneRunner, RecordingChecksNameTheSource) {
  io::Recording rec = nez_recording("nez_slow", 12.0).rec;
  EXPECT_NO_THROW(check_tuning_recording(rec, "a.hdf5"));
  io::Recording partly = rec;
  partly.opt_quat(500, 2) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(
      error_of([&] { check_tuning_recording(partly, "b.hdf5"); }).find("b.hdf5: reference orientation of sample 500"),
      std::string::npos);
  io::Recording all_nan = rec;
  all_nan.opt_quat.setConstant(std::numeric_limits<double>::quiet_NaN());
  EXPECT_NE(
      error_of([&] { check_tuning_recording(all_nan, "c.hdf5"); }).find("c.hdf5: the reference orientation is NaN"),
      std::string::npos);
  io::Recording none = rec;
  none.opt_quat.resize(0, 4);
  EXPECT_NE(error_of([&] { check_tuning_recording(none, "d.csv"); }).find("d.csv: no reference"), std::string::npos);
}

TEST(TuneRunner, IntensityClassesFollowTheScenarios) {
  // The static start of a Nez scenario is class 0; the fast scenario's motion is mostly fast (Table 1: 700 +- 400
  // deg/s, above the intermediate class's 450 deg/s bound most of the time).
  const io::Recording fast = nez_recording("nez_fast", 30.0).rec;
  const auto classes = intensity_classes(fast);
  std::size_t at_rest_static = 0, rest = 0, moving_fast = 0, moving = 0;
  for (std::size_t i = 0; i < fast.size(); ++i) {
    const double t = static_cast<double>(fast.time_ns(i)) * 1e-9;
    if (t > 1.0 && t < 9.0) {
      ++rest;
      at_rest_static += classes[i] == 0;
    } else if (t > 12.0) {
      ++moving;
      moving_fast += classes[i] == 3;
    }
  }
  EXPECT_EQ(at_rest_static, rest);
  EXPECT_GT(moving_fast, moving / 2);
}

// `bsn tune --by-intensity` on mekf turns its per-class sets into mekf_adaptive's table: the block, written into
// a body file as the command prints it, loads and gives the filter exactly those sets (a set that was not fully
// identified is completed from its mekf preset, as the identification ran it), the other classes keep Table 3.
TEST(TuneByIntensity, AdaptiveBlockLoadsIntoTheBodyFileAndSetsTheClasses) {
  const std::vector<ClassSet> sets = {
      {2, {"mekf", {{"sigma_g", 0.00562}, {"sigma_bg", 0.000141}, {"sigma_a", 12.9}, {"sigma_m", 3.16}}}},
      {3, {"mekf", {{"preset", 3}, {"sigma_a", 15.8}}}},
  };
  const fusion::FilterSpec spec = adaptive_spec_of(sets, 286.0);
  std::string block = "{name: " + spec.name;
  for (const auto& [k, v] : spec.parameters) block += ", " + k + ": " + std::to_string(v);
  const auto body =
      config::parse_body_model("segments:\n  - name: hand\n    node: imu\n    filter: " + block + "}\n", "body.yaml");
  const auto filter = fusion::make_filter(body.segments.at(0).filter);
  const auto& m = dynamic_cast<const fusion::MekfFilter&>(*filter);
  EXPECT_EQ(m.params().table_rate_hz, 286.0);
  const auto near = [](double a, double b) { return std::abs(a - b) <= 1e-6 * b; };  // to_string's 6 decimals
  EXPECT_TRUE(near(m.sets()[2].sigma_g, 0.00562) && near(m.sets()[2].sigma_bg, 0.000141) &&
              near(m.sets()[2].sigma_a, 12.9) && near(m.sets()[2].sigma_m, 3.16));
  const fusion::MekfNoise& fast = fusion::kNezTable3[3];
  EXPECT_TRUE(near(m.sets()[3].sigma_g, fast.sigma_g) && near(m.sets()[3].sigma_a, 15.8) &&
              near(m.sets()[3].sigma_m, fast.sigma_m));
  for (const std::size_t c : {0u, 1u}) {
    EXPECT_EQ(m.sets()[c].sigma_a, fusion::kNezTable3[c].sigma_a);
    EXPECT_EQ(m.sets()[c].sigma_m, fusion::kNezTable3[c].sigma_m);
  }
  EXPECT_THROW(adaptive_spec_of({{4, {"mekf", {}}}}, 128.0), std::invalid_argument);
  EXPECT_THROW(adaptive_spec_of({{1, {"seel_ruppin", {}}}}, 128.0), std::invalid_argument);
}

}  // namespace
}  // namespace bsn::eval
