// DlkfFilter (Fan et al. 2018 §2.4.1, Fig. 4) against its defining properties: TRIAD (eqs. 1-4) is exact for any
// heading, roll and pitch never depend on the magnetometer (Fan test B), each of the two linear filters is
// consistent with the noise it assumes (NEES), the low-pass gyro bias removes a bias at rest, and bad input never
// touches the state.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "bsn/fusion/dlkf_filter.hpp"
#include "kalman_test_util.hpp"

namespace bsn::fusion {
namespace {

using namespace bsn::fusion::test;

TEST(Dlkf, TriadMatchesTheTrueOrientationForAnyHeadingAndEulerEq4) {
  for (double yaw : {-179.0, -100.0, -10.0, 0.0, 45.0, 135.0, 180.0}) {
    const Quat q = from_yaw_pitch_roll({yaw * kDeg, 30 * kDeg, -50 * kDeg});
    const ImuSample s = static_sample(q, 0);
    EXPECT_LT(angle_between(DlkfFilter::triad(s.acc, s.mag), q), 1e-12) << yaw;
    // Roll and pitch depend on the first vector only: any field gives the same inclination.
    const Quat other = DlkfFilter::triad(s.acc, s.mag + Vec3(20, -5, 30));
    const YawPitchRoll a = to_yaw_pitch_roll(other);
    EXPECT_NEAR(a.pitch, 30 * kDeg, 1e-12);
    EXPECT_NEAR(a.roll, -50 * kDeg, 1e-12);
  }
}

TEST(Dlkf, InitialisesFromTheFirstSampleForAnyHeadingAndStaysOnAStaticSensor) {
  for (double yaw : {-179.0, -120.0, -45.0, 0.0, 60.0, 135.0, 180.0}) {
    DlkfFilter f;
    const Quat q = from_yaw_pitch_roll({yaw * kDeg, -25 * kDeg, 40 * kDeg});
    ASSERT_EQ(f.update(static_sample(q, 0)), UpdateResult::kInitialised);
    EXPECT_LT(angle_between(f.orientation(), q), 1e-9) << yaw;
    EXPECT_TRUE(f.flags().reinitialised);
    for (std::uint64_t k = 1; k <= 500; ++k)
      ASSERT_EQ(f.update(static_sample(q, k * 10 * kMs)), UpdateResult::kUpdated);
    EXPECT_LT(angle_between(f.orientation(), q), 1e-9) << yaw;
    EXPECT_TRUE(f.flags().resting);
    EXPECT_FALSE(f.flags().initialising);
  }
}

// Static accuracy with sensor noise and a gyro bias at every heading: the low-pass bias (Fan eqs. 11-12) learns the
// bias after t_b = 2 s of rest, and the error stays well below a degree.
TEST(Dlkf, StaticAccuracyAnyHeadingWithNoiseAndBias) {
  for (double yaw : {-150.0, -30.0, 90.0, 170.0}) {
    DlkfFilter f;
    const Quat q = from_yaw_pitch_roll({yaw * kDeg, 5 * kDeg, -10 * kDeg});
    const Vec3 bias(0.01, -0.008, 0.005);
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

// Fan test B with all magnetic adaption off: roll and pitch come from the gravity filter alone (TRIAD, gravity
// first), so they stay within 0.1 deg; the yaw is pulled (the disturbance is felt).
TEST(Dlkf, FanTestBMagnetDoesNotMoveRollAndPitch) {
  DlkfFilter::Params p;
  p.mag_rejection = 0.0;
  DlkfFilter f(p);
  const Quat q = from_yaw_pitch_roll({70 * kDeg, 12 * kDeg, -20 * kDeg});
  double max_tilt_dev = 0, max_yaw_dev = 0;
  for (std::uint64_t k = 0; k <= 3000; ++k) {
    ImuSample s = static_sample(q, k * 10 * kMs);
    s.mag += magnet_field(0.01 * static_cast<double>(k));
    f.update(s);
    const YawPitchRoll est = to_yaw_pitch_roll(f.orientation());
    max_tilt_dev = std::max({max_tilt_dev, std::abs(est.pitch - 12 * kDeg), std::abs(est.roll + 20 * kDeg)});
    max_yaw_dev = std::max(max_yaw_dev, std::abs(est.yaw - 70 * kDeg));
  }
  EXPECT_LT(max_tilt_dev, 0.1 * kDeg);
  EXPECT_GT(max_yaw_dev, 1.0 * kDeg);
}

// Consistency of both linear filters: N independent runs of a sensor turning about all axes with exactly the noise
// the filter assumes: gyro white noise, accelerometer = gravity + Gauss-Markov external acceleration + white noise,
// magnetometer = field + Gauss-Markov disturbance + white noise. For each filter the 6-dof NEES at the end of each
// run, averaged over the N runs, must lie in the two-sided 95 % interval of chi^2(6 N) / N. (The two filters share
// the gyro noise, so they are tested separately, not as one 12-dof state.)
TEST(Dlkf, BothFiltersConsistentNeesOnLongSimulatedRuns) {
  DlkfFilter::Params p;
  p.gyro_bias_lowpass = 0.0;
  p.mag_rejection = 0.0;
  p.acc_rejection_m_s2 = 0.0;
  const double dt = 0.01;
  const int runs = 100;
  const int steps = 6000;
  const double c_ext = std::exp(-dt / p.tau_ext_acc_s), c_dist = std::exp(-dt / p.tau_mag_disturbance_s);
  double nees_g = 0, nees_m = 0;
  for (int r = 0; r < runs; ++r) {
    DlkfFilter f(p);
    std::mt19937_64 rng(500 + r);
    std::normal_distribution<double> g(0.0, 1.0);
    auto n3 = [&] { return Vec3(g(rng), g(rng), g(rng)); };
    RotatingSensor sensor(70 + r, dt, {p.sigma_g, 0.0, p.sigma_a, p.sigma_m}, from_yaw_pitch_roll({r * 0.9, -0.3, 0.2}),
                          Vec3::Zero());
    Vec3 ext = p.sigma_ext_acc * n3(), dist = p.sigma_mag_disturbance * n3();
    ImuSample s = sensor.first();
    s.acc += ext;
    s.mag += dist;
    f.update(s);
    for (int k = 0; k < steps; ++k) {
      ext = c_ext * ext + std::sqrt(1 - c_ext * c_ext) * p.sigma_ext_acc * n3();
      dist = c_dist * dist + std::sqrt(1 - c_dist * c_dist) * p.sigma_mag_disturbance * n3();
      s = sensor.next();
      s.acc += ext;
      s.mag += dist;
      f.update(s);
    }
    Eigen::Matrix<double, 6, 1> eg, em;
    eg << sensor.q().conjugate() * Vec3(0, 0, kGravity) - f.state().gravity.vector(),
        ext - f.state().gravity.disturbance();
    em << sensor.q().conjugate() * kEarthField - f.state().magnetic.vector(), dist - f.state().magnetic.disturbance();
    nees_g += eg.dot(f.gravity_covariance().ldlt().solve(eg));
    nees_m += em.dot(f.magnetic_covariance().ldlt().solve(em));
  }
  const auto [lo, hi] = chi2_interval_95(6.0 * runs, runs);
  EXPECT_GT(nees_g / runs, lo);
  EXPECT_LT(nees_g / runs, hi);
  EXPECT_GT(nees_m / runs, lo);
  EXPECT_LT(nees_m / runs, hi);
  RecordProperty("mean_nees_gravity", std::to_string(nees_g / runs));
  RecordProperty("mean_nees_magnetic", std::to_string(nees_m / runs));
}

TEST(Dlkf, CovariancesStaySymmetricPositiveDefinite) {
  DlkfFilter f;
  RotatingSensor sensor(3, 0.005, {0.01, 1e-3, 0.5, 1.0}, Quat::Identity(), Vec3(0.01, 0, 0), 6.0);
  f.update(sensor.first());
  for (int k = 0; k < 8000; ++k) {
    f.update(sensor.next());
    for (const dlkf::Mat6* p : {&f.gravity_covariance(), &f.magnetic_covariance()}) {
      // Exactly symmetric by construction: the filter clamps only the variances and never symmetrises.
      ASSERT_TRUE(*p == p->transpose()) << k;
      ASSERT_EQ(p->llt().info(), Eigen::Success) << k;
    }
  }
}

// SplitKalman processes the three axes as sequential scalar updates; with R diagonal that is the batch update
// K = P H^T S^-1, x += K (y - H x), P = (I - K H) P (I - K H)^T + K R K^T, up to rounding.
TEST(Dlkf, SequentialScalarCorrectionEqualsTheBatchUpdate) {
  dlkf::SplitKalman f;
  f.initialise(Vec3(0.3, -0.2, 9.7), 0.05 * 0.05, 3.0 * 3.0);
  const Eigen::Matrix3d turn = Quat(Eigen::AngleAxisd(0.05, Vec3(0.2, 0.5, 1.0).normalized())).toRotationMatrix();
  for (int step = 0; step < 20; ++step) {
    f.predict(turn, 4e-6 * 0.01, 0.9, 9.0);
    const Vec3 y(0.1 * std::sin(step), 0.2 * std::cos(step), 9.81 + 0.5 * std::sin(0.3 * step));
    const double r = 0.05 * 0.05;
    Eigen::Matrix<double, 3, 6> h;
    h << Eigen::Matrix3d::Identity(), Eigen::Matrix3d::Identity();
    const Eigen::Matrix3d s = h * f.p * h.transpose() + r * Eigen::Matrix3d::Identity();
    const Eigen::Matrix<double, 6, 3> k = f.p * h.transpose() * s.inverse();
    const dlkf::Vec6 x_batch = f.x + k * (y - h * f.x);
    const dlkf::Mat6 a = dlkf::Mat6::Identity() - k * h;
    const dlkf::Mat6 p_batch = a * f.p * a.transpose() + r * k * k.transpose();
    f.correct(y, r);
    EXPECT_LT((f.x - x_batch).cwiseAbs().maxCoeff(), 1e-12 * x_batch.cwiseAbs().maxCoeff()) << step;
    EXPECT_LT((f.p - p_batch).cwiseAbs().maxCoeff(), 1e-9 * p_batch.cwiseAbs().maxCoeff()) << step;
  }
}

TEST(Dlkf, SlowerMagnetometerAndSixDSamples) {
  DlkfFilter f;
  RotatingSensor sensor(11, 0.01, {1e-3, 0.0, 0.05, 0.3}, from_yaw_pitch_roll({2.0, 0.1, 0.3}), Vec3::Zero());
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

TEST(Dlkf, StartsWithoutMagnetometerAndTakesTheHeadingFromTheFirstOne) {
  DlkfFilter f;
  const Quat q = from_yaw_pitch_roll({-2.0, 0.2, 0.1});
  ImuSample s = static_sample(q, 0);
  s.has_mag = false;
  ASSERT_EQ(f.update(s), UpdateResult::kInitialised);
  EXPECT_NEAR(to_yaw_pitch_roll(f.orientation()).yaw, 0.0, 1e-9);
  f.update(static_sample(q, 10 * kMs));
  EXPECT_LT(angle_between(f.orientation(), q), 1e-6);
}

TEST(Dlkf, BadInputNeverTouchesTheState) {
  DlkfFilter f;
  const Quat q = from_yaw_pitch_roll({1.0, 0.2, -0.3});
  f.update(static_sample(q, 0));
  f.update(static_sample(q, 10 * kMs));
  const DlkfFilter::State before = f.state();
  ImuSample bad = static_sample(q, 20 * kMs);
  bad.acc.y() = std::nan("");
  EXPECT_EQ(f.update(bad), UpdateResult::kRejected);
  EXPECT_EQ(f.update(static_sample(q, 10 * kMs)), UpdateResult::kRejected);
  EXPECT_EQ(f.update(static_sample(q, 5 * kMs)), UpdateResult::kRejected);
  EXPECT_EQ(f.state().q.coeffs(), before.q.coeffs());
  EXPECT_EQ(f.state().gravity.p, before.gravity.p);
  EXPECT_EQ(f.state().magnetic.x, before.magnetic.x);
  EXPECT_EQ(f.update(static_sample(q, 10 * kMs + 5'000 * kMs)), UpdateResult::kInitialised);
  EXPECT_TRUE(f.flags().reinitialised);
  ImuSample wild = static_sample(q, 10 * kMs + 5'900 * kMs);
  wild.gyr = Vec3(1e6, -1e6, 1e6);
  wild.acc = Vec3(1e9, 0, -1e9);
  wild.mag = Vec3(1e9, 1e9, 0);
  f.update(wild);
  EXPECT_TRUE(f.orientation().coeffs().allFinite());
  EXPECT_TRUE(f.gravity_covariance().allFinite());
  EXPECT_TRUE(f.magnetic_covariance().allFinite());
}

TEST(Dlkf, FactoryMakesItAndChecksParameters) {
  auto f = make_filter({"dlkf", {{"sigma_ext_acc", 2.0}}});
  EXPECT_EQ(f->name(), "dlkf");
  EXPECT_EQ(dynamic_cast<DlkfFilter&>(*f).params().sigma_ext_acc, 2.0);
  EXPECT_THROW(make_filter({"dlkf", {{"tau_ext_acc_s", 0}}}), std::invalid_argument);
  EXPECT_THROW(make_filter({"dlkf", {{"gyro_bias_lowpass", 2}}}), std::invalid_argument);
  EXPECT_THROW(make_filter({"dlkf", {{"no_such", 1}}}), std::invalid_argument);
}

}  // namespace
}  // namespace bsn::fusion
