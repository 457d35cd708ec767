// Small pieces the Kalman filters (MEKF, EKF, DLKF) share. Private to fusion_core.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "bsn/fusion/imu_sample.hpp"

namespace bsn::fusion::kalman_support {

using Mat3 = Eigen::Matrix3d;

inline std::uint64_t seconds_to_ns(double s) { return static_cast<std::uint64_t>(std::llround(s * 1e9)); }

/// Cross-product matrix: skew(a) * b = a x b.
inline Mat3 skew(const Vec3& a) {
  Mat3 m;
  m << 0.0, -a.z(), a.y(), a.z(), 0.0, -a.x(), -a.y(), a.x(), 0.0;
  return m;
}

/// True when acc and mag give a well-defined TRIAD orientation (neither zero nor parallel).
inline bool acc_mag_usable(const Vec3& acc, const Vec3& mag) {
  const double na = acc.norm(), nm = mag.norm();
  return na > 1e-6 && nm > 1e-9 && acc.cross(mag).norm() > 1e-3 * na * nm;
}

/// Dip angle of the field m below the horizontal plane whose upward normal is up (unit), rad, positive downwards
/// (Fan eq. 17 with the estimated vertical).
inline double dip_angle(const Vec3& m, const Vec3& up) {
  const double n = m.norm();
  if (!(n > 0.0)) return 0.0;
  return std::asin(std::clamp(-m.dot(up) / n, -1.0, 1.0));
}

/// The rest flag: gyro norm and accelerometer deviation from g below thresholds for at least min_ns. still and
/// still_since_ns are the caller's state.
inline bool update_rest(bool& still, std::uint64_t& still_since_ns, const ImuSample& s, double gyr_max, double acc_max,
                        std::uint64_t min_ns) {
  const bool still_now =
      s.has_gyr && s.has_acc && s.gyr.norm() < gyr_max && std::abs(s.acc.norm() - kGravity) < acc_max;
  if (!still_now) {
    still = false;
  } else if (!still) {
    still = true;
    still_since_ns = s.timestamp_ns;
  }
  return still && s.timestamp_ns - still_since_ns >= min_ns;
}

/// Makes a covariance symmetric and clamps its diagonal away from zero and from overflow, so that rounding never
/// lets it lose positive definiteness.
template <class Mat>
void condition_covariance(Mat& p, double min_variance, double max_variance) {
  p = 0.5 * (p + p.transpose()).eval();
  for (int i = 0; i < p.rows(); ++i) p(i, i) = std::clamp(p(i, i), min_variance, max_variance);
}

}  // namespace bsn::fusion::kalman_support
