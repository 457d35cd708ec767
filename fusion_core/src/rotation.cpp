#include "bsn/fusion/rotation.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace bsn::fusion {
namespace {

Quat axis_rotation(int axis, double angle) { return Quat(Eigen::AngleAxisd(angle, Vec3::Unit(axis))); }

}  // namespace

Quat from_yaw_pitch_roll(const YawPitchRoll& ypr) {
  return compose(Vec3(ypr.yaw, ypr.pitch, ypr.roll), AxisSequence{});
}

YawPitchRoll to_yaw_pitch_roll(const Quat& q) {
  const Vec3 a = decompose(q, AxisSequence{});
  return {a.x(), a.y(), a.z()};
}

std::string AxisSequence::name() const {
  std::string s(3, 'x');
  for (int i = 0; i < 3; ++i)
    s[static_cast<std::size_t>(i)] = static_cast<char>('x' + axes[static_cast<std::size_t>(i)]);
  return s;
}

std::optional<AxisSequence> parse_axis_sequence(std::string_view text) {
  if (text.size() != 3) return std::nullopt;
  AxisSequence seq;
  for (std::size_t i = 0; i < 3; ++i) {
    const char c = text[i];
    if (c < 'x' || c > 'z') return std::nullopt;
    seq.axes[i] = c - 'x';
  }
  if (seq.axes[0] == seq.axes[1] || seq.axes[1] == seq.axes[2] || seq.axes[0] == seq.axes[2]) return std::nullopt;
  return seq;
}

namespace {

// For R = R_i(a) R_j(b) R_k(c) with distinct i, j, k and s = +1 for a cyclic (i, j, k), -1 otherwise:
//   sin b = s R(i,k),  a = atan2(-s R(j,k), R(k,k)),  c = atan2(-s R(i,j), R(i,i)).
// The five elements come straight from the quaternion, R = ((w^2 - |v|^2) I + 2 v v^T + 2 w [v]x) / |q|^2, without
// building the matrix: the joint angles decompose every joint sample twice, and every orientation has its yaw,
// pitch and roll. One instance per sequence, so the indices and signs are constants and only the arithmetic is left.
template <int i, int j, int k>
Vec3 decompose_sequence(const Quat& q) {
  // (a, b, 3 - a - b) is a cyclic order of (x, y, z): (b - a) mod 3 == 1.
  constexpr auto cyclic = [](int a, int b) { return (b - a + 3) % 3 == 1; };
  constexpr double s = cyclic(i, j) ? 1.0 : -1.0;
  const double w = q.w();
  const double v[3] = {q.x(), q.y(), q.z()};
  const double n2 = w * w + v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
  const double diag = w * w - (n2 - w * w);  // w^2 - |v|^2
  // Off the diagonal [v]x(a, b) = -v_c when (a, b, c) is cyclic, +v_c otherwise.
  auto element = [&](int a, int b) {
    if (a == b) return diag + 2.0 * v[a] * v[a];
    const int c = 3 - a - b;
    const double cross = cyclic(a, b) ? -v[c] : v[c];
    return 2.0 * (v[a] * v[b] + w * cross);
  };
  const double sb = std::clamp(s * element(i, k) / n2, -1.0, 1.0);
  const double b = std::asin(sb);
  double a, c;
  if (std::abs(sb) > 1.0 - 1e-12) {
    // Gimbal lock: only a +- c is defined. Put it all in the first angle.
    c = 0.0;
    const Eigen::Matrix3d r = q.normalized().toRotationMatrix();
    const Eigen::Matrix3d rest = r * axis_rotation(j, -b).toRotationMatrix();
    // At the lock R_j(b) R_k(c) R_j(-b) turns about +-axis i, so rest is a pure rotation about axis i.
    a = std::atan2(s * rest(k, j), rest(j, j));
  } else {
    a = std::atan2(-s * element(j, k), element(k, k));
    c = std::atan2(-s * element(i, j), element(i, i));
  }
  return {a, b, c};
}

}  // namespace

Vec3 decompose(const Quat& q, const AxisSequence& seq) {
  switch (seq.axes[0] * 9 + seq.axes[1] * 3 + seq.axes[2]) {
    case 0 * 9 + 1 * 3 + 2:
      return decompose_sequence<0, 1, 2>(q);
    case 0 * 9 + 2 * 3 + 1:
      return decompose_sequence<0, 2, 1>(q);
    case 1 * 9 + 0 * 3 + 2:
      return decompose_sequence<1, 0, 2>(q);
    case 1 * 9 + 2 * 3 + 0:
      return decompose_sequence<1, 2, 0>(q);
    case 2 * 9 + 0 * 3 + 1:
      return decompose_sequence<2, 0, 1>(q);
    case 2 * 9 + 1 * 3 + 0:
      return decompose_sequence<2, 1, 0>(q);
  }
  // Not three distinct axes: parse_axis_sequence refuses them, so only code can make one.
  throw std::invalid_argument("decompose: an axis sequence needs three distinct axes, not " + seq.name());
}

Quat compose(const Vec3& angles, const AxisSequence& seq) {
  return (axis_rotation(seq.axes[0], angles[0]) * axis_rotation(seq.axes[1], angles[1]) *
          axis_rotation(seq.axes[2], angles[2]))
      .normalized();
}

Quat relative_orientation(const Quat& q_parent, const Quat& q_child) {
  return (q_parent.conjugate() * q_child).normalized();
}

double angle_between(const Quat& q_a, const Quat& q_b) {
  const Quat e = (q_a * q_b.conjugate()).normalized();
  return 2.0 * std::acos(std::clamp(std::abs(e.w()), 0.0, 1.0));
}

Quat orientation_from_acc_mag(const Vec3& acc, const Vec3& mag) {
  // Earth axes expressed in the sensor frame: up along acc, east = north x up ... built by cross products.
  const Vec3 up = acc.normalized();
  const Vec3 east = mag.cross(up).normalized();
  const Vec3 north = up.cross(east);
  Eigen::Matrix3d r_earth_to_sensor;  // columns: earth x, y, z in sensor coordinates
  r_earth_to_sensor.col(0) = east;
  r_earth_to_sensor.col(1) = north;
  r_earth_to_sensor.col(2) = up;
  // The rows of the sensor-to-earth rotation are the earth axes in sensor coordinates.
  return canonical(Quat(Eigen::Matrix3d(r_earth_to_sensor.transpose())));
}

Quat orientation_from_acc(const Vec3& acc) {
  // Shortest rotation taking the measured up direction to earth z: pitch and roll only, zero yaw component
  // is then removed by re-composing from the z-y-x angles.
  const Quat tilt = Quat::FromTwoVectors(acc.normalized(), Vec3::UnitZ());
  YawPitchRoll ypr = to_yaw_pitch_roll(tilt);
  ypr.yaw = 0.0;
  return from_yaw_pitch_roll(ypr);
}

Quat canonical(const Quat& q) {
  Quat n = q.normalized();
  if (n.w() < 0.0) n.coeffs() = -n.coeffs();
  return n;
}

}  // namespace bsn::fusion
