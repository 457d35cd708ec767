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
// Measured 2026-12-02 with the defaults after issue 12's shared detector (mean total / inclination RMSE, deg; before
// it in brackets).
const std::map<std::string, double> kMeanTotalRmseBarDeg = {
    {"complementary", 3.00},  // 2.73 / 1.04 (13.09 / 9.64 before its rest bias low-pass and tilt clip; 3.97 / 1.73
                              // before the accelerometer was never skipped and the shared detector came in)
    {"seel_ruppin", 2.28},    // 2.07 / 0.61 (2.21 / 0.61): the best (VQF: 2.51 / 0.61)
    {"madgwick", 3.51},       // 3.19 / 1.67
    {"madgwick6", 4.73},      // 4.30 / 1.15
    {"iecf", 3.44},           // 3.13 / 1.92 (3.05 / 1.99)
    {"iecf6", 5.16},          // 4.69 / 1.95
    // ekf: 2.42 / 1.09 (3.08 / 1.05; 2.40 / 1.01 before acc_variance_cap; 2.42 / 1.05 before rest_bias_update)
    {"ekf", 2.66},
    {"mekf", 2.72},  // 2.47 / 0.94 (3.85 / 1.17; 2.94 / 0.92 before rest_bias_update)
    // mekf_adaptive: 4.27 / 0.93 (4.77 / 1.23; 5.06 / 1.21 before immediate_up_switch; 5.09 / 1.04 before
    // rest_bias_update)
    {"mekf_adaptive", 4.70},
    {"dlkf", 5.67},  // 5.15 / 3.20 (5.81 / 3.20)
};

// The best filter's figures (seel_ruppin, 2.07 / 0.61 deg), held at measured + 10 % (the project's target is
// 2.5 / 0.6 deg; the inclination is just above it).
constexpr double kBestTotalBarDeg = 2.28;
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
