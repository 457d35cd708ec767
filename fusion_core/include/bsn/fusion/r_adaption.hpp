// R-adaption for the Kalman filters (Fan et al. 2018, §2.2.1 eq. 10): while the magnetic field is disturbed the
// magnetometer's measurement variance is set to infinity, so the filter does not trust it; otherwise it keeps its
// nominal value. The disturbance is judged by the shared MagDisturbanceDetector (low-passed magnitude and dip, two
// thresholds, a minimum clean time, the lag tolerance, a new field after a steady disturbance, and the reduced gain
// after a long rejection, which here multiplies the variance by 1 / mag_reduced_gain^2).
#pragma once

#include <cstdint>
#include <limits>

#include "bsn/fusion/mag_disturbance_detector.hpp"
#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion {

class MagneticRAdaption {
 public:
  /// Throws std::invalid_argument on bad thresholds (MagDisturbanceDetector's checks).
  explicit MagneticRAdaption(const MagDisturbanceDetector::Params& params) : detector_(params) {}
  MagneticRAdaption() : MagneticRAdaption(MagDisturbanceDetector::Params{}) {}

  /// A reference field: magnitude and the sine of its dip (the filters derive it once, at their start).
  struct Reference {
    double norm = 0.0;     ///< |h_ref|, uT; 0 = not known yet
    double sin_dip = 0.0;  ///< sine of the dip below the horizontal, positive downwards
    /// The reference of field m in a frame whose unit upward vertical is `up`.
    static Reference of(const Vec3& m, const Vec3& up);
  };
  /// Judges reading m with `up` the estimated unit vertical in m's frame (Fan eq. 17) and rate_rad_s the horizontal
  /// angular rate (lag tolerance). A `ref` other than the last one passed becomes the detector's reference (the
  /// detector then lets it follow the clean field). Returns the factor for the nominal measurement variance: 1
  /// (trusted), +infinity (disturbed, eq. 10), or 1 / mag_reduced_gain^2 after mag_accept_after_s of rejection.
  double update(std::uint64_t t_ns, const Vec3& m, const Vec3& up, const Reference& ref, double rate_rad_s = 0.0,
                double dt_s = 0.0);

  /// True while the field is judged disturbed (including the clean waiting period).
  bool disturbed() const { return detector_.disturbed(); }
  const MagDisturbanceDetector& detector() const { return detector_; }

  /// Forgets the history: the next sample is judged on its own.
  void reset() {
    detector_.reset();
    last_ref_ = Reference{};
  }

  static constexpr double kInfiniteVariance = std::numeric_limits<double>::infinity();

 private:
  MagDisturbanceDetector detector_;
  Reference last_ref_;  ///< the reference last passed in (norm 0: none)
};

}  // namespace bsn::fusion
