// A field fixed to the sensor (a magnet or a phone near it) against a field fixed to the room: the first must be
// learned, the second never. On the simulator with a consumer sensor (gyro scale and misalignment errors, a
// magnetometer one sample behind the gyro and low-passed), through seel_ruppin, the filter that uses the rule.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "bsn/fusion/orientation_error.hpp"
#include "bsn/fusion/seel_ruppin_filter.hpp"
#include "bsn/fusion/sensor_fixed_field.hpp"
#include "bsn/sim/scenario.hpp"
#include "bsn/sim/sensor_model.hpp"
#include "filter_test_util.hpp"

namespace bsn::fusion {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kRestS = 8.0;

// A hand-held sensor, still for kRestS, then turned in every direction (RMS 60 deg/s, 0.1-0.5 Hz: tens of degrees
// about each axis); with `carried`, also carried about the room meanwhile: moved by 1.5 m and back along changing
// horizontal and rising directions, 0.94 s each way, a 1 s pause after each return (the sensor stays 1-1.8 m above the
// floor).
sim::ScenarioSpec hand_held(std::uint64_t seed, bool carried, double duration_s = 120.0, double rate_deg_s = 60.0) {
  sim::ScenarioSpec spec;
  spec.name = "hand-held";
  spec.duration_s = duration_s;
  spec.seed = seed;
  sim::RandomMotion m;
  m.angular_rate_rms_rad_s = rate_deg_s * kDeg;
  m.min_frequency_hz = 0.1;
  m.max_frequency_hz = 0.5;
  m.active = {{kRestS - 1.0, 1e9, 1.0}};
  m.seed = seed;
  spec.free_motion.random = m;
  if (carried) {
    const Vec3 directions[] = {Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.6, 0.6, 0.53), Vec3(-0.7, 0.3, 0.65)};
    constexpr double kDistance = 1.5, kDuration = 0.94, kPause = 1.0;
    int i = 0;
    for (double t = kRestS; t + 2 * kDuration < duration_s; t += 2 * kDuration + kPause, ++i) {
      const Vec3 d = directions[i % 4].normalized() * kDistance;
      spec.free_motion.moves.push_back({d, t, kDuration});
      spec.free_motion.moves.push_back({-d, t + kDuration, kDuration});
    }
  }
  spec.sensors = filter_test::consumer_mems_lagging_magnetometer();
  return spec;
}

// A phone-like magnet fixed to the sensor: 3 cm from it, its field there about 7 uT, mostly across the sensor's z
// axis, so that it turns the heading of a level sensor by up to 20 deg and |m| and the dip change little.
sim::AttachedMagnet phone_like_magnet() {
  sim::AttachedMagnet magnet;
  magnet.segment = 0;
  magnet.offset_m = Vec3(0.0, 0.03, 0.0);
  magnet.moment_am2 = Vec3(0.002, 0.0, 0.0004);
  return magnet;
}

// The floor of a motion lab: randomly oriented dipoles on a jittered 1 m grid 0.35 m under it (de Vries et al.
// 2009's lab shape, as the Nez bench models it), each of moment_am2 per axis (normal).
void add_lab_floor(sim::MagneticEnvironment& env, std::uint64_t seed, double moment_am2) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int ix = -4; ix <= 4; ++ix) {
    for (int iy = -4; iy <= 4; ++iy) {
      sim::Dipole d;
      const double jx = normal(rng), jy = normal(rng);  // sequenced draws: the same layout on any compiler
      const double mx = normal(rng), my = normal(rng), mz = normal(rng);
      d.position_m = Vec3(ix + 0.3 * jx, iy + 0.3 * jy, -0.35);
      d.moment_am2 = moment_am2 * Vec3(mx, my, mz);
      env.dipoles.push_back(d);
    }
  }
}

struct Figures {
  double rms_heading_deg = 0.0;  ///< from `scored_from_s` on
  Vec3 offset = Vec3::Zero();    ///< the field fixed to the sensor the filter ended with
  std::uint32_t changes = 0;
  std::uint32_t blocks_judged = 0;
  double field_heading_rms_deg = 0.0;  ///< how far the field the sensor passed through turns from the earth's
};

