// Synthetic samples shared by every filter test: a still sensor with a given orientation (static_sample, whose time
// is always written with its unit: at_s(1.5) or at_ns(k * 10 * kMs)), seeded white noise, and a sensor turning
// smoothly from the simulator (turning_sensor).
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <vector>

#include "bsn/fusion/imu_sample.hpp"
#include "bsn/fusion/rotation.hpp"
#include "bsn/sim/magnetic_environment.hpp"
#include "bsn/sim/scenario.hpp"
#include "bsn/sim/sensor_model.hpp"

namespace bsn::fusion::filter_test {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr std::uint64_t kMs = 1'000'000;  ///< ns

/// The simulator's default earth field, ENU, uT: 49 uT with a dip of 64 deg (central Europe).
inline const Vec3 kField = sim::MagneticEnvironment{}.earth_field(0.0);

/// A sample time. Made only by at_s() or at_ns(), so every call site says its unit.
struct SampleTime {
  std::uint64_t ns;
};
inline SampleTime at_s(double seconds) { return {seconds_to_ns(seconds)}; }
constexpr SampleTime at_ns(std::uint64_t ns) { return {ns}; }

/// consumer_mems with its magnetometer calibrated: bsn calibrate removes hard and soft iron, and what it leaves is far
/// below the field.
inline sim::SensorErrors calibrated_consumer_mems() {
  sim::SensorErrors e = *sim::sensor_preset("consumer_mems");
  e.mag.hard_iron = Vec3::Zero();
  e.mag.soft_iron = sim::Mat3::Identity();
  return e;
}

/// The same with its magnetometer reading one IMU sample behind the gyro's and low-passed at 25 Hz (a part sampled
/// at 100 Hz averages internally well below its 50 Hz Nyquist limit). No dropped samples: a drop is a gap, another
/// case.
inline sim::SensorErrors consumer_mems_lagging_magnetometer() {
  sim::SensorErrors e = calibrated_consumer_mems();
  e.mag_rate_hz = 0.0;
  e.mag_delay_samples = 1;
  e.mag_bandwidth_hz = 25.0;
  e.drop_probability = 0.0;
  return e;
}

/// Nez et al. 2018's random motion of `intensity` (their Table 1) at their 128 Hz, `duration_s` long: at rest for the
/// first 10 s, then moving (1 s ramp) until `moving_until_s`, measured by `sensors`.
inline sim::ScenarioSpec nez_random_motion(sim::Intensity intensity, std::uint64_t seed, double duration_s,
                                           double moving_until_s, const sim::SensorErrors& sensors) {
  sim::ScenarioSpec spec;
  spec.name = "Nez random motion";
  spec.duration_s = duration_s;
  spec.rate_hz = 128.0;
  spec.seed = seed;
  sim::RandomMotion m = sim::random_motion_for(intensity, seed);
  m.active = {{10.0, moving_until_s, 1.0}};
  spec.free_motion.random = m;
  spec.sensors = sensors;
  return spec;
}

/// Angle wrapped to [-pi, pi].
inline double wrap(double angle) { return std::remainder(angle, 2 * std::numbers::pi); }

/// Noise-free sample at time t of a sensor at rest with true orientation q (sensor-to-earth) in the earth field
/// `field` (ENU, uT); the gyro reads `gyr` (a bias, say), rad/s.
inline ImuSample static_sample(const Quat& q, SampleTime t, const Vec3& field = kField,
                               const Vec3& gyr = Vec3::Zero()) {
  ImuSample s;
  s.timestamp_ns = t.ns;
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

/// Per-sample white noise of turning_sensor() when it is not ideal: a consumer MEMS sensor at 100 Hz.
struct TurningNoise {
  static constexpr double kGyrRadS = 0.005;  ///< gyro, rad/s
  static constexpr double kAccMS2 = 0.02;    ///< accelerometer, m/s^2
  static constexpr double kMagUT = 0.3;      ///< magnetometer, uT
};

/// A sensor at the centre of a free body turning smoothly at random (the simulator's RandomMotion, RMS rate
/// 0.5 rad/s from 0.1 to 0.4 Hz, no translation: only gravity acts on the accelerometer), in kField, sampled at
/// 100 Hz for duration_s from t = 0. ideal = exact readings; otherwise seeded white noise of TurningNoise.
inline std::vector<sim::ScenarioSample> turning_sensor(std::uint64_t seed, double duration_s, bool ideal) {
  sim::ScenarioSpec spec;
  spec.duration_s = duration_s;
  spec.rate_hz = 100.0;
  spec.seed = seed;
  sim::RandomMotion motion;
  motion.angular_rate_rms_rad_s = 0.5;
  motion.min_frequency_hz = 0.1;
  motion.max_frequency_hz = 0.4;
  motion.seed = seed;
  spec.free_motion.random = motion;
  const double sqrt_rate = std::sqrt(spec.rate_hz);  // white_density * sqrt(rate) = per-sample SD
  spec.sensors.gyr.white_density = TurningNoise::kGyrRadS / sqrt_rate;
  spec.sensors.acc.white_density = TurningNoise::kAccMS2 / sqrt_rate;
  spec.sensors.mag.white_density = TurningNoise::kMagUT / sqrt_rate;
  sim::ScenarioRunner runner(spec, {}, ideal);
  std::vector<sim::ScenarioSample> samples, one;
  samples.reserve(runner.sample_count());
  while (runner.next(one)) samples.push_back(one.front());
  return samples;
}

/// A stream with everything a filter keeps between samples at work, at 100 Hz for 45 s, white noise of TurningNoise
/// throughout and a gyro bias of about 0.6 deg/s: 10 s at rest (rest detection, bias learning), then turning_sensor()'s
/// motion with a 0.5 s gap (bridged) at 20 s and a 1.5 s gap (restart) at 28 s, the magnetometer on four samples of
/// five, and a 20 uT disturbance (40 % of the field, beyond every detector's threshold) from 33 s to 38 s.
inline std::vector<ImuSample> stateful_stream() {
  const Vec3 bias(0.01, -0.008, 0.005);
  const std::vector<sim::ScenarioSample> motion = turning_sensor(5, 35.0, false);
  WhiteNoise noise(7, TurningNoise::kAccMS2, TurningNoise::kGyrRadS, TurningNoise::kMagUT);
  std::vector<ImuSample> out;
  for (int k = 0; k < 1000; ++k) {
    out.push_back(noise.add_to(
        static_sample(motion.front().truth, at_ns(static_cast<std::uint64_t>(k) * 10 * kMs), kField, bias)));
  }
  const std::uint64_t motion_start_ns = 10'000 * kMs;
  for (std::size_t k = 0; k < motion.size(); ++k) {
    ImuSample s = motion[k].sample;
    s.timestamp_ns += motion_start_ns;
    const double t_s = static_cast<double>(s.timestamp_ns) * 1e-9;
    if ((t_s > 20.0 && t_s < 20.5) || (t_s > 28.0 && t_s < 29.5)) continue;  // the gaps
    s.gyr += bias;
    s.has_mag = k % 5 != 0;
    if (t_s >= 33.0 && t_s < 38.0) s.mag += motion[k].truth.conjugate() * Vec3(0.0, 20.0, 0.0);
    out.push_back(s);
  }
  return out;
}

}  // namespace bsn::fusion::filter_test
