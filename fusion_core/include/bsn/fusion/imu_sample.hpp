#pragma once

#include <cmath>
#include <cstdint>

#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion {

/// A duration in seconds (how parameters give it) as nanoseconds (how samples are timed), rounded to the nearest.
inline std::uint64_t seconds_to_ns(double s) { return static_cast<std::uint64_t>(std::llround(s * 1e9)); }

/// One MIMU sample in the sensor frame, SI units (see rotation.hpp for the frames).
struct ImuSample {
  std::uint64_t timestamp_ns = 0;  ///< sensor clock, ns; filters take dt from consecutive timestamps
  Vec3 acc = Vec3::Zero();         ///< specific force, m/s^2 (+g on the up axis at rest)
  Vec3 gyr = Vec3::Zero();         ///< angular rate, rad/s
  Vec3 mag = Vec3::Zero();         ///< magnetic field, uT
  bool has_acc = true;
  bool has_gyr = true;
  bool has_mag = true;  ///< false for a sample without magnetometer reading (6D update)

  /// True when every value of every present channel is finite (no NaN, no Inf).
  bool values_finite() const {
    return (!has_acc || acc.allFinite()) && (!has_gyr || gyr.allFinite()) && (!has_mag || mag.allFinite());
  }

  /// True when the values and the squared norms of every present channel are finite: the sample can be used in
  /// arithmetic without overflowing (1e300 is a finite value whose square is not). Filters reject anything else.
  /// A squared norm is finite exactly when every component is finite and the sum does not overflow, so this one
  /// test covers values_finite() too.
  bool finite() const {
    return (!has_acc || std::isfinite(acc.squaredNorm())) && (!has_gyr || std::isfinite(gyr.squaredNorm())) &&
           (!has_mag || std::isfinite(mag.squaredNorm()));
  }
};

}  // namespace bsn::fusion
