// Synthetic samples shared by the complementary-filter tests (Seel-Ruppin, Madgwick, IECF, the components): a
// still sensor with a given orientation, optionally with seeded white noise. Self-contained (no simulator), so
// the tests pin the filters, not the simulator.
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>

#include "bsn/fusion/imu_sample.hpp"
#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion::filter_test {

constexpr double kDeg = std::numbers::pi / 180.0;

/// ENU field of 49 uT with a dip of 64 deg (central Europe).
inline const Vec3 kField(0.0, 49.0 * std::cos(64.0 * kDeg), -49.0 * std::sin(64.0 * kDeg));

/// Seconds to nanoseconds, rounded.
inline std::uint64_t ns(double seconds) { return static_cast<std::uint64_t>(std::llround(seconds * 1e9)); }

/// Angle wrapped to [-pi, pi].
inline double wrap(double angle) { return std::remainder(angle, 2 * std::numbers::pi); }

/// Noise-free sample at t_s seconds of a sensor at rest with true orientation q (sensor-to-earth) in the earth field
/// `field` (ENU, uT); the gyro reads `gyr` (a bias, say).
inline ImuSample static_sample(const Quat& q, double t_s, const Vec3& field = kField, const Vec3& gyr = Vec3::Zero()) {
  ImuSample s;
  s.timestamp_ns = ns(t_s);
  s.acc = q.conjugate() * Vec3(0, 0, kGravity);
  s.gyr = gyr;
  s.mag = q.conjugate() * field;
  return s;
}

/// Seeded white noise of fixed standard deviations per channel, added to samples.
class WhiteNoise {
 public:
  WhiteNoise(std::uint32_t seed, double acc_sd_m_s2, double gyr_sd_rad_s, double mag_sd_uT)
      : rng_(seed), acc_(0.0, acc_sd_m_s2), gyr_(0.0, gyr_sd_rad_s), mag_(0.0, mag_sd_uT) {}

  /// Adds one draw to every channel of s (magnetometer, accelerometer, gyro, in that order) and returns it.
  ImuSample add_to(ImuSample s) {
    s.mag += draw(mag_);
    s.acc += draw(acc_);
    s.gyr += draw(gyr_);
    return s;
  }

 private:
  Vec3 draw(std::normal_distribution<double>& d) {
    const double x = d(rng_);  // named draws: the order of function arguments is unspecified
    const double y = d(rng_);
    const double z = d(rng_);
    return Vec3(x, y, z);
  }

  std::mt19937 rng_;
  std::normal_distribution<double> acc_, gyr_, mag_;
};

}  // namespace bsn::fusion::filter_test
