// The orientation every filter starts from (and re-initialises to after a gap): TRIAD from the accelerometer
// and the magnetometer when the field gives a heading, else the tilt from the accelerometer with zero yaw.
#pragma once

#include <optional>

#include "bsn/fusion/imu_sample.hpp"
#include "bsn/fusion/orientation_filter.hpp"

namespace bsn::fusion {

struct StartOrientation {
  Quat q = Quat::Identity();  ///< sensor-to-earth
  bool with_mag = false;      ///< the heading comes from the magnetometer
};

/// True when the sample's magnetometer gives a heading: a field that is neither zero (|m| > 1e-9 uT) nor within
/// min_sin_angle (sine of the angle) of the accelerometer's direction. Needs |acc| > 1e-6 m/s^2.
inline bool heading_from_mag_possible(const ImuSample& s, double min_sin_angle = 1e-3) {
  if (!s.has_mag || !s.has_acc) return false;
  const double mag_norm = s.mag.norm(), acc_norm = s.acc.norm();
  return mag_norm > 1e-9 && acc_norm > 1e-6 && s.mag.cross(s.acc).norm() > min_sin_angle * mag_norm * acc_norm;
}

/// The start orientation from one sample; nullopt without a usable accelerometer (|acc| <= 1e-6 m/s^2: no
/// direction of gravity). min_sin_angle as for heading_from_mag_possible().
inline std::optional<StartOrientation> start_orientation(const ImuSample& s, double min_sin_angle = 1e-3) {
  if (!s.has_acc || !(s.acc.norm() > 1e-6)) return std::nullopt;
  const bool with_mag = heading_from_mag_possible(s, min_sin_angle);
  return StartOrientation{with_mag ? orientation_from_acc_mag(s.acc, s.mag) : orientation_from_acc(s.acc), with_mag};
}

/// The flags of the update that (re)initialised a filter: initialising and reinitialised, not resting.
inline FilterFlags start_flags(bool mag_rejected) {
  FilterFlags flags;
  flags.initialising = true;
  flags.reinitialised = true;
  flags.mag_rejected = mag_rejected;
  return flags;
}

}  // namespace bsn::fusion
