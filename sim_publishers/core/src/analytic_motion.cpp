#include <cmath>
#include <numbers>
#include <random>

#include "bsn/sim/motion_model.hpp"

namespace bsn::sim {
namespace {

struct AngleRate {
  double angle;
  double rate;
};

AngleRate evaluate(const SinusoidalRotation::Axis& a, double t) {
  const double w = 2.0 * std::numbers::pi * a.frequency_hz;
  return {a.offset_rad + a.amplitude_rad * std::sin(w * t + a.phase_rad),
          a.amplitude_rad * w * std::cos(w * t + a.phase_rad)};
}

}  // namespace

SinusoidalRotation SinusoidalRotation::from_seed(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double deg = std::numbers::pi / 180.0;
  auto axis = [&](double max_amp_deg) {
    Axis a;
    a.offset_rad = (u(rng) - 0.5) * max_amp_deg * deg;
    a.amplitude_rad = (0.3 + 0.7 * u(rng)) * max_amp_deg * deg;
    a.frequency_hz = 0.1 + 0.3 * u(rng);
    a.phase_rad = 2.0 * std::numbers::pi * u(rng);
    return a;
  };
  Params p;
  p.yaw = axis(60.0);
  p.pitch = axis(30.0);
  p.roll = axis(30.0);
  return SinusoidalRotation(p);
}

MotionState SinusoidalRotation::at(double t) const {
  const AngleRate yaw = evaluate(params_.yaw, t), pitch = evaluate(params_.pitch, t), roll = evaluate(params_.roll, t);
  MotionState m;
  m.q_sensor_to_earth = fusion::from_yaw_pitch_roll({yaw.angle, pitch.angle, roll.angle});
  // Body rate of the intrinsic z-y'-x'' rotation from the Euler angle rates.
  const double sp = std::sin(pitch.angle), cp = std::cos(pitch.angle);
  const double sr = std::sin(roll.angle), cr = std::cos(roll.angle);
  m.angular_rate_sensor =
      Vec3(roll.rate - yaw.rate * sp, pitch.rate * cr + yaw.rate * cp * sr, -pitch.rate * sr + yaw.rate * cp * cr);
  m.linear_acc_earth = Vec3::Zero();
  return m;
}

}  // namespace bsn::sim
