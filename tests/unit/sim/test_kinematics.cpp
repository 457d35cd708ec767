// The noise-free kinematics are exact: orientation, body rate and specific force agree with each other
// and with numerical differentiation of the analytic trajectories.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "bsn/sim/body.hpp"

namespace bsn::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

Gait walking() { return Gait{110.0, 1.3, 30.0 * kDeg, std::nullopt, {}, {}}; }

// q' = 1/2 q (0, w_sensor): the derivative of a sensor-to-earth quaternion from the body rate.
Eigen::Vector4d quat_rate(const Eigen::Vector4d& q, const Vec3& w) {
  const Quat d = Quat(q[0], q[1], q[2], q[3]) * Quat(0.0, w.x(), w.y(), w.z());
  return 0.5 * Eigen::Vector4d(d.w(), d.x(), d.y(), d.z());
}

TEST(SimKinematics, GyroIntegratesToTheTruthOrientationOverSixtySecondsOfGait) {
  // Classical RK4 at 400 Hz: its global error is O(dt^4) (~1e-9 rad here), so any inconsistency between the
  // analytic body rate and the orientation shows far above the 1e-6 rad tolerance. Each step reuses the
  // previous step's end state, so a step costs two evaluations of the body.
  const Body body = lower_body(walking());
  std::vector<SegmentState> start, mid, end;
  body.evaluate(0.0, start);
  std::vector<Eigen::Vector4d> q(body.size());
  for (std::size_t i = 0; i < body.size(); ++i) {
    q[i] = Eigen::Vector4d(start[i].q_sensor.w(), start[i].q_sensor.x(), start[i].q_sensor.y(), start[i].q_sensor.z());
  }
  const double dt = 2.5e-3;
  const int steps = 24000;  // 60 s
  for (int k = 0; k < steps; ++k) {
    const double t = k * dt;
    body.evaluate(t + 0.5 * dt, mid);
    body.evaluate(t + dt, end);
    for (std::size_t i = 0; i < body.size(); ++i) {
      const Eigen::Vector4d k1 = quat_rate(q[i], start[i].gyr_sensor);
      const Eigen::Vector4d k2 = quat_rate(q[i] + 0.5 * dt * k1, mid[i].gyr_sensor);
      const Eigen::Vector4d k3 = quat_rate(q[i] + 0.5 * dt * k2, mid[i].gyr_sensor);
      const Eigen::Vector4d k4 = quat_rate(q[i] + dt * k3, end[i].gyr_sensor);
      q[i] = (q[i] + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)).normalized();
    }
    std::swap(start, end);
  }
  for (std::size_t i = 0; i < body.size(); ++i) {
    const Quat integrated(q[i][0], q[i][1], q[i][2], q[i][3]);
    EXPECT_LT(fusion::angle_between(integrated, start[i].q_sensor), 1e-6) << body.segment(i).name;
  }
}

TEST(SimKinematics, GaitMovesEveryJointAndWalksAtTheConfiguredSpeed) {
  const Body body = lower_body(walking());
  std::vector<SegmentState> a, b;
  body.evaluate(0.0, a);
  body.evaluate(10.0, b);
  const Vec3 travelled = b[0].origin - a[0].origin;
  EXPECT_NEAR(travelled.head<2>().norm(), 13.0, 0.05);  // 1.3 m/s for 10 s, plus a 2 cm sway
  EXPECT_NEAR(std::atan2(travelled.y(), travelled.x()), 30.0 * kDeg, 0.01);
  double peak_rate[7] = {};
  for (double t = 0.0; t < 2.0; t += 0.01) {
    body.evaluate(t, a);
    for (std::size_t i = 0; i < 7; ++i) peak_rate[i] = std::max(peak_rate[i], a[i].gyr_sensor.norm());
  }
  // Distal segments turn faster than proximal ones; the foot exceeds 100 deg/s in swing.
  EXPECT_GT(peak_rate[3], 100.0 * kDeg);
  EXPECT_GT(peak_rate[3], peak_rate[1]);
  EXPECT_GT(peak_rate[0], 1.0 * kDeg);
}