Figures run(const sim::ScenarioSpec& spec, bool learning, double scored_from_s) {
  SeelRuppinFilter::Params params;
  params.mag_offset_learning = learning ? 1.0 : 0.0;
  SeelRuppinFilter filter(params);
  sim::ScenarioRunner runner(spec, {}, false);
  std::vector<sim::ScenarioSample> out;
  double heading_sq = 0.0, field_sq = 0.0, scored = 0.0;
  const Vec3 earth = spec.magnetic.earth_field(0.0);
  while (runner.next(out)) {
    const sim::ScenarioSample& s = out.front();
    filter.update(s.sample);
    if (static_cast<double>(s.sample.timestamp_ns) * 1e-9 < scored_from_s) continue;
    heading_sq += std::pow(error_angles(filter.orientation(), s.truth).heading, 2);
    const Vec3 field = s.truth._transformVector(s.sample.mag);
    const double turn = std::atan2(earth.x() * field.y() - earth.y() * field.x(), earth.head<2>().dot(field.head<2>()));
    field_sq += turn * turn;
    scored += 1.0;
  }
  Figures r;
  r.rms_heading_deg = std::sqrt(heading_sq / scored) / kDeg;
  r.field_heading_rms_deg = std::sqrt(field_sq / scored) / kDeg;
  r.offset = filter.state().mag_offset.offset();
  r.changes = filter.state().mag_offset.changes();
  r.blocks_judged = filter.state().mag_offset.blocks_judged();
  return r;
}

// The component alone, with exact readings: m = R^T h + b for a sensor turning about every axis is learned to within
// the readings' rounding, and a sensor at rest never decides (its rotations cannot tell b from h).
TEST(SensorFixedField, LearnsAnOffsetThatTurnsWithTheSensorAndNothingAtRest) {
  SensorFixedField::Params p;
  SensorFixedField turning(p, "test"), resting(p, "test");
  const Vec3 h(0.0, 20.0, -40.0), b(3.0, -2.0, 1.0);
  bool changed = false;
  for (int i = 0; i <= 1100; ++i) {  // 11 s at 100 Hz: one block
    const double t = 0.01 * i;
    const Quat q = exp_rotation_vector(Vec3(0.6 * std::sin(1.3 * t), 0.5 * std::sin(0.9 * t + 1.0), 0.8 * std::sin(t)));
    const std::uint64_t t_ns = static_cast<std::uint64_t>(i) * 10'000'000ULL;
    changed = turning.update(t_ns, q, q.conjugate()._transformVector(h) + b) || changed;
    resting.update(t_ns, Quat::Identity(), h + b);
  }
  EXPECT_TRUE(changed);
  EXPECT_LT((turning.offset() - b).norm(), 1e-6);
  EXPECT_LT((turning.field_inertial() - h).norm(), 1e-6);
  EXPECT_EQ(resting.blocks_judged(), 0u);
  EXPECT_EQ(resting.offset(), Vec3::Zero());
}

TEST(SensorFixedField, RejectsParametersOutOfRange) {
  SensorFixedField::Params p;
  p.mag_offset_row_s = 20.0;  // longer than the block
  EXPECT_THROW(SensorFixedField(p, "test"), std::invalid_argument);
  p = {};
  p.mag_offset_learning = 2.0;
  EXPECT_THROW(SensorFixedField(p, "test"), std::invalid_argument);
  p = {};
  p.mag_offset_min_spread = 0.0;
  EXPECT_THROW(SensorFixedField(p, "test"), std::invalid_argument);
}

// A magnet fixed to the sensor from the first sample: the detector's reference is learned with it, so nothing flags
// it, and the heading follows the magnet's field. The rule must find the offset within a block or two of turning and
// take the heading back to the earth's: within 0.5 uT, and the heading RMS from 40 s on under 2 deg (the clean-field
// target of the translation case) and under half of what it is without the rule. Three motion and noise seeds.
TEST(SensorFixedField, AMagnetFixedToTheSensorIsLearnedAndTheHeadingRecovers) {
  for (const std::uint64_t seed : {21, 22, 23}) {
    sim::ScenarioSpec spec = hand_held(seed, false);
    spec.magnetic.attached_magnets.push_back(phone_like_magnet());
    const Vec3 truth = phone_like_magnet().field_sensor_ut();
    ASSERT_GT(truth.norm(), 5.0);
    const Figures with = run(spec, true, 40.0);
    const Figures without = run(spec, false, 40.0);
    EXPECT_LT((with.offset - truth).norm(), 0.5)
        << "seed " << seed << ": offset " << with.offset.transpose() << " uT against " << truth.transpose();
    EXPECT_LT(with.rms_heading_deg, 2.0) << "seed " << seed;
    EXPECT_LT(with.rms_heading_deg, 0.5 * without.rms_heading_deg)
        << "seed " << seed << ": without the rule " << without.rms_heading_deg << " deg";
    if (seed == 21) {
      RecordProperty("rms_heading_deg", std::to_string(with.rms_heading_deg));
      RecordProperty("rms_heading_without_rule_deg", std::to_string(without.rms_heading_deg));
    }
  }
}

