#include "bsn/sim/mimu_synthesizer.hpp"

#include <cmath>
#include <numbers>

namespace bsn::sim {

Vec3 EarthField::vector_enu() const {
  const double dip = dip_deg * std::numbers::pi / 180.0;
  return Vec3(0.0, magnitude_ut * std::cos(dip), -magnitude_ut * std::sin(dip));
}

MimuSynthesizer::MimuSynthesizer(const EarthField& field, const WhiteNoise& noise, std::uint64_t seed)
    : field_enu_(field.vector_enu()), noise_(noise), rng_(seed) {}

Vec3 MimuSynthesizer::noise(double sigma) {
  if (sigma <= 0.0) return Vec3::Zero();
  return Vec3(normal_(rng_), normal_(rng_), normal_(rng_)) * sigma;
}

fusion::ImuSample MimuSynthesizer::measure(const MotionState& m, std::uint64_t timestamp_ns) {
  const Quat earth_to_sensor = m.q_sensor_to_earth.conjugate();
  fusion::ImuSample s;
  s.timestamp_ns = timestamp_ns;
  // Specific force: what the accelerometer feels is the acceleration minus gravity (gravity = -g z).
  s.acc = earth_to_sensor * (m.linear_acc_earth + Vec3(0.0, 0.0, fusion::kGravity)) + noise(noise_.acc_m_s2);
  s.gyr = m.angular_rate_sensor + noise(noise_.gyr_rad_s);
  s.mag = earth_to_sensor * field_enu_ + noise(noise_.mag_ut);
  return s;
}

}  // namespace bsn::sim
