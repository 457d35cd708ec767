// The simulator's true anatomical joint angles and its sensor mounting: the alignment moves read with ISB signs
// (hip and knee flexion, ankle dorsiflexion positive), gait stays in the ranges of normal walking, and each sensor
// sits on its segment at its own random rotation and offset.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <numbers>

#include "bsn/sim/scenario.hpp"

namespace bsn::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

ScenarioSpec walking_session(double walk_s) {
  ScenarioSpec spec;
  spec.name = "session";
  spec.body = BodyKind::kLowerBody;
  Gait gait;
  gait.alignment = AlignmentMoves{};
  spec.gait = gait;
  spec.duration_s = gait.alignment->walk_start_s() + walk_s;
  return spec;
}

/// Per joint, the anatomical angles at every sample.
std::map<std::string, std::vector<Vec3>> truth_angles(const ScenarioSpec& spec) {
  ScenarioRunner runner(spec, {}, true);
  std::map<std::string, std::vector<Vec3>> out;
  std::vector<ScenarioSample> samples;
  while (runner.next(samples)) {
    for (std::size_t j = 0; j < samples.size(); ++j) {
      if (!samples[j].joint_relative) continue;
      out[runner.body().segment(j).joint].push_back(samples[j].joint_anatomical);
    }
  }
  return out;
}

TEST(SimJointTruth, AlignmentMovesReadWithIsbSigns) {
  const ScenarioSpec spec = walking_session(1.0);
  const AlignmentMoves m = *spec.gait->alignment;
  const auto angles = truth_angles(spec);
  const auto at = [&](const std::string& joint, double t_s) {
    return angles.at(joint)[static_cast<std::size_t>(t_s * spec.rate_hz)];
  };
  // The N-pose: every joint at zero (exactly: the segments are parallel).
  for (const auto& [joint, series] : angles) EXPECT_LT(series[100].norm(), 1e-9) << joint;
  // The left leg's first flexion at its height (hip up from 0.4 F, knee up from 0.35 F, ankle still up at 0.28 F):
  // the full amplitudes, positive. The right leg stands meanwhile.
  const double t = m.pose_s;
  EXPECT_NEAR(at("hip_l", t + 0.45 * m.flexion_s)[0], m.hip_flexion_rad, 1e-9);
  EXPECT_NEAR(at("knee_l", t + 0.45 * m.flexion_s)[0], m.knee_flexion_rad, 1e-9);
  EXPECT_NEAR(at("ankle_l", t + 0.27 * m.flexion_s)[0], m.ankle_flexion_rad, 1e-9);
  EXPECT_LT(at("knee_r", t + 0.45 * m.flexion_s).norm(), 1e-9);
  // The right leg's turn reads the same: mirrored sides read alike.
  const double t_right = m.pose_s + m.flexions_per_leg * m.flexion_s;
  EXPECT_NEAR(at("hip_r", t_right + 0.45 * m.flexion_s)[0], m.hip_flexion_rad, 1e-9);
  EXPECT_NEAR(at("knee_r", t_right + 0.45 * m.flexion_s)[0], m.knee_flexion_rad, 1e-9);
}

TEST(SimJointTruth, GaitStaysInTheRangesOfNormalWalking) {
  // Normal gait (Perry & Burnfield): knee 0..65 deg flexion, hip -20..+35 deg, ankle -20..+15 deg. The simulator's
  // harmonics must stay inside, or a demo's "plausible range" check would test the simulator, not bsn.
  const ScenarioSpec spec = walking_session(10.0);
  const auto angles = truth_angles(spec);
  const auto from = static_cast<std::size_t>((spec.gait->alignment->walk_start_s() + 1.0) * spec.rate_hz);
  const std::map<std::string, std::pair<double, double>> ranges{
      {"knee", {0, 65}}, {"hip", {-20, 35}}, {"ankle", {-20, 15}}};
  for (const auto& [joint, series] : angles) {
    const auto& [lo, hi] = ranges.at(joint.substr(0, joint.find('_')));
    double min = 1e9, max = -1e9;
    for (std::size_t k = from; k < series.size(); ++k) {
      min = std::min(min, series[k][0] / kDeg);
      max = std::max(max, series[k][0] / kDeg);
    }
    EXPECT_GE(min, lo) << joint;
    EXPECT_LE(max, hi) << joint;
    EXPECT_GT(max - min, 10.0) << joint << " hardly moves";
  }
}

TEST(SimJointTruth, SensorsAreMountedAtRandom) {
  ScenarioSpec spec = walking_session(1.0);
  const Body nominal = lower_body(spec.gait, spec.pose);
  const Body mounted = build_body(spec);
  for (std::size_t i = 0; i < mounted.size(); ++i) {
    SCOPED_TRACE(mounted.segment(i).name);
    // Any rotation: a uniform one is within 20 deg of the nominal mounting with a chance of 0.3 %.
    EXPECT_GT(fusion::angle_between(mounted.segment(i).sensor_to_segment, nominal.segment(i).sensor_to_segment),
              20 * kDeg);
    EXPECT_LE((mounted.segment(i).sensor_offset - nominal.segment(i).sensor_offset).norm(), 0.02 + 1e-12);
    for (std::size_t j = 0; j < i; ++j)
      EXPECT_GT(fusion::angle_between(mounted.segment(i).sensor_to_segment, mounted.segment(j).sensor_to_segment), 1e-3)
          << "the same mounting as " << mounted.segment(j).name;
  }
  spec.mounting = Mounting{0.0, 0.0};
  const Body exact = build_body(spec);
  for (std::size_t i = 0; i < exact.size(); ++i)
    EXPECT_LT(fusion::angle_between(exact.segment(i).sensor_to_segment, Quat::Identity()), 1e-12);
}

TEST(SimJointTruth, SegmentTruthIsTheSensorTruthTurnedByTheTrueMounting) {
  // The truth of an aligned estimate (bsn/truth/segment_orientation) is the sensor's truth without its mounting:
  // q_segment = q_sensor * conj(sensor_to_segment), the mounting an exact alignment finds; and standing in the N-pose
  // every segment's ISB long axis Y points up.
  const ScenarioSpec spec = walking_session(2.0);
  ScenarioRunner runner(spec, {}, true);
  std::vector<ScenarioSample> samples;
  double worst = 0.0;
  for (std::uint64_t k = 0; runner.next(samples); ++k) {
    for (std::size_t j = 0; j < samples.size(); ++j) {
      const Quat expected =
          fusion::segment_orientation(samples[j].truth, true_sensor_to_segment(runner.body().segment(j)));
      worst = std::max(worst, fusion::angle_between(samples[j].segment_truth, expected));
      if (k == 100) {  // 1 s into the first N-pose
        SCOPED_TRACE(runner.body().segment(j).name);
        EXPECT_GT((samples[j].segment_truth * Vec3::UnitY()).z(), std::cos(2 * kDeg));
      }
    }
  }
  EXPECT_LT(worst, 1e-9);
}

}  // namespace
}  // namespace bsn::sim
