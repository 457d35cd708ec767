#include "bsn/fusion/orientation_error.hpp"

#include <algorithm>
#include <cmath>

namespace bsn::fusion {

ErrorAngles error_angles(const Quat& q_est, const Quat& q_ref) {
  const Quat e = (q_est * q_ref.conjugate()).normalized();
  const double w = std::abs(e.w());
  ErrorAngles out;
  out.total = 2.0 * std::acos(std::clamp(w, 0.0, 1.0));
  // atan of |z/w| written with atan2 so that w = 0 (a 180 deg heading error) is handled.
  out.heading = 2.0 * std::atan2(std::abs(e.z()), w);
  out.inclination = 2.0 * std::acos(std::clamp(std::sqrt(e.w() * e.w() + e.z() * e.z()), 0.0, 1.0));
  return out;
}

ErrorAngles RmsErrorAccumulator::rms() const {
  if (count_ == 0) return {};
  const double n = static_cast<double>(count_);
  return {std::sqrt(total_sq_ / n), std::sqrt(heading_sq_ / n), std::sqrt(inclination_sq_ / n)};
}

}  // namespace bsn::fusion
