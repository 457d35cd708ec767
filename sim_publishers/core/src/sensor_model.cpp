#include "bsn/sim/sensor_model.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace bsn::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

void check_channel(const ChannelErrors& e, const char* name) {
  auto bad = [&](const std::string& what) {
    throw std::invalid_argument(std::string("sensor errors of ") + name + ": " + what);
  };
  if (!(e.white_density >= 0.0) || !std::isfinite(e.white_density)) bad("white_density must be >= 0 and finite");
  if (!(e.bias_random_walk >= 0.0) || !std::isfinite(e.bias_random_walk)) bad("bias_random_walk must be >= 0");
  if (!(e.bias_instability >= 0.0) || !std::isfinite(e.bias_instability)) bad("bias_instability must be >= 0");
  if (!(e.bias_correlation_s > 0.0)) bad("bias_correlation_s must be > 0");
  if (!e.bias.allFinite() || !e.hard_iron.allFinite() || !e.nonorthogonality.allFinite() ||
      !e.mounting_rad.allFinite() || !e.soft_iron.allFinite() || !e.scale.allFinite()) {
    bad("a bias, scale or matrix entry is not finite");
  }
  if (!(e.range > 0.0)) bad("range must be > 0");
  if (!(e.lsb >= 0.0) || !std::isfinite(e.lsb)) bad("lsb must be >= 0 and finite");
  if (!(std::abs(e.physical_from_reading().determinant()) > 1e-9))
    bad("scale, non-orthogonality or soft iron is singular");
  for (const BiasStep& s : e.bias_steps) {
    if (!std::isfinite(s.at_s) || !s.value.allFinite()) bad("a bias step is not finite");
  }
}

}  // namespace

Mat3 ChannelErrors::physical_from_reading() const {
  Mat3 t = Mat3::Identity();
  t(1, 0) = nonorthogonality.x();
  t(2, 0) = nonorthogonality.y();
  t(2, 1) = nonorthogonality.z();
  const Mat3 r =
      (Eigen::AngleAxisd(mounting_rad.z(), Vec3::UnitZ()) * Eigen::AngleAxisd(mounting_rad.y(), Vec3::UnitY()) *
       Eigen::AngleAxisd(mounting_rad.x(), Vec3::UnitX()))
          .toRotationMatrix();
  return r * t * scale.asDiagonal() * soft_iron;
}

bool ChannelErrors::ideal() const {
  return white_density == 0.0 && bias.isZero() && bias_random_walk == 0.0 && bias_instability == 0.0 &&
         scale == Vec3::Ones() && nonorthogonality.isZero() && mounting_rad.isZero() && soft_iron == Mat3::Identity() &&
         hard_iron.isZero() && bias_steps.empty() && std::isinf(range) && lsb == 0.0;
}

std::vector<std::string> sensor_preset_names() { return {"ideal", "consumer_mems", "opal", "zhang_yang_table1"}; }

