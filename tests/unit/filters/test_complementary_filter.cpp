// ComplementaryFilter against its defining properties: first-order corrections with the configured time
// constants, a magnetometer that only ever turns the heading, dt from timestamps, a gap bridged by the gyro. What every
// filter must do (start, bad input, gaps, flags, tracking) is in test_filter_contract.cpp.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "bsn/fusion/complementary_filter.hpp"
#include "filter_test_util.hpp"

namespace bsn::fusion {
namespace {

using filter_test::at_ns;
using filter_test::kDeg;
using filter_test::kField;
using filter_test::kMs;
using filter_test::static_sample;

Vec3 rotate_about_up(const Vec3& v, double angle) { return Eigen::AngleAxisd(angle, Vec3::UnitZ()) * v; }

// A field whose heading turns at constant magnitude and dip: the heading error must decay as exp(-t/tau_mag)
// (exactly, since each step removes the fraction 1 - exp(-dt/tau)), and inclination must not move at all.
TEST(ComplementaryFilter, HeadingConvergesWithTauMagAndNeverTilts) {
  for (double tau : {1.0, 5.0}) {
    ComplementaryFilter::Params p;
    p.tau_mag_s = tau;
    ComplementaryFilter f(p);
    const Quat q = from_yaw_pitch_roll({30 * kDeg, 10 * kDeg, 5 * kDeg});
    f.update(static_sample(q, at_ns(0)));
    const Vec3 turned = rotate_about_up(kField, 50 * kDeg);
    const Quat target =
        orientation_from_acc_mag(static_sample(q, at_ns(0), turned).acc, static_sample(q, at_ns(0), turned).mag);
    const double initial_error = angle_between(f.orientation(), target);
    ASSERT_NEAR(initial_error, 50 * kDeg, 1e-9);
    const std::uint64_t dt = 10 * kMs;
    const auto steps = static_cast<std::uint64_t>(tau / 0.01);
    for (std::uint64_t k = 1; k <= steps; ++k) {
      f.update(static_sample(q, at_ns(k * dt), turned));
      const YawPitchRoll est = to_yaw_pitch_roll(f.orientation());
      ASSERT_NEAR(est.pitch, 10 * kDeg, 1e-9);
      ASSERT_NEAR(est.roll, 5 * kDeg, 1e-9);
    }
    // After one time constant, exp(-1) of the error remains.
    EXPECT_NEAR(angle_between(f.orientation(), target) / initial_error, std::exp(-1.0), 1e-3) << "tau " << tau;
  }
}

TEST(ComplementaryFilter, TiltConvergesWithTauAcc) {
  ComplementaryFilter::Params p;
  p.tau_acc_s = 2.0;
  ComplementaryFilter f(p);
  const Quat truth = from_yaw_pitch_roll({0, 0, 0});
  // Start from a sample that shows a 10 deg tilt, then give the true (level) readings without magnetometer.
  ImuSample first = static_sample(from_yaw_pitch_roll({0, 0, 10 * kDeg}), at_ns(0));
  first.has_mag = false;
  f.update(first);
  auto inclination_error = [&] {
    const Vec3 up_est = f.orientation().conjugate() * Vec3::UnitZ();
    const Vec3 up_true = truth.conjugate() * Vec3::UnitZ();
    return std::acos(std::clamp(up_est.dot(up_true), -1.0, 1.0));
  };
  ASSERT_NEAR(inclination_error(), 10 * kDeg, 1e-9);
  for (std::uint64_t k = 1; k <= 200; ++k) {
    ImuSample s = static_sample(truth, at_ns(k * 10 * kMs));
    s.has_mag = false;
    f.update(s);
  }
  EXPECT_NEAR(inclination_error() / (10 * kDeg), std::exp(-1.0), 1e-3);
}

TEST(ComplementaryFilter, DtComesFromTimestamps) {
  // Constant-rate rotation about a fixed axis sampled at 50 Hz and at 200 Hz: with exact readings both must
  // follow the truth, which a filter assuming a fixed rate could not.
  const Vec3 rate = Vec3(0.2, -0.5, 1.0);
  ComplementaryFilter::Params exact;
  exact.mag_latency_s = 0.0;  // exact samples: the magnetometer is in step with the gyro, nothing to bring forward
  for (double hz : {50.0, 200.0}) {
    ComplementaryFilter f(exact);
    const auto step_ns = static_cast<std::uint64_t>(1e9 / hz);
    Quat truth = from_yaw_pitch_roll({0.3, 0.1, -0.2});
    for (std::uint64_t k = 0; k <= static_cast<std::uint64_t>(10 * hz); ++k) {
      const double t = static_cast<double>(k * step_ns) * 1e-9;
      const Quat q = truth * exp_rotation_vector(rate * t);
      ImuSample s = static_sample(q, at_ns(k * step_ns));
      s.gyr = rate;
      f.update(s);
    }
    const Quat final_truth = truth * exp_rotation_vector(rate * static_cast<double>(10 * hz * step_ns) * 1e-9);
    EXPECT_LT(angle_between(f.orientation(), final_truth), 1e-6) << hz << " Hz";
  }
}

TEST(ComplementaryFilter, ShortGapIsBridgedLongGapReinitialises) {
  ComplementaryFilter::Params p;
  p.max_gap_s = 1.0;
  p.mag_latency_s = 0.0;  // exact samples: the magnetometer is in step with the gyro
  ComplementaryFilter f(p);
  const Vec3 rate(0, 0, 0.5);
  const Quat start = Quat::Identity();
  f.update(static_sample(start, at_ns(0)));
  // 0.5 s gap while turning at a constant rate: one gyro step over the gap lands on the truth.
  ImuSample s = static_sample(start * exp_rotation_vector(rate * 0.5), at_ns(500 * kMs));
  s.gyr = rate;
  EXPECT_EQ(f.update(s), UpdateResult::kUpdated);
  EXPECT_FALSE(f.flags().reinitialised);
  EXPECT_LT(angle_between(f.orientation(), start * exp_rotation_vector(rate * 0.5)), 1e-6);
  // A 3 s gap re-initialises from that sample and says so.
  const Quat later = from_yaw_pitch_roll({2.0, 0.1, 0.3});
  EXPECT_EQ(f.update(static_sample(later, at_ns(3500 * kMs))), UpdateResult::kInitialised);
  EXPECT_TRUE(f.flags().reinitialised);
  EXPECT_LT(angle_between(f.orientation(), later), 1e-9);
}

TEST(ComplementaryFilter, WithoutMagnetometerHeadingFollowsTheGyroOnly) {
  ComplementaryFilter f;
  const Quat q = from_yaw_pitch_roll({0.7, 0.0, 0.0});
  f.update(static_sample(q, at_ns(0)));
  for (std::uint64_t k = 1; k <= 500; ++k) {
    ImuSample s = static_sample(q, at_ns(k * 10 * kMs), rotate_about_up(kField, 1.0));  // would pull yaw if used
    s.has_mag = false;
    EXPECT_EQ(f.update(s), UpdateResult::kUpdated);
    EXPECT_FALSE(f.flags().mag_rejected);
  }
  EXPECT_NEAR(to_yaw_pitch_roll(f.orientation()).yaw, 0.7, 1e-9);
}

TEST(ComplementaryFilter, DisturbedFieldMagnitudeIsRejectedAndFlagged) {
  ComplementaryFilter f;  // the shared detector: |m| band 10 % in, 7 % out
  const Quat q = from_yaw_pitch_roll({0.4, 0.1, 0.0});
  f.update(static_sample(q, at_ns(0)));
  for (std::uint64_t k = 1; k <= 300; ++k) {
    const Vec3 disturbed = rotate_about_up(kField, 1.0) * 1.5;  // +50 % and turned: a magnet nearby
    f.update(static_sample(q, at_ns(k * 10 * kMs), disturbed));
    EXPECT_TRUE(f.flags().mag_rejected);
  }
  EXPECT_LT(angle_between(f.orientation(), q), 1e-9);
  // Trusted again once the field has stayed inside the inner band for mag_min_clean_s (0.5 s), not before.
  for (std::uint64_t k = 301; k <= 340; ++k) {
    f.update(static_sample(q, at_ns(k * 10 * kMs)));
    EXPECT_TRUE(f.flags().mag_rejected) << k;
  }
  for (std::uint64_t k = 341; k <= 400; ++k) f.update(static_sample(q, at_ns(k * 10 * kMs)));
  EXPECT_FALSE(f.flags().mag_rejected);
}

TEST(FilterFactory, MakesTheComplementaryFilterWithParameters) {
  auto f = make_filter({"complementary", {{"tau_acc_s", 3.0}, {"tau_mag_s", 7.0}}});
  ASSERT_NE(f, nullptr);
  EXPECT_EQ(f->name(), "complementary");
  const auto* cf = dynamic_cast<const ComplementaryFilter*>(f.get());
  ASSERT_NE(cf, nullptr);
  EXPECT_EQ(cf->params().tau_acc_s, 3.0);
  EXPECT_EQ(cf->params().tau_mag_s, 7.0);
}

TEST(FilterFactory, ChecksTheComplementaryFilterParameters) {
  for (double bad : {0.0, -1.0, std::nan("")}) {
    EXPECT_THROW(make_filter({"complementary", {{"tau_acc_s", bad}}}), std::invalid_argument);
  }
}

}  // namespace
}  // namespace bsn::fusion