TEST(SimKinematics, GaitInWindowsStandsUprightBetweenAndMovesWhereScripted) {
  // Walking on the spot from 10 to 20 s (ramps of 0.5 s), carried 3 m east from 11 to 13 s.
  Gait gait = walking();
  gait.speed_m_s = 0.0;
  gait.active = {Window{10.0, 20.0, 0.5}};
  gait.moves = {ScriptedMove{Vec3(3.0, 0.0, 0.0), 11.0, 2.0}};
  const Body body = lower_body(gait);
  const std::size_t pelvis = *body.find("pelvis"), thigh = *body.find("thigh_l"), shank = *body.find("shank_l");
  std::vector<SegmentState> s;
  for (double t : {5.0, 9.9, 20.6, 30.0}) {
    SCOPED_TRACE(t);
    body.evaluate(t, s);
    // Standing upright: no motion at all, and every segment parallel to the pelvis (the gait's mean angles out).
    for (const SegmentState& seg : s) {
      EXPECT_LT(seg.omega_earth.norm(), 1e-12);
      EXPECT_LT(seg.velocity.norm(), 1e-12);
      EXPECT_LT(fusion::angle_between(seg.q_segment, s[pelvis].q_segment), 1e-12);
    }
    EXPECT_NEAR(s[pelvis].origin.x(), t < 11.0 ? 0.0 : 3.0, 1e-12);
  }
  // Walking: the knee flexes (gait's mean 28 deg plus its harmonics) and the thigh swings.
  double knee_min = 1e9, knee_max = -1e9;
  for (double t = 14.0; t < 19.0; t += 0.01) {
    body.evaluate(t, s);
    const double knee = fusion::angle_between(s[thigh].q_segment, s[shank].q_segment);
    knee_min = std::min(knee_min, knee);
    knee_max = std::max(knee_max, knee);
  }
  EXPECT_GT(knee_max - knee_min, 30.0 * kDeg);
  EXPECT_GT(knee_max, 40.0 * kDeg);
}

TEST(SimKinematics, AccelerometerAtRestEqualsRotatedGravity) {
  FreeMotion still;
  still.pose.orientation = {40.0 * kDeg, -25.0 * kDeg, 70.0 * kDeg};
  std::vector<SegmentState> s;
  for (const Body& body : {free_body(still), lower_body(std::nullopt), upper_body(std::nullopt)}) {
    for (double t : {0.0, 3.3, 100.0}) {
      body.evaluate(t, s);
      for (const SegmentState& x : s) {
        const Vec3 expected = x.q_sensor.conjugate() * Vec3(0.0, 0.0, fusion::kGravity);
        EXPECT_LT((x.specific_force_sensor() - expected).norm(), 1e-12);
        EXPECT_LT(x.gyr_sensor.norm(), 1e-15);
      }
    }
  }
}

// Central second difference of the sensor position: truncation error h^2/12 |p''''|, rounding 4 eps |p| / h^2.
void expect_acceleration_matches_position(const Body& body, double t_end, double tolerance) {
  const double h = 1e-4;
  std::vector<SegmentState> m, c, p;
  for (double t = 0.1; t < t_end; t += 0.37) {
    body.evaluate(t - h, m);
    body.evaluate(t, c);
    body.evaluate(t + h, p);
    for (std::size_t i = 0; i < body.size(); ++i) {
      const Vec3 fd_acc = (p[i].position - 2.0 * c[i].position + m[i].position) / (h * h);
      const Vec3 fd_vel = (p[i].position - m[i].position) / (2.0 * h);
      EXPECT_LT((fd_acc - c[i].acceleration).norm(), tolerance) << body.segment(i).name << " t=" << t;
      EXPECT_LT((fd_vel - c[i].velocity).norm(), 1e-5) << body.segment(i).name << " t=" << t;
      const Vec3 expected = c[i].q_sensor.conjugate() * (fd_acc + Vec3(0.0, 0.0, fusion::kGravity));
      EXPECT_LT((c[i].specific_force_sensor() - expected).norm(), tolerance) << body.segment(i).name;
    }
  }
}

TEST(SimKinematics, SpecificForceAgreesWithTheSecondDerivativeOfThePosition) {
  // h = 1e-4 s. Gait: |p''''| of the foot ~1e4 m/s^4 -> truncation ~1e-5 m/s^2; rounding ~1e-6 m/s^2 at 10 m
  // from the origin. Fast random motion: |p''''| < 4 harmonics * 18 m/s^2 * (2 pi 3 Hz)^2 ~ 2.6e4 m/s^4.
  expect_acceleration_matches_position(lower_body(walking()), 6.0, 1e-4);
  expect_acceleration_matches_position(upper_body(Reaching{}), 6.0, 1e-4);
  FreeMotion fast;
  fast.random = random_motion_for(Intensity::kFast, 3);
  fast.rotations = {{Vec3(1, 2, 3).normalized(), 2.0, 1.0, 1.5}};
  fast.moves = {{Vec3(0.5, -0.2, 0.1), 2.0, 1.0}};
  expect_acceleration_matches_position(free_body(fast), 6.0, 1e-4);
}

