// Fan et al. 2018's standard tests A-E (bsn eval --standard-tests): Table 5's grades, and every filter that rejects
// the magnetometer still catching the disturbances of tests B, C and E.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "bsn/eval/standard_tests.hpp"
#include "bsn/fusion/orientation_error.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/sim/scenario.hpp"
#include "bsn/sim/scenario_file.hpp"

namespace bsn::eval {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
// The filters that reject the magnetometer (all share MagDisturbanceDetector), as the registry tells.
std::vector<std::string> rejecting_filters() {
  std::vector<std::string> names;
  for (const fusion::FilterInfo& f : fusion::filter_registry()) {
    if (f.rejects_magnetometer) names.emplace_back(f.name);
  }
  return names;
}

TEST(StandardTests, GradesAreThoseOfFansTable5) {
  EXPECT_EQ(grade_of(0.0), Grade::kGood);
  EXPECT_EQ(grade_of(2.0), Grade::kGood);
  EXPECT_EQ(grade_of(2.01), Grade::kAcceptable);
  EXPECT_EQ(grade_of(5.0), Grade::kAcceptable);
  EXPECT_EQ(grade_of(5.01), Grade::kPoor);
  EXPECT_EQ(grade_of(std::nan("")), Grade::kPoor);
  ASSERT_EQ(fan_standard_tests().size(), 5u);
  EXPECT_EQ(fan_standard_tests().front().scenario, "fan_a");
}

// A disturbance is caught when the magnetometer is rejected while the true field differs from the earth field by
// more than 10 % (the size of the disturbance vector), over the first 10 s of each disturbed stretch (before the
// rules for a long disturbance may take a steady field in). B brings a magnet close five times, C puts a strong
// object next to the sensor, E carries it over a ferromagnetic floor. Every filter that rejects shares one detector,
// which sees only |m| and the dip: B's magnet changes them by 7.6 % and 7.4 deg at its closest and by a fraction of
// that at the edge of the stretch, so 80 % leaves room for the last 4 cm of each approach (the field crosses the
// thresholds there) and for the low-pass's delay. D's disturbance is below every threshold by design (Fan: threshold
// methods cannot see it). The check runs over five noise realisations (the scenario's seed and four others): a
// detector whose thresholds sit at the edge of what B shows catches it on some seeds and not on others.
TEST(StandardTests, FiltersThatRejectTheMagnetometerCatchTheDisturbancesOfBCAndEOnEverySeed) {
  std::vector<std::pair<std::string, fusion::FilterSpec>> filters;
  for (const std::string& name : rejecting_filters()) {
    filters.emplace_back(name, fusion::FilterSpec{name, {}});
  }
  for (const std::optional<std::uint64_t> seed :
       {std::optional<std::uint64_t>{}, std::optional<std::uint64_t>{101}, std::optional<std::uint64_t>{202},
        std::optional<std::uint64_t>{303}, std::optional<std::uint64_t>{404}}) {
    const std::string seed_name = seed ? std::to_string(*seed) : "the scenario's";
    const auto results = run_standard_tests(BSN_SCENARIO_DIR, filters, 3.0, seed);
    ASSERT_EQ(results.size(), 5 * filters.size());
    for (const auto& r : results) {
      EXPECT_EQ(r.trial.non_finite, 0u) << r.filter << " " << r.test << " seed " << seed_name;
      EXPECT_GT(r.trial.scored, 1000u) << r.filter << " " << r.test;
      if (r.test == "B" || r.test == "C" || r.test == "E") {
        ASSERT_GT(r.disturbed_samples, 100u) << r.test;  // the scenario does disturb
        EXPECT_GE(r.caught_fraction, 0.8) << r.filter << " in test " << r.test << ", seed " << seed_name;
      }
      if (r.test == "A") {
        // A is a clean field with motion: the magnetometer must be kept (>= 95 % accepted in a clean
        // field in motion).
        EXPECT_LE(r.mag_rejected_fraction, 0.05) << r.filter << " in test A, seed " << seed_name;
      }
    }
  }
}

// Test B judges the inclination; its heading tells whether a filter lets a magnet that comes to a resting sensor turn
// its heading before the detector flags it. B's magnet lies east of the sensor: at its closest it adds 19.5 uT across
// the 21.5 uT horizontal field, turning the field's horizontal direction by 42 deg while |m| changes by 7.6 % and the
// dip by 7.4 deg, so the detector flags it only on the last centimetres of each approach. Below the thresholds the
// field still turns (a 10 uT sideways field keeps |m| within 2 % and the dip within 3 deg, and turns the direction
// by 25 deg), and a heading that follows the magnetometer within a fraction of a second turns with it. Each filter
// runs the test with and without the magnet; the magnet may cost the worst heading error no more than Fan's "good"
// grade, 2 deg. Before their default noise was set for it, mekf_adaptive (Nez's static set, sigma_g 0.1
// rad/s/sqrt(Hz): a heading time constant of 0.44 s) exceeded the run without the magnet by 5.5-6.2 deg and dlkf
// (sigma_m 0.5 uT) by 7.3-8.5 deg; the others by 0.4-1.3 deg. With their new defaults mekf_adaptive 1.2-1.9 deg,
// dlkf 1.6-1.8 deg.
TEST(StandardTests, AMagnetBroughtToARestingSensorTurnsTheHeadingLittleMoreThanNone) {
  for (const std::string& name : rejecting_filters()) {
    for (const std::uint64_t seed : {2, 101, 202, 303, 404}) {
      sim::ScenarioSpec spec = sim::load_scenario(std::string(BSN_SCENARIO_DIR) + "/fan_b.yaml");
      spec.seed = seed;
      ASSERT_FALSE(spec.magnetic.dipoles.empty());
      sim::ScenarioSpec without = spec;
      without.magnetic.dipoles.clear();
      double worst[2] = {0.0, 0.0};
      for (int k = 0; k < 2; ++k) {
        auto filter = fusion::make_filter({name, {}});
        sim::ScenarioRunner runner(k == 0 ? spec : without, {}, false);
        std::vector<sim::ScenarioSample> out;
        while (runner.next(out)) {
          const sim::ScenarioSample& s = out.front();
          if (s.dropped) continue;
          filter->update(s.sample);
          if (static_cast<double>(s.sample.timestamp_ns) * 1e-9 < 3.0) continue;  // Table 5's start-up
          worst[k] = std::max(worst[k], fusion::error_angles(filter->orientation(), s.truth).heading);
        }
      }
      EXPECT_LT(worst[0], worst[1] + 2.0 * kDeg)
          << name << ", seed " << seed << ": worst heading error " << worst[0] / kDeg << " deg with the magnet, "
          << worst[1] / kDeg << " deg without";
    }
  }
}

}  // namespace
}  // namespace bsn::eval
