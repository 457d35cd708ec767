// EkfFilter (Fan et al. 2018 §2.4.2, 7-state [q, b]) against its defining properties: initialisation and static
// accuracy at any heading, the joint accelerometer + magnetometer update that lets a magnet tilt the estimate (Fan
// test B: roll/pitch move), consistency with the noise it assumes (NEES), and bad input never touching the state.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "bsn/fusion/ekf_filter.hpp"
#include "kalman_test_util.hpp"

namespace bsn::fusion {
namespace {

using namespace bsn::fusion::test;

TEST(Ekf, InitialisesFromTheFirstSampleForAnyHeadingAndStaysOnAStaticSensor) {
  for (double yaw : {-179.0, -120.0, -45.0, 0.0, 60.0, 135.0, 180.0}) {
    EkfFilter f;
    const Quat q = from_yaw_pitch_roll({yaw * kDeg, -25 * kDeg, 40 * kDeg});
    ASSERT_EQ(f.update(static_sample(q, 0)), UpdateResult::kInitialised);
    EXPECT_LT(angle_between(f.orientation(), q), 1e-9) << yaw;
    EXPECT_TRUE(f.flags().reinitialised);
    for (std::uint64_t k = 1; k <= 500; ++k)
      ASSERT_EQ(f.update(static_sample(q, k * 10 * kMs)), UpdateResult::kUpdated);
    EXPECT_LT(angle_between(f.orientation(), q), 1e-8) << yaw;
    EXPECT_TRUE(f.flags().resting);
    EXPECT_FALSE(f.flags().initialising);
  }
}

TEST(Ekf, StaticAccuracyAnyHeadingWithNoiseAndBias) {
  for (double yaw : {-150.0, -30.0, 90.0, 170.0}) {
    EkfFilter f;
    const Quat q = from_yaw_pitch_roll({yaw * kDeg, 5 * kDeg, -10 * kDeg});
    const Vec3 bias(0.01, -0.008, 0.005);  // the magnetometer makes every axis observable here
    std::mt19937_64 rng(42);
    std::normal_distribution<double> g(0.0, 1.0);
    auto n3 = [&] { return Vec3(g(rng), g(rng), g(rng)); };
    double sq = 0;
    int count = 0;
    for (std::uint64_t k = 0; k <= 6000; ++k) {
      ImuSample s = static_sample(q, k * 10 * kMs);
      s.acc += 0.02 * n3();
      s.mag += 0.2 * n3();
      s.gyr = bias + 0.003 * n3();
      f.update(s);
      if (k > 4000) {
        sq += std::pow(angle_between(f.orientation(), q), 2);
        ++count;
      }
    }
    EXPECT_LT(std::sqrt(sq / count), 0.5 * kDeg) << yaw;
    EXPECT_LT((f.gyro_bias() - bias).norm(), 1e-3) << yaw;
  }
}

// Fan test B with all magnetic adaption off (Fan §3.2): the joint update pulls roll or pitch with the magnet (Fan
// measured 1.2 deg); here the bound is 0.3 deg, three times the 0.1 deg that the decoupled filters must keep.
TEST(Ekf, FanTestBMagnetMovesRollOrPitch) {
  EkfFilter::Params p;
  p.mag_rejection = 0.0;
  EkfFilter f(p);
  const Quat q = from_yaw_pitch_roll({70 * kDeg, 12 * kDeg, -20 * kDeg});
  double max_tilt_dev = 0;
  for (std::uint64_t k = 0; k <= 3000; ++k) {
    ImuSample s = static_sample(q, k * 10 * kMs);
    s.mag += magnet_field(0.01 * static_cast<double>(k));
    f.update(s);
    const YawPitchRoll est = to_yaw_pitch_roll(f.orientation());
    max_tilt_dev = std::max({max_tilt_dev, std::abs(est.pitch - 12 * kDeg), std::abs(est.roll + 20 * kDeg)});
  }
  EXPECT_GT(max_tilt_dev, 0.3 * kDeg);
  RecordProperty("max_tilt_dev_deg", std::to_string(max_tilt_dev / kDeg));
}

// Consistency: N independent runs of a sensor turning about all axes, with exactly the noise the filter assumes
// (its defaults). The 6-dof NEES e^T P^-1 e of [dtheta, db] at the end of each run, averaged over the N runs, must lie
// in the two-sided 95 % interval of chi^2(6 N) / N. Runs are independent, so the sum is chi^2(6 N) if P is right.
TEST(Ekf, ConsistentNeesOnLongSimulatedRuns) {
  const EkfFilter::Params defaults;
  const double dt = 0.01;
  const int runs = 24;
  const int steps = 6000;  // 60 s each
  double nees_sum = 0;
  for (int r = 0; r < runs; ++r) {
    EkfFilter::Params p;
    p.mag_rejection = 0.0;
    EkfFilter f(p);
    std::mt19937_64 rng(1000 + r);
    std::normal_distribution<double> g(0.0, 1.0);
    const Vec3 bias0 = p.init_bias_sigma_rad_s * Vec3(g(rng), g(rng), g(rng));
    RotatingSensor sensor(7 + r, dt, {defaults.sigma_g, defaults.sigma_bg, defaults.sigma_a, defaults.sigma_m},
                          from_yaw_pitch_roll({r * 0.7, 0.2, -0.1}), bias0);
    // The EKF takes its earth-field reference from the first sample and assumes it exact (Fan §2.4.2: it needs a
    // predefined reference), so that sample is given without noise; every later one has the assumed noise.
    f.update(sensor.first(false));
    for (int k = 0; k < steps; ++k) f.update(sensor.next());
    Eigen::Matrix<double, 6, 1> e;
    e.head<3>() = body_error(f.orientation(), sensor.q());
    e.tail<3>() = sensor.bias() - f.gyro_bias();
    nees_sum += e.dot(f.error_covariance().ldlt().solve(e));
  }
  const double mean_nees = nees_sum / runs;
  const auto [lo, hi] = chi2_interval_95(6.0 * runs, runs);
  EXPECT_GT(mean_nees, lo);
  EXPECT_LT(mean_nees, hi);
  RecordProperty("mean_nees", std::to_string(mean_nees));
}

TEST(Ekf, SlowerMagnetometerAndSixDSamples) {
  EkfFilter f;
  RotatingSensor sensor(11, 0.01, {1e-3, 1e-5, 0.05, 0.3}, from_yaw_pitch_roll({2.0, 0.1, 0.3}), Vec3::Zero());
  f.update(sensor.first());
  double worst = 0;
  for (int k = 1; k <= 6000; ++k) {
    ImuSample s = sensor.next();
    s.has_mag = (k % 4 == 0) && k < 3000;  // 25 Hz magnetometer, then none for 30 s
    ASSERT_EQ(f.update(s), UpdateResult::kUpdated);
    if (k > 1000) worst = std::max(worst, angle_between(f.orientation(), sensor.q()));
  }
  EXPECT_LT(worst, 2.0 * kDeg);
}

TEST(Ekf, BadInputNeverTouchesTheState) {
  EkfFilter f;
  const Quat q = from_yaw_pitch_roll({1.0, 0.2, -0.3});
  f.update(static_sample(q, 0));
  f.update(static_sample(q, 10 * kMs));
  const EkfFilter::State before = f.state();
  ImuSample bad = static_sample(q, 20 * kMs);
  bad.gyr.x() = std::nan("");
  EXPECT_EQ(f.update(bad), UpdateResult::kRejected);
  bad = static_sample(q, 20 * kMs);
  bad.mag.z() = INFINITY;
  EXPECT_EQ(f.update(bad), UpdateResult::kRejected);
  EXPECT_EQ(f.update(static_sample(q, 10 * kMs)), UpdateResult::kRejected);  // zero dt
  EXPECT_EQ(f.update(static_sample(q, 5 * kMs)), UpdateResult::kRejected);   // backwards
  EXPECT_EQ(f.state().q.coeffs(), before.q.coeffs());
  EXPECT_EQ(f.state().p, before.p);
  EXPECT_EQ(f.state().bias, before.bias);
  // A gap longer than max_gap_s re-initialises and says so.
  EXPECT_EQ(f.update(static_sample(q, 10 * kMs + 5'000 * kMs)), UpdateResult::kInitialised);
  EXPECT_TRUE(f.flags().reinitialised);
  // Saturated values and a huge step within the gap limit never give a non-finite state.
  ImuSample wild = static_sample(q, 10 * kMs + 5'900 * kMs);
  wild.gyr = Vec3(1e6, -1e6, 1e6);
  wild.acc = Vec3(1e9, 0, -1e9);
  wild.mag = Vec3(1e9, 1e9, 0);
  f.update(wild);
  EXPECT_TRUE(f.orientation().coeffs().allFinite());
  EXPECT_TRUE(f.covariance().allFinite());
  EXPECT_TRUE(f.gyro_bias().allFinite());
}

TEST(Ekf, FactoryMakesItAndChecksParameters) {
  auto f = make_filter({"ekf", {{"sigma_a", 0.5}}});
  EXPECT_EQ(f->name(), "ekf");
  EXPECT_EQ(dynamic_cast<EkfFilter&>(*f).params().sigma_a, 0.5);
  EXPECT_THROW(make_filter({"ekf", {{"sigma_g", 0}}}), std::invalid_argument);
  EXPECT_THROW(make_filter({"ekf", {{"mag_rejection", 0.5}}}), std::invalid_argument);
  EXPECT_THROW(make_filter({"ekf", {{"no_such", 1}}}), std::invalid_argument);
}

TEST(Ekf, CovarianceStaysSymmetricPositiveDefinite) {
  EkfFilter f;
  RotatingSensor sensor(3, 0.005, {0.01, 1e-3, 0.5, 1.0}, Quat::Identity(), Vec3(0.01, 0, 0), 6.0);
  f.update(sensor.first());
  for (int k = 0; k < 8000; ++k) {
    f.update(sensor.next());
    const EkfFilter::Mat7& p = f.covariance();
    ASSERT_LT((p - p.transpose()).cwiseAbs().maxCoeff(), 1e-15);
    ASSERT_EQ(p.llt().info(), Eigen::Success) << k;
  }
}

}  // namespace
}  // namespace bsn::fusion