// Not harmed: carried about a lab whose floor bends the field's heading along the path by 3.6-17 deg RMS on these seeds
// (de Vries et al. measured 3 deg at 1 m in a real lab), turned as above. The field then changes with the position,
// which no rotation explains, and the rule must never take it for a sensor-fixed field: no change on any of four seeds,
// although most blocks turn enough to be judged, so the heading is the same as without the rule.
TEST(SensorFixedField, ACarriedSensorInAnInhomogeneousFieldLearnsNothing) {
  for (const std::uint64_t seed : {31, 32, 33, 34}) {
    sim::ScenarioSpec spec = hand_held(seed, true);
    add_lab_floor(spec.magnetic, seed, 50.0);
    const Figures with = run(spec, true, kRestS);
    const Figures without = run(spec, false, kRestS);
    EXPECT_GT(with.field_heading_rms_deg, 3.0) << "seed " << seed << ": the field is not inhomogeneous enough";
    EXPECT_GE(with.blocks_judged, 5u) << "seed " << seed;
    EXPECT_EQ(with.changes, 0u) << "seed " << seed << ": learned " << with.offset.transpose() << " uT";
    EXPECT_NEAR(with.rms_heading_deg, without.rms_heading_deg, 1e-9) << "seed " << seed;
    if (seed == 31) RecordProperty("field_heading_rms_deg", std::to_string(with.field_heading_rms_deg));
  }
}

// Slower motion, as a hand moves in a lab: Nez et al.'s slow random motion instead of the 60 deg/s turns. Its blocks
// turn less about some axis, yet the field they show still tells a fixed offset from a position's field. The magnet
// must be learned by the end (within 1 uT of its 7.5 uT) and the heading improved, and carried about the lab floor in
// the same motion nothing may be learned.
sim::ScenarioSpec in_slow_motion(sim::ScenarioSpec spec, std::uint64_t seed) {
  sim::RandomMotion m = sim::random_motion_for(sim::Intensity::kSlow, seed);
  m.active = {{kRestS - 1.0, 1e9, 1.0}};
  spec.free_motion.random = m;
  return spec;
}

TEST(SensorFixedField, InSlowMotionTheMagnetIsLearnedAndAFloorsFieldIsNot) {
  for (const std::uint64_t seed : {21, 22, 23}) {
    sim::ScenarioSpec spec = in_slow_motion(hand_held(seed, false), seed);
    spec.magnetic.attached_magnets.push_back(phone_like_magnet());
    const Vec3 truth = phone_like_magnet().field_sensor_ut();
    const Figures with = run(spec, true, 40.0);
    const Figures without = run(spec, false, 40.0);
    EXPECT_LT((with.offset - truth).norm(), 1.0)
        << "seed " << seed << ": offset " << with.offset.transpose() << " uT against " << truth.transpose();
    EXPECT_LT(with.rms_heading_deg, without.rms_heading_deg) << "seed " << seed;
  }
  std::uint32_t judged = 0;
  for (const std::uint64_t seed : {31, 32, 33, 34}) {
    sim::ScenarioSpec spec = in_slow_motion(hand_held(seed, true), seed);
    add_lab_floor(spec.magnetic, seed, 50.0);
    const Figures with = run(spec, true, kRestS);
    EXPECT_EQ(with.changes, 0u) << "seed " << seed << ": learned " << with.offset.transpose() << " uT";
    judged += with.blocks_judged;
  }
  EXPECT_GE(judged, 10u);  // the carried blocks were judged, not passed over
}

}  // namespace
}  // namespace bsn::fusion
