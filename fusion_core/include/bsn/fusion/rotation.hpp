// Conventions of the whole project, in one place:
//  - earth frame ENU (x east, y magnetic north, z up);
//  - Hamilton quaternions (w, x, y, z); q is sensor-to-earth: v_E = q * v_S * conj(q);
//  - Euler angles are intrinsic z-y'-x'' (yaw, pitch, roll) in radians.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <optional>
#include <string>
#include <string_view>

namespace bsn::fusion {

using Vec3 = Eigen::Vector3d;
using Quat = Eigen::Quaterniond;

/// Standard gravity, m/s^2: the magnitude of the specific force at rest.
inline constexpr double kGravity = 9.80665;

/// Intrinsic z-y'-x'' angles, radians. yaw in (-pi, pi], pitch in [-pi/2, pi/2], roll in (-pi, pi].
struct YawPitchRoll {
  double yaw = 0.0;
  double pitch = 0.0;
  double roll = 0.0;
};

/// Sensor-to-earth quaternion of the intrinsic z-y'-x'' rotation (yaw, then pitch, then roll).
Quat from_yaw_pitch_roll(const YawPitchRoll& ypr);

/// Inverse of from_yaw_pitch_roll. At pitch = +-90 deg (gimbal lock) roll is set to 0 and yaw takes
/// the whole rotation about the vertical.
YawPitchRoll to_yaw_pitch_roll(const Quat& q);

/// An intrinsic Tait-Bryan rotation sequence of three distinct axes, e.g. "zyx" = z, then y', then x''.
struct AxisSequence {
  std::array<int, 3> axes{2, 1, 0};  ///< 0 = x, 1 = y, 2 = z
  std::string name() const;
};

/// Parses "zyx", "zxy", "xyz", ... (three distinct letters of x, y, z). Returns nullopt otherwise.
std::optional<AxisSequence> parse_axis_sequence(std::string_view text);

/// Angles (a1, a2, a3) with q = R_{axes[0]}(a1) * R_{axes[1]}(a2) * R_{axes[2]}(a3); the middle angle is in
/// [-pi/2, pi/2]. At the singularity the third angle is set to 0.
Vec3 decompose(const Quat& q, const AxisSequence& seq);

/// Composes the rotation of decompose() back into a quaternion.
Quat compose(const Vec3& angles, const AxisSequence& seq);

/// Relative orientation of a child frame in its parent frame: conj(q_parent) * q_child.
Quat relative_orientation(const Quat& q_parent, const Quat& q_child);

/// Rotation angle of q_a * conj(q_b) in radians, in [0, pi]: the total orientation error (BROAD's metric).
double angle_between(const Quat& q_a, const Quat& q_b);

/// Quaternion of the rotation by the rotation vector v (axis * angle, radians). Inline and trig-free for the
/// small angles of per-sample steps and corrections: below a half-angle of 0.1 rad the Taylor series of
/// cos(a/2) and sin(a/2)/a are used (truncation error below 1e-20); larger angles take sin and cos.
inline Quat exp_rotation_vector(const Vec3& v) {
  const double h2 = 0.25 * v.squaredNorm();  // (angle / 2)^2
  if (!(h2 < 1e-2)) {
    const double angle = v.norm();
    const double s = std::sin(0.5 * angle) / angle;
    return Quat(std::cos(0.5 * angle), s * v.x(), s * v.y(), s * v.z());
  }
  const double c =
      1.0 - h2 * (1.0 / 2) *
                (1.0 - h2 * (1.0 / 12) * (1.0 - h2 * (1.0 / 30) * (1.0 - h2 * (1.0 / 56) * (1.0 - h2 * (1.0 / 90)))));
  const double s =
      0.5 * (1.0 - h2 * (1.0 / 6) *
                       (1.0 - h2 * (1.0 / 20) *
                                  (1.0 - h2 * (1.0 / 42) * (1.0 - h2 * (1.0 / 72) * (1.0 - h2 * (1.0 / 110))))));
  return Quat(c, s * v.x(), s * v.y(), s * v.z());
}

/// Earth axis `axis` (0 = east, 1 = north, 2 = up) in sensor coordinates for a unit sensor-to-earth q:
/// conj(q) * e * q, which is row `axis` of R(q), computed without a full rotation.
inline Vec3 earth_axis_in_sensor(const Quat& q, int axis) {
  const double w = q.w(), x = q.x(), y = q.y(), z = q.z();
  switch (axis) {
    case 0:
      return Vec3(1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y));
    case 1:
      return Vec3(2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x));
    default:
      return Vec3(2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y));
  }
}

/// q * v * conj(q) for a unit q, written out and always inlined (Eigen's q * v, and this function too, end up as
/// out-of-line calls in hot loops otherwise): v + 2w (u x v) + 2 u x (u x v) with u the vector part of q.
EIGEN_ALWAYS_INLINE Vec3 rotate(const Quat& q, const Vec3& v) {
  const Vec3 u = q.vec();
  const Vec3 t = 2.0 * u.cross(v);
  return v + q.w() * t + u.cross(t);
}

/// 1 / sqrt(n2). Without square root or division when n2 is within 1e-3 of 1, as the squared norm of a unit
/// quaternion after a small step is: the binomial series to the fifth power then errs by less than 3e-19.
inline double inverse_sqrt_near_one(double n2) {
  const double d = n2 - 1.0;
  if (!(std::abs(d) < 1e-3)) return 1.0 / std::sqrt(n2);
  const double d2 = d * d;  // Estrin's scheme: a shorter dependency chain than Horner's
  return (1.0 - (1.0 / 2) * d) + d2 * ((3.0 / 8) - (5.0 / 16) * d) + d2 * d2 * ((35.0 / 128) - (63.0 / 256) * d);
}

/// Sensor-to-earth orientation whose earth z is along the specific force (up) and whose earth y is along the
/// horizontal part of the magnetic field (north). Correct for any heading. Requires acc and mag not parallel.
Quat orientation_from_acc_mag(const Vec3& acc, const Vec3& mag);

/// Sensor-to-earth orientation from the accelerometer alone, with zero yaw (no heading information).
Quat orientation_from_acc(const Vec3& acc);

/// Returns q with w >= 0 (q and -q are the same rotation), normalised.
Quat canonical(const Quat& q);

}  // namespace bsn::fusion