TEST(SimKinematics, ScriptedRotationsAndMovesEndWhereScripted) {
  FreeMotion m;
  m.rotations = {{Vec3::UnitZ(), 90.0 * kDeg, 1.0, 2.0}, {Vec3::UnitX(), -45.0 * kDeg, 4.0, 1.0}};
  m.moves = {{Vec3(1.0, 0.0, 0.5), 0.5, 2.0}};
  const Body body = free_body(m);
  std::vector<SegmentState> s;
  body.evaluate(10.0, s);
  const Quat expected =
      Quat(Eigen::AngleAxisd(90.0 * kDeg, Vec3::UnitZ())) * Quat(Eigen::AngleAxisd(-45.0 * kDeg, Vec3::UnitX()));
  EXPECT_LT(fusion::angle_between(s[0].q_sensor, expected), 1e-12);
  EXPECT_LT((s[0].position - Vec3(1.0, 0.0, 1.5)).norm(), 1e-12);
  EXPECT_LT(s[0].gyr_sensor.norm(), 1e-12);
  body.evaluate(2.0, s);  // mid-rotation about z: rate 90 deg * 1.875 / 2 s (minimum-jerk peak)
  EXPECT_NEAR(s[0].gyr_sensor.z(), 90.0 * kDeg * 1.875 / 2.0, 1e-12);
}

TEST(SimKinematics, RandomMotionHasTheIntensityStatisticsOfNezTable1) {
  for (Intensity level : {Intensity::kSlow, Intensity::kIntermediate, Intensity::kFast}) {
    FreeMotion m;
    m.random = random_motion_for(level, 11);
    const Body body = free_body(m);
    std::vector<SegmentState> s;
    double sum_w2 = 0.0, sum_a2 = 0.0;
    const int n = 12000;  // 600 s (the duration of Nez et al.'s recordings) at 20 Hz
    for (int k = 0; k < n; ++k) {
      body.evaluate(k * 0.05, s);
      sum_w2 += s[0].gyr_sensor.squaredNorm();
      sum_a2 += s[0].acceleration.squaredNorm();
    }
    const IntensityStats st = nez_table1(level);
    // RMS of the magnitude = sqrt(mean^2 + SD^2). Twelve random frequencies per quantity: the realised RMS
    // is within a few percent of the target (beats between close harmonics, the rotation chain's coupling).
    EXPECT_NEAR(std::sqrt(sum_w2 / n) / kDeg, std::hypot(st.rate_mean_deg_s, st.rate_sd_deg_s),
                0.15 * std::hypot(st.rate_mean_deg_s, st.rate_sd_deg_s));
    EXPECT_NEAR(std::sqrt(sum_a2 / n) / fusion::kGravity, std::hypot(st.acc_mean_g, st.acc_sd_g),
                0.15 * std::hypot(st.acc_mean_g, st.acc_sd_g));
  }
}

TEST(SimKinematics, ChainEvaluationEqualsWholeBodyEvaluation) {
  // Sensors with their own (jittered) instants evaluate only their chain: it must give the same numbers.
  const Body body = upper_body(Reaching{});
  std::vector<SegmentState> all, chain;
  for (double t : {0.3, 2.9}) {
    body.evaluate(t, all);
    for (std::size_t i = 0; i < body.size(); ++i) {
      body.evaluate_chain(t, i, chain);
      EXPECT_EQ(chain[i].q_sensor.coeffs(), all[i].q_sensor.coeffs());
      EXPECT_EQ(chain[i].gyr_sensor, all[i].gyr_sensor);
      EXPECT_EQ(chain[i].acceleration, all[i].acceleration);
    }
  }
}

TEST(SimKinematics, RejectsBadBodies) {
  SegmentDef a, b;
  a.name = "a";
  b.name = "a";
  b.parent = 0;
  EXPECT_THROW(Body({a, b}), std::invalid_argument);
  b.name = "b";
  b.parent = 1;
  EXPECT_THROW(Body({a, b}), std::invalid_argument);
  b.parent = 0;
  b.rotation = {{Vec3(1.0, 1.0, 0.0), Signal{}}};
  EXPECT_THROW(Body({a, b}), std::invalid_argument);
}

}  // namespace
}  // namespace bsn::sim
