// The project's conventions: ENU, Hamilton sensor-to-earth quaternions, intrinsic z-y'-x'' Euler angles.
#include <gtest/gtest.h>

#include <numbers>
#include <random>

#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

void expect_vec_near(const Vec3& a, const Vec3& b, double tol) {
  EXPECT_NEAR((a - b).norm(), 0.0, tol) << "got " << a.transpose() << " expected " << b.transpose();
}

Quat random_quat(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
}

TEST(Conventions, QuaternionProductIsHamilton) {
  // i * j = k in Hamilton's convention (JPL would give -k).
  const Quat i(0, 1, 0, 0), j(0, 0, 1, 0);
  const Quat k = i * j;
  EXPECT_DOUBLE_EQ(k.w(), 0.0);
  EXPECT_DOUBLE_EQ(k.z(), 1.0);
}

TEST(Conventions, QuaternionMapsSensorToEarth) {
  // A sensor turned +90 deg about up (yaw): its x axis points north (earth y) in ENU.
  const Quat q = from_yaw_pitch_roll({90 * kDeg, 0, 0});
  expect_vec_near(q * Vec3::UnitX(), Vec3::UnitY(), 1e-12);
  // Written out as v_E = q * v_S * conj(q).
  const Quat v(0, 1, 0, 0);
  const Quat ve = q * v * q.conjugate();
  expect_vec_near(ve.vec(), Vec3::UnitY(), 1e-12);
}

TEST(Conventions, PositivePitchPutsTheNoseDown) {
  // Intrinsic y' rotation by +30 deg turns x towards -z (right-hand rule about y).
  const Quat q = from_yaw_pitch_roll({0, 30 * kDeg, 0});
  expect_vec_near(q * Vec3::UnitX(), Vec3(std::cos(30 * kDeg), 0, -std::sin(30 * kDeg)), 1e-12);
}

TEST(Conventions, PositiveRollLiftsYUp) {
  const Quat q = from_yaw_pitch_roll({0, 0, 20 * kDeg});
  expect_vec_near(q * Vec3::UnitY(), Vec3(0, std::cos(20 * kDeg), std::sin(20 * kDeg)), 1e-12);
}

TEST(Conventions, EulerOrderIsYawThenPitchThenRoll) {
  const YawPitchRoll ypr{40 * kDeg, -25 * kDeg, 70 * kDeg};
  const Quat expected = Quat(Eigen::AngleAxisd(ypr.yaw, Vec3::UnitZ())) *
                        Quat(Eigen::AngleAxisd(ypr.pitch, Vec3::UnitY())) *
                        Quat(Eigen::AngleAxisd(ypr.roll, Vec3::UnitX()));
  EXPECT_LT(angle_between(from_yaw_pitch_roll(ypr), expected), 1e-12);
}

TEST(Conventions, YawPitchRollRoundTrip) {
  std::mt19937_64 rng(1);
  for (int i = 0; i < 1000; ++i) {
    const Quat q = random_quat(rng);
    const YawPitchRoll ypr = to_yaw_pitch_roll(q);
    EXPECT_LE(std::abs(ypr.pitch), std::numbers::pi / 2 + 1e-12);
    EXPECT_LT(angle_between(from_yaw_pitch_roll(ypr), q), 1e-9);
  }
}

TEST(Conventions, KnownAnglesAreRecovered) {
  const YawPitchRoll in{-120 * kDeg, 35 * kDeg, 150 * kDeg};
  const YawPitchRoll out = to_yaw_pitch_roll(from_yaw_pitch_roll(in));
  EXPECT_NEAR(out.yaw, in.yaw, 1e-12);
  EXPECT_NEAR(out.pitch, in.pitch, 1e-12);
  EXPECT_NEAR(out.roll, in.roll, 1e-12);
}

TEST(Conventions, GimbalLockKeepsTheRotation) {
  for (double pitch : {90 * kDeg, -90 * kDeg}) {
    const Quat q = from_yaw_pitch_roll({30 * kDeg, pitch, 50 * kDeg});
    const YawPitchRoll ypr = to_yaw_pitch_roll(q);
    EXPECT_DOUBLE_EQ(ypr.roll, 0.0);
    EXPECT_LT(angle_between(from_yaw_pitch_roll(ypr), q), 1e-6);
  }
}

TEST(AxisSequences, ParseAcceptsOnlyThreeDistinctAxes) {
  for (const char* ok : {"xyz", "xzy", "yxz", "yzx", "zxy", "zyx"}) {
    ASSERT_TRUE(parse_axis_sequence(ok).has_value()) << ok;
    EXPECT_EQ(parse_axis_sequence(ok)->name(), ok);
  }
  for (const char* bad : {"", "zy", "zyxz", "zzx", "xyx", "abc", "ZYX"}) EXPECT_FALSE(parse_axis_sequence(bad)) << bad;
}

