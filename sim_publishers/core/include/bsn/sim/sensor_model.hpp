// MIMU sensor error models: what a real sensor adds to the exact channels. Each channel follows the error
// model of Zhang & Yang 2015, eq. 8, read backwards (physical u -> reading g):
//   u = R T S A_si (g - b - b_hi)   =>   g = (R T S A_si)^-1 u + b + b_hi + drifting bias + white noise,
// then saturated at +-range and quantised to the LSB. R: mounting (misalignment), T: non-orthogonality,
// S: scale (physical unit per reading unit, 1 = exact), A_si: soft iron (magnetometer only, else I).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include "bsn/fusion/imu_sample.hpp"

namespace bsn::sim {

using fusion::Vec3;
using Mat3 = Eigen::Matrix3d;

/// A bias that appears at at_s and stays (e.g. the 2 deg/s gyro bias of Seel & Ruppin 2017, section 3.2).
struct BiasStep {
  double at_s = 0.0;
  Vec3 value = Vec3::Zero();
};

/// Errors of one three-axis channel, in the channel's unit (rad/s, m/s^2 or uT).
struct ChannelErrors {
  double white_density = 0.0;         ///< white noise density, unit/sqrt(Hz) (per-reading SD = density*sqrt(own rate))
  Vec3 bias = Vec3::Zero();           ///< constant bias b, unit
  double bias_random_walk = 0.0;      ///< bias random walk density, unit/sqrt(s): the bias moves by this*sqrt(dt)
  double bias_instability = 0.0;      ///< SD of the first-order Gauss-Markov bias, unit
  double bias_correlation_s = 100.0;  ///< correlation time of that bias, s
  Vec3 scale = Vec3::Ones();          ///< S diagonal: physical units per reading unit
  Vec3 nonorthogonality = Vec3::Zero();  ///< alpha, beta, gamma of T (lower triangular, unit diagonal)
  Vec3 mounting_rad = Vec3::Zero();      ///< phi, theta, psi of R = Rz(psi) Ry(theta) Rx(phi)
  Mat3 soft_iron = Mat3::Identity();     ///< A_si (magnetometer)
  Vec3 hard_iron = Vec3::Zero();         ///< b_hi (magnetometer), unit
  std::vector<BiasStep> bias_steps;
  double range = std::numeric_limits<double>::infinity();  ///< saturation at +-range, unit
  double lsb = 0.0;                                        ///< quantisation step, unit (0 = none)

  /// H = R T S A_si: reading -> physical.
  Mat3 physical_from_reading() const;
  /// Every error switched off?
  bool ideal() const;
};

struct SensorErrors {
  ChannelErrors gyr, acc, mag;
  double mag_rate_hz = 0.0;  ///< magnetometer sample rate, Hz (0 = every IMU sample)
  /// The magnetometer reads the field of this many IMU samples earlier: a part whose magnetometer is read out
  /// before the gyro is sampled, or a separate chip on a slower bus, lags the gyro (0 = in step).
  int mag_delay_samples = 0;
  /// Corner of the magnetometer's own first-order low-pass (its internal averaging), Hz; 0 = none. It acts on
  /// the physical field at the IMU rate, before the other errors, so a fast rotation shows in the reading late
  /// and slightly shrunk (ratio 1 / sqrt(1 + (f_rot / f_c)^2)).
  double mag_bandwidth_hz = 0.0;
  double jitter_s = 0.0;          ///< SD of the sampling instant around its nominal time, s
  double drop_probability = 0.0;  ///< chance that a sample is lost, 0..1

  static SensorErrors ideal() { return {}; }
};

/// Preset names: ideal, consumer_mems, opal, zhang_yang_table1.
std::optional<SensorErrors> sensor_preset(std::string_view name);
std::vector<std::string> sensor_preset_names();

/// One sensor's error state (drifting biases, random streams). Deterministic for a given seed.
class SensorSimulator {
 public:
  /// Throws std::invalid_argument on a non-positive rate or a negative or non-finite error parameter.
  SensorSimulator(const SensorErrors& errors, double rate_hz, std::uint64_t seed);

  /// The reading of exact sensor-frame values at time t_s (advances the biases by one sample period).
  /// `has_mag` = false on the samples where a slower magnetometer has no new reading.
  fusion::ImuSample measure(const Vec3& gyr, const Vec3& specific_force, const Vec3& mag, double t_s,
                            std::uint64_t timestamp_ns, bool has_mag);

  const SensorErrors& errors() const { return errors_; }

 private:
  struct ChannelState {
    Mat3 reading_from_physical = Mat3::Identity();
    double white_sd = 0.0;
    Vec3 random_walk = Vec3::Zero();
    Vec3 markov = Vec3::Zero();
    double markov_decay = 0.0, markov_drive = 0.0, walk_drive = 0.0;
  };
  Vec3 apply(const ChannelErrors& e, ChannelState& s, const Vec3& physical, double t_s);
  Vec3 normal3();

  SensorErrors errors_;
  ChannelState gyr_, acc_, mag_;
  double mag_lowpass_alpha_ = 1.0;  ///< 1 - exp(-2 pi f_c dt): the first-order step at the IMU rate (1 = none)
  Vec3 mag_lowpassed_ = Vec3::Zero();
  bool mag_lowpass_started_ = false;
  std::vector<Vec3> mag_delay_line_;  ///< the last mag_delay_samples fields, oldest at mag_delay_next_
  std::size_t mag_delay_next_ = 0;
  bool mag_delay_filled_ = false;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
};

/// splitmix64: decorrelated seeds for each sensor from one scenario seed.
std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t stream);

}  // namespace bsn::sim
