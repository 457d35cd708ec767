// The reusable components of the filters: rest detection, low-pass gyro bias, magnetic-disturbance detection, and the
// inline rotation helpers used per sample. The contract of every filter is in test_filter_contract.cpp.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "bsn/fusion/gyro_bias_lowpass.hpp"
#include "bsn/fusion/mag_disturbance_detector.hpp"
#include "bsn/fusion/rest_detector.hpp"
#include "filter_test_util.hpp"

namespace bsn::fusion {
namespace {

using filter_test::at_s;
using filter_test::kDeg;
using filter_test::kField;
using filter_test::static_sample;

// ---------------------------------------------------------------------------------------------------------------
// RestDetector

TEST(RestDetector, RestingOnlyAfterTheMinimumStillTime) {
  RestDetector d({0.05, 0.5, 1.5});
  for (int i = 0; i < 149; ++i) EXPECT_FALSE(d.update(static_sample(Quat::Identity(), at_s(i * 0.01)))) << i;
  EXPECT_TRUE(d.update(static_sample(Quat::Identity(), at_s(1.5))));
  // A rate above the threshold ends the rest at once and restarts the timer.
  EXPECT_FALSE(d.update(static_sample(Quat::Identity(), at_s(1.51), kField, Vec3(0, 0.06, 0))));
  EXPECT_FALSE(d.update(static_sample(Quat::Identity(), at_s(2.5))));
  EXPECT_FALSE(d.update(static_sample(Quat::Identity(), at_s(3.99))));
  EXPECT_TRUE(d.update(static_sample(Quat::Identity(), at_s(4.0))));
  // So does a specific force off g by more than the threshold (an acceleration at zero rate).
  ImuSample s = static_sample(Quat::Identity(), at_s(4.01));
  s.acc.z() += 0.6;
  EXPECT_FALSE(d.update(s));
  EXPECT_THROW(RestDetector({0.0, 0.5, 1.5}), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------------------------
// GyroBiasLowPass (Fan eqs. 11-12)

TEST(GyroBiasLowPass, AveragesTheFirstRestThenFollowsWithCornerFrequency) {
  GyroBiasLowPass lp;                   // f_c = 0.05 Hz, omega_min = 3 deg/s, t_b = 2 s
  const Vec3 bias(0.01, -0.02, 0.015);  // rad/s, every component below 3 deg/s
  std::mt19937 rng(5);
  const double sd = 0.002;  // rad/s per reading
  std::normal_distribution<double> noise(0.0, sd);
  const double ts = 0.01;
  double t = 0.0;
  for (; t < 2.0 - 1e-9; t += ts) lp.update(seconds_to_ns(t), ts, bias + Vec3(noise(rng), noise(rng), noise(rng)));
  EXPECT_EQ(lp.bias(), Vec3::Zero());  // not updated before t_b
  // Half a second after updating starts (50 readings), the estimate is their mean: within 4 SD of the mean's own
  // noise, sd / sqrt(50), of the bias on every axis (a low-pass started from zero would still lack 85 % of it).
  const double t_start = 2.0 + ts;
  for (; t < t_start + 0.5 - 1e-9; t += ts)
    lp.update(seconds_to_ns(t), ts, bias + Vec3(noise(rng), noise(rng), noise(rng)));
  EXPECT_LT((lp.bias() - bias).cwiseAbs().maxCoeff(), 4 * sd / std::sqrt(50.0));
  // After the running mean (one time constant 1 / (2 pi f_c) of still time) it is the low-pass: a bias change is
  // followed with that time constant, 1 - 1/e of the way after one more time constant.
  const double tau = 1.0 / (2 * std::numbers::pi * 0.05);
  for (; t < t_start + tau + 1.0; t += ts) lp.update(seconds_to_ns(t), ts, bias);
  const Vec3 before = lp.bias();
  const Vec3 moved = bias + Vec3(0.0, 0.01, 0.0);
  const double t_move = t;
  for (; t < t_move + tau - 1e-9; t += ts) lp.update(seconds_to_ns(t), ts, moved);
  EXPECT_NEAR((lp.bias().y() - before.y()) / (moved.y() - before.y()), 1 - std::exp(-1.0), 0.01);
  for (; t < 40.0; t += ts) lp.update(seconds_to_ns(t), ts, moved + Vec3(noise(rng), noise(rng), noise(rng)));
  EXPECT_LT((lp.bias() - moved).norm(), 3e-4);
  EXPECT_TRUE(lp.updating());
}

TEST(GyroBiasLowPass, FreezesWhileAnyComponentExceedsOmegaMin) {
  GyroBiasLowPass lp;
  const Vec3 bias(0.01, 0.0, -0.01);
  double t = 0.0;
  for (; t < 20.0; t += 0.01) lp.update(seconds_to_ns(t), 0.01, bias);
  const Vec3 learned = lp.bias();
  // One component above 3 deg/s (the others at the bias) is motion: nothing is learned from it.
  for (; t < 30.0; t += 0.01) lp.update(seconds_to_ns(t), 0.01, bias + Vec3(0, 4 * kDeg, 0));
  EXPECT_EQ(lp.bias(), learned);
  EXPECT_FALSE(lp.updating());
  // Still again: the update resumes only after t_b.
  const double still_from = t;
  for (; t < still_from + 1.9; t += 0.01) lp.update(seconds_to_ns(t), 0.01, Vec3(0.02, 0.0, 0.0));
  EXPECT_EQ(lp.bias(), learned);
  for (; t < still_from + 2.5; t += 0.01) lp.update(seconds_to_ns(t), 0.01, Vec3(0.02, 0.0, 0.0));
  EXPECT_NE(lp.bias(), learned);
}

// ---------------------------------------------------------------------------------------------------------------
// MagDisturbanceDetector (Fan sections 2.2.1 and 5.1)

TEST(MagDisturbanceDetector, DipAngleOfTheEarthField) {
  EXPECT_NEAR(MagDisturbanceDetector::dip_angle(kField, Vec3::UnitZ()), 64 * kDeg, 1e-12);
}

// The threshold logic on its own: each reading judged unfiltered, the reference fixed (no low-pass, no averaging),
// enter 10 % / 8 deg, leave 5 % / 4 deg, 1 s clean.
MagDisturbanceDetector::Params unfiltered() {
  MagDisturbanceDetector::Params p;
  p.mag_norm_enter = 0.10;
  p.mag_norm_leave = 0.05;
  p.mag_dip_enter_rad = 0.14;
  p.mag_dip_leave_rad = 0.07;
  p.mag_min_clean_s = 1.0;
  p.mag_lowpass_tau_s = 0.0;
  p.mag_reference_tau_s = 1e12;
  return p;
}
// A reference that the clean field does not move (as averaged over 1e12 s).
void fix_reference(MagDisturbanceDetector& d, const Vec3& field) {
  d.set_reference(field.norm(), MagDisturbanceDetector::dip_angle(field, Vec3::UnitZ()), 1e12);
}

// A field near a single threshold with noise: one threshold chatters, two thresholds with a minimum clean time
// do not. (The new-field rule is switched off: a field hovering at 8 % for 20 s would rightly be adopted.)
TEST(MagDisturbanceDetector, TwoThresholdsDoNotChatterWhereOneDoes) {
  auto transitions = [](const MagDisturbanceDetector::Params& p) {
    MagDisturbanceDetector d(p);
    std::mt19937 rng(9);
    std::normal_distribution<double> noise(0.0, 0.02);
    fix_reference(d, kField);
    d.update(0, kField, Vec3::UnitZ());
    int changes = 0;
    bool last = false;
    for (int i = 1; i < 3000; ++i) {
      const double scale = 1.0 + 0.08 + noise(rng);  // hovers around 8 % above the reference
      const bool disturbed = d.update(seconds_to_ns(i * 0.01), kField * scale, Vec3::UnitZ());
      changes += disturbed != last;
      last = disturbed;
    }
    return changes;
  };
  MagDisturbanceDetector::Params single = unfiltered();
  single.mag_norm_enter = single.mag_norm_leave = 0.08;
  single.mag_min_clean_s = 1e-9;
  single.mag_max_rejection_s = 1e6;
  EXPECT_GT(transitions(single), 100);
  MagDisturbanceDetector::Params two = unfiltered();
  two.mag_max_rejection_s = 1e6;
  EXPECT_EQ(transitions(two), 1);  // enters once (a sample beyond 10 %), stays
}

TEST(MagDisturbanceDetector, CleanAgainOnlyAfterTheMinimumDurationInsideTheInnerBand) {
  MagDisturbanceDetector d(unfiltered());  // enter 10 %, leave 5 %, min_clean 1 s
  fix_reference(d, kField);
  EXPECT_FALSE(d.update(0, kField, Vec3::UnitZ()));
  EXPECT_TRUE(d.update(seconds_to_ns(0.01), kField * 1.2, Vec3::UnitZ()));   // magnitude: at once
  EXPECT_TRUE(d.update(seconds_to_ns(0.02), kField * 1.07, Vec3::UnitZ()));  // between the bands: still disturbed
  for (int i = 3; i < 102; ++i) EXPECT_TRUE(d.update(seconds_to_ns(i * 0.01), kField * 1.02, Vec3::UnitZ())) << i;
  // A sample between the bands restarts the clean timer.
  EXPECT_TRUE(d.update(seconds_to_ns(1.02), kField * 1.07, Vec3::UnitZ()));
  for (int i = 103; i < 202; ++i) EXPECT_TRUE(d.update(seconds_to_ns(i * 0.01), kField, Vec3::UnitZ())) << i;
  EXPECT_FALSE(d.update(seconds_to_ns(2.03), kField, Vec3::UnitZ()));
  // Dip: the same magnitude turned 12 deg towards the vertical is a disturbance.
  const Vec3 steeper = Eigen::AngleAxisd(12 * kDeg, Vec3::UnitX()) * kField;
  EXPECT_NEAR(steeper.norm(), kField.norm(), 1e-9);
  EXPECT_TRUE(d.update(seconds_to_ns(2.04), steeper, Vec3::UnitZ()));
  MagDisturbanceDetector::Params crossed = unfiltered();
  crossed.mag_norm_leave = 0.2;  // above enter
  EXPECT_THROW(MagDisturbanceDetector{crossed}, std::invalid_argument);
}

// The dip bands are tested on sines against bounds derived from the reference's sine and cosine (no asin per
// sample): the decisions must be those of the angles, on both sides of each threshold, also where a band limit
// lies beyond the vertical.
TEST(MagDisturbanceDetector, DipDecisionsAreThoseOfTheAngles) {
  for (double ref_dip_deg : {64.0, -30.0, 85.0}) {
    const Vec3 reference = Eigen::AngleAxisd((64.0 - ref_dip_deg) * kDeg, Vec3::UnitX()) * kField;
    ASSERT_NEAR(MagDisturbanceDetector::dip_angle(reference, Vec3::UnitZ()), ref_dip_deg * kDeg, 1e-12);
    for (double change_deg = -20.0; change_deg <= 20.0; change_deg += 0.25) {
      const double new_dip_deg = ref_dip_deg + change_deg;
      if (std::abs(new_dip_deg) > 90.0) continue;  // not a dip
      MagDisturbanceDetector d(unfiltered());      // enter 0.14 rad, leave 0.07 rad
      fix_reference(d, reference);
      d.update(0, reference, Vec3::UnitZ());
      const Vec3 turned = Eigen::AngleAxisd(-change_deg * kDeg, Vec3::UnitX()) * reference;
      const bool disturbed = d.update(seconds_to_ns(0.01), turned, Vec3::UnitZ());
      EXPECT_EQ(disturbed, std::abs(change_deg * kDeg) > 0.14) << ref_dip_deg << " " << change_deg;
      EXPECT_EQ(d.state().inside_leave_band, std::abs(change_deg * kDeg) < 0.07) << ref_dip_deg << " " << change_deg;
      EXPECT_NEAR(d.last_dip_deviation(), std::abs(change_deg) * kDeg, 1e-9);
      EXPECT_NEAR(d.last_norm_deviation(), 0.0, 1e-12);
    }
  }
}

// The low-pass is what makes the decision robust (VQF): readings whose noise alone crosses the enter threshold now
// and then (SD 1/3 of the 10 % threshold, about one reading in 400 beyond it) are judged disturbed unfiltered,
// but not low-passed; a real step beyond the threshold is still flagged within a few time constants.
TEST(MagDisturbanceDetector, LowPassIgnoresNoiseButNotAStep) {
  auto disturbed_fraction = [](double tau_s) {
    MagDisturbanceDetector::Params p = unfiltered();
    p.mag_lowpass_tau_s = tau_s;
    p.mag_min_clean_s = 0.02;
    MagDisturbanceDetector d(p);
    fix_reference(d, kField);
    std::mt19937 rng(4);
    std::normal_distribution<double> noise(0.0, 0.033);
    int disturbed = 0;
    for (int i = 0; i < 20000; ++i)
      disturbed += d.update(seconds_to_ns(i * 0.02), kField * (1.0 + noise(rng)), Vec3::UnitZ());
    return disturbed / 20000.0;
  };
  EXPECT_GT(disturbed_fraction(0.0), 0.002);    // 3 SD: 0.27 % of the readings, each held a reading longer
  EXPECT_LT(disturbed_fraction(0.02), 0.0005);  // SD 1/sqrt(3) as large: 5 SD
  MagDisturbanceDetector d;                     // defaults: low-pass 0.02 s
  d.update(0, kField, Vec3::UnitZ());
  std::uint64_t flagged_ns = 0;
  for (int i = 1; i < 50 && flagged_ns == 0; ++i) {
    if (d.update(seconds_to_ns(i * 0.02), kField * 1.2, Vec3::UnitZ())) flagged_ns = seconds_to_ns(i * 0.02);
  }
  // A 20 % step crosses 10 % when 1 - (1 - k)^n > 1/2, k = dt / (tau + dt) = 1/2 at 50 Hz: the second reading.
  EXPECT_EQ(flagged_ns, seconds_to_ns(0.04));
}

// The reference starts as the first reading and then averages the clean field: a first reading off by 4 % (noise,
// a start in motion) is forgotten, so a later 7 % change of the magnitude is judged against the true field.
TEST(MagDisturbanceDetector, ReferenceAveragesTheCleanField) {
  MagDisturbanceDetector d;
  d.update(0, kField * 1.04, Vec3::UnitZ());
  for (int i = 1; i <= 500; ++i) ASSERT_FALSE(d.update(seconds_to_ns(i * 0.02), kField, Vec3::UnitZ())) << i;
  EXPECT_NEAR(d.state().ref_norm, kField.norm(), 0.001 * kField.norm());  // a running mean over 10 s
  EXPECT_NEAR(d.last_norm_deviation(), 0.0, 1e-3);
}

// ---------------------------------------------------------------------------------------------------------------
// Inline helpers of rotation.hpp that the filters use per sample.

TEST(RotationHelpers, InverseSqrtNearOneAndRotateMatchTheirDefinitions) {
  for (double n2 : {1.0, 1.0 + 1e-12, 1.0 - 3e-7, 1.0 + 4e-4, 1.0 - 9.99e-4, 1.0 + 1e-3, 0.5, 2.0, 1e-20, 1e20}) {
    EXPECT_NEAR(inverse_sqrt_near_one(n2) * std::sqrt(n2), 1.0, 4e-16) << n2;
  }
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int i = 0; i < 100; ++i) {
    const Quat q = Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
    const Vec3 v(n(rng), n(rng), n(rng));
    EXPECT_LT((rotate(q, v) - q * v).norm(), 1e-14 * v.norm());
  }
}

}  // namespace
}  // namespace bsn::fusion
