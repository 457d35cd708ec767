#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "bsn/calib/allan.hpp"
#include "bsn/sim/scenario.hpp"
#include "bsn/sim/scenario_file.hpp"

namespace bsn::calib {
namespace {

// White noise of density N plus a rate random walk of density K, sampled at fs.
Eigen::VectorXd white_plus_random_walk(double n_density, double k_density, double fs, Eigen::Index samples,
                                       std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> unit(0.0, 1.0);
  Eigen::VectorXd x(samples);
  double walk = 0.0;
  for (Eigen::Index k = 0; k < samples; ++k) {
    walk += k_density / std::sqrt(fs) * unit(rng);  // K sqrt(dt) per step
    x(k) = n_density * std::sqrt(fs) * unit(rng) + walk;
  }
  return x;
}

TEST(AllanDeviation, PureWhiteNoiseFallsAsOneOverRootTau) {
  const double n_density = 2e-3, fs = 100.0;
  const Eigen::VectorXd x = white_plus_random_walk(n_density, 0.0, fs, 100000, 1);
  const auto curve = allan_deviation(x, fs);
  ASSERT_GT(curve.size(), 20u);
  EXPECT_DOUBLE_EQ(curve.front().tau_s, 0.01);
  EXPECT_LE(curve.back().tau_s, 500.0);
  for (const AllanPoint& p : curve) {
    if (p.tau_s > 10.0) break;  // beyond, fewer than 100 independent clusters: the estimate scatters > 10 %
    EXPECT_NEAR(p.adev, n_density / std::sqrt(p.tau_s), 0.1 * n_density / std::sqrt(p.tau_s)) << p.tau_s;
  }
}

TEST(AllanDeviation, RecoversWhiteNoiseAndRateRandomWalkDensitiesWithinTenPercent) {
  // Gyro-like: N = 0.01 deg/s/sqrt(Hz) = 1.75e-4 rad/s/sqrt(Hz); K = 2e-4 rad/s^2/sqrt(Hz), the two lines
  // crossing at sqrt(3) N / K = 1.5 s, so 4000 s hold thousands of random-walk cluster times. (With K ten times
  // smaller the 4000 s record itself scatters K by +-15 % from seed to seed: the data, not the method.)
  const double n_density = 1.75e-4, k_density = 2e-4, fs = 50.0;
  const Eigen::VectorXd x = white_plus_random_walk(n_density, k_density, fs, 200000, 2);  // 4000 s
  const NoiseCoefficients c = fit_noise_coefficients(allan_deviation(x, fs));
  std::printf("N %.4g (true %.4g)  K %.4g (true %.4g)  B %.4g\n", c.white_density, n_density, c.rate_random_walk,
              k_density, c.bias_instability);
  EXPECT_NEAR(c.white_density, n_density, 0.1 * n_density);
  EXPECT_NEAR(c.rate_random_walk, k_density, 0.1 * k_density);
  // Without a flicker floor the minimum sits where the two lines cross: min adev = sqrt(2 N K / sqrt(3)).
  const double floor = std::sqrt(2.0 * n_density * k_density / std::sqrt(3.0));
  EXPECT_NEAR(c.bias_instability * 0.664, floor, 0.2 * floor);
  const FilterNoise f = filter_noise(c, fs);
  EXPECT_NEAR(f.sigma_white, n_density * std::sqrt(fs), 0.1 * n_density * std::sqrt(fs));
}

TEST(AllanDeviation, BadInputGivesAnEmptyCurveAndZeroCoefficients) {
  Eigen::VectorXd x = Eigen::VectorXd::Ones(100);
  x(50) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(allan_deviation(x, 100.0).empty());
  EXPECT_TRUE(allan_deviation(Eigen::VectorXd::Ones(2), 100.0).empty());
  EXPECT_TRUE(allan_deviation(Eigen::VectorXd::Ones(100), 0.0).empty());
  const NoiseCoefficients c = fit_noise_coefficients({});
  EXPECT_EQ(c.white_density, 0.0);
  EXPECT_EQ(c.bias_instability, 0.0);
  EXPECT_EQ(c.rate_random_walk, 0.0);
  // A constant series: zero deviation everywhere, no NaN.
  const NoiseCoefficients flat = fit_noise_coefficients(allan_deviation(Eigen::VectorXd::Ones(1000), 100.0));
  EXPECT_TRUE(std::isfinite(flat.white_density) && std::isfinite(flat.rate_random_walk));
}

}  // namespace
}  // namespace bsn::calib

