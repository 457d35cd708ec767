// ISB anatomical joint angles: postures described by where each segment axis points give the named angles with
// the documented signs on both sides, the decomposition and its inverse round-trip, mirrored motions read alike,
// joint names imply their convention, and the sensor mounting from axis directions.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "bsn/fusion/anatomy.hpp"
#include "bsn/fusion/body_fusion.hpp"

namespace bsn::fusion {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
// Postures are built from exact axis directions: only floating-point rounding separates angle and expectation.
constexpr double kExactRad = 1e-9;

/// The child segment's orientation in its parent's frame from the child's X (anterior) and Y (superior) axes in
/// parent coordinates: how an anatomist describes a posture, independent of the decomposition under test.
Quat posture(const Vec3& x_axis, const Vec3& y_axis) {
  Eigen::Matrix3d r;
  r.col(0) = x_axis.normalized();
  r.col(1) = y_axis.normalized();
  r.col(2) = r.col(0).cross(r.col(1));
  return Quat(r);
}

const JointConvention kLeftKnee{JointType::kKnee, BodySide::kLeft}, kRightKnee{JointType::kKnee, BodySide::kRight};
const JointConvention kLeftHip{JointType::kHip, BodySide::kLeft}, kRightHip{JointType::kHip, BodySide::kRight};
const JointConvention kLeftAnkle{JointType::kAnkle, BodySide::kLeft}, kRightAnkle{JointType::kAnkle, BodySide::kRight};

void expect_angles_deg(const Vec3& rad, double a, double b, double c) {
  EXPECT_NEAR(rad[0], a * kDeg, kExactRad);
  EXPECT_NEAR(rad[1], b * kDeg, kExactRad);
  EXPECT_NEAR(rad[2], c * kDeg, kExactRad);
}

TEST(Anatomy, KneeFlexedNinetyReadsPlusNinetyOnBothSides) {
  // The shank points back: its long (superior) axis along the thigh's anterior axis, its anterior axis down.
  const Quat flexed = posture(-Vec3::UnitY(), Vec3::UnitX());
  for (const JointConvention& knee : {kLeftKnee, kRightKnee})
    expect_angles_deg(anatomical_angles(flexed, knee), 90, 0, 0);
}

TEST(Anatomy, HipAbductedTwentyReadsMinusTwentyAdductionOnBothSides) {
  const double s = std::sin(20 * kDeg), c = std::cos(20 * kDeg);
  // The knee moves out (laterally): the thigh's superior axis tilts medially. Medial is -Z on the right, +Z on the
  // left.
  expect_angles_deg(anatomical_angles(posture(Vec3::UnitX(), Vec3(0, c, -s)), kRightHip), 0, -20, 0);
  expect_angles_deg(anatomical_angles(posture(Vec3::UnitX(), Vec3(0, c, s)), kLeftHip), 0, -20, 0);
}

TEST(Anatomy, HipFlexionAndInternalRotationArePositiveOnBothSides) {
  const double s = std::sin(30 * kDeg), c = std::cos(30 * kDeg);
  // Flexion: the knee comes forward, the thigh's superior axis tilts back.
  const Quat flexed = posture(Vec3(c, s, 0), Vec3(-s, c, 0));
  for (const JointConvention& hip : {kLeftHip, kRightHip}) expect_angles_deg(anatomical_angles(flexed, hip), 30, 0, 0);
  // Internal rotation: the thigh's anterior axis turns medially.
  expect_angles_deg(anatomical_angles(posture(Vec3(c, 0, -s), Vec3::UnitY()), kRightHip), 0, 0, 30);
  expect_angles_deg(anatomical_angles(posture(Vec3(c, 0, s), Vec3::UnitY()), kLeftHip), 0, 0, 30);
}

TEST(Anatomy, AnkleDorsiflexionIsPositiveOnBothSides) {
  const double s = std::sin(15 * kDeg), c = std::cos(15 * kDeg);
  // The toes come up: the foot's anterior axis tilts up.
  const Quat dorsiflexed = posture(Vec3(c, s, 0), Vec3(-s, c, 0));
  for (const JointConvention& ankle : {kLeftAnkle, kRightAnkle})
    expect_angles_deg(anatomical_angles(dorsiflexed, ankle), 15, 0, 0);
  const Quat plantarflexed = posture(Vec3(c, -s, 0), Vec3(s, c, 0));
  expect_angles_deg(anatomical_angles(plantarflexed, kLeftAnkle), -15, 0, 0);
}

TEST(Anatomy, ElbowWristAndTrunkFlexionArePositive) {
  // Elbow flexed 90: the forearm points forward (its superior axis back), the palm up.
  const Quat elbow = posture(Vec3::UnitY(), -Vec3::UnitX());
  for (BodySide side : {BodySide::kLeft, BodySide::kRight})
    expect_angles_deg(anatomical_angles(elbow, {JointType::kElbow, side}), 90, 0, 0);
  // Trunk bent forward 30: its superior axis tilts forward.
  const double s = std::sin(30 * kDeg), c = std::cos(30 * kDeg);
  expect_angles_deg(anatomical_angles(posture(Vec3(c, -s, 0), Vec3(s, c, 0)), {JointType::kTrunkPelvis}), 30, 0, 0);
}

TEST(Anatomy, RoundTripIsExact) {
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> angle(-std::numbers::pi, std::numbers::pi), middle(-1.5, 1.5);
  for (JointType type : {JointType::kHip, JointType::kKnee, JointType::kAnkle, JointType::kTrunkPelvis,
                         JointType::kShoulder, JointType::kElbow, JointType::kWrist}) {
    for (BodySide side : {BodySide::kLeft, BodySide::kRight, BodySide::kMidline}) {
      for (int k = 0; k < 50; ++k) {
        const Vec3 angles(angle(rng), middle(rng), angle(rng));
        const Quat q = relative_from_anatomical(angles, {type, side});
        EXPECT_LT((anatomical_angles(q, {type, side}) - angles).cwiseAbs().maxCoeff(), kExactRad);
        EXPECT_LT(angle_between(relative_from_anatomical(anatomical_angles(q, {type, side}), {type, side}), q),
                  kExactRad);
      }
    }
  }
}

TEST(Anatomy, MirroredMotionReadsTheSameOnTheLeft) {
  // The mirror image (Z -> -Z) of a right-side posture is the same motion on the left: M R M, M = diag(1, 1, -1).
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> angle(-1.2, 1.2);
  const Eigen::Matrix3d m = Eigen::Vector3d(1, 1, -1).asDiagonal();
  for (JointType type : {JointType::kHip, JointType::kKnee, JointType::kAnkle, JointType::kShoulder, JointType::kElbow,
                         JointType::kWrist}) {
    for (int k = 0; k < 20; ++k) {
      const Quat right = compose(Vec3(angle(rng), angle(rng), angle(rng)), AxisSequence{{0, 1, 2}});
      const Quat left(Eigen::Matrix3d(m * right.toRotationMatrix() * m));
      EXPECT_LT((anatomical_angles(right, {type, BodySide::kRight}) - anatomical_angles(left, {type, BodySide::kLeft}))
                    .cwiseAbs()
                    .maxCoeff(),
                kExactRad);
    }
  }
}

TEST(Anatomy, JointNamesImplyTheirConvention) {
  EXPECT_EQ(infer_joint_convention("knee_l"), kLeftKnee);
  EXPECT_EQ(infer_joint_convention("hip_right"), kRightHip);
  EXPECT_EQ(infer_joint_convention("Left_Ankle"), kLeftAnkle);
  EXPECT_EQ(infer_joint_convention("r_elbow"), (JointConvention{JointType::kElbow, BodySide::kRight}));
  EXPECT_EQ(infer_joint_convention("lumbar"), (JointConvention{JointType::kTrunkPelvis, BodySide::kMidline}));
  EXPECT_EQ(infer_joint_convention("knee"), (JointConvention{JointType::kKnee, BodySide::kMidline}));
  EXPECT_EQ(infer_joint_convention("j12").type, JointType::kNone);
  EXPECT_EQ(infer_joint_convention("pelvis-thigh_l").type, JointType::kNone);
  EXPECT_EQ(anatomical_angle_names(JointType::kAnkle)[0], "dorsiflexion_plantarflexion");
  EXPECT_EQ(anatomical_angle_names(JointType::kNone)[0], "");
  EXPECT_EQ(anatomical_angles(Quat(0.5, 0.5, 0.5, 0.5), {}), Vec3::Zero());
}

TEST(Anatomy, MountingFromSensorAxisDirections) {
  using D = Direction;
  const auto simulator = sensor_to_segment_from_axes({D::kAnterior, D::kLeft, D::kSuperior});
  ASSERT_TRUE(simulator);
  EXPECT_LT(angle_between(*simulator, default_sensor_to_segment()), kExactRad);
  // Sensor x anterior maps onto segment X, sensor z (up) onto segment Y.
  EXPECT_LT((*simulator * Vec3::UnitX() - Vec3::UnitX()).norm(), kExactRad);
  EXPECT_LT((*simulator * Vec3::UnitZ() - Vec3::UnitY()).norm(), kExactRad);
  EXPECT_FALSE(sensor_to_segment_from_axes({D::kAnterior, D::kRight, D::kSuperior})) << "a mirror";
  EXPECT_FALSE(sensor_to_segment_from_axes({D::kAnterior, D::kPosterior, D::kSuperior})) << "two axes on one line";
}

/// The exact reading of a still sensor with sensor-to-earth orientation q.
ImuSample still_sample(const Quat& q, std::uint64_t t_ns) {
  ImuSample s;
  s.timestamp_ns = t_ns;
  s.acc = q.conjugate() * Vec3(0.0, 0.0, kGravity);
  s.gyr = Vec3::Zero();
  s.mag = q.conjugate() * Vec3(0.0, 20.0, -44.0);
  return s;
}

TEST(Anatomy, BodyFusionGivesAnatomicalAnglesThroughAKnownMounting) {
  // A left knee flexed 40 deg, both sensors at arbitrary orientations on their segments; the body model knows the
  // mountings. The anatomical angles must be exact; the published orientation is the segment frame.
  BodyModel body;
  body.segments.resize(2);
  body.segments[0].name = body.segments[0].node = "thigh_l";
  body.segments[1].name = body.segments[1].node = "shank_l";
  body.segments[1].parent = "thigh_l";
  body.segments[1].joint = "knee_l";
  const Quat thigh_mount = from_yaw_pitch_roll({0.4, -1.1, 2.0}), shank_mount = from_yaw_pitch_roll({-2.5, 0.3, 0.7});
  body.segments[0].sensor_to_segment = thigh_mount;
  body.segments[1].sensor_to_segment = shank_mount;
  const Vec3 knee(40 * kDeg, 5 * kDeg, -10 * kDeg);
  const Quat thigh = from_yaw_pitch_roll({0.3, 0.0, 0.5 * std::numbers::pi});  // standing: Y up, facing north-east
  const Quat shank = thigh * relative_from_anatomical(knee, kLeftKnee);
  BodyFusion f(body, {}, {}, 0);
  const std::uint64_t step = 10'000'000;
  for (std::uint64_t k = 0; k < 50; ++k) {
    const SampleResult& t = f.process({"thigh_l", k, still_sample(thigh * thigh_mount, k * step)}, 0);
    EXPECT_TRUE(t.aligned);
    EXPECT_LT(angle_between(t.orientation, thigh), kExactRad);
    const SampleResult& r = f.process({"shank_l", k, still_sample(shank * shank_mount, k * step)}, 0);
    ASSERT_TRUE(r.joint);
    EXPECT_EQ(r.joint->convention, kLeftKnee);
    EXPECT_TRUE(r.joint->aligned);
    EXPECT_LT((r.joint->anatomical - knee).cwiseAbs().maxCoeff(), kExactRad);
  }
  // Without the mountings the sensor frames are published and the angles are those of the default mounting: wrong.
  body.segments[0].sensor_to_segment.reset();
  body.segments[1].sensor_to_segment.reset();
  BodyFusion unaligned(body, {}, {}, 0);
  unaligned.process({"thigh_l", 0, still_sample(thigh * thigh_mount, 0)}, 0);
  const SampleResult& r = unaligned.process({"shank_l", 0, still_sample(shank * shank_mount, 0)}, 0);
  ASSERT_TRUE(r.joint);
  EXPECT_FALSE(r.aligned);
  EXPECT_FALSE(r.joint->aligned);
  EXPECT_GT((r.joint->anatomical - knee).cwiseAbs().maxCoeff(), 10 * kDeg);
  // A live alignment brings them back.
  ASSERT_TRUE(unaligned.update_alignment("thigh_l", thigh_mount));
  ASSERT_TRUE(unaligned.update_alignment("shank_l", shank_mount));
  EXPECT_FALSE(unaligned.process({"shank_l", 1, still_sample(shank * shank_mount, step)}, 0).joint)
      << "a joint from the parent's frame before the alignment";
  unaligned.process({"thigh_l", 1, still_sample(thigh * thigh_mount, step)}, 0);
  const SampleResult& aligned = unaligned.process({"shank_l", 2, still_sample(shank * shank_mount, 2 * step)}, 0);
  ASSERT_TRUE(aligned.joint);
  EXPECT_TRUE(aligned.joint->aligned);
  EXPECT_LT((aligned.joint->anatomical - knee).cwiseAbs().maxCoeff(), kExactRad);
}

}  // namespace
}  // namespace bsn::fusion
