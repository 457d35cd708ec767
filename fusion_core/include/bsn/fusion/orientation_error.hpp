// Orientation error metrics as BROAD defines them (Laidig et al. 2021), for evaluation against a reference.
#pragma once

#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion {

/// Error of an estimate against a reference, radians. With e = q_est * conj(q_ref) (earth frame):
/// total = 2 acos|e.w|, heading = 2 atan|e.z / e.w|, inclination = 2 acos sqrt(e.w^2 + e.z^2).
struct ErrorAngles {
  double total = 0.0;
  double heading = 0.0;
  double inclination = 0.0;
};

ErrorAngles error_angles(const Quat& q_est, const Quat& q_ref);

/// Accumulates root-mean-square errors over samples.
class RmsErrorAccumulator {
 public:
  void add(const ErrorAngles& e) {
    total_sq_ += e.total * e.total;
    heading_sq_ += e.heading * e.heading;
    inclination_sq_ += e.inclination * e.inclination;
    ++count_;
  }
  std::size_t count() const { return count_; }
  /// RMS of each angle, radians; zeros when empty.
  ErrorAngles rms() const;

 private:
  double total_sq_ = 0.0, heading_sq_ = 0.0, inclination_sq_ = 0.0;
  std::size_t count_ = 0;
};

}  // namespace bsn::fusion