namespace bsn::calib {
namespace {

// A 30-minute static recording (sim_publishers/scenarios/allan_static_30min.yaml) with a 50 Hz
// magnetometer beside the 100 Hz IMU. Each channel, taken at its own rate from its own timestamps, gives the white
// noise density it has within 10 % (the scatter of an Allan estimate at tau = 1 s over 30 min is about
// 1 / sqrt(number of 1 s clusters) = 2.4 %; quantisation adds up to 1.5 % on the gyro). The configured density is
// a property of the part, whatever its rate: each reading's SD is density * sqrt(the channel's own rate).
TEST(AllanDeviation, EveryChannelAtItsOwnRateRecoversItsDensity) {
  const sim::ScenarioSpec spec = sim::load_scenario(std::string(BSN_SCENARIO_DIR) + "/allan_static_30min.yaml");
  sim::ScenarioRunner runner(spec, {}, false);
  const auto n = static_cast<Eigen::Index>(runner.sample_count());
  using Rows = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
  Rows gyr(n, 3), acc(n, 3), mag(n, 3);
  std::vector<std::uint64_t> t_ns(static_cast<std::size_t>(n));
  std::vector<sim::ScenarioSample> out;
  for (Eigen::Index i = 0; runner.next(out); ++i) {
    const fusion::ImuSample& s = out.front().sample;
    gyr.row(i) = s.gyr.transpose();
    acc.row(i) = s.acc.transpose();
    if (s.has_mag) {
      mag.row(i) = s.mag.transpose();
    } else {
      mag.row(i).setConstant(std::numeric_limits<double>::quiet_NaN());
    }
    t_ns[static_cast<std::size_t>(i)] = s.timestamp_ns;
  }
  struct Channel {
    const Rows* data;
    double density;  // configured, unit/sqrt(Hz)
    double rate_hz;  // its own rate
  };
  const Channel channels[] = {{&gyr, spec.sensors.gyr.white_density, 100.0},
                              {&acc, spec.sensors.acc.white_density, 100.0},
                              {&mag, spec.sensors.mag.white_density, 50.0}};
  ASSERT_EQ(spec.sensors.mag_rate_hz, 50.0);
  for (const Channel& c : channels) {
    const OwnRateSeries series = own_rate_series(*c.data, t_ns);
    EXPECT_NEAR(series.rate_hz, c.rate_hz, 0.01 * c.rate_hz);  // the median interval, through 20 us jitter
    for (int axis = 0; axis < 3; ++axis) {
      const Eigen::VectorXd x = series.xyz.col(axis);
      const NoiseCoefficients k = fit_noise_coefficients(allan_deviation(x, series.rate_hz));
      EXPECT_NEAR(k.white_density, c.density, 0.10 * c.density) << "rate " << c.rate_hz << " axis " << axis;
    }
  }
}

TEST(AllanDeviation, OwnRateSeriesSkipsNanRowsAndCountsGaps) {
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> xyz(8, 3);
  xyz.setOnes();
  xyz.row(1).setConstant(std::numeric_limits<double>::quiet_NaN());
  xyz.row(3).setConstant(std::numeric_limits<double>::quiet_NaN());
  const std::vector<std::uint64_t> t = {0, 10, 20, 30, 40, 60, 80, 100};
  const OwnRateSeries s = own_rate_series(xyz, t);
  EXPECT_EQ(s.xyz.rows(), 6);
  EXPECT_NEAR(s.rate_hz, 1e9 / 20.0, 1e-3);  // intervals 20, 20, 20, 20, 20 ns
  EXPECT_EQ(s.gaps, 0u);
  EXPECT_EQ(own_rate_series(xyz.topRows(2), std::span(t).first(2)).rate_hz, 0.0);
}

}  // namespace
}  // namespace bsn::calib
