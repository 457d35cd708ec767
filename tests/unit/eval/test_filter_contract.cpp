// The contract every registered filter keeps, whatever its method: run over every name of the factory.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>

#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/sim/mimu_synthesizer.hpp"
#include "bsn/sim/motion_model.hpp"

namespace bsn::fusion {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr std::uint64_t kMs = 1'000'000;
const Vec3 kField = sim::EarthField{}.vector_enu();

class FilterContract : public ::testing::TestWithParam<std::string> {
 protected:
  std::unique_ptr<OrientationFilter> make() const { return make_filter({GetParam(), {}}); }
};

ImuSample static_sample(const Quat& q, std::uint64_t t_ns) {
  ImuSample s;
  s.timestamp_ns = t_ns;
  s.acc = q.conjugate() * Vec3(0, 0, kGravity);
  s.mag = q.conjugate() * kField;
  return s;
}

bool unit_and_finite(const Quat& q) { return q.coeffs().allFinite() && std::abs(q.norm() - 1.0) < 1e-6; }

TEST_P(FilterContract, HostileInputNeverThrowsNorProducesNonFiniteOutput) {
  auto f = make();
  std::mt19937_64 rng(99);
  std::uniform_int_distribution<int> kind(0, 11);
  std::normal_distribution<double> n(0.0, 1.0);
  const double inf = std::numeric_limits<double>::infinity(), nan = std::nan("");
  std::uint64_t t = 1'000'000'000;
  for (int i = 0; i < 100000; ++i) {
    ImuSample s = static_sample(Quat(n(rng), n(rng), n(rng), n(rng)).normalized(), t);
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
    ASSERT_NO_THROW(f->update(s)) << GetParam() << " sample " << i << " kind " << k;
    ASSERT_TRUE(unit_and_finite(f->orientation()))
        << GetParam() << " sample " << i << " kind " << k << ": q = " << f->orientation().coeffs().transpose();
    ASSERT_TRUE(f->gyro_bias().allFinite()) << GetParam() << " sample " << i << " kind " << k;
  }
}

TEST_P(FilterContract, NonFiniteInputLeavesTheStateUntouched) {
  auto f = make();
  const Quat q = from_yaw_pitch_roll({0.5, 0.2, -0.1});
  for (std::uint64_t k = 0; k < 100; ++k) f->update(static_sample(q, k * 10 * kMs));
  const Quat before = f->orientation();
  const Vec3 bias = f->gyro_bias();
  ImuSample bad = static_sample(q, 100 * 10 * kMs);
  bad.gyr.z() = std::nan("");
  EXPECT_EQ(f->update(bad), UpdateResult::kRejected) << GetParam();
  EXPECT_EQ(f->orientation().coeffs(), before.coeffs()) << GetParam();
  EXPECT_EQ(f->gyro_bias(), bias) << GetParam();
}

TEST_P(FilterContract, SameStreamGivesBitIdenticalOutput) {
  const auto motion = sim::SinusoidalRotation::from_seed(3);
  std::vector<Quat> first;
  for (int run = 0; run < 2; ++run) {
    auto f = make();
    sim::MimuSynthesizer synth(sim::EarthField{}, sim::WhiteNoise{}, 5);
    for (std::uint64_t k = 0; k < 3000; ++k) {
      f->update(synth.measure(motion.at(static_cast<double>(k) * 0.01), k * 10 * kMs));
      if (run == 0) {
        first.push_back(f->orientation());
      } else {
        ASSERT_EQ(f->orientation().coeffs(), first[k].coeffs()) << GetParam() << " sample " << k;
      }
    }
  }
}

// Initialisation from the first accelerometer and magnetometer sample is right for any heading, and a static
// sensor with exact readings stays there.
TEST_P(FilterContract, StartsAtTheTrueOrientationForAnyHeading) {
  for (double yaw : {-179.0, -120.0, -45.0, 0.0, 60.0, 135.0, 180.0}) {
    auto f = make();
    const Quat q = from_yaw_pitch_roll({yaw * kDeg, 25 * kDeg, -40 * kDeg});
    for (std::uint64_t k = 0; k < 1000; ++k) f->update(static_sample(q, k * 10 * kMs));
    EXPECT_TRUE(f->initialised());
    EXPECT_LT(angle_between(f->orientation(), q), 1.0 * kDeg) << GetParam() << " yaw " << yaw;
  }
}

// Without magnetometer (6D) inclination is still observable: a start 10 deg off in tilt converges.
TEST_P(FilterContract, SixAxisStreamRecoversInclination) {
  auto f = make();
  const Quat q = from_yaw_pitch_roll({0.7, 0.3, 0.2});
  ImuSample first = static_sample(from_yaw_pitch_roll({0.7, 0.3, 0.2 + 10 * kDeg}), 0);
  first.has_mag = false;
  f->update(first);
  for (std::uint64_t k = 1; k < 6000; ++k) {
    ImuSample s = static_sample(q, k * 10 * kMs);
    s.has_mag = false;
    f->update(s);
  }
  const Vec3 up_est = f->orientation().conjugate() * Vec3::UnitZ();
  const Vec3 up_true = q.conjugate() * Vec3::UnitZ();
  EXPECT_LT(std::acos(std::clamp(up_est.dot(up_true), -1.0, 1.0)), 0.5 * kDeg) << GetParam();
}

// A magnetometer at a quarter of the IMU rate (samples without it in between) still tracks a noisy motion.
TEST_P(FilterContract, SlowerMagnetometerStillTracks) {
  const auto motion = sim::SinusoidalRotation::from_seed(8);
  sim::MimuSynthesizer synth(sim::EarthField{}, sim::WhiteNoise{}, 9);
  auto f = make();
  double worst = 0.0;
  for (std::uint64_t k = 0; k < 6000; ++k) {
    const auto m = motion.at(static_cast<double>(k) * 0.01);
    ImuSample s = synth.measure(m, k * 10 * kMs);
    s.has_mag = k % 4 == 0;
    f->update(s);
    if (k > 2000) worst = std::max(worst, angle_between(f->orientation(), m.q_sensor_to_earth));
  }
  // Every filter of the project must stay within the accuracy bsn promises live (2 deg) on clean data.
  EXPECT_LT(worst, 2.0 * kDeg) << GetParam();
}

INSTANTIATE_TEST_SUITE_P(AllFilters, FilterContract, ::testing::ValuesIn(filter_names()),
                         [](const ::testing::TestParamInfo<std::string>& info) { return info.param; });

}  // namespace
}  // namespace bsn::fusion
