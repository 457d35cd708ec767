// The contract every registered filter keeps, whatever its method: one suite over filter_registry(), 6D-only filters
// told by the registry's flag. On exact data the bounds are numerical (rounding, or the filter's own integration
// error); on noisy data they follow from the noise. Each filter's own properties live in its test_<filter>.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <ostream>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "bsn/fusion/orientation_filter.hpp"
#include "filter_test_util.hpp"

namespace bsn::fusion {

// gtest names a parameter in failure messages by this (ADL: in the namespace of FilterInfo).
void PrintTo(const FilterInfo& info, std::ostream* os) { *os << info.name; }

namespace {

using filter_test::at_ns;
using filter_test::at_s;
using filter_test::kDeg;
using filter_test::kField;
using filter_test::kMs;
using filter_test::static_sample;
using filter_test::turning_sensor;

class FilterContract : public ::testing::TestWithParam<FilterInfo> {
 protected:
  std::unique_ptr<OrientationFilter> make() const { return GetParam().make({GetParam().name, {}}); }
  bool six_d_only() const { return GetParam().six_d_only; }
};

double inclination_error(const Quat& estimate, const Quat& truth) {
  const Vec3 up_est = estimate.conjugate() * Vec3::UnitZ();
  const Vec3 up_true = truth.conjugate() * Vec3::UnitZ();
  return std::atan2(up_est.cross(up_true).norm(), up_est.dot(up_true));
}

TEST(FilterRegistry, ListsUniqueNamesAndNamesAnUnknownOne) {
  std::vector<std::string> in_order;
  for (const FilterInfo& f : filter_registry()) in_order.emplace_back(f.name);
  EXPECT_EQ(filter_names(), in_order);
  EXPECT_EQ(std::set<std::string>(in_order.begin(), in_order.end()).size(), in_order.size());
  try {
    make_filter({"kalman9000", {}});
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("kalman9000"), std::string::npos);
  }
}

TEST(FilterRegistry, RestoringAnotherFiltersStateThrowsNamingBoth) {
  const auto complementary = make_filter({"complementary", {}});
  complementary->update(filter_test::static_sample(Quat::Identity(), at_s(0)));
  const auto madgwick = make_filter({"madgwick", {}});
  try {
    madgwick->restore(*complementary->save());
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'complementary' into filter 'madgwick'"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(madgwick->initialised());
}

TEST_P(FilterContract, IsListedNamedAndChecksParameterNames) {
  const auto names = filter_names();
  EXPECT_NE(std::find(names.begin(), names.end(), GetParam().name), names.end());
  EXPECT_EQ(make()->name(), GetParam().name);
  EXPECT_EQ(make_filter({GetParam().name, {}})->name(), GetParam().name);
  try {
    make_filter({GetParam().name, {{"no_such_parameter", 1.0}}});
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_parameter"), std::string::npos);
  }
  for (double bad : {0.0, -1.0, std::nan("")}) {
    EXPECT_THROW(make_filter({GetParam().name, {{"max_gap_s", bad}}}), std::invalid_argument) << bad;
  }
}

// The registry's rejects_magnetometer says the filter takes the shared MagDisturbanceDetector's parameters (the
// tests that force a rejection set them); a 9D filter without the flag takes none of them, so a filter given the
// detector but not the flag fails here instead of having its rejection tests run without the rejection.
TEST_P(FilterContract, RejectsMagnetometerFlagMatchesTheDetectorParameters) {
  // The set CleanFieldMotion forces the rejection with: valid together for every filter with the detector.
  const std::vector<std::pair<std::string, double>> detector = {{"mag_norm_enter", 1e-6},
                                                                {"mag_norm_leave", 1e-6},
                                                                {"mag_reference_tau_s", 1e6},
                                                                {"mag_max_rejection_s", 1e6},
                                                                {"mag_accept_after_s", 1e6}};
  if (GetParam().rejects_magnetometer) {
    EXPECT_NO_THROW(make_filter({GetParam().name, detector}));
  } else if (!six_d_only()) {
    for (const auto& parameter : detector) {
      EXPECT_THROW(make_filter({GetParam().name, {parameter}}), std::invalid_argument) << parameter.first;
    }
  }
  EXPECT_FALSE(GetParam().rejects_magnetometer && six_d_only());
}

// TRIAD from the first exact sample is exact to rounding at any heading (6D-only filters too take the first heading
// from the magnetometer), and exact readings of a still sensor leave nothing to correct. 1e-9 rad is a few thousand
// roundings; holding over 10 s gets 1e-8 rad: the EKF's additive quaternion state is renormalised every step.
TEST_P(FilterContract, StartsAtTheTrueOrientationForAnyHeadingAndHoldsIt) {
  for (double yaw : {-179.0, -100.0, -30.0, 0.0, 45.0, 120.0, 180.0}) {
    auto f = make();
    const Quat q = from_yaw_pitch_roll({yaw * kDeg, 20 * kDeg, -35 * kDeg});
    ASSERT_EQ(f->update(static_sample(q, at_s(0))), UpdateResult::kInitialised);
    EXPECT_TRUE(f->initialised());
    EXPECT_TRUE(f->flags().reinitialised);
    EXPECT_TRUE(f->flags().initialising);
    EXPECT_LT(angle_between(f->orientation(), q), 1e-9) << yaw;
    for (std::uint64_t k = 1; k <= 1000; ++k) {
      ASSERT_EQ(f->update(static_sample(q, at_ns(k * 10 * kMs))), UpdateResult::kUpdated);
    }
    EXPECT_LT(angle_between(f->orientation(), q), 1e-8) << yaw;
    EXPECT_FALSE(f->flags().reinitialised);
    EXPECT_FALSE(f->flags().mag_rejected);
  }
}

TEST_P(FilterContract, RejectsNonFiniteInputAndTimeNotAdvancingWithoutTouchingTheState) {
  auto f = make();
  const Quat q = from_yaw_pitch_roll({30 * kDeg, 5 * kDeg, 0});
  f->update(static_sample(q, at_s(0)));
  for (int i = 1; i <= 300; ++i) f->update(static_sample(q, at_s(i * 0.01), kField, Vec3(0.01, 0, 0)));
  const Quat q_before = f->orientation();
  const Vec3 bias_before = f->gyro_bias();
  const FilterClock clock_before = f->clock();
  for (double bad : {std::nan(""), std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()}) {
    for (int channel = 0; channel < 3; ++channel) {
      ImuSample s = static_sample(q, at_s(3.01));
      (channel == 0 ? s.acc : channel == 1 ? s.gyr : s.mag)[channel] = bad;
      EXPECT_EQ(f->update(s), UpdateResult::kRejected);
    }
  }
  ImuSample huge = static_sample(q, at_s(3.01));
  huge.acc *= 1e300;  // finite values whose squared norm is not
  EXPECT_EQ(f->update(huge), UpdateResult::kRejected);
  EXPECT_EQ(f->update(static_sample(q, at_s(3.0))), UpdateResult::kRejected);  // dt = 0
  EXPECT_EQ(f->update(static_sample(q, at_s(2.5))), UpdateResult::kRejected);  // dt < 0
  EXPECT_EQ(f->orientation().coeffs(), q_before.coeffs());
  EXPECT_EQ(f->gyro_bias(), bias_before);
  EXPECT_EQ(f->clock().last_ns, clock_before.last_ns);
  EXPECT_EQ(f->clock().init_ns, clock_before.init_ns);
  EXPECT_EQ(f->update(static_sample(q, at_s(3.01))), UpdateResult::kUpdated);
  EXPECT_EQ(f->clock().last_ns, at_s(3.01).ns);
}

// The gap rule of OrientationFilter::update(): a gap up to max_gap_s (1 s) is bridged; a longer one restarts the
// orientation from the sample, exactly as at a first start, and keeps the gyro bias estimate bit for bit. The bias is
// learnt first from 30 s of a still sensor whose gyro reads a bias (every component below the 3 deg/s still threshold
// of the low-pass estimates). For a filter that estimates no bias the bias part holds trivially.
TEST_P(FilterContract, GapRestartsTheOrientationAndKeepsTheGyroBias) {
  auto f = make();
  const Quat q = from_yaw_pitch_roll({-60 * kDeg, 10 * kDeg, 5 * kDeg});
  const Vec3 gyro_bias(0.01, -0.008, 0.005);
  f->update(static_sample(q, at_s(0), kField, gyro_bias));
  for (int i = 1; i <= 3000; ++i) f->update(static_sample(q, at_s(i * 0.01), kField, gyro_bias));
  EXPECT_EQ(f->update(static_sample(q, at_s(30.5), kField, gyro_bias)), UpdateResult::kUpdated);  // 0.5 s gap
  EXPECT_FALSE(f->flags().reinitialised);
  const Vec3 bias_before = f->gyro_bias();

  const Quat q2 = from_yaw_pitch_roll({100 * kDeg, -30 * kDeg, 20 * kDeg});
  EXPECT_EQ(f->update(static_sample(q2, at_s(32.0), kField, gyro_bias)), UpdateResult::kInitialised);  // 1.5 s gap
  EXPECT_TRUE(f->flags().reinitialised);
  EXPECT_TRUE(f->flags().initialising);
  EXPECT_EQ(f->clock().init_ns, at_s(32.0).ns);
  EXPECT_LT(angle_between(f->orientation(), q2), 1e-9);
  EXPECT_EQ(f->gyro_bias(), bias_before);

  EXPECT_EQ(f->update(static_sample(q2, at_s(1e7), kField, gyro_bias)), UpdateResult::kInitialised);  // huge gap
  EXPECT_TRUE(f->orientation().coeffs().allFinite());
  EXPECT_EQ(f->gyro_bias(), bias_before);
  EXPECT_EQ(f->update(static_sample(q2, at_s(1e7 + 0.01), kField, gyro_bias)), UpdateResult::kUpdated);
  EXPECT_FALSE(f->flags().reinitialised);

  f->reset();  // unlike a gap, reset() forgets the bias too
  EXPECT_FALSE(f->initialised());
  EXPECT_EQ(f->gyro_bias(), Vec3::Zero());
  EXPECT_EQ(f->orientation().coeffs(), Quat::Identity().coeffs());
}

TEST_P(FilterContract, HostileInputNeverThrowsNorProducesNonFiniteOutput) {
  auto f = make();
  std::mt19937_64 rng(99);
  std::uniform_int_distribution<int> kind(0, 11);
  std::normal_distribution<double> n(0.0, 1.0);
  const double inf = std::numeric_limits<double>::infinity(), nan = std::nan("");
  std::uint64_t t = 1'000'000'000;
  for (int i = 0; i < 100000; ++i) {
    ImuSample s = static_sample(Quat(n(rng), n(rng), n(rng), n(rng)).normalized(), at_ns(t));
    s.gyr = Vec3(n(rng), n(rng), n(rng));
    t += 10 * kMs;
    const int k = kind(rng);
    switch (k) {
      case 0:
        s.acc.x() = nan;
        break;
      case 1:
        s.gyr.y() = inf;
        break;
      case 2:
        s.mag.z() = -inf;
        break;
      case 3:
        s.acc *= 1e300;
        break;  // huge
      case 4:
        s.timestamp_ns = t - 5'000 * kMs;
        break;  // back in time
      case 5:
        s.timestamp_ns = t += 1'000'000'000'000'000ull;
        break;  // far ahead (~11 days)
      case 6:
        s.timestamp_ns = t -= 10 * kMs;
        break;  // zero dt
      case 7:
        s.acc = Vec3::Constant(160.0);
        s.gyr = Vec3::Constant(35.0);
        break;  // saturated MEMS
      case 8:
        s.acc.setZero();
        s.mag.setZero();
        break;  // free fall, no field
      case 9:
        s.mag = s.acc;
        break;  // field along gravity
      case 10:
        s.has_mag = false;
        s.mag.setConstant(nan);
        break;  // missing channel
      default:
        break;  // a good sample
    }
    ASSERT_NO_THROW(f->update(s)) << " sample " << i << " kind " << k;
    ASSERT_TRUE(f->orientation().coeffs().allFinite()) << " sample " << i << " kind " << k;
    ASSERT_NEAR(f->orientation().norm(), 1.0, 1e-9) << " sample " << i << " kind " << k;
    ASSERT_TRUE(f->gyro_bias().allFinite()) << " sample " << i << " kind " << k;
  }
}

// Finite values over sixty decades (and rates up to 1e300 rad/s), missing channels, zero fields, tiny and huge steps.
TEST_P(FilterContract, ExtremeFiniteInputNeverProducesNonFiniteOutput) {
  auto f = make();
  f->update(static_sample(Quat::Identity(), at_s(0)));
  std::mt19937 rng(13);
  std::uniform_real_distribution<double> exponent(-30, 30), sign(-1, 1);
  double t = 0.0;
  for (int i = 0; i < 20000; ++i) {
    t += (i % 101 == 0) ? 1e4 : (i % 7 == 0 ? 1e-9 : 0.01);
    ImuSample s;
    s.timestamp_ns = seconds_to_ns(t);
    for (int k = 0; k < 3; ++k) {
      s.acc[k] = sign(rng) * std::pow(10.0, exponent(rng));
      s.gyr[k] = sign(rng) * std::pow(10.0, 10 * exponent(rng));
      s.mag[k] = (i % 11 == 0) ? 0.0 : sign(rng) * std::pow(10.0, exponent(rng));
    }
    s.has_mag = i % 3 != 0;
    s.has_gyr = i % 13 != 0;
    f->update(s);
    ASSERT_TRUE(f->orientation().coeffs().allFinite()) << i;
    ASSERT_NEAR(f->orientation().norm(), 1.0, 1e-9) << i;
    ASSERT_TRUE(f->gyro_bias().allFinite()) << i;
  }
}

TEST_P(FilterContract, SameStreamGivesBitIdenticalOutput) {
  const auto stream = turning_sensor(3, 30.0, false);
  std::vector<Quat> first;
  for (int run = 0; run < 2; ++run) {
    auto f = make();
    for (std::size_t k = 0; k < stream.size(); ++k) {
      f->update(stream[k].sample);
      if (run == 0) {
        first.push_back(f->orientation());
      } else {
        ASSERT_EQ(f->orientation().coeffs(), first[k].coeffs()) << " sample " << k;
      }
    }
  }
}

// One sample's output, compared bit for bit.
struct Output {
  Quat q;
  Vec3 bias;
  FilterFlags flags;
};
Output output_of(const OrientationFilter& f) { return {f.orientation(), f.gyro_bias(), f.flags()}; }
::testing::AssertionResult identical(const Output& a, const Output& b) {
  if (a.q.coeffs() != b.q.coeffs()) return ::testing::AssertionFailure() << "orientations differ";
  if (a.bias != b.bias) return ::testing::AssertionFailure() << "gyro biases differ";
  if (a.flags.resting != b.flags.resting || a.flags.mag_rejected != b.flags.mag_rejected ||
      a.flags.initialising != b.flags.initialising || a.flags.reinitialised != b.flags.reinitialised) {
    return ::testing::AssertionFailure() << "flags differ";
  }
  return ::testing::AssertionSuccess();
}

// save() holds everything a filter keeps between samples: a fresh filter of the same parameters that restore()s it
// continues bit for bit as the one it was saved from, wherever the stream is saved (at rest while the bias is learnt,
// in motion, just after the restart of a long gap, within a magnetometer disturbance), and the saved filter itself
// continues unchanged by the saving.
TEST_P(FilterContract, SavedAndRestoredStateContinuesBitIdentically) {
  const std::vector<ImuSample> stream = filter_test::stateful_stream();
  std::vector<Output> reference;
  auto f = make();
  int resting = 0, rejected = 0, restarts = 0;
  for (const ImuSample& s : stream) {
    f->update(s);
    reference.push_back(output_of(*f));
    resting += f->flags().resting;
    rejected += f->flags().mag_rejected;
    restarts += f->flags().reinitialised;
  }
  // The stream does what it claims: rest, the restart after the long gap, a rejected magnetometer.
  EXPECT_GT(resting, 100);
  EXPECT_EQ(restarts, 2);  // the first sample and the long gap
  if (GetParam().rejects_magnetometer) {
    EXPECT_GT(rejected, 100);
  }
  for (const double save_at_s : {5.0, 15.0, 29.6, 35.0}) {
    const auto save_at = static_cast<std::size_t>(
        std::find_if(stream.begin(), stream.end(),
                     [&](const ImuSample& s) { return s.timestamp_ns >= at_s(save_at_s).ns; }) -
        stream.begin());
    ASSERT_LT(save_at, stream.size());
    auto saved = make();
    for (std::size_t k = 0; k <= save_at; ++k) saved->update(stream[k]);
    const std::unique_ptr<FilterSnapshot> snapshot = saved->save();
    EXPECT_EQ(snapshot->filter(), GetParam().name);
    auto restored = make();
    restored->restore(*snapshot);
    EXPECT_TRUE(restored->initialised());
    ASSERT_TRUE(identical(output_of(*restored), reference[save_at])) << "sample " << save_at;
    for (std::size_t k = save_at + 1; k < stream.size(); ++k) {
      saved->update(stream[k]);
      restored->update(stream[k]);
      ASSERT_TRUE(identical(output_of(*saved), reference[k])) << "sample " << k << ", saved at " << save_at_s << " s";
      ASSERT_TRUE(identical(output_of(*restored), reference[k]))
          << "sample " << k << ", saved at " << save_at_s << " s";
    }
  }
}

// reset() forgets everything: the same stream afterwards gives a fresh filter's output bit for bit.
TEST_P(FilterContract, ResetThenTheSameStreamGivesAFreshFiltersOutput) {
  const std::vector<ImuSample> stream = filter_test::stateful_stream();
  auto fresh = make();
  auto used = make();
  for (const ImuSample& s : stream) used->update(s);
  used->reset();
  EXPECT_FALSE(used->initialised());
  for (std::size_t k = 0; k < stream.size(); ++k) {
    fresh->update(stream[k]);
    used->update(stream[k]);
    ASSERT_TRUE(identical(output_of(*used), output_of(*fresh))) << "sample " << k;
  }
}

// Without magnetometer (6D) the inclination is still observable: a start 10 deg off in tilt converges on exact data.
// Most filters reach the numerical floor (Madgwick a limit cycle of one gradient step, 2 beta dt = 4e-4 rad) within
// 60 s; the slowest is the MEKF with Nez's fast set, whose sigma_a = 10 m/s^2 trusts the accelerometer little: it
// still removes 95 % of the error, hence 0.5 deg.
TEST_P(FilterContract, SixAxisStreamRecoversInclination) {
  auto f = make();
  const Quat q = from_yaw_pitch_roll({0.7, 0.3, 0.2});
  ImuSample first = static_sample(from_yaw_pitch_roll({0.7, 0.3, 0.2 + 10 * kDeg}), at_s(0));
  first.has_mag = false;
  f->update(first);
  for (std::uint64_t k = 1; k < 6000; ++k) {
    ImuSample s = static_sample(q, at_ns(k * 10 * kMs));
    s.has_mag = false;
    f->update(s);
  }
  EXPECT_LT(inclination_error(f->orientation(), q), 0.5 * kDeg);
}

// A magnetometer at a fifth of the IMU rate still brings the heading to a field turned by 40 deg; samples without it
// are 6D updates. A 6D-only filter ignores the magnetometer altogether: with exact still readings its heading stays
// where it started, to rounding. The 9D filters converge to the turned heading within 2.5 deg in 180 s, three time
// constants of the slowest: mekf's fast set (Nez Table 3, sigma_m 45 uT), with the bias learned at rest
// (rest_bias_update), turns the heading with a time constant of about 60 s (1.4 deg left; within 60 s while the
// vertical bias stayed unlearned, whose variance made the filter expect the heading to drift). The complementary
// filter applies its heading gain per magnetometer sample, so its time constant is 5 tau_mag = 20 s; Seel-Ruppin's
// integral term (zeta) and the EKF's bias state take part of the step into the bias estimate and overshoot by 1.5
// deg, decaying over minutes.
TEST_P(FilterContract, SlowMagnetometerStillCorrectsTheHeadingAnd6DIgnoresIt) {
  auto f = make();
  const Quat q = from_yaw_pitch_roll({10 * kDeg, 0, 0});
  f->update(static_sample(q, at_s(0)));
  const Vec3 turned = Eigen::AngleAxisd(40 * kDeg, Vec3::UnitZ()) * kField;
  for (int i = 1; i <= 18000; ++i) {
    ImuSample s = static_sample(q, at_s(i * 0.01), turned);
    s.has_mag = i % 5 == 0;
    ASSERT_EQ(f->update(s), UpdateResult::kUpdated);
  }
  const double yaw = to_yaw_pitch_roll(f->orientation()).yaw;
  if (six_d_only()) {
    EXPECT_NEAR(yaw, 10 * kDeg, 1e-9);
  } else {
    EXPECT_NEAR(yaw, -30 * kDeg, 2.5 * kDeg);
  }
}

TEST_P(FilterContract, RestingAndInitialisingFlags) {
  auto f = make();
  f->update(static_sample(Quat::Identity(), at_s(0)));
  EXPECT_TRUE(f->flags().initialising);
  for (int i = 1; i <= 400; ++i) f->update(static_sample(Quat::Identity(), at_s(i * 0.01)));
  EXPECT_FALSE(f->flags().initialising);
  EXPECT_TRUE(f->flags().resting);
  f->update(static_sample(Quat::Identity(), at_s(4.01), kField, Vec3(0.5, 0, 0)));
  EXPECT_FALSE(f->flags().resting);
}

// A sensor turning smoothly with exact readings is followed to the filters' integration error. A filter that turns by
// each sample's rate over the step before it (first order) sums the rate's change over every step times dt / 2, so it
// lags by at most dt / 2 * |w(t) - w(0)| <= dt * max |w|; the Kalman filters take the mean rate of the step (second
// order) and stay far inside that bound. The corrections towards the exact acc and mag keep it from growing further.
TEST_P(FilterContract, FollowsARotationOnExactData) {
  const auto stream = turning_sensor(8, 60.0, true);
  constexpr double kDt = 0.01;
  double max_rate = 0.0;
  for (const auto& s : stream) max_rate = std::max(max_rate, s.sample.gyr.norm());
  ASSERT_GT(max_rate, 0.5);  // a real rotation
  auto f = make();
  double worst = 0.0;
  for (std::size_t k = 0; k < stream.size(); ++k) {
    f->update(stream[k].sample);
    worst = std::max(worst, angle_between(f->orientation(), stream[k].truth));
  }
  EXPECT_LT(worst, kDt * max_rate);
}

// With consumer-MEMS white noise (TurningNoise) the error is the exact-data lag of FollowsARotationOnExactData (at most
// dt * max |w|) plus what the noise adds, which is small: per sample the accelerometer shows the tilt to 0.02 / 9.81
// rad = 0.12 deg and the magnetometer the heading to 0.3 / 21.5 rad = 0.8 deg, every filter averages over hundreds of
// samples (under 0.1 deg), and the gyro noise walks by 0.005 rad/s * 0.01 s * sqrt(100) = 0.03 deg per second. After
// the start-up (20 s) the worst error stays below the lag bound + 0.3 deg, with the magnetometer at the IMU rate and at
// a quarter of it (samples without it in between).
TEST_P(FilterContract, TracksANoisyRotationWithFullAndQuarterRateMagnetometer) {
  const auto stream = turning_sensor(8, 60.0, false);
  constexpr double kDt = 0.01;
  double max_rate = 0.0;
  for (const auto& s : stream) max_rate = std::max(max_rate, s.sample.gyr.norm());
  for (int mag_every : {1, 4}) {
    auto f = make();
    double worst = 0.0;
    for (std::size_t k = 0; k < stream.size(); ++k) {
      ImuSample s = stream[k].sample;
      s.has_mag = k % static_cast<std::size_t>(mag_every) == 0;
      f->update(s);
      if (k > 2000) worst = std::max(worst, angle_between(f->orientation(), stream[k].truth));
    }
    EXPECT_LT(worst, kDt * max_rate + 0.3 * kDeg) << "magnetometer every " << mag_every << " samples";
  }
}

// A sensor that changes its rate (a firmware setting, a USB hiccup) must not leave a filter wrong:
// nothing physical changes when a still sensor goes 100 Hz -> 10 kHz for 5 s -> 100 Hz, so every coefficient that
// depends on dt (gains, low-pass designs) must follow it. The sensor is still, tilted, with white noise of
// TurningNoise per sample and no gyro bias (6D filters would drift in heading with one, whatever the rate); the
// reference error is the worst over the last 5 s before the step. After the step back the error may exceed it only by
// what the noise can add in 10 s: the same 0.3 deg the noisy-tracking contract allows (a 10 kHz stretch gives each
// filter 100 times as many noisy corrections).
TEST_P(FilterContract, RateStepLeavesTheOrientationRight) {
  const Quat q = from_yaw_pitch_roll({40 * kDeg, 15 * kDeg, -25 * kDeg});
  filter_test::WhiteNoise noise(21, filter_test::TurningNoise::kAccMS2, filter_test::TurningNoise::kGyrRadS,
                                filter_test::TurningNoise::kMagUT);
  const Vec3 bias = Vec3::Zero();
  auto f = make();
  std::uint64_t t_ns = 0;
  double worst_before = 0.0, worst_at_fast = 0.0, worst_after = 0.0;
  auto run = [&](double seconds, std::uint64_t period_ns, double* worst, double score_from_s) {
    const std::uint64_t end_ns = t_ns + seconds_to_ns(seconds);
    const std::uint64_t score_ns = t_ns + seconds_to_ns(score_from_s);
    while (t_ns < end_ns) {
      t_ns += period_ns;
      f->update(noise.add_to(static_sample(q, at_ns(t_ns), kField, bias)));
      if (t_ns >= score_ns) *worst = std::max(*worst, angle_between(f->orientation(), q));
    }
  };
  f->update(noise.add_to(static_sample(q, at_ns(0), kField, bias)));
  run(30.0, 10 * kMs, &worst_before, 25.0);
  run(5.0, 100'000, &worst_at_fast, 0.0);
  run(10.0, 10 * kMs, &worst_after, 0.0);
  EXPECT_LT(worst_before, 1.0 * kDeg);  // the filter settled before the step
  EXPECT_LT(worst_at_fast, worst_before + 0.3 * kDeg);
  EXPECT_LT(worst_after, worst_before + 0.3 * kDeg);
}

INSTANTIATE_TEST_SUITE_P(AllFilters, FilterContract,
                         ::testing::ValuesIn(filter_registry().begin(), filter_registry().end()),
                         [](const ::testing::TestParamInfo<FilterInfo>& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace bsn::fusion
