// Small synthetic-data generators shared by the Kalman filter tests (MEKF, EKF, DLKF). Seeded, self-contained:
// they do not use the simulator, so that the tests pin the filters, not the simulator.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>

#include "bsn/fusion/imu_sample.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/rotation.hpp"
#include "filter_test_util.hpp"

namespace bsn::fusion::filter_test {

/// Noise levels of the synthetic sensor, as the Kalman filters model them.
struct SensorNoise {
  double gyr_density = 0.0;      ///< white gyro noise, rad/s/sqrt(Hz): per-sample sd = density / sqrt(dt)
  double bias_walk_density = 0;  ///< bias random walk, rad/s/sqrt(s): per-step sd = density * sqrt(dt)
  double acc_sd = 0.0;           ///< per-sample accelerometer noise, m/s^2
  double mag_sd = 0.0;           ///< per-sample magnetometer noise, uT
};

/// A sensor turning smoothly about all three axes (sum of sines, ~1 rad/s), with a gyro bias random walk and white
/// noise on every channel. The truth is integrated with 5 midpoint substeps per sample, far finer than the filters' own
/// integration error at the rates used.
class RotatingSensor {
 public:
  RotatingSensor(std::uint64_t seed, double dt_s, const SensorNoise& noise, const Quat& q0, const Vec3& bias0,
                 double rate_scale = 1.0)
      : rng_(seed), dt_(dt_s), noise_(noise), q_(q0), bias_(bias0), scale_(rate_scale) {}

  Vec3 rate(double t) const {
    return scale_ * Vec3(0.9 * std::sin(0.7 * t + 0.3), 0.7 * std::sin(1.1 * t + 1.9), 1.0 * std::sin(0.45 * t + 4.0));
  }

  /// Advances the truth by one sample period and returns the sample measured at the new time.
  ImuSample next() {
    constexpr int kSub = 5;
    const double h = dt_ / kSub;
    for (int i = 0; i < kSub; ++i) q_ = (q_ * exp_rotation_vector(rate(t_ + (i + 0.5) * h) * h)).normalized();
    t_ += dt_;
    ++k_;
    for (int i = 0; i < 3; ++i) bias_[i] += noise_.bias_walk_density * std::sqrt(dt_) * gauss();
    ImuSample s;
    s.timestamp_ns = k_ * seconds_to_ns(dt_);
    s.gyr = rate(t_) + bias_ + noise_.gyr_density / std::sqrt(dt_) * gauss3();
    s.acc = q_.conjugate() * Vec3(0, 0, kGravity) + noise_.acc_sd * gauss3();
    s.mag = q_.conjugate() * kField + noise_.mag_sd * gauss3();
    return s;
  }

  /// Sample at t = 0 (first call only), with the same noise; noisy = false gives it exact (for filters that take a
  /// reference from the first sample and assume it exact).
  ImuSample first(bool noisy = true) {
    const double k = noisy ? 1.0 : 0.0;
    ImuSample s;
    s.timestamp_ns = 0;
    s.gyr = rate(0.0) + bias_ + k * noise_.gyr_density / std::sqrt(dt_) * gauss3();
    s.acc = q_.conjugate() * Vec3(0, 0, kGravity) + k * noise_.acc_sd * gauss3();
    s.mag = q_.conjugate() * kField + k * noise_.mag_sd * gauss3();
    return s;
  }

  const Quat& q() const { return q_; }
  const Vec3& bias() const { return bias_; }

 private:
  double gauss() { return normal_(rng_); }
  Vec3 gauss3() { return Vec3(gauss(), gauss(), gauss()); }

  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  double dt_;
  SensorNoise noise_;
  Quat q_;
  Vec3 bias_;
  double scale_;
  double t_ = 0.0;
  std::uint64_t k_ = 0;
};

/// Sensor-frame rotation vector e with q_true = q_est * exp(e).
inline Vec3 body_error(const Quat& q_est, const Quat& q_true) {
  Quat d = (q_est.conjugate() * q_true).normalized();
  if (d.w() < 0) d.coeffs() = -d.coeffs();
  const Eigen::AngleAxisd aa(d);
  return aa.angle() * aa.axis();
}

/// Two-sided 95 % interval of chi^2(dof) / scale, by the Wilson-Hilferty approximation (error < 0.1 % for
/// dof >= 50).
inline std::pair<double, double> chi2_interval_95(double dof, double scale) {
  constexpr double z = 1.959963985;
  auto quantile = [dof](double zz) {
    const double c = 2.0 / (9.0 * dof);
    const double v = 1.0 - c + zz * std::sqrt(c);
    return dof * v * v * v;
  };
  return {quantile(-z) / scale, quantile(z) / scale};
}

/// Fan test B: a magnet approaches a static sensor five times. Extra field (sensor frame, uT) at time t: five
/// 3-s smooth bumps, 5 s apart starting at t = 3 s, of a 40 uT field mostly along the sensor's -x and z axes, so that
/// magnitude and dip both change by tens of percent / degrees.
inline Vec3 magnet_field(double t) {
  double bump = 0.0;
  for (int i = 0; i < 5; ++i) {
    const double t0 = 3.0 + 5.0 * i;
    if (t > t0 && t < t0 + 3.0) bump = std::pow(std::sin(std::numbers::pi * (t - t0) / 3.0), 2);
  }
  return bump * Vec3(-30.0, 12.0, 24.0);
}

/// Largest deviations of a filter's Euler angles from the truth over a run, rad.
struct EulerDeviation {
  double tilt = 0.0;  ///< max over time of |pitch error| and |roll error|
  double yaw = 0.0;   ///< max over time of |yaw error|
};

/// Runs Fan test B on a fresh filter: the sensor sits still for 30 s at 100 Hz at yaw 70, pitch 12, roll -20 deg
/// while the magnet of magnet_field() approaches five times. Returns how far the estimate strayed.
inline EulerDeviation fan_test_b(OrientationFilter& f) {
  const YawPitchRoll truth{70 * kDeg, 12 * kDeg, -20 * kDeg};
  const Quat q = from_yaw_pitch_roll(truth);
  EulerDeviation dev;
  for (std::uint64_t k = 0; k <= 3000; ++k) {
    ImuSample s = static_sample(q, at_ns(k * 10 * kMs));
    s.mag += magnet_field(0.01 * static_cast<double>(k));
    f.update(s);
    const YawPitchRoll est = to_yaw_pitch_roll(f.orientation());
    dev.tilt = std::max({dev.tilt, std::abs(est.pitch - truth.pitch), std::abs(est.roll - truth.roll)});
    dev.yaw = std::max(dev.yaw, std::abs(est.yaw - truth.yaw));
  }
  return dev;
}

}  // namespace bsn::fusion::filter_test