std::optional<SensorErrors> sensor_preset(std::string_view name) {
  SensorErrors e;
  if (name == "ideal") return e;
  if (name == "consumer_mems") {
    // A typical 9-axis consumer MEMS part (MPU-9250 class, datasheet orders of magnitude), 16-bit ADCs.
    e.gyr.white_density = 0.01 * kDeg;  // 0.01 deg/s/sqrt(Hz)
    e.gyr.bias = Vec3(0.5, -0.3, 0.2) * kDeg;
    e.gyr.bias_random_walk = 2e-5;
    e.gyr.bias_instability = 0.01 * kDeg;
    e.gyr.scale = Vec3(1.01, 0.99, 1.005);
    e.gyr.nonorthogonality = Vec3(0.005, -0.004, 0.003);
    e.gyr.range = 2000.0 * kDeg;
    e.gyr.lsb = e.gyr.range / 32768.0;
    e.acc.white_density = 300e-6 * fusion::kGravity;  // 300 ug/sqrt(Hz)
    e.acc.bias = Vec3(0.05, -0.08, 0.10);
    e.acc.bias_instability = 0.002;
    e.acc.scale = Vec3(0.995, 1.01, 1.003);
    e.acc.nonorthogonality = Vec3(-0.003, 0.004, 0.002);
    e.acc.range = 16.0 * fusion::kGravity;
    e.acc.lsb = e.acc.range / 32768.0;
    e.mag.white_density = 0.06;  // 0.42 uT RMS per reading at its 50 Hz
    e.mag.hard_iron = Vec3(12.0, -8.0, 20.0);
    e.mag.soft_iron << 1.02, 0.01, 0.0, 0.01, 0.98, 0.005, 0.0, 0.005, 1.01;
    e.mag.range = 4900.0;
    e.mag.lsb = 0.15;
    e.mag_rate_hz = 50.0;
    e.jitter_s = 20e-6;
    e.drop_probability = 0.001;
    return e;
  }
  if (name == "opal") {
    // Nez et al. 2018, Table 2 (Allan variance of APDM Opal): sigma_g, sigma_a, sigma_m are white-noise
    // densities (the Allan deviation at tau = 1 s, unit/sqrt(Hz); sigma_g = 1e-3 rad/s/sqrt(Hz) ~ 0.057
    // deg/s/sqrt(Hz), the manufacturer's 0.05 deg/s/sqrt(Hz) quoted in their discussion); sigma_bg = 3e-3 rad/s
    // is the gyro bias instability.
    e.gyr.white_density = 1e-3;
    e.gyr.bias_instability = 3e-3;
    e.acc.white_density = 4e-3;
    e.mag.white_density = 0.2;
    // APDM's sensor table for its monitors (apdm.com, Wearable-Sensors/Sapphire, "Sensor Characteristics"; the
    // Sapphire is the Opal's logging sibling, the Opal's own sheet was not at hand): accelerometer range
    // +-2 g or +-6 g; the larger, since Nez's fast motion (Table 1: 4 +- 2 g) reaches it. The same table gives a
    // 50 Hz bandwidth on all three channels, i.e. no lag of the magnetometer behind the gyro: mag_bandwidth_hz and
    // mag_delay_samples stay 0 (the simulator would filter the magnetometer alone; README, Tuning, for the
    // experiment).
    e.acc.range = 6.0 * fusion::kGravity;
    return e;
  }
  if (name == "zhang_yang_table1") {
    // Zhang & Yang 2015, Table I, magnetometer only (gyro and accelerometer exact). The table is in milligauss:
    // 1 mG = 0.1 uT. Noise: SD 0.1 mG per sample at their 33 Hz.
    e.mag.nonorthogonality = Vec3(0.1, 0.1, 0.1);
    e.mag.mounting_rad = Vec3(0.1, 0.1, 0.1);
    e.mag.scale = Vec3(1.0 / 1.2, 1.0 / 1.383, 1.0 / 1.12);
    e.mag.bias = Vec3(3200.0, 3200.0, 3200.0);
    e.mag.hard_iron = Vec3(26.8, -12.3, -10.9);
    e.mag.soft_iron << 1.0, 0.1, 0.1, 0.1, 1.0, 0.1, 0.1, 0.1, 1.0;
    e.mag.white_density = 0.01 / std::sqrt(33.0);
    return e;
  }
  return std::nullopt;
}

std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t stream) {
  std::uint64_t z = seed + 0x9e3779b97f4a7c15ull * (stream + 1);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

SensorSimulator::SensorSimulator(const SensorErrors& errors, double rate_hz, std::uint64_t seed)
    : errors_(errors), rng_(seed) {
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz)) throw std::invalid_argument("sensor rate must be > 0 Hz");
  check_channel(errors.gyr, "gyr");
  check_channel(errors.acc, "acc");
  check_channel(errors.mag, "mag");
  if (!(errors.mag_rate_hz >= 0.0) || !std::isfinite(errors.mag_rate_hz)) {
    throw std::invalid_argument("mag_rate_hz must be >= 0");
  }
  if (!(errors.jitter_s >= 0.0) || !std::isfinite(errors.jitter_s))
    throw std::invalid_argument("jitter_s must be >= 0");
  if (!(errors.drop_probability >= 0.0 && errors.drop_probability <= 1.0)) {
    throw std::invalid_argument("drop_probability must be in [0, 1]");
  }
  if (errors.mag_delay_samples < 0 || errors.mag_delay_samples > 1000) {
    throw std::invalid_argument("mag_delay_samples must be in [0, 1000]");
  }
  if (!(errors.mag_bandwidth_hz >= 0.0) || !std::isfinite(errors.mag_bandwidth_hz)) {
    throw std::invalid_argument("mag_bandwidth_hz must be >= 0");
  }
  const double dt = 1.0 / rate_hz;
  if (errors.mag_bandwidth_hz > 0.0)
    mag_lowpass_alpha_ = 1.0 - std::exp(-2.0 * std::numbers::pi * errors.mag_bandwidth_hz * dt);
  mag_delay_line_.assign(static_cast<std::size_t>(errors.mag_delay_samples), Vec3::Zero());
  auto init = [&](const ChannelErrors& e, ChannelState& s) {
    s.reading_from_physical = e.physical_from_reading().inverse();
    s.white_sd = e.white_density * std::sqrt(rate_hz);
    s.walk_drive = e.bias_random_walk * std::sqrt(dt);
    s.markov_decay = std::exp(-dt / e.bias_correlation_s);
    s.markov_drive = e.bias_instability * std::sqrt(1.0 - s.markov_decay * s.markov_decay);
  };
  init(errors_.gyr, gyr_);
  init(errors_.acc, acc_);
  init(errors_.mag, mag_);
  // A slower magnetometer's white noise is drawn per IMU sample but only every (rate / mag_rate)-th draw is read:
  // its per-reading SD is the density over the magnetometer's own bandwidth, density * sqrt(mag_rate), so that the
  // Allan deviation of its readings at their own rate gives back the configured density.
  if (errors.mag_rate_hz > 0.0 && errors.mag_rate_hz < rate_hz) {
    mag_.white_sd = errors.mag.white_density * std::sqrt(errors.mag_rate_hz);
  }
  // The Gauss-Markov bias starts in its stationary distribution, not at zero.
  if (errors_.gyr.bias_instability > 0.0) gyr_.markov = normal3() * errors_.gyr.bias_instability;
  if (errors_.acc.bias_instability > 0.0) acc_.markov = normal3() * errors_.acc.bias_instability;
  if (errors_.mag.bias_instability > 0.0) mag_.markov = normal3() * errors_.mag.bias_instability;
}

