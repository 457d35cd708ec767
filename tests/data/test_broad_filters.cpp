// Every filter on the real BROAD recordings, one fixed parameter set (the defaults) for all trials.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <numbers>

#include "broad_data.hpp"
#include "bsn/eval/evaluation.hpp"

namespace bsn {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

// Mean total RMSE bar per filter, degrees: the figure measured with `bsn eval ../shared/data/broad --filter NAME`
// plus 10 %, so a regression of accuracy fails here. A new filter must get its bar.
// Measured 2026-11-22 with the defaults (mean total / inclination RMSE, deg).
const std::map<std::string, double> kMeanTotalRmseBarDeg = {
    {"complementary", 14.4},  // 13.09 / 9.64: no bias estimate; fails on the fast-translation trial
    {"seel_ruppin", 2.45},    // 2.22 / 0.61: the best; the project target is <= 2.5 / 0.6 (VQF: 2.51 / 0.61)
    {"madgwick", 3.5},        // 3.19 / 1.67
    {"madgwick6", 4.7},       // 4.30 / 1.15
    {"iecf", 3.4},            // 3.06 / 2.02
    {"iecf6", 5.2},           // 4.69 / 1.95
    {"ekf", 3.2},             // 2.87 / 1.01
    {"mekf", 4.0},            // 3.67 / 0.93
    {"mekf_adaptive", 6.0},   // 5.45 / 1.21: Table 3 sets within their Table 1 ranges, rate-scaled
    {"dlkf", 5.0},            // 4.53 / 3.20
};

// The best filter's figures, held at measured + 10 % (the project's target is 2.5 / 0.6 deg; the inclination,
// 0.607 deg, is just above it).
constexpr double kBestTotalBarDeg = 2.45;
constexpr double kBestInclinationBarDeg = 0.67;

TEST(BroadFilters, EveryFilterRunsEveryTrialUnderItsBar) {
  BSN_REQUIRE_BROAD();
  std::vector<io::Recording> trials;
  std::vector<std::string> names;
  for (const auto& f : testing::broad_files()) {
    trials.push_back(io::read_broad_hdf5(f.string()));
    names.push_back(f.stem().string());
  }
  std::vector<eval::TrialResult> results;
  for (const auto& filter : fusion::filter_names()) {
    for (std::size_t i = 0; i < trials.size(); ++i) {
      results.push_back(eval::run_trial(trials[i], names[i], {filter, {}}, filter));
      const auto& r = results.back();
      EXPECT_EQ(r.non_finite, 0u) << filter << " on " << r.trial;
      EXPECT_GT(r.scored, trials[i].size() / 4) << filter << " on " << r.trial;
    }
  }
  std::printf("%s", eval::to_table(results).c_str());
  for (const auto& m : eval::means_by_filter(results)) {
    const auto bar = kMeanTotalRmseBarDeg.find(m.filter);
    if (bar == kMeanTotalRmseBarDeg.end()) {
      ADD_FAILURE() << "no accuracy bar for filter '" << m.filter << "'; measured mean total RMSE "
                    << m.mean_rmse.total * kDeg << " deg";
      continue;
    }
    EXPECT_LT(m.mean_rmse.total * kDeg, bar->second) << m.filter;
  }
  const auto means = eval::means_by_filter(results);
  const auto best = std::min_element(
      means.begin(), means.end(), [](const auto& a, const auto& b) { return a.mean_rmse.total < b.mean_rmse.total; });
  ASSERT_NE(best, means.end());
  std::printf("best filter: %s, mean total %.2f deg, inclination %.2f deg (target 2.5 / 0.6)\n", best->filter.c_str(),
              best->mean_rmse.total * kDeg, best->mean_rmse.inclination * kDeg);
  EXPECT_LT(best->mean_rmse.total * kDeg, kBestTotalBarDeg);
  EXPECT_LT(best->mean_rmse.inclination * kDeg, kBestInclinationBarDeg);
}

}  // namespace
}  // namespace bsn
