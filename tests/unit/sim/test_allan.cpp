// The simulated gyro noise has the configured densities: the calibration engineer's Allan analysis
// (bsn::calib, an independent implementation) recovers them from a static recording of the simulator.
#include <gtest/gtest.h>

#include <Eigen/Core>

#include "bsn/calib/allan.hpp"
#include "bsn/sim/sensor_model.hpp"

namespace bsn::sim {
namespace {

TEST(SimAllan, StaticGyroRecoversTheConfiguredWhiteAndRandomWalkDensities) {
  // 30 min at 200 Hz. The -1/2 and +1/2 slopes cross at tau = sqrt(3) N / K ~ 0.7 s, so both are well inside
  // the curve: the white part is fitted from ~1e5 clusters, the random walk from hundreds to thousands
  // (relative error of the Allan deviation ~ 1 / sqrt(2 clusters): a few percent at most).
  const double rate_hz = 200.0;
  const double white = 0.002;  // rad/s/sqrt(Hz)
  const double walk = 0.005;   // rad/s/sqrt(s)
  SensorErrors errors;
  errors.gyr.white_density = white;
  errors.gyr.bias_random_walk = walk;
  errors.gyr.bias = Vec3(0.01, -0.02, 0.005);  // a constant bias does not change the curve
  SensorSimulator sensor(errors, rate_hz, 21);
  const Eigen::Index n = 30 * 60 * 200;
  Eigen::MatrixXd gyr(n, 3);
  const Vec3 at_rest = Vec3::Zero(), gravity(0.0, 0.0, fusion::kGravity), field(0.0, 21.5, -44.0);
  for (Eigen::Index k = 0; k < n; ++k) {
    gyr.row(k) = sensor.measure(at_rest, gravity, field, static_cast<double>(k) / rate_hz, 0, true).gyr.transpose();
  }
  for (int axis = 0; axis < 3; ++axis) {
    const Eigen::VectorXd x = gyr.col(axis);
    const calib::NoiseCoefficients c = calib::fit_noise_coefficients(calib::allan_deviation(x, rate_hz));
    EXPECT_NEAR(c.white_density, white, 0.10 * white) << "axis " << axis;
    EXPECT_NEAR(c.rate_random_walk, walk, 0.10 * walk) << "axis " << axis;
  }
}

}  // namespace
}  // namespace bsn::sim
