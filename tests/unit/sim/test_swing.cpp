// The motion and sensor of `bsn sim --node` without a scenario: random_swing and swing_scenario. Gyro against
// orientation consistency, seeds and the noise model in general are the other files' tests.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>

#include "bsn/sim/scenario.hpp"

namespace bsn::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

double swing_angle(double offset, const Signal::Harmonic& h, double t) {
  return offset + h.amplitude * std::sin(2.0 * std::numbers::pi * h.frequency_hz * t + h.phase_rad);
}

TEST(SimSwing, OrientationIsTheSwingOfYawPitchAndRollAboutAFixedPoint) {
  const FreeMotion m = random_swing(21);
  ASSERT_TRUE(m.swing);
  EXPECT_FALSE(m.random);
  const Body body = free_body(m, "n1");
  std::vector<SegmentState> s;
  for (double t : {0.0, 1.3, 7.7, 42.0}) {
    body.evaluate(t, s);
    const fusion::YawPitchRoll& o = m.pose.orientation;
    const Quat expected =
        fusion::from_yaw_pitch_roll({swing_angle(o.yaw, m.swing->yaw, t), swing_angle(o.pitch, m.swing->pitch, t),
                                     swing_angle(o.roll, m.swing->roll, t)});
    EXPECT_LT(fusion::angle_between(s[0].q_sensor, expected), 1e-12) << "t=" << t;
    EXPECT_LT(s[0].acceleration.norm(), 1e-12) << "t=" << t;  // rotation only: the accelerometer feels gravity
  }
}

TEST(SimSwing, RangesAndFrequenciesAreBoundedAwayFromGimbalLock) {
  for (std::uint64_t seed = 1; seed < 50; ++seed) {
    const FreeMotion m = random_swing(seed);
    const fusion::YawPitchRoll& o = m.pose.orientation;
    const double max_deg[3] = {60.0, 30.0, 30.0};
    const double offset[3] = {o.yaw, o.pitch, o.roll};
    const Signal::Harmonic h[3] = {m.swing->yaw, m.swing->pitch, m.swing->roll};
    for (int i = 0; i < 3; ++i) {
      SCOPED_TRACE("seed " + std::to_string(seed) + " angle " + std::to_string(i));
      EXPECT_LE(std::abs(offset[i]), 0.5 * max_deg[i] * kDeg);
      EXPECT_GE(h[i].amplitude, 0.3 * max_deg[i] * kDeg);
      EXPECT_LE(h[i].amplitude, max_deg[i] * kDeg);
      EXPECT_GE(h[i].frequency_hz, 0.1);
      EXPECT_LE(h[i].frequency_hz, 0.4);
    }
    EXPECT_LT(std::abs(o.pitch) + m.swing->pitch.amplitude, 45.0 * kDeg) << "seed " << seed;
  }
}

TEST(SimSwing, IdealNodeReadsRotatedGravityAndTheDefaultEarthField) {
  ScenarioRunner runner(swing_scenario("n1", 6, 100.0, 10.0), {}, true);
  ASSERT_EQ(runner.segment_names(), std::vector<std::string>{"n1"});
  EXPECT_EQ(runner.sample_count(), 1000u);
  const Vec3 field = MagneticEnvironment{}.earth_field(0.0);
  std::vector<ScenarioSample> out;
  for (std::uint64_t k = 0; runner.next(out); ++k) {
    const Quat e2s = out[0].truth.conjugate();
    ASSERT_LT((out[0].sample.acc - e2s * Vec3(0, 0, fusion::kGravity)).norm(), 1e-12) << k;
    ASSERT_LT((out[0].sample.mag - e2s * field).norm(), 1e-12) << k;
    ASSERT_EQ(out[0].sample.timestamp_ns, k * 10'000'000u);
    ASSERT_FALSE(out[0].dropped);
  }
}

TEST(SimSwing, NodeNoiseAtOneHundredHertzIsTheFormerPerSampleNoise) {
  // The node used to add white noise of fixed per-sample SD (0.005 rad/s, 0.02 m/s^2, 0.3 uT); its densities
  // reproduce that at the default 100 Hz. 3n normal deviates per channel: relative standard error 1/sqrt(6n).
  const ScenarioSpec spec = swing_scenario("n1", 7, 100.0, 100.0);
  ScenarioRunner noisy(spec, {}, false), exact(spec, {}, true);
  std::vector<ScenarioSample> a, b;
  double gyr = 0.0, acc = 0.0, mag = 0.0;
  int n = 0;
  for (; noisy.next(a) && exact.next(b); ++n) {
    gyr += (a[0].sample.gyr - b[0].sample.gyr).squaredNorm();
    acc += (a[0].sample.acc - b[0].sample.acc).squaredNorm();
    mag += (a[0].sample.mag - b[0].sample.mag).squaredNorm();
  }
  ASSERT_EQ(n, 10000);
  EXPECT_NEAR(std::sqrt(gyr / (3.0 * n)), 0.005, 0.02 * 0.005);
  EXPECT_NEAR(std::sqrt(acc / (3.0 * n)), 0.02, 0.02 * 0.02);
  EXPECT_NEAR(std::sqrt(mag / (3.0 * n)), 0.3, 0.02 * 0.3);
}

TEST(SimSwing, WithoutADurationTheNodeRunsUntilStopped) {
  const ScenarioSpec spec = swing_scenario("n1", 1, 100.0, 0.0);
  EXPECT_TRUE(std::isinf(spec.duration_s));
  ScenarioRunner runner(spec, {}, false);
  EXPECT_EQ(runner.sample_count(), std::numeric_limits<std::uint64_t>::max());
  std::vector<ScenarioSample> out;
  EXPECT_TRUE(runner.next(out));
}

}  // namespace
}  // namespace bsn::sim
