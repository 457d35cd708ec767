// Fan et al. 2018's standard tests A-E (bsn eval --standard-tests): Table 5's grades, and every filter that rejects
// the magnetometer still catching the disturbances of tests B, C and E.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "bsn/eval/standard_tests.hpp"
#include "bsn/fusion/orientation_filter.hpp"

namespace bsn::eval {
namespace {

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
  for (const char* name : {"complementary", "seel_ruppin", "iecf", "ekf", "mekf", "mekf_adaptive", "dlkf"}) {
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
        // A is a clean field with motion: the magnetometer must be kept (issue 12: >= 95 % accepted in a clean
        // field in motion).
        EXPECT_LE(r.mag_rejected_fraction, 0.05) << r.filter << " in test A, seed " << seed_name;
      }
    }
  }
}

}  // namespace
}  // namespace bsn::eval
