// Madgwick's gradient descent (GDA): the paper's objective and gradient (and the factor-two reference error of
// the copied C code), convergence and step size at rest, and the weaknesses the seeds document: a magnetic
// heading change or a magnet tilts the GDA (Seel & Ruppin Fig. 6, Fan test B).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "bsn/fusion/madgwick_filter.hpp"
#include "filter_test_util.hpp"

namespace bsn::fusion {
namespace {

using filter_test::at_s;
using filter_test::kDeg;
using filter_test::kField;
using filter_test::static_sample;
using filter_test::wrap;

Quat random_orientation(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
}

// At the true orientation with consistent gravity and field, the paper's objective f and its gradient J^T f
// vanish: the reference b has the norm and vertical component of the measured field. The copied C code's
// reference has half that norm; its magnetic objective then stays at |f_b| = 1/2 (shown for contrast).
TEST(Madgwick, ObjectiveAndGradientVanishAtTheTrueOrientation) {
  std::mt19937 rng(21);
  for (int trial = 0; trial < 50; ++trial) {
    const Quat q = random_orientation(rng);
    const double dip = (-80 + 160.0 * trial / 49) * kDeg;
    const Vec3 field(0, std::cos(dip), -std::sin(dip));
    const Vec3 a = q.conjugate() * Vec3::UnitZ();
    const Vec3 m = q.conjugate() * field;
    const Vec3 b = MadgwickFilter::magnetic_reference(q, m);
    EXPECT_LT((b - field).norm(), 1e-12) << trial;
    EXPECT_LT(MadgwickFilter::objective(q, Vec3::UnitZ(), a).norm(), 1e-12);
    EXPECT_LT(MadgwickFilter::objective(q, b, m).norm(), 1e-12);
    EXPECT_LT(MadgwickFilter::gradient(q, a, m, true).norm(), 1e-12);
    EXPECT_NEAR(MadgwickFilter::objective(q, 0.5 * b, m).norm(), 0.5, 1e-12);  // the C code's reference
  }
}

TEST(Madgwick, JacobianIsTheDerivativeOfTheObjective) {
  std::mt19937 rng(4);
  for (int trial = 0; trial < 20; ++trial) {
    const Quat q = random_orientation(rng);
    const Vec3 d = Vec3(0.3, 0.5, -0.8);
    const Vec3 s(0.1, 0.2, 0.3);
    const MadgwickFilter::Jacobian j = MadgwickFilter::jacobian(q, d);
    for (int c = 0; c < 4; ++c) {
      Eigen::Vector4d wxyz(q.w(), q.x(), q.y(), q.z()), delta = Eigen::Vector4d::Zero();
      delta[c] = 1e-6;
      const Eigen::Vector4d p = wxyz + delta, m = wxyz - delta;
      const Vec3 numeric = (MadgwickFilter::objective(Quat(p[0], p[1], p[2], p[3]), d, s) -
                            MadgwickFilter::objective(Quat(m[0], m[1], m[2], m[3]), d, s)) /
                           2e-6;
      EXPECT_LT((numeric - j.col(c)).norm(), 1e-8) << trial << " " << c;
    }
  }
}

// Started 40 deg off in every axis, the 9D filter at rest converges to the true orientation (not a biased one),
// within the limit cycle of a normalised step (2 beta dt per sample).
TEST(Madgwick, ConvergesToTheTrueOrientationAtRest) {
  for (bool nine_d : {true, false}) {
    MadgwickFilter::Params p;
    p.beta = 0.1;  // Fan's setting; the default 0.02 needs 20 s for the 40 deg
    MadgwickFilter f(p, nine_d);
    const Quat q_true = from_yaw_pitch_roll({70 * kDeg, -20 * kDeg, 15 * kDeg});
    const Quat q_start = from_yaw_pitch_roll({30 * kDeg, 20 * kDeg, -25 * kDeg});
    f.update(static_sample(q_start, at_s(0)));
    for (int i = 1; i <= 3000; ++i) f.update(static_sample(q_true, at_s(i * 0.01)));
    const YawPitchRoll est = to_yaw_pitch_roll(f.orientation());
    if (nine_d) {
      EXPECT_LT(angle_between(f.orientation(), q_true), 0.05 * kDeg);
    } else {
      EXPECT_NEAR(est.pitch, -20 * kDeg, 0.05 * kDeg);
      EXPECT_NEAR(est.roll, 15 * kDeg, 0.05 * kDeg);
    }
  }
}

// The normalised gradient step has length beta * dt in quaternion space, so the orientation turns at no more than
// 2 beta rad/s; while the error is large nearly all of the step is rotation (the paper's Jacobian of the
// 1 - 2(..) form adds a small radial part that normalisation removes): a 30 deg roll error shrinks by 85-100 %
// of 2 beta * 1 s in the first second.
TEST(Madgwick, CorrectionRateIsTwoBeta) {
  for (double beta : {0.05, 0.1}) {
    MadgwickFilter::Params p;
    p.beta = beta;
    MadgwickFilter f(p, false);
    f.update(static_sample(from_yaw_pitch_roll({0, 0, 30 * kDeg}), at_s(0)));
    for (int i = 1; i <= 100; ++i) f.update(static_sample(Quat::Identity(), at_s(i * 0.01)));
    const double turned = 30 * kDeg - to_yaw_pitch_roll(f.orientation()).roll;
    EXPECT_LE(turned, 2 * beta * 1.0 + 1e-9) << beta;
    EXPECT_GE(turned, 0.85 * 2 * beta * 1.0) << beta;
  }
}

// Seel & Ruppin section 3.1 / Fig. 6: the field's heading jumps at constant magnitude and vertical component.
// The GDA corrects along the geodesic between reference and measurement, which tilts it: roll or pitch moves by
// more than 1 deg (for both the 50 deg and the ~180 deg jump), before the yaw finally follows the field.
TEST(Madgwick, HeadingJumpTiltsTheGradientDescent) {
  for (double jump_deg : {50.0, 178.0}) {
    MadgwickFilter::Params p;
    p.beta = 0.1;  // "reasonably fast convergence" (the paper) and Fan's setting
    MadgwickFilter f(p, true);
    const Quat q_true = Quat::Identity();
    f.update(static_sample(q_true, at_s(0)));
    const Vec3 turned = Eigen::AngleAxisd(jump_deg * kDeg, Vec3::UnitZ()) * kField;
    double max_tilt = 0.0;
    for (int i = 1; i <= 6000; ++i) {
      f.update(static_sample(q_true, at_s(i * 0.01), turned));
      const YawPitchRoll est = to_yaw_pitch_roll(f.orientation());
      max_tilt = std::max({max_tilt, std::abs(est.pitch), std::abs(est.roll)});
    }
    EXPECT_GT(max_tilt, 1 * kDeg) << jump_deg;
    EXPECT_NEAR(wrap(to_yaw_pitch_roll(f.orientation()).yaw + jump_deg * kDeg), 0.0, 0.5 * kDeg) << jump_deg;
  }
}

// Fan test B: a magnet brought near a static sensor five times moves the GDA's roll and pitch.
TEST(Madgwick, MagnetNearStaticSensorMovesRollOrPitch) {
  MadgwickFilter::Params p;
  p.beta = 0.1;  // Fan's Table 1
  MadgwickFilter f(p, true);
  const Quat q_true = from_yaw_pitch_roll({-70 * kDeg, 5 * kDeg, 10 * kDeg});
  const YawPitchRoll truth = to_yaw_pitch_roll(q_true);
  const Vec3 magnet_sensor(60, -35, 80);
  double max_tilt = 0.0;
  for (int i = 0; i <= 2500; ++i) {
    const double t = i * 0.01;
    ImuSample s = static_sample(q_true, at_s(t));
    const double phase = std::fmod(t, 5.0);
    s.mag += (phase < 2.0 ? std::pow(std::sin(std::numbers::pi * phase / 2.0), 2) : 0.0) * magnet_sensor;
    f.update(s);
    const YawPitchRoll est = to_yaw_pitch_roll(f.orientation());
    max_tilt = std::max({max_tilt, std::abs(est.pitch - truth.pitch), std::abs(wrap(est.roll - truth.roll))});
  }
  EXPECT_GT(max_tilt, 1 * kDeg);
}

TEST(Madgwick, SixAxisVariantIgnoresTheMagnetometer) {
  auto f = make_filter({"madgwick6", {}});
  f->update(static_sample(Quat::Identity(), at_s(0)));
  const Vec3 turned = Eigen::AngleAxisd(90 * kDeg, Vec3::UnitZ()) * kField;
  for (int i = 1; i <= 500; ++i) f->update(static_sample(Quat::Identity(), at_s(i * 0.01), turned));
  EXPECT_LT(angle_between(f->orientation(), Quat::Identity()), 1e-9);
  EXPECT_FALSE(f->flags().mag_rejected);
}

// The norm after a gradient step is computed from a formula near 1; a step of beta dt ~ 1 (beta = 100 rad/s at
// 100 Hz) must still leave a unit quaternion.
TEST(Madgwick, HugeStepsStayUnit) {
  for (double beta : {50.0, 100.0, 200.0, 1e4}) {
    MadgwickFilter::Params p;
    p.beta = beta;
    MadgwickFilter f(p, true);
    std::mt19937 rng(8);
    const Quat q_true = random_orientation(rng);
    f.update(static_sample(Quat::Identity(), at_s(0)));
    for (int i = 1; i <= 300; ++i) {
      ASSERT_EQ(f.update(static_sample(q_true, at_s(i * 0.01))), UpdateResult::kUpdated);
      ASSERT_NEAR(f.orientation().norm(), 1.0, 1e-12) << beta << " " << i;
    }
  }
}

TEST(Madgwick, FactoryChecksParameters) {
  EXPECT_EQ(make_filter({"madgwick", {{"beta", 0.2}}})->name(), "madgwick");
  EXPECT_THROW(make_filter({"madgwick", {{"beta", 0.0}}}), std::invalid_argument);
  EXPECT_THROW(make_filter({"madgwick6", {{"gyro_bias_lowpass", 2.0}}}), std::invalid_argument);
}

}  // namespace
}  // namespace bsn::fusion