TEST(AxisSequences, DecomposeComposeRoundTripForEverySequence) {
  std::mt19937_64 rng(2);
  for (const char* name : {"xyz", "xzy", "yxz", "yzx", "zxy", "zyx"}) {
    const AxisSequence seq = *parse_axis_sequence(name);
    for (int i = 0; i < 300; ++i) {
      const Quat q = random_quat(rng);
      const Vec3 a = decompose(q, seq);
      EXPECT_LE(std::abs(a[1]), std::numbers::pi / 2 + 1e-12);
      EXPECT_LT(angle_between(compose(a, seq), q), 1e-9) << name;
    }
  }
}

TEST(AxisSequences, DecomposeRecoversKnownAnglesForEverySequence) {
  const Vec3 angles(25 * kDeg, -40 * kDeg, 65 * kDeg);
  for (const char* name : {"xyz", "xzy", "yxz", "yzx", "zxy", "zyx"}) {
    const AxisSequence seq = *parse_axis_sequence(name);
    expect_vec_near(decompose(compose(angles, seq), seq), angles, 1e-12);
  }
}

TEST(AxisSequences, GimbalLockForEverySequence) {
  for (const char* name : {"xyz", "xzy", "yxz", "yzx", "zxy", "zyx"}) {
    const AxisSequence seq = *parse_axis_sequence(name);
    const Quat q = compose(Vec3(20 * kDeg, 90 * kDeg, 35 * kDeg), seq);
    EXPECT_LT(angle_between(compose(decompose(q, seq), seq), q), 1e-6) << name;
  }
}

TEST(Relative, ChildInParentFrame) {
  std::mt19937_64 rng(3);
  const Quat parent = random_quat(rng), child = random_quat(rng);
  const Quat rel = relative_orientation(parent, child);
  EXPECT_LT(angle_between(parent * rel, child), 1e-12);
  // A knee flexed 60 deg about the thigh's y axis shows as 60 deg about y.
  const Quat thigh = from_yaw_pitch_roll({10 * kDeg, 5 * kDeg, -3 * kDeg});
  const Quat shank = thigh * Quat(Eigen::AngleAxisd(60 * kDeg, Vec3::UnitY()));
  expect_vec_near(decompose(relative_orientation(thigh, shank), *parse_axis_sequence("zyx")), Vec3(0, 60 * kDeg, 0),
                  1e-12);
}

TEST(Relative, AngleBetweenIsTheRotationAngle) {
  const Quat a = from_yaw_pitch_roll({0.3, 0.2, -0.1});
  const Quat b = a * Quat(Eigen::AngleAxisd(7 * kDeg, Vec3(1, 2, 3).normalized()));
  EXPECT_NEAR(angle_between(a, b), 7 * kDeg, 1e-12);
  EXPECT_NEAR(angle_between(a, Quat(-a.coeffs())), 0.0, 1e-7);  // q and -q are the same rotation
}

TEST(Initialisation, FromAccAndMagForAnyHeading) {
  std::mt19937_64 rng(4);
  const Vec3 field(0, 49 * std::cos(64 * kDeg), -49 * std::sin(64 * kDeg));  // ENU, dip 64 deg
  for (int i = 0; i < 500; ++i) {
    const Quat q = random_quat(rng);
    const Vec3 acc = q.conjugate() * Vec3(0, 0, kGravity);
    const Vec3 mag = q.conjugate() * field;
    EXPECT_LT(angle_between(orientation_from_acc_mag(acc, mag), q), 1e-9);
  }
}

TEST(Initialisation, FromAccAloneHasZeroYawAndTheRightTilt) {
  const Quat q = from_yaw_pitch_roll({77 * kDeg, 20 * kDeg, -35 * kDeg});
  const Quat est = orientation_from_acc(q.conjugate() * Vec3(0, 0, kGravity));
  const YawPitchRoll ypr = to_yaw_pitch_roll(est);
  EXPECT_NEAR(ypr.yaw, 0.0, 1e-12);
  EXPECT_NEAR(ypr.pitch, 20 * kDeg, 1e-12);
  EXPECT_NEAR(ypr.roll, -35 * kDeg, 1e-12);
}

TEST(ExpMap, SmallAndLargeAngles) {
  const Vec3 v = Vec3(0.3, -0.2, 0.5);
  EXPECT_LT(angle_between(exp_rotation_vector(v), Quat(Eigen::AngleAxisd(v.norm(), v.normalized()))), 1e-12);
  const Quat tiny = exp_rotation_vector(Vec3(1e-14, 0, 0));
  EXPECT_NEAR(tiny.norm(), 1.0, 1e-15);
  EXPECT_NEAR(2 * tiny.x(), 1e-14, 1e-26);
}

}  // namespace
}  // namespace bsn::fusion
