// Nez et al. 2018 reproduced on the simulator: the MEKF's four sigmas identified on each of the three
// 10-minute Nez scenarios (Opal-like sensor, 128 Hz), and the fast one again with a magnetometer that lags the gyro.
// Labelled slow (about a minute on two free cores).
#include <gtest/gtest.h>

#include <numbers>

#include "bsn/eval/tune_runner.hpp"
#include "bsn/sim/scenario_file.hpp"

namespace bsn::eval {
namespace {

TuneResult identify(const char* name, const sim::ScenarioSpec& spec, int preset) {
  const TuneRecording rec{name, simulate_recording(spec), {}};
  TuneSetup setup = nez_mekf_setup(rec, preset);  // Table 3's set of the scenario's intensity, no magnetometer lag
  setup.options.max_evaluations = 300;
  TuneResult r = tune(setup);
  std::printf("%s: sigma_g %.3g sigma_bg %.3g sigma_a %.3g sigma_m %.3g, %.2f deg (Table 3: %.2f deg)\n", name,
              r.values[0], r.values[1], r.values[2], r.values[3], r.fit_rmse[0] * 180 / std::numbers::pi,
              r.base_fit_rmse[0] * 180 / std::numbers::pi);
  return r;
}

sim::ScenarioSpec scenario(const char* name) {
  return sim::load_scenario(std::string(BSN_SCENARIO_DIR) + "/" + name + ".yaml");
}

TEST(TuneNezScenarios, IdentifiedSetsBeatTable3AndSigmaAGrowsWithIntensity) {
  const char* scenarios[] = {"nez_slow", "nez_intermediate", "nez_fast"};
  std::vector<double> sigma_a, sigma_m;
  for (int s = 0; s < 3; ++s) {
    const TuneResult r = identify(scenarios[s], scenario(scenarios[s]), s + 1);
    // Identified on the scenario itself, the set must beat the preset identified on other sensors (Nez's point:
    // the sigmas belong to the sensor and the motion). The preset is inside the searched ranges, so this fails
    // only if the search does not find a point better than one it could have visited.
    EXPECT_LT(r.fit_rmse[0], r.base_fit_rmse[0]) << scenarios[s];
    sigma_a.push_back(r.values[2]);
    sigma_m.push_back(r.values[3]);
  }
  // Table 3: sigma_a grows with the intensity (external acceleration is part of the accelerometer's error). Ties
  // are allowed: on the simulator the intermediate and fast optima both lie at the range's upper end (the
  // simulated Opal gyro has white noise and bias instability only, so trusting it beats any accelerometer
  // correction under strong external acceleration).
  EXPECT_LE(sigma_a[0], sigma_a[1]);
  EXPECT_LE(sigma_a[1], sigma_a[2]);
  EXPECT_LT(sigma_a[0], sigma_a[2]);

  // Table 3's sigma_m grows from slow to fast; the Opal-like sensor's does not, and the experiment of the README
  // (Tuning) says why: only a magnetometer that lags the gyro makes its reading worse the faster the sensor turns
  // (off by |w| x lag), and the Opal's specification (one 50 Hz bandwidth on every channel) gives it no such lag.
  // A calibration residual, the lab's field (de Vries 2009) and Nez's reference (alignment, time shift) at their
  // published sizes do not order sigma_m either (tests/bench/bench_nez_sources.cpp). One sample of lag (7.8 ms) on the
  // same fast motion must raise the identified sigma_m, above the slow one's.
  sim::ScenarioSpec lagging = scenario("nez_fast");
  lagging.sensors.mag_delay_samples = 1;
  const double lagged_sigma_m = identify("nez_fast, magnetometer 1 sample late", lagging, 3).values[3];
  EXPECT_GT(lagged_sigma_m, sigma_m[2]);
  EXPECT_GT(lagged_sigma_m, sigma_m[0]);
}

}  // namespace
}  // namespace bsn::eval
