#include "bsn/sim/magnetic_environment.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace bsn::sim {
namespace {

// 0 outside, 1 inside deeper than edge, C2-smooth in between (per axis, multiplied).
double box_weight(const Vec3& p, const FloorRegion& r) {
  double w = 1.0;
  for (int i = 0; i < 3; ++i) {
    const double depth = std::min(p[i] - r.min_m[i], r.max_m[i] - p[i]);
    if (depth <= 0.0) return 0.0;
    if (r.edge_m > 0.0 && depth < r.edge_m) w *= smooth_step(depth, 0.0, r.edge_m).value;
  }
  return w;
}

double envelope_or_one(const std::vector<Window>& windows, double t) {
  return windows.empty() ? 1.0 : std::clamp(envelope_at(windows, t).value, 0.0, 1.0);
}

}  // namespace

Vec3 dipole_field(const Vec3& m, const Vec3& r) {
  const double n = r.norm();
  if (!(n > 1e-9)) return Vec3::Zero();
  const Vec3 u = r / n;
  return 0.1 * (3.0 * u * m.dot(u) - m) / (n * n * n);
}

Vec3 MagneticEnvironment::earth_field(double t) const {
  double heading = 0.0;
  for (const HeadingChange& h : heading_changes) {
    heading += h.delta_rad * (h.ramp_s > 0.0 ? smooth_step(t, h.at_s, h.ramp_s).value : (t >= h.at_s ? 1.0 : 0.0));
  }
  const double dip = dip_deg * std::numbers::pi / 180.0;
  const double horizontal = magnitude_ut * std::cos(dip);
  // Heading 0 points to the y axis (magnetic north); positive turns towards west (counter-clockwise).
  return Vec3(-horizontal * std::sin(heading), horizontal * std::cos(heading), -magnitude_ut * std::sin(dip));
}

Vec3 MagneticEnvironment::field_at(const Vec3& p, double t) const {
  Vec3 b = earth_field(t);
  for (const Dipole& d : dipoles) {
    const double e = envelope_or_one(d.active, t);
    if (d.approach_from_m.isZero()) {
      if (e > 0.0) b += dipole_field(d.moment_am2 * e, p - d.position_m);
    } else {
      b += dipole_field(d.moment_am2, p - (d.position_m + (1.0 - e) * d.approach_from_m));
    }
  }
  for (const FloorRegion& r : floor_regions) {
    const double w = box_weight(p, r) * envelope_or_one(r.active, t);
    if (w > 0.0) b += w * r.field_ut;
  }
  return b;
}

Vec3 MagneticEnvironment::sensor_field(std::size_t segment, const Vec3& p, const Quat& q, double t) const {
  Vec3 b = q.conjugate() * field_at(p, t);
  for (const AttachedMagnet& m : attached_magnets) {
    if (m.segment == segment) b += m.field_sensor_ut();
  }
  return b;
}

MagnitudeDip magnitude_and_dip(const Vec3& f) {
  const double n = f.norm();
  return {n, n > 0.0 ? std::asin(std::clamp(-f.z() / n, -1.0, 1.0)) : 0.0};
}

}  // namespace bsn::sim
