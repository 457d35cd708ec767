// The simulator's noise-free channels are exact physics of its motion.
#include <gtest/gtest.h>

#include <numbers>

#include "bsn/sim/mimu_synthesizer.hpp"
#include "bsn/sim/motion_model.hpp"

namespace bsn::sim {
namespace {

using fusion::angle_between;
using fusion::exp_rotation_vector;

TEST(SimCore, GyroIntegratesToTheTruthOrientation) {
  // Midpoint-rate integration with a fine step: its error shrinks as dt^2, so any mismatch between the
  // analytic rate and the orientation shows up far above the tolerance.
  const SinusoidalRotation motion = SinusoidalRotation::from_seed(5);
  const double dt = 1e-4;
  Quat q = motion.at(0.0).q_sensor_to_earth;
  const int steps = 200000;  // 20 s
  for (int k = 0; k < steps; ++k) {
    const double t = k * dt;
    q = (q * exp_rotation_vector(motion.at(t + 0.5 * dt).angular_rate_sensor * dt)).normalized();
  }
  EXPECT_LT(angle_between(q, motion.at(steps * dt).q_sensor_to_earth), 1e-6);
}

TEST(SimCore, IdealChannelsAreRotatedGravityAndField) {
  const SinusoidalRotation motion = SinusoidalRotation::from_seed(6);
  const EarthField field{49.0, 64.0};
  MimuSynthesizer synth(field, WhiteNoise::none(), 1);
  for (double t : {0.0, 1.3, 7.7}) {
    const MotionState m = motion.at(t);
    const fusion::ImuSample s = synth.measure(m, 5);
    const Quat e2s = m.q_sensor_to_earth.conjugate();
    EXPECT_LT((s.acc - e2s * Vec3(0, 0, fusion::kGravity)).norm(), 1e-12);
    EXPECT_LT((s.mag - e2s * field.vector_enu()).norm(), 1e-12);
    EXPECT_LT((s.gyr - m.angular_rate_sensor).norm(), 1e-15);
    EXPECT_EQ(s.timestamp_ns, 5u);
  }
}

TEST(SimCore, EarthFieldHasTheConfiguredMagnitudeAndDip) {
  const Vec3 f = EarthField{50.0, 60.0}.vector_enu();
  EXPECT_NEAR(f.norm(), 50.0, 1e-12);
  EXPECT_NEAR(f.x(), 0.0, 1e-12);                                                  // points to magnetic north
  EXPECT_NEAR(std::atan2(-f.z(), f.y()) * 180.0 / std::numbers::pi, 60.0, 1e-12);  // down in the north
}

TEST(SimCore, SameSeedSameNoiseOtherSeedOtherNoise) {
  const SinusoidalRotation motion = SinusoidalRotation::from_seed(7);
  MimuSynthesizer a(EarthField{}, WhiteNoise{}, 42), b(EarthField{}, WhiteNoise{}, 42),
      c(EarthField{}, WhiteNoise{}, 43);
  bool differs = false;
  for (int k = 0; k < 100; ++k) {
    const MotionState m = motion.at(k * 0.01);
    const auto sa = a.measure(m, 0), sb = b.measure(m, 0), sc = c.measure(m, 0);
    EXPECT_EQ(sa.acc, sb.acc);
    EXPECT_EQ(sa.gyr, sb.gyr);
    EXPECT_EQ(sa.mag, sb.mag);
    differs = differs || sa.gyr != sc.gyr;
  }
  EXPECT_TRUE(differs);
}

TEST(SimCore, NoiseHasTheConfiguredStandardDeviation) {
  const WhiteNoise noise{0.01, 0.05, 0.5};
  MimuSynthesizer synth(EarthField{}, noise, 3);
  const MotionState still;
  const int n = 20000;
  double sum_sq = 0.0;
  for (int k = 0; k < n; ++k) sum_sq += synth.measure(still, 0).gyr.squaredNorm();
  // 3n samples of a zero-mean normal: the estimate's relative standard error is 1/sqrt(6n) ~ 0.3 %.
  EXPECT_NEAR(std::sqrt(sum_sq / (3.0 * n)), noise.gyr_rad_s, 0.02 * noise.gyr_rad_s);
}

TEST(SimCore, MotionIsBoundedAwayFromGimbalLock) {
  for (std::uint64_t seed = 1; seed < 50; ++seed) {
    const SinusoidalRotation motion = SinusoidalRotation::from_seed(seed);
    const auto& p = motion.params();
    EXPECT_LT(std::abs(p.pitch.offset_rad) + std::abs(p.pitch.amplitude_rad), 45.0 * std::numbers::pi / 180.0);
  }
}

}  // namespace
}  // namespace bsn::sim
