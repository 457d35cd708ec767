// Turns exact kinematics into MIMU samples: accelerometer = specific force, gyroscope = body rate,
// magnetometer = earth field, all in the sensor frame, with optional seeded white noise.
#pragma once

#include <cstdint>
#include <random>

#include "bsn/fusion/imu_sample.hpp"
#include "bsn/sim/motion_model.hpp"

namespace bsn::sim {

/// Homogeneous earth field in ENU from magnitude and dip (positive dip points the field down).
struct EarthField {
  double magnitude_ut = 49.0;  ///< uT
  double dip_deg = 64.0;       ///< inclination below the horizon, degrees
  Vec3 vector_enu() const;
};

/// White noise standard deviation per sample of each channel (0 = exact).
struct WhiteNoise {
  double gyr_rad_s = 0.005;  ///< rad/s
  double acc_m_s2 = 0.02;    ///< m/s^2
  double mag_ut = 0.3;       ///< uT
  static WhiteNoise none() { return {0.0, 0.0, 0.0}; }
};

class MimuSynthesizer {
 public:
  MimuSynthesizer(const EarthField& field, const WhiteNoise& noise, std::uint64_t seed);

  /// The sample a sensor with state `m` reads, stamped with `timestamp_ns`.
  fusion::ImuSample measure(const MotionState& m, std::uint64_t timestamp_ns);

 private:
  Vec3 noise(double sigma);

  Vec3 field_enu_;
  WhiteNoise noise_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
};

}  // namespace bsn::sim
