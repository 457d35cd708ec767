// Nez et al. 2018 reproduced on the simulator (issue 17): the MEKF's four sigmas identified on each of the three
// 10-minute Nez scenarios (Opal-like sensor, 128 Hz). Labelled slow (about 30 s on two free cores).
#include <gtest/gtest.h>

#include <numbers>

#include "bsn/eval/tune_runner.hpp"
#include "bsn/sim/scenario_file.hpp"

namespace bsn::eval {
namespace {

TEST(TuneNezScenarios, IdentifiedSetsBeatTable3AndSigmaAGrowsWithIntensity) {
  const char* scenarios[] = {"nez_slow", "nez_intermediate", "nez_fast"};
  std::vector<double> sigma_a;
  for (int s = 0; s < 3; ++s) {
    const sim::ScenarioSpec spec = sim::load_scenario(std::string(BSN_SCENARIO_DIR) + "/" + scenarios[s] + ".yaml");
    const TuneRecording rec{scenarios[s], simulate_recording(spec), {}};
    TuneSetup setup;
    // The base is Table 3's set of the scenario's intensity (preset 1 slow, 2 intermediate, 3 fast).
    setup.base = {"mekf", {{"preset", s + 1.0}}};
    setup.ranges = default_param_ranges("mekf");
    setup.fit = {&rec};
    setup.options.max_evaluations = 300;
    const TuneResult r = tune(setup);
    // Identified on the scenario itself, the set must beat the preset identified on other sensors (Nez's point:
    // the sigmas belong to the sensor and the motion). The preset is inside the searched ranges, so this fails
    // only if the search does not find a point better than one it could have visited.
    EXPECT_LT(r.fit_rmse[0], r.base_fit_rmse[0]) << scenarios[s];
    sigma_a.push_back(r.values[2]);
    std::printf("%s: sigma_g %.3g sigma_bg %.3g sigma_a %.3g sigma_m %.3g, %.2f deg (Table 3: %.2f deg)\n",
                scenarios[s], r.values[0], r.values[1], r.values[2], r.values[3],
                r.fit_rmse[0] * 180 / std::numbers::pi, r.base_fit_rmse[0] * 180 / std::numbers::pi);
  }
  // Table 3: sigma_a grows with the intensity (external acceleration is part of the accelerometer's error). Ties
  // are allowed: on the simulator the intermediate and fast optima both lie at the range's upper end (the
  // simulated Opal gyro has white noise and bias instability only, so trusting it beats any accelerometer
  // correction under strong external acceleration).
  EXPECT_LE(sigma_a[0], sigma_a[1]);
  EXPECT_LE(sigma_a[1], sigma_a[2]);
  EXPECT_LT(sigma_a[0], sigma_a[2]);
}

}  // namespace
}  // namespace bsn::eval
