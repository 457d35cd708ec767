// MagneticRAdaption against Fan et al. 2018 §2.2.1 / eq. 10: the variance factor is 1 in a clean field and infinite
// while disturbed, with two thresholds and a minimum clean time so that a deviation hovering near one threshold does
// not chatter.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "bsn/fusion/r_adaption.hpp"

namespace bsn::fusion {
namespace {

constexpr std::uint64_t kMs = 1'000'000;

TEST(MagneticRAdaption, CleanFieldKeepsTheNominalVariance) {
  MagneticRAdaption r;
  for (std::uint64_t k = 0; k < 100; ++k) {
    EXPECT_EQ(r.update(k * 10 * kMs, 1.0 + 0.04 * std::sin(0.1 * static_cast<double>(k)), 0.05), 1.0);
  }
  EXPECT_FALSE(r.disturbed());
}

// The filters pass the cosine of the dip deviation (no inverse sine); it must judge every sample exactly as the
// angle does, across both thresholds and the clean waiting time.
TEST(MagneticRAdaption, CosineOfTheDipDeviationJudgesExactlyAsTheAngle) {
  MagneticRAdaption by_angle, by_cosine;
  int disturbed = 0;
  for (std::uint64_t k = 0; k < 2000; ++k) {
    const double t = 0.01 * static_cast<double>(k);
    // Dip deviation sweeping +-0.3 rad across both thresholds (0.1745 / 0.0873), magnitude mostly clean.
    const double dip_dev = 0.3 * std::sin(0.7 * t) * std::sin(0.13 * t);
    const double ratio = 1.0 + 0.03 * std::sin(1.3 * t);
    const double a = by_angle.update(k * 10 * kMs, ratio, dip_dev);
    const double c = by_cosine.update_from_cosine(k * 10 * kMs, ratio, std::cos(dip_dev));
    ASSERT_EQ(a, c) << "t = " << t << ", dip deviation " << dip_dev;
    disturbed += std::isinf(a) ? 1 : 0;
  }
  EXPECT_GT(disturbed, 100);  // both states were visited
  EXPECT_LT(disturbed, 1900);
  MagneticRAdaption r;
  EXPECT_TRUE(std::isinf(r.update_from_cosine(0, 1.0, std::nan(""))));
}

// The filters pass the raw reading, the estimated vertical and a Reference; in any sensor orientation this must
// judge every sample as the magnitude ratio and dip angle do.
TEST(MagneticRAdaption, ReadingAgainstItsReferenceJudgesAsRatioAndAngle) {
  constexpr double kDip = 64.0 * 3.14159265358979323846 / 180.0;
  auto earth_field = [](double magnitude, double dip) {
    return Vec3(0.0, magnitude * std::cos(dip), -magnitude * std::sin(dip));  // ENU
  };
  const MagneticRAdaption::Reference ref = MagneticRAdaption::Reference::of(earth_field(49.0, kDip), Vec3::UnitZ());
  EXPECT_NEAR(ref.norm, 49.0, 1e-12);
  EXPECT_NEAR(std::asin(ref.sin_dip), kDip, 1e-12);
  const Quat q = from_yaw_pitch_roll({0.7, -0.4, 1.1});  // sensor-to-earth
  const Vec3 up = q.conjugate() * Vec3::UnitZ();
  MagneticRAdaption by_angle, by_reading;
  int disturbed = 0;
  for (std::uint64_t k = 0; k < 2000; ++k) {
    const double t = 0.01 * static_cast<double>(k);
    const double dip_dev = 0.3 * std::sin(0.7 * t) * std::sin(0.13 * t);
    const double ratio = 1.0 + 0.15 * std::sin(1.3 * t) * std::sin(0.05 * t);
    const Vec3 m = q.conjugate() * earth_field(49.0 * ratio, kDip + dip_dev);
    const double a = by_angle.update(k * 10 * kMs, ratio, dip_dev);
    const double r = by_reading.update(k * 10 * kMs, m, up, ref);
    // Away from the thresholds (rounding of the reading's construction decides exactly at them).
    const bool near_threshold =
        std::abs(std::abs(dip_dev) - 0.1745) < 1e-9 || std::abs(std::abs(dip_dev) - 0.0873) < 1e-9 ||
        std::abs(std::abs(ratio - 1.0) - 0.1) < 1e-9 || std::abs(std::abs(ratio - 1.0) - 0.05) < 1e-9;
    if (!near_threshold) {
      ASSERT_EQ(a, r) << "t = " << t;
    }
    disturbed += std::isinf(a) ? 1 : 0;
  }
  EXPECT_GT(disturbed, 100);  // both states were visited
  EXPECT_LT(disturbed, 1900);
}

TEST(MagneticRAdaption, MagnitudeOrDipBeyondTheEnterThresholdGivesInfiniteVariance) {
  MagneticRAdaption r;
  EXPECT_TRUE(std::isinf(r.update(0, 1.11, 0.0)));
  MagneticRAdaption r2;
  EXPECT_TRUE(std::isinf(r2.update(0, 1.0, -0.18)));
  MagneticRAdaption r3;
  EXPECT_TRUE(std::isinf(r3.update(0, std::nan(""), 0.0)));
}

// A magnitude oscillating between the exit (5 %) and enter (10 %) thresholds must neither leave nor enter the
// disturbed state: that is what the second threshold is for.
TEST(MagneticRAdaption, TwoThresholdsDoNotChatter) {
  MagneticRAdaption r;
  r.update(0, 1.2, 0.0);
  ASSERT_TRUE(r.disturbed());
  for (std::uint64_t k = 1; k < 500; ++k) {
    const double ratio = 1.075 + 0.02 * std::sin(0.3 * static_cast<double>(k));  // 5.5 % .. 9.5 %
    EXPECT_TRUE(std::isinf(r.update(k * 10 * kMs, ratio, 0.0))) << k;
  }
  MagneticRAdaption clean;
  for (std::uint64_t k = 0; k < 500; ++k) {
    const double ratio = 1.075 + 0.02 * std::sin(0.3 * static_cast<double>(k));
    EXPECT_EQ(clean.update(k * 10 * kMs, ratio, 0.0), 1.0) << k;
  }
}

TEST(MagneticRAdaption, TrustsAgainOnlyAfterTheMinimumCleanTime) {
  MagneticRAdaption::Params p;
  p.min_clean_s = 1.0;
  MagneticRAdaption r(p);
  r.update(0, 1.5, 0.0);
  // Clean from 10 ms on: still rejected up to 1.01 s, trusted from then on.
  for (std::uint64_t t = 10; t < 1010; t += 10) EXPECT_TRUE(std::isinf(r.update(t * kMs, 1.0, 0.0))) << t;
  EXPECT_EQ(r.update(1010 * kMs, 1.0, 0.0), 1.0);
  // A short spike restarts the clean clock.
  r.update(1020 * kMs, 1.3, 0.0);
  EXPECT_TRUE(std::isinf(r.update(1500 * kMs, 1.0, 0.0)));
  EXPECT_TRUE(std::isinf(r.update(2400 * kMs, 1.0, 0.0)));
  EXPECT_EQ(r.update(2500 * kMs, 1.0, 0.0), 1.0);
}

TEST(MagneticRAdaption, RejectsInconsistentThresholds) {
  MagneticRAdaption::Params p;
  p.magnitude_exit = 0.2;  // above enter
  EXPECT_THROW(MagneticRAdaption{p}, std::invalid_argument);
  p = {};
  p.dip_exit_rad = 0.0;
  EXPECT_THROW(MagneticRAdaption{p}, std::invalid_argument);
  p = {};
  p.min_clean_s = -1.0;
  EXPECT_THROW(MagneticRAdaption{p}, std::invalid_argument);
}

}  // namespace
}  // namespace bsn::fusion
