// DlkfFilter (Fan et al. 2018 §2.4.1, Fig. 4) against its own defining properties: TRIAD (eqs. 1-4) is exact for
// any heading, each of the two linear filters is consistent with the noise it assumes (NEES), the sequential scalar
// correction equals the batch update, and a start without magnetometer takes the heading from the first one. What it
// shares with the EKF and MEKF (initialisation and static accuracy at any heading with the low-pass gyro bias,
// covariances, bad input, factory, and Fan test B: roll and pitch never depend on the magnetometer) is in
// test_kalman_common.cpp.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>

#include "bsn/fusion/dlkf_filter.hpp"
#include "kalman_test_util.hpp"

namespace bsn::fusion {
namespace {

using namespace bsn::fusion::filter_test;

TEST(Dlkf, TriadMatchesTheTrueOrientationForAnyHeadingAndEulerEq4) {
  for (double yaw : {-179.0, -100.0, -10.0, 0.0, 45.0, 135.0, 180.0}) {
    const Quat q = from_yaw_pitch_roll({yaw * kDeg, 30 * kDeg, -50 * kDeg});
    const ImuSample s = static_sample(q, at_ns(0));
    EXPECT_LT(angle_between(DlkfFilter::triad(s.acc, s.mag), q), 1e-12) << yaw;
    // Roll and pitch depend on the first vector only: any field gives the same inclination.
    const Quat other = DlkfFilter::triad(s.acc, s.mag + Vec3(20, -5, 30));
    const YawPitchRoll a = to_yaw_pitch_roll(other);
    EXPECT_NEAR(a.pitch, 30 * kDeg, 1e-12);
    EXPECT_NEAR(a.roll, -50 * kDeg, 1e-12);
  }
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
    em << sensor.q().conjugate() * kField - f.state().magnetic.vector(), dist - f.state().magnetic.disturbance();
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

TEST(Dlkf, StartsWithoutMagnetometerAndTakesTheHeadingFromTheFirstOne) {
  DlkfFilter f;
  const Quat q = from_yaw_pitch_roll({-2.0, 0.2, 0.1});
  ImuSample s = static_sample(q, at_ns(0));
  s.has_mag = false;
  ASSERT_EQ(f.update(s), UpdateResult::kInitialised);
  EXPECT_NEAR(to_yaw_pitch_roll(f.orientation()).yaw, 0.0, 1e-9);
  f.update(static_sample(q, at_ns(10 * kMs)));
  EXPECT_LT(angle_between(f.orientation(), q), 1e-6);
}

}  // namespace
}  // namespace bsn::fusion