// The draws are sequenced (z, y, x: the order GCC happened to evaluate the constructor's arguments in, so existing
// recordings stay bit-identical): the order of function arguments is unspecified, and clang's differs.
Vec3 SensorSimulator::normal3() {
  const double z = normal_(rng_);
  const double y = normal_(rng_);
  const double x = normal_(rng_);
  return Vec3(x, y, z);
}

Vec3 SensorSimulator::apply(const ChannelErrors& e, ChannelState& s, const Vec3& u, double t) {
  Vec3 g = s.reading_from_physical * u + e.bias + e.hard_iron + s.random_walk + s.markov;
  for (const BiasStep& step : e.bias_steps) {
    if (t >= step.at_s) g += step.value;
  }
  if (s.white_sd > 0.0) g += normal3() * s.white_sd;
  if (s.walk_drive > 0.0) s.random_walk += normal3() * s.walk_drive;
  if (s.markov_drive > 0.0) s.markov = s.markov_decay * s.markov + normal3() * s.markov_drive;
  for (int i = 0; i < 3; ++i) {
    double v = std::clamp(g[i], -e.range, e.range);
    if (e.lsb > 0.0) v = std::round(v / e.lsb) * e.lsb;
    g[i] = v;
  }
  return g;
}

fusion::ImuSample SensorSimulator::measure(const Vec3& gyr, const Vec3& specific_force, const Vec3& mag, double t,
                                           std::uint64_t timestamp_ns, bool has_mag) {
  fusion::ImuSample s;
  s.timestamp_ns = timestamp_ns;
  s.gyr = apply(errors_.gyr, gyr_, gyr, t);
  s.acc = apply(errors_.acc, acc_, specific_force, t);
  // The magnetometer's own dynamics act on the physical field: its low-pass (exact first-order step, started at
  // the first field), then its delay behind the gyro (the first samples repeat the first field).
  Vec3 field = mag;
  if (mag_lowpass_alpha_ < 1.0) {
    mag_lowpassed_ =
        mag_lowpass_started_ ? Vec3(mag_lowpassed_ + mag_lowpass_alpha_ * (field - mag_lowpassed_)) : field;
    mag_lowpass_started_ = true;
    field = mag_lowpassed_;
  }
  if (!mag_delay_line_.empty()) {
    if (!mag_delay_filled_) {
      std::fill(mag_delay_line_.begin(), mag_delay_line_.end(), field);
      mag_delay_filled_ = true;
    }
    const Vec3 delayed = mag_delay_line_[mag_delay_next_];
    mag_delay_line_[mag_delay_next_] = field;
    mag_delay_next_ = (mag_delay_next_ + 1) % mag_delay_line_.size();
    field = delayed;
  }
  s.mag = apply(errors_.mag, mag_, field, t);
  s.has_mag = has_mag;
  return s;
}

}  // namespace bsn::sim
