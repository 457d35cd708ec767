// BodyFusion without DDS: calibration before gate and filter, gate rejections by reason, joint angles as the
// relative orientation of two segments, unknown nodes, stale and fresh nodes, and a clock reset restarting a filter.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "bsn/fusion/body_fusion.hpp"

namespace bsn::fusion {
namespace {

constexpr std::uint64_t kStepNs = 10'000'000;  // 100 Hz
constexpr std::uint64_t kSecondNs = 1'000'000'000;
constexpr double kDegToRad = std::numbers::pi / 180.0;
// Exact samples: the only error is floating-point rounding over a few hundred updates, far below this.
constexpr double kExactRad = 1e-9;
const Vec3 kEarthField(0.0, 20.0, -44.0);  // uT, ENU: north and down (48 uT, dip 65.6 deg)

/// The exact reading, at sensor time t_ns, of a sensor with sensor-to-earth orientation q turning at gyr (rad/s,
/// sensor frame).
ImuSample exact_sample_at_ns(const Quat& q, std::uint64_t t_ns, const Vec3& gyr = Vec3::Zero()) {
  ImuSample s;
  s.timestamp_ns = t_ns;
  s.acc = q.conjugate() * Vec3(0.0, 0.0, kGravity);
  s.gyr = gyr;
  s.mag = q.conjugate() * kEarthField;
  return s;
}

SegmentSpec segment(const std::string& name, const std::string& node, const std::string& parent = "") {
  SegmentSpec s;
  s.name = name;
  s.node = node;
  s.parent = parent;
  return s;
}

/// upper (node "nu", root) <- lower (node "nl", joint "knee" in z-x'-y'').
BodyModel two_segment_body() {
  BodyModel body;
  body.segments = {segment("upper", "nu"), segment("lower", "nl", "upper")};
  body.segments[1].joint = "knee";
  body.segments[1].joint_axes = *parse_axis_sequence("zxy");
  return body;
}

BodyModel one_segment_body() {
  BodyModel body;
  body.segments = {segment("solo", "n")};
  return body;
}

std::uint64_t rejected(const BodyFusion& f, std::size_t segment, SampleVerdict reason) {
  return f.segment(segment).gate.counters().rejected[static_cast<std::size_t>(rejection_index(reason))];
}

TEST(BodyFusion, CalibrationIsAppliedBeforeTheFilter) {
  // A still sensor whose raw channels are u = H (raw - B) inverted: raw = H^-1 u + B.
  calib::SensorCalibration c;
  c.accelerometer = calib::ChannelCalibration{Vec3(0.8, -0.5, 0.3), Eigen::Matrix3d::Identity()};
  c.accelerometer->transform << 1.02, 0.01, 0.0, 0.0, 0.98, -0.02, 0.01, 0.0, 1.01;
  c.gyroscope = calib::ChannelCalibration{Vec3(0.02, -0.01, 0.03), Eigen::Matrix3d::Identity()};  // 1.7 deg/s
  c.magnetometer = calib::ChannelCalibration{Vec3(15.0, -8.0, 22.0), Eigen::Matrix3d::Identity()};
  c.magnetometer->transform << 1.1, 0.05, 0.0, 0.05, 0.9, 0.02, 0.0, 0.02, 1.05;
  auto raw_of = [](const calib::ChannelCalibration& ch, const Vec3& u) -> Vec3 {
    return ch.transform.inverse() * u + ch.bias;
  };
  const Quat q = from_yaw_pitch_roll({0.6, -0.2, 0.3});

  BodyFusion calibrated(one_segment_body(), {{"n", c}}, {}, 0);
  BodyFusion uncalibrated(one_segment_body(), {}, {}, 0);
  for (std::uint64_t k = 0; k < 200; ++k) {  // 2 s still
    ImuSample raw = exact_sample_at_ns(q, k * kStepNs);
    raw.acc = raw_of(*c.accelerometer, raw.acc);
    raw.gyr = raw_of(*c.gyroscope, raw.gyr);
    raw.mag = raw_of(*c.magnetometer, raw.mag);
    const SampleResult& r = calibrated.process({"n", k, raw}, k * kStepNs);
    ASSERT_EQ(r.outcome, SampleOutcome::kEstimated) << "sample " << k;
    EXPECT_LT(angle_between(r.orientation, q), kExactRad) << "sample " << k;
    if (k == 0) {
      // Without the calibration the start orientation is tilted at least by the angle between the raw and the
      // true specific force (both must map to up).
      const Vec3 true_acc = q.conjugate() * Vec3(0.0, 0.0, kGravity);
      const double tilt = std::acos(raw.acc.normalized().dot(true_acc.normalized()));
      ASSERT_GT(tilt, 3.0 * kDegToRad);
      EXPECT_GE(angle_between(uncalibrated.process({"n", k, raw}, 0).orientation, q), tilt - kExactRad);
    }
  }
}

TEST(BodyFusion, CalibratesEveryChannelOfAMovingSensor) {
  // The filter sees exactly u = H (raw - B): the same as an uncalibrated pipeline fed u, bit for bit.
  calib::SensorCalibration c;
  c.accelerometer = calib::ChannelCalibration{Vec3(0.3, 0.1, -0.2), Eigen::Matrix3d::Identity() * 1.01};
  c.gyroscope = calib::ChannelCalibration{Vec3(0.01, 0.02, -0.01), Eigen::Matrix3d::Identity() * 0.99};
  c.magnetometer = calib::ChannelCalibration{Vec3(5.0, -3.0, 7.0), Eigen::Matrix3d::Identity() * 1.05};
  BodyFusion calibrated(one_segment_body(), {{"n", c}}, {}, 0);
  BodyFusion fed_calibrated(one_segment_body(), {}, {}, 0);
  const Vec3 rate(0.4, -0.3, 0.8);  // rad/s, sensor frame
  const Quat q0 = from_yaw_pitch_roll({-1.0, 0.3, 0.5});
  for (std::uint64_t k = 0; k < 300; ++k) {
    const Quat q = q0 * exp_rotation_vector(rate * (static_cast<double>(k * kStepNs) * 1e-9));
    const ImuSample raw = exact_sample_at_ns(q, k * kStepNs, rate);
    ImuSample u = raw;
    u.acc = calib::apply(*c.accelerometer, raw.acc);
    u.gyr = calib::apply(*c.gyroscope, raw.gyr);
    u.mag = calib::apply(*c.magnetometer, raw.mag);
    const Quat a = calibrated.process({"n", k, raw}, 0).orientation;
    const Quat b = fed_calibrated.process({"n", k, u}, 0).orientation;
    ASSERT_EQ(a.coeffs(), b.coeffs()) << "sample " << k;
  }
}

TEST(BodyFusion, GateRejectionsAreCountedByReason) {
  BodyFusion f(one_segment_body(), {}, {}, 0);
  const Quat q = Quat::Identity();
  auto send = [&](std::uint64_t seq, const ImuSample& s) { return f.process({"n", seq, s}, 0); };
  auto at = [&](std::uint64_t t_ns) { return exact_sample_at_ns(q, t_ns); };

  // No accelerometer to start from: the gate passes it, the filter cannot use it.
  ImuSample no_acc = at(0);
  no_acc.has_acc = false;
  SampleResult r = send(0, no_acc);
  EXPECT_EQ(r.outcome, SampleOutcome::kFilterRejected);
  EXPECT_EQ(r.verdict, SampleVerdict::kAccepted);
  for (std::uint64_t k = 1; k <= 9; ++k) ASSERT_EQ(send(k, at(k * kStepNs)).outcome, SampleOutcome::kEstimated);

  ImuSample nan = at(10 * kStepNs);
  nan.acc.x() = std::numeric_limits<double>::quiet_NaN();
  ImuSample huge = at(11 * kStepNs);
  huge.gyr.z() = 1e4;  // rad/s
  const std::vector<std::pair<SampleResult, SampleVerdict>> bad{
      {send(10, nan), SampleVerdict::kNonFinite},
      {send(11, huge), SampleVerdict::kOutOfRange},
      {send(9, at(9 * kStepNs)), SampleVerdict::kDuplicate},                   // the last accepted, again
      {send(12, at(5 * kStepNs)), SampleVerdict::kTimeBackward},               // reordered
      {send(13, at(9 * kStepNs + 2 * kSecondNs)), SampleVerdict::kTimeJump}};  // beyond the 1 s default
  for (const auto& [result, reason] : bad) {
    EXPECT_EQ(result.outcome, SampleOutcome::kGateRejected);
    EXPECT_EQ(result.verdict, reason);
  }
  EXPECT_EQ(send(20, at(20 * kStepNs)).outcome, SampleOutcome::kEstimated);  // seq 14..19 lost

  const auto& c = f.segment(0).gate.counters();
  EXPECT_EQ(c.received, 16u);
  EXPECT_EQ(c.accepted, 11u);
  EXPECT_EQ(c.missing, 6u);
  EXPECT_EQ(c.clock_resets, 0u);
  for (const auto& [result, reason] : bad) EXPECT_EQ(rejected(f, 0, reason), 1u) << rejection_index(reason);
  EXPECT_EQ(f.segment(0).filter_rejected, 1u);
}

TEST(BodyFusion, JointAngleIsTheRelativeOrientation) {
  // Two still segments in known orientations: the joint is q_upper* (x) q_lower = compose(angles, zxy).
  const AxisSequence zxy = *parse_axis_sequence("zxy");
  const Vec3 angles(0.5, -0.2, 0.9);  // rad; middle angle within +-pi/2, so the decomposition is unique
  const Quat q_upper = from_yaw_pitch_roll({0.7, -0.3, 0.4});
  const Quat q_lower = q_upper * compose(angles, zxy);

  BodyFusion f(two_segment_body(), {}, {}, 0);
  // The child before its parent has an orientation: no joint yet. The root has none.
  EXPECT_FALSE(f.process({"nl", 0, exact_sample_at_ns(q_lower, 0)}, 0).joint);
  EXPECT_FALSE(f.process({"nu", 0, exact_sample_at_ns(q_upper, 0)}, 0).joint);
  int joints = 0;
  for (std::uint64_t k = 1; k < 100; ++k) {
    EXPECT_FALSE(f.process({"nu", k, exact_sample_at_ns(q_upper, k * kStepNs)}, 0).joint);
    const SampleResult& r = f.process({"nl", k, exact_sample_at_ns(q_lower, k * kStepNs)}, 0);
    ASSERT_TRUE(r.joint) << "sample " << k;
    ++joints;
    EXPECT_EQ(r.joint->parent, 0u);
    EXPECT_EQ(r.joint->child, 1u);
    EXPECT_GE(r.joint->relative.w(), 0.0);
    EXPECT_LT(angle_between(r.joint->relative, q_upper.conjugate() * q_lower), kExactRad) << "sample " << k;
    EXPECT_LT((r.joint->angles - angles).cwiseAbs().maxCoeff(), kExactRad) << "sample " << k;
    EXPECT_FALSE(r.joint->stale);
  }
  EXPECT_EQ(joints, 99);
}

// The parent's sample of an instant often arrives after the child's: the joint then pairs the child with the parent
// of a few samples before. Two segments turning rigidly together (a fixed joint) at 2 rad/s about the vertical, the
// parent's samples three behind the child's: paired as they are, the joint turns by 2 rad/s x 0.03 s = 3.4 deg;
// with the parent turned on by its rate to the child's time, the joint is the fixed one (exact data, constant rate:
// the extrapolation is exact up to rounding and the filters' own corrections, far below 0.1 deg).
TEST(BodyFusion, AParentThatLagsIsTurnedToTheChildsTime) {
  const Quat fixed = compose(Vec3(0.4, 0.1, -0.3), *parse_axis_sequence("zxy"));
  const Quat q0 = from_yaw_pitch_roll({0.3, -0.2, 0.1});
  constexpr double kRate = 2.0;  // rad/s about the earth's z
  auto upper_at = [&](std::uint64_t k) {
    return Quat(Eigen::AngleAxisd(kRate * 1e-9 * static_cast<double>(k * kStepNs), Vec3::UnitZ())) * q0;
  };
  auto sample = [&](const Quat& q, std::uint64_t k) {
    return exact_sample_at_ns(q, k * kStepNs, q.conjugate() * Vec3(0.0, 0.0, kRate));
  };
  auto worst_joint_error = [&](double max_extrapolation_s) {
    BodyFusion::Params params;
    params.max_joint_extrapolation_s = max_extrapolation_s;
    BodyFusion f(two_segment_body(), {}, params, 0);
    constexpr std::uint64_t kLag = 3;
    double worst = 0.0;
    for (std::uint64_t k = 0; k < 400; ++k) {
      if (k >= kLag) f.process({"nu", k - kLag, sample(upper_at(k - kLag), k - kLag)}, 0);
      const SampleResult& r = f.process({"nl", k, sample(upper_at(k) * fixed, k)}, 0);
      if (k >= 300) {
        EXPECT_TRUE(r.joint) << k;
        if (r.joint) worst = std::max(worst, angle_between(r.joint->relative, fixed));
      }
    }
    return worst;
  };
  EXPECT_LT(worst_joint_error(0.05), 0.1 * kDegToRad);
  EXPECT_GT(worst_joint_error(0.0), 3.0 * kDegToRad);  // the lag this removes
}

TEST(BodyFusion, UnknownNodesAreCountedAndListed) {
  BodyFusion f(two_segment_body(), {}, {}, 0);
  const ImuSample s = exact_sample_at_ns(Quat::Identity(), 0);
  std::vector<bool> first;
  for (const char* node : {"x1", "x1", "x2", "x1"}) {
    const SampleResult& r = f.process({node, 0, s}, 0);
    EXPECT_EQ(r.outcome, SampleOutcome::kUnknownNode);
    first.push_back(r.new_unknown_node);
  }
  EXPECT_EQ(first, (std::vector<bool>{true, false, true, false}));
  EXPECT_EQ(f.unknown_node_samples(), 4u);
  EXPECT_EQ(f.unknown_nodes(), (std::vector<std::string>{"x1", "x2"}));

  // The list is bounded; the count is not.
  for (int i = 0; i < 30; ++i) f.process({"y" + std::to_string(i), 0, s}, 0);
  EXPECT_EQ(f.unknown_node_samples(), 34u);
  ASSERT_EQ(f.unknown_nodes().size(), BodyFusion::kMaxUnknownNodesListed);
  EXPECT_EQ(f.unknown_nodes().back(), "y" + std::to_string(BodyFusion::kMaxUnknownNodesListed - 3));
  for (std::size_t i = 0; i < 2; ++i) EXPECT_EQ(f.segment(i).gate.counters().received, 0u);
}

TEST(BodyFusion, NodesTurnStaleAndFresh) {
  const std::uint64_t t0 = 1000 * kSecondNs;  // arrival clock at the start
  const std::uint64_t timeout = 300'000'000;  // the default 0.3 s
  BodyFusion f(two_segment_body(), {}, {}, t0);
  auto stale_now = [&](std::uint64_t now) {
    const auto s = f.check_stale(now);
    return std::vector<std::size_t>(s.begin(), s.end());
  };
  using Segments = std::vector<std::size_t>;

  const std::uint64_t upper_at = t0 + kSecondNs / 2;
  EXPECT_FALSE(f.process({"nu", 0, exact_sample_at_ns(Quat::Identity(), 0)}, upper_at).node_fresh);
  EXPECT_EQ(stale_now(upper_at + timeout), Segments{});
  EXPECT_EQ(stale_now(upper_at + timeout + 1), Segments{0});
  EXPECT_EQ(stale_now(upper_at + timeout + 2), Segments{}) << "only the change is reported";
  // The node that never sent gets the 2 s discovery grace.
  EXPECT_EQ(stale_now(t0 + 2 * kSecondNs), Segments{});
  EXPECT_EQ(stale_now(t0 + 2 * kSecondNs + 1), Segments{1});
  EXPECT_TRUE(f.segment(0).stale && f.segment(1).stale);

  // The child sends while its parent is stale: it is fresh again, and its joint is flagged stale.
  const SampleResult& lower = f.process({"nl", 0, exact_sample_at_ns(Quat::Identity(), 0)}, t0 + 3 * kSecondNs);
  EXPECT_TRUE(lower.node_fresh);
  ASSERT_TRUE(lower.joint);
  EXPECT_TRUE(lower.joint->stale);
  EXPECT_FALSE(f.segment(1).stale);
  EXPECT_TRUE(f.process({"nu", 1, exact_sample_at_ns(Quat::Identity(), kStepNs)}, t0 + 3 * kSecondNs).node_fresh);
  EXPECT_FALSE(f.process({"nu", 2, exact_sample_at_ns(Quat::Identity(), 2 * kStepNs)}, t0 + 3 * kSecondNs).node_fresh);
  EXPECT_FALSE(f.process({"nl", 1, exact_sample_at_ns(Quat::Identity(), kStepNs)}, t0 + 3 * kSecondNs).joint->stale);
  EXPECT_EQ(stale_now(t0 + 3 * kSecondNs + timeout), Segments{});
}

TEST(BodyFusion, ClockResetRestartsTheFilter) {
  BodyFusion f(one_segment_body(), {}, {}, 0);
  const Quat before = from_yaw_pitch_roll({0.2, 0.1, -0.1});
  const std::uint64_t t_before = 5000 * kSecondNs;
  for (std::uint64_t k = 0; k < 100; ++k) f.process({"n", k, exact_sample_at_ns(before, t_before + k * kStepNs)}, 0);

  // The node reboots: sequence and clock restart, and it now lies a quarter turn away.
  const Quat after = from_yaw_pitch_roll({0.2 + std::numbers::pi / 2, 0.1, -0.1});
  const int rebase_after = SampleGate::Params{}.rebase_after;
  for (int j = 0; j < rebase_after; ++j) {
    const SampleResult& r = f.process({"n", std::uint64_t(j), exact_sample_at_ns(after, 5 * kStepNs * (j + 1))}, 0);
    if (j + 1 < rebase_after) {
      EXPECT_EQ(r.verdict, SampleVerdict::kTimeBackward) << j;
      EXPECT_FALSE(r.clock_reset);
      continue;
    }
    EXPECT_EQ(r.verdict, SampleVerdict::kAcceptedClockReset);
    EXPECT_TRUE(r.clock_reset);
    ASSERT_EQ(r.outcome, SampleOutcome::kEstimated);
    // Restarted, the filter starts from this sample; carried on, one 50 ms step could not turn it 90 deg.
    EXPECT_TRUE(r.flags.reinitialised);
    EXPECT_LT(angle_between(r.orientation, after), kExactRad);
  }
  EXPECT_EQ(f.segment(0).gate.counters().clock_resets, 1u);
  EXPECT_EQ(rejected(f, 0, SampleVerdict::kTimeBackward), std::uint64_t(rebase_after - 1));
}

TEST(BodyFusion, ALiveCalibrationAppliesFromTheNextSampleAndRestartsTheFilter) {
  // A magnetometer with a hard-iron offset as large as the field: the heading is far off. A live calibration
  // removes the offset from the next sample on and restarts the filter, which starts at the true heading at once
  // instead of turning slowly (tau_mag 4 s) from the wrong one.
  BodyFusion f(one_segment_body(), {}, {}, 0);
  const Quat q = from_yaw_pitch_roll({1.2, 0.1, -0.2});
  const Vec3 offset(30.0, -25.0, 10.0);
  std::uint64_t t = kSecondNs;
  auto heading_error = [&](const Quat& estimate) {
    return std::abs(to_yaw_pitch_roll(relative_orientation(q, estimate)).yaw);
  };
  double before = 0.0;
  for (int k = 0; k < 200; ++k, t += kStepNs) {
    ImuSample s = exact_sample_at_ns(q, t);
    s.mag += offset;
    const SampleResult& r = f.process({"n", static_cast<std::uint64_t>(k), s}, t);
    ASSERT_EQ(r.outcome, SampleOutcome::kEstimated);
    before = heading_error(r.orientation);
  }
  EXPECT_GT(before, 10.0 * kDegToRad);
  calib::SensorCalibration live;
  live.magnetometer = calib::ChannelCalibration{offset, calib::Mat3::Identity()};
  ASSERT_EQ(f.update_calibration("n", live), std::optional<std::size_t>(0));
  EXPECT_EQ(f.update_calibration("nobody", live), std::nullopt);
  EXPECT_TRUE(f.segment(0).calibration.magnetometer->bias.isApprox(offset));
  ImuSample s = exact_sample_at_ns(q, t);
  s.mag += offset;
  const SampleResult& r = f.process({"n", 200, s}, t);
  ASSERT_EQ(r.outcome, SampleOutcome::kEstimated);
  EXPECT_TRUE(r.flags.reinitialised);
  EXPECT_LT(heading_error(r.orientation), kExactRad * 1e3);
  // The gate's counters belong to the node, not to its calibration: they go on.
  EXPECT_EQ(f.segment(0).gate.counters().accepted, 201u);
}

}  // namespace
}  // namespace bsn::fusion
