// Test helpers for calib_core: the sensor model of Zhang & Yang 2015 (Table I) and a consumer-grade gyro.
#pragma once

#include <Eigen/Geometry>
#include <random>
#include <vector>

#include "bsn/calib/field_calibration.hpp"
#include "bsn/calib/pose_segmentation.hpp"

namespace bsn::calib::testing {

using Quat = Eigen::Quaterniond;

/// H = R T S A_si and B = b + b_hi of Table I (raw unit: LSB; calibrated unit: mG).
struct PaperSensor {
  Mat3 transform;
  Vec3 bias;
};

inline PaperSensor paper_sensor() {
  const double alpha = 0.1, beta = 0.1, gamma = 0.1, phi = 0.1, theta = 0.1, psi = 0.1;
  Mat3 t;
  t << 1, 0, 0, alpha, 1, 0, beta, gamma, 1;  // eq. 1
  const Mat3 s = Vec3(1 / 1.2, 1 / 1.383, 1 / 1.12).asDiagonal();
  Mat3 a_si;
  a_si << 1, 0.1, 0.1, 0.1, 1, 0.1, 0.1, 0.1, 1;
  const Mat3 r = (Eigen::AngleAxisd(psi, Vec3::UnitZ()) * Eigen::AngleAxisd(theta, Vec3::UnitY()) *
                  Eigen::AngleAxisd(phi, Vec3::UnitX()))
                     .toRotationMatrix();  // eq. 4
  return {r * t * s * a_si, Vec3(32000 + 268, 32000 - 123, 32000 - 109)};
}

/// A uniformly distributed random orientation (sensor-to-earth).
inline Quat random_orientation(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Quat q(n(rng), n(rng), n(rng), n(rng));
  return q.normalized();
}

/// Earth field in ENU with magnitude m and inclination (dip) `dip_rad` downwards.
inline Vec3 earth_field(double m, double dip_rad) { return m * Vec3(0.0, std::cos(dip_rad), -std::sin(dip_rad)); }

/// Raw reading g = H^-1 u + B + noise for the sensor at orientation q in field m_earth.
inline Vec3 raw_reading(const PaperSensor& s, const Quat& q, const Vec3& m_earth, double noise_sd,
                        std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, noise_sd);
  const Vec3 u = q.conjugate() * m_earth;
  return s.transform.inverse() * u + s.bias + Vec3(n(rng), n(rng), n(rng));
}

/// A consumer-grade MEMS gyro (MPU-9250/BMI160 class after a rest-bias calibration): white noise density, a
/// residual bias per axis, scale-factor error per axis and small axis misalignment.
struct ConsumerGyro {
  double noise_density = 0.01 * M_PI / 180.0;     ///< rad/s/sqrt(Hz) (0.01 deg/s/sqrt(Hz))
  double residual_bias_sd = 0.02 * M_PI / 180.0;  ///< rad/s, per axis, left after removing the rest bias
  double scale_error_sd = 0.002;                  ///< per axis, relative (0.2 %, after factory trim)
  double misalignment_sd = 0.001;                 ///< rad, off-diagonal terms
  double rate_hz = 100.0;
};

/// Integrates the gyro of `gyro` over a smooth turn from q_a to q_b lasting `duration_s`: the estimated
/// orientation of the end in the start frame (compare with q_a^-1 q_b). `error_matrix` = (I + scale +
/// misalignment) and `bias` are drawn once per run by the caller.
inline Quat integrate_turn(const Quat& q_a, const Quat& q_b, double duration_s, const ConsumerGyro& gyro,
                           const Mat3& error_matrix, const Vec3& bias, std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, gyro.noise_density * std::sqrt(gyro.rate_hz));
  const int steps = static_cast<int>(duration_s * gyro.rate_hz);
  const double dt = 1.0 / gyro.rate_hz;
  const Quat rel = q_a.conjugate() * q_b;
  const Eigen::AngleAxisd turn(rel);
  Quat truth_prev = Quat::Identity();
  Quat estimate = Quat::Identity();
  for (int k = 1; k <= steps; ++k) {
    const double tau = static_cast<double>(k) / steps;
    const double progress = tau * tau * tau * (10 - 15 * tau + 6 * tau * tau);  // minimum-jerk profile
    const Quat truth(Eigen::AngleAxisd(turn.angle() * progress, turn.axis()));
    const Eigen::AngleAxisd step(truth_prev.conjugate() * truth);  // body-frame rotation over this step
    const Vec3 rate = step.axis() * step.angle() / dt;
    const Vec3 measured = error_matrix * rate + bias + Vec3(n(rng), n(rng), n(rng));
    const double angle = measured.norm() * dt;
    if (angle > 0.0) estimate = estimate * Quat(Eigen::AngleAxisd(angle, measured.normalized()));
    estimate.normalize();
    truth_prev = truth;
  }
  return estimate;
}

/// A hand-turned calibration recording: rest `rest_s` at each orientation, smooth turns of `turn_s` between
/// them; gyro with `error_matrix`, constant `gyro_bias` and white noise; the paper's magnetometer.
struct HandRecording {
  Points3 rates{3, 0};
  Points3 mag{3, 0};
};

inline HandRecording hand_turned_recording(const std::vector<Quat>& orientations, double rest_s, double turn_s,
                                           const ConsumerGyro& gyro, const Mat3& error_matrix, const Vec3& gyro_bias,
                                           const PaperSensor& sensor, const Vec3& m_earth, double mag_noise_sd,
                                           std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, gyro.noise_density * std::sqrt(gyro.rate_hz));
  const double dt = 1.0 / gyro.rate_hz;
  std::vector<Vec3> rates, mags;
  auto emit = [&](const Quat& q, const Vec3& true_rate) {
    rates.push_back(error_matrix * true_rate + gyro_bias + Vec3(n(rng), n(rng), n(rng)));
    mags.push_back(raw_reading(sensor, q, m_earth, mag_noise_sd, rng));
  };
  const int rest_steps = static_cast<int>(rest_s * gyro.rate_hz);
  const int turn_steps = static_cast<int>(turn_s * gyro.rate_hz);
  for (std::size_t j = 0; j < orientations.size(); ++j) {
    for (int k = 0; k < rest_steps; ++k) emit(orientations[j], Vec3::Zero());
    if (j + 1 == orientations.size()) break;
    const Eigen::AngleAxisd turn(orientations[j].conjugate() * orientations[j + 1]);
    Quat prev = orientations[j];
    for (int k = 1; k <= turn_steps; ++k) {
      const double tau = static_cast<double>(k) / turn_steps;
      const double progress = tau * tau * tau * (10 - 15 * tau + 6 * tau * tau);
      const Quat q = orientations[j] * Quat(Eigen::AngleAxisd(turn.angle() * progress, turn.axis()));
      const Eigen::AngleAxisd step(prev.conjugate() * q);
      emit(q, step.axis() * step.angle() / dt);
      prev = q;
    }
  }
  HandRecording r;
  r.rates.resize(3, static_cast<Eigen::Index>(rates.size()));
  r.mag.resize(3, static_cast<Eigen::Index>(mags.size()));
  for (std::size_t k = 0; k < rates.size(); ++k) {
    r.rates.col(static_cast<Eigen::Index>(k)) = rates[k];
    r.mag.col(static_cast<Eigen::Index>(k)) = mags[k];
  }
  return r;
}

}  // namespace bsn::calib::testing
