// Properties every Kalman orientation filter (EKF, MEKF, DLKF) must have, written once as typed tests over the three:
// initialisation and static accuracy at any heading, a slower magnetometer and 6D samples, covariances that stay
// symmetric positive definite, bad input never touching the state, the factory entry, and (for the filters whose
// tilt ignores the magnetometer) Fan test B. Each filter's own properties (NEES, closed forms, TRIAD, adaptive
// switching) are in test_ekf.cpp, test_mekf.cpp and test_dlkf.cpp. A Traits struct below says how to make each
// filter and holds the few checks in which the filters differ.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "bsn/fusion/dlkf_filter.hpp"
#include "bsn/fusion/ekf_filter.hpp"
#include "bsn/fusion/mekf_filter.hpp"
#include "kalman_test_util.hpp"

namespace bsn::fusion {
namespace {

using namespace bsn::fusion::filter_test;

using Parameters = std::vector<std::pair<std::string, double>>;

/// What the EKF and MEKF share: a state of orientation q, gyro bias and one covariance P.
template <class F>
struct OneCovarianceTraits {
  using Filter = F;
  /// Largest allowed |P - P^T| entry.
  static constexpr double kAsymmetry = 1e-15;
  template <class Check>
  static void for_each_covariance(const Filter& f, Check&& check) {
    check(f.covariance());
  }
  static void expect_same_state(const typename Filter::State& a, const typename Filter::State& b) {
    EXPECT_EQ(a.q.coeffs(), b.q.coeffs());
    EXPECT_EQ(a.p, b.p);
    EXPECT_EQ(a.bias, b.bias);
  }
};

struct EkfTraits : OneCovarianceTraits<EkfFilter> {
  static constexpr std::string_view kFactoryName = "ekf";
  static Filter make() { return Filter{}; }
  static Filter make_with_all_features() { return Filter{}; }
  /// How closely a static sensor's orientation is held after 5 s of exact samples, rad: 1e-8 for the EKF's additive
  /// quaternion state, 1e-9 for the others.
  static constexpr double kStaticHoldRad = 1e-8;
  /// Gyro bias of the static-accuracy test: the magnetometer makes every axis observable.
  static Vec3 static_bias(const Quat& /*q*/) { return Vec3(0.01, -0.008, 0.005); }
  /// Bias random walk of the slower-magnetometer test, rad/s/sqrt(s).
  static constexpr double kBiasWalkDensity = 1e-5;
  /// A parameter override (the last one) that params() must read back, and out-of-range values.
  static inline const Parameters kConfigured = {{"sigma_a", 0.5}};
  static double read_back(const Filter& f) { return f.params().sigma_a; }
  static inline const Parameters kOutOfRange = {{"sigma_g", 0}, {"mag_rejection", 0.5}};
};

struct MekfTraits : OneCovarianceTraits<MekfFilter> {
  static constexpr std::string_view kFactoryName = "mekf";
  static Filter make() { return Filter{}; }
  /// The adaptive variant: its noise-set switches must keep P positive definite too.
  static Filter make_with_all_features() { return Filter(Filter::Params{}, true); }
  static Filter make_without_mag_rejection() {
    Filter::Params p;
    p.mag_rejection = 0.0;
    return Filter(p, false);
  }
  static constexpr double kStaticHoldRad = 1e-9;
  /// Horizontal in the earth frame: the MEKF's magnetometer update only turns the yaw, so the bias is learnt by the
  /// accelerometer update, which sees only its horizontal part.
  static Vec3 static_bias(const Quat& q) { return q.conjugate() * Vec3(0.01, -0.008, 0.0); }
  static constexpr double kBiasWalkDensity = 1e-5;
  static inline const Parameters kConfigured = {{"preset", 1}, {"sigma_a", 0.5}};
  static double read_back(const Filter& f) { return f.noise().sigma_a; }
  static inline const Parameters kOutOfRange = {{"preset", 4}, {"preset", 1.5}, {"sigma_g", -1}};
};

/// The adaptive MEKF, for Fan test B only.
struct MekfAdaptiveTraits {
  static MekfFilter make_without_mag_rejection() {
    MekfFilter::Params p;
    p.mag_rejection = 0.0;
    return MekfFilter(p, true);
  }
};

struct DlkfTraits {
  using Filter = DlkfFilter;
  static constexpr std::string_view kFactoryName = "dlkf";
  static Filter make() { return Filter{}; }
  static Filter make_with_all_features() { return Filter{}; }
  static Filter make_without_mag_rejection() {
    Filter::Params p;
    p.mag_rejection = 0.0;
    return Filter(p);
  }
  static constexpr double kStaticHoldRad = 1e-9;
  /// The low-pass bias (Fan eqs. 11-12) learns any bias after t_b = 2 s of rest.
  static Vec3 static_bias(const Quat& /*q*/) { return Vec3(0.01, -0.008, 0.005); }
  /// None: the DLKF estimates the bias only at rest, so a walking bias in motion is not what it models.
  static constexpr double kBiasWalkDensity = 0.0;
  /// Exactly symmetric by construction: the filter clamps only the variances and never symmetrises.
  static constexpr double kAsymmetry = 0.0;
  template <class Check>
  static void for_each_covariance(const Filter& f, Check&& check) {
    check(f.gravity_covariance());
    check(f.magnetic_covariance());
  }
  static void expect_same_state(const Filter::State& a, const Filter::State& b) {
    EXPECT_EQ(a.q.coeffs(), b.q.coeffs());
    EXPECT_EQ(a.gravity.x, b.gravity.x);
    EXPECT_EQ(a.gravity.p, b.gravity.p);
    EXPECT_EQ(a.magnetic.x, b.magnetic.x);
    EXPECT_EQ(a.magnetic.p, b.magnetic.p);
  }
  static inline const Parameters kConfigured = {{"sigma_ext_acc", 2.0}};
  static double read_back(const Filter& f) { return f.params().sigma_ext_acc; }
  static inline const Parameters kOutOfRange = {{"tau_ext_acc_s", 0}, {"gyro_bias_lowpass", 2}};
};

template <class Traits>
class KalmanFilter : public ::testing::Test {};
using KalmanFilters = ::testing::Types<EkfTraits, MekfTraits, DlkfTraits>;
TYPED_TEST_SUITE(KalmanFilter, KalmanFilters);

TYPED_TEST(KalmanFilter, InitialisesFromTheFirstSampleForAnyHeadingAndStaysOnAStaticSensor) {
  for (double yaw : {-179.0, -120.0, -45.0, 0.0, 60.0, 135.0, 180.0}) {
    auto f = TypeParam::make();
    const Quat q = from_yaw_pitch_roll({yaw * kDeg, -25 * kDeg, 40 * kDeg});
    ASSERT_EQ(f.update(static_sample(q, at_ns(0))), UpdateResult::kInitialised);
    EXPECT_LT(angle_between(f.orientation(), q), 1e-9) << yaw;
    EXPECT_TRUE(f.flags().reinitialised);
    EXPECT_TRUE(f.flags().initialising);
    for (std::uint64_t k = 1; k <= 500; ++k)
      ASSERT_EQ(f.update(static_sample(q, at_ns(k * 10 * kMs))), UpdateResult::kUpdated);
    EXPECT_LT(angle_between(f.orientation(), q), TypeParam::kStaticHoldRad) << yaw;
    EXPECT_TRUE(f.flags().resting);
    EXPECT_FALSE(f.flags().initialising);
    EXPECT_FALSE(f.flags().mag_rejected);
  }
}

// Static accuracy with sensor noise and a gyro bias at every heading: the error stays well inside the accuracy a
// static sensor of this noise allows (tilt noise ~ sigma_acc/g = 0.1 deg per sample, averaged by the filter), and
// the bias is learnt to 1e-3 rad/s.
TYPED_TEST(KalmanFilter, StaticAccuracyAnyHeadingWithNoiseAndBias) {
  for (double yaw : {-150.0, -30.0, 90.0, 170.0}) {
    auto f = TypeParam::make();
    const Quat q = from_yaw_pitch_roll({yaw * kDeg, 5 * kDeg, -10 * kDeg});
    const Vec3 bias = TypeParam::static_bias(q);
    std::mt19937_64 rng(42);
    std::normal_distribution<double> g(0.0, 1.0);
    auto n3 = [&] { return Vec3(g(rng), g(rng), g(rng)); };
    double sq = 0;
    int count = 0;
    for (std::uint64_t k = 0; k <= 6000; ++k) {
      ImuSample s = static_sample(q, at_ns(k * 10 * kMs));
      s.acc += 0.02 * n3();
      s.mag += 0.2 * n3();
      s.gyr = bias + 0.003 * n3();
      f.update(s);
      if (k > 4000) {
        sq += std::pow(angle_between(f.orientation(), q), 2);
        ++count;
      }
    }
    EXPECT_LT(std::sqrt(sq / count), 0.5 * kDeg) << yaw;
    EXPECT_LT((f.gyro_bias() - bias).norm(), 1e-3) << yaw;
  }
}

TYPED_TEST(KalmanFilter, SlowerMagnetometerAndSixDSamples) {
  auto f = TypeParam::make();
  RotatingSensor sensor(11, 0.01, {1e-3, TypeParam::kBiasWalkDensity, 0.05, 0.3}, from_yaw_pitch_roll({2.0, 0.1, 0.3}),
                        Vec3::Zero());
  f.update(sensor.first());
  double worst = 0;
  for (int k = 1; k <= 6000; ++k) {
    ImuSample s = sensor.next();
    s.has_mag = (k % 4 == 0) && k < 3000;  // 25 Hz magnetometer, then none for 30 s
    ASSERT_EQ(f.update(s), UpdateResult::kUpdated);
    if (k > 1000) worst = std::max(worst, angle_between(f.orientation(), sensor.q()));
  }
  EXPECT_LT(worst, 2.0 * kDeg);
}

// Through fast motion (6 rad/s scale, 200 Hz), magnetometer updates and (MEKF) noise-set switches.
TYPED_TEST(KalmanFilter, CovarianceStaysSymmetricPositiveDefinite) {
  auto f = TypeParam::make_with_all_features();
  RotatingSensor sensor(3, 0.005, {0.01, 1e-3, 0.5, 1.0}, Quat::Identity(), Vec3(0.01, 0, 0), 6.0);
  f.update(sensor.first());
  for (int k = 0; k < 8000; ++k) {
    f.update(sensor.next());
    TypeParam::for_each_covariance(f, [k](const auto& p) {
      ASSERT_LE((p - p.transpose()).cwiseAbs().maxCoeff(), TypeParam::kAsymmetry) << k;
      ASSERT_EQ(p.llt().info(), Eigen::Success) << k;
    });
    if (this->HasFatalFailure()) return;
  }
}

TYPED_TEST(KalmanFilter, BadInputNeverTouchesTheState) {
  auto f = TypeParam::make();
  const Quat q = from_yaw_pitch_roll({1.0, 0.2, -0.3});
  f.update(static_sample(q, at_ns(0)));
  f.update(static_sample(q, at_ns(10 * kMs)));
  const auto before = f.state();
  ImuSample bad = static_sample(q, at_ns(20 * kMs));
  bad.gyr.x() = std::nan("");
  EXPECT_EQ(f.update(bad), UpdateResult::kRejected);
  bad = static_sample(q, at_ns(20 * kMs));
  bad.acc.y() = std::nan("");
  EXPECT_EQ(f.update(bad), UpdateResult::kRejected);
  bad = static_sample(q, at_ns(20 * kMs));
  bad.mag.z() = INFINITY;
  EXPECT_EQ(f.update(bad), UpdateResult::kRejected);
  EXPECT_EQ(f.update(static_sample(q, at_ns(10 * kMs))), UpdateResult::kRejected);  // zero dt
  EXPECT_EQ(f.update(static_sample(q, at_ns(5 * kMs))), UpdateResult::kRejected);   // backwards
  TypeParam::expect_same_state(before, f.state());
  // A gap longer than max_gap_s re-initialises and says so.
  EXPECT_EQ(f.update(static_sample(q, at_ns(10 * kMs + 5'000 * kMs))), UpdateResult::kInitialised);
  EXPECT_TRUE(f.flags().reinitialised);
  // Saturated values and a huge step within the gap limit never give a non-finite state.
  ImuSample wild = static_sample(q, at_ns(10 * kMs + 5'900 * kMs));
  wild.gyr = Vec3(1e6, -1e6, 1e6);
  wild.acc = Vec3(1e9, 0, -1e9);
  wild.mag = Vec3(1e9, 1e9, 0);
  f.update(wild);
  EXPECT_TRUE(f.orientation().coeffs().allFinite());
  TypeParam::for_each_covariance(f, [](const auto& p) { EXPECT_TRUE(p.allFinite()); });
  EXPECT_TRUE(f.gyro_bias().allFinite());
}

TYPED_TEST(KalmanFilter, FactoryMakesItAndChecksParameters) {
  const std::string name(TypeParam::kFactoryName);
  const auto f = make_filter({name, TypeParam::kConfigured});
  EXPECT_EQ(f->name(), name);
  const auto* typed = dynamic_cast<const typename TypeParam::Filter*>(f.get());
  ASSERT_NE(typed, nullptr);
  EXPECT_EQ(TypeParam::read_back(*typed), TypeParam::kConfigured.back().second);
  for (const auto& parameter : TypeParam::kOutOfRange)
    EXPECT_THROW(make_filter({name, {parameter}}), std::invalid_argument) << parameter.first << " " << parameter.second;
  EXPECT_THROW(make_filter({name, {{"no_such", 1}}}), std::invalid_argument);
}

// Fan test B with all magnetic adaption off, for the filters whose roll and pitch never depend on the magnetometer
// (MEKF: Suh's projection lets it turn only the yaw; DLKF: TRIAD takes the tilt from the gravity filter alone). Roll
// and pitch stay within 0.1 deg while the yaw is pulled by more than a degree (the disturbance is felt). The EKF,
// whose joint update tilts with the magnet, has the opposite test in test_ekf.cpp.
template <class Traits>
class KalmanTiltIgnoresMagnetometer : public ::testing::Test {};
using TiltDecoupledFilters = ::testing::Types<MekfTraits, MekfAdaptiveTraits, DlkfTraits>;
TYPED_TEST_SUITE(KalmanTiltIgnoresMagnetometer, TiltDecoupledFilters);

TYPED_TEST(KalmanTiltIgnoresMagnetometer, FanTestBMagnetDoesNotMoveRollAndPitch) {
  auto f = TypeParam::make_without_mag_rejection();
  const EulerDeviation dev = fan_test_b(f);
  EXPECT_LT(dev.tilt, 0.1 * kDeg);
  EXPECT_GT(dev.yaw, 1.0 * kDeg);
}

}  // namespace
}  // namespace bsn::fusion
