// MagneticRAdaption against Fan et al. 2018 §2.2.1 / eq. 10: the variance factor is 1 in a clean field, infinite while
// the shared MagDisturbanceDetector flags a disturbance, and 1 / mag_reduced_gain^2 once a rejection has lasted
// mag_accept_after_s. Its decisions are the detector's (the Kalman filters and seel_ruppin/iecf judge alike).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>

#include "bsn/fusion/r_adaption.hpp"

namespace bsn::fusion {
namespace {

constexpr std::uint64_t kMs = 1'000'000;
constexpr double kDip = 64.0 * std::numbers::pi / 180.0;

Vec3 earth_field(double magnitude, double dip) {
  return Vec3(0.0, magnitude * std::cos(dip), -magnitude * std::sin(dip));
}

TEST(MagneticRAdaption, ReferenceHasTheDipOfTheField) {
  const MagneticRAdaption::Reference ref = MagneticRAdaption::Reference::of(earth_field(49.0, kDip), Vec3::UnitZ());
  EXPECT_NEAR(ref.norm, 49.0, 1e-12);
  EXPECT_NEAR(std::asin(ref.sin_dip), kDip, 1e-12);
}

// In any sensor orientation the variance factor follows the detector fed the same readings: 1 where it is clean,
// infinite where it is disturbed.
TEST(MagneticRAdaption, VarianceFactorIsTheDetectorsDecision) {
  const Quat q = from_yaw_pitch_roll({0.7, -0.4, 1.1});  // sensor-to-earth
  const Vec3 up = q.conjugate() * Vec3::UnitZ();
  const MagneticRAdaption::Reference ref =
      MagneticRAdaption::Reference::of(q.conjugate() * earth_field(49.0, kDip), up);
  MagneticRAdaption r;
  MagDisturbanceDetector d;
  d.set_reference(49.0, kDip);
  int disturbed = 0;
  for (std::uint64_t k = 0; k < 3000; ++k) {
    const double t = 0.01 * static_cast<double>(k);
    const double dip_dev = 0.2 * std::sin(0.7 * t) * std::sin(0.13 * t);
    const double ratio = 1.0 + 0.12 * std::sin(1.3 * t) * std::sin(0.05 * t);
    const Vec3 m = q.conjugate() * earth_field(49.0 * ratio, kDip + dip_dev);
    const double factor = r.update(k * 10 * kMs, m, up, ref);
    const bool d_disturbed = d.update(k * 10 * kMs, m, up);
    ASSERT_EQ(std::isinf(factor), d_disturbed) << "t = " << t;
    if (!d_disturbed) {
      ASSERT_EQ(factor, 1.0);
    }
    disturbed += d_disturbed ? 1 : 0;
  }
  EXPECT_GT(disturbed, 100);  // both states were visited
  EXPECT_LT(disturbed, 2900);
}

// No heading collapse: a disturbance that never ends (a magnet moving about, never one steady field) is rejected for
// mag_accept_after_s, then used with 1 / reduced_gain^2 times the variance.
TEST(MagneticRAdaption, LongRejectionUsesTheFieldAtReducedGain) {
  MagneticRAdaption r;
  const MagneticRAdaption::Reference ref = MagneticRAdaption::Reference::of(earth_field(49.0, kDip), Vec3::UnitZ());
  EXPECT_EQ(r.update(0, earth_field(49.0, kDip), Vec3::UnitZ(), ref), 1.0);
  const MagDisturbanceDetector::Params p;
  double factor = 0.0;
  for (std::uint64_t k = 1; k * 10 * kMs < 70'000 * kMs; ++k) {
    const double t = 0.01 * static_cast<double>(k);
    const double ratio = 1.3 + 0.2 * std::sin(0.5 * t);  // 10-50 % off, changing: never a new reference
    factor = r.update(k * 10 * kMs, earth_field(49.0 * ratio, kDip), Vec3::UnitZ(), ref);
    if (t < p.mag_accept_after_s - 0.1) {
      ASSERT_TRUE(std::isinf(factor)) << t;
    }
  }
  EXPECT_NEAR(factor, 1.0 / (p.mag_reduced_gain * p.mag_reduced_gain), 1e-12);
  EXPECT_TRUE(r.disturbed());
}

TEST(MagneticRAdaption, RejectsInconsistentThresholds) {
  MagDisturbanceDetector::Params p;
  p.mag_norm_leave = 0.2;  // above enter
  EXPECT_THROW(MagneticRAdaption{p}, std::invalid_argument);
  p = {};
  p.mag_dip_leave_rad = 0.0;
  EXPECT_THROW(MagneticRAdaption{p}, std::invalid_argument);
  p = {};
  p.mag_min_clean_s = -1.0;
  EXPECT_THROW(MagneticRAdaption{p}, std::invalid_argument);
}

}  // namespace
}  // namespace bsn::fusion
