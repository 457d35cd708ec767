// Magnetic-disturbance detection on field magnitude and dip angle (Fan et al. 2018, sections 2.2.1 and 5.1).
// A ferromagnetic object changes |m| and the dip angle of the field. One threshold chatters when the field
// hovers near it, and a filter that takes the samples which happen to dip below it is corrupted (Fan's
// test E), so the detector uses two thresholds and a minimum duration:
//   - disturbed as soon as |m| or the dip leaves the outer band (enter thresholds);
//   - clean again only after both have stayed inside the inner band (leave thresholds) for min_clean_s.
// The reference magnitude and dip are the first ones seen after reset(), unless set explicitly.
// Per sample it takes one square root and no trigonometry: the dip thresholds are compared as sines
// (asin is monotonic), against bounds derived once when the reference is set.
#pragma once

#include <array>
#include <cstdint>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion {

class MagDisturbanceDetector {
 public:
  /// Detector thresholds. The Params of a filter that uses the detector derive from this struct, so the field
  /// names are the filter parameter names (mag_disturbance_param_fields() lists them).
  struct Params {
    /// Disturbed when | |m| - ref | / ref exceeds this fraction. Default 0.10.
    double mag_norm_enter = 0.10;
    /// Clean again only below this fraction (<= mag_norm_enter). Default 0.05 (Fan's test E threshold).
    double mag_norm_leave = 0.05;
    /// Disturbed when |dip - ref_dip| exceeds this, rad. Default 0.14 rad (8 deg).
    double mag_dip_enter_rad = 0.14;
    /// Clean again only below this, rad (<= mag_dip_enter_rad). Default 0.07 rad (4 deg).
    double mag_dip_leave_rad = 0.07;
    /// Both must stay inside the leave band this long before the field is trusted again, s. Default 1 s.
    double mag_min_clean_s = 1.0;
  };

  struct State {
    bool reference_known = false;
    double ref_norm = 0.0;  ///< reference |m|, uT
    double ref_dip = 0.0;   ///< reference dip angle, rad (positive: field points below horizontal)
    bool disturbed = false;
    bool inside_leave_band = false;     ///< the last sample was inside the inner band
    std::uint64_t inside_since_ns = 0;  ///< start of the current stay inside the inner band
    double last_norm = 0.0;             ///< |m| of the last sample, uT
    double last_down = 0.0;             ///< -(m . up) of the last sample, uT: |m| sin(dip)
  };

  /// Throws std::invalid_argument on a non-positive or non-finite parameter, or a leave threshold above its
  /// enter threshold.
  explicit MagDisturbanceDetector(const Params& params);
  MagDisturbanceDetector() : MagDisturbanceDetector(Params{}) {}

  /// Dip angle of the field m seen from a frame whose unit "up" is up, rad: asin(-(m . up) / |m|).
  static double dip_angle(const Vec3& m, const Vec3& up);

  /// Feeds one magnetometer reading (sensor frame) and the unit up direction in the same frame (e.g. from the
  /// filter's current orientation, as in Fan's eq. 17). Returns disturbed(). A zero or non-finite field
  /// counts as disturbed; the first valid reading after reset() becomes the reference.
  bool update(std::uint64_t t_ns, const Vec3& mag, const Vec3& up);

  /// Fixes the reference instead of learning it from the first reading.
  void set_reference(double norm_uT, double dip_rad);

  bool disturbed() const { return state_.disturbed; }
  /// | |m| - ref | / ref of the last sample (computed on demand).
  double last_norm_deviation() const;
  /// |dip - ref_dip| of the last sample, rad (computed on demand).
  double last_dip_deviation() const;
  void reset() { state_ = State{}; }
  const State& state() const { return state_; }

 private:
  /// Bounds of the two bands for the current reference: |m| in uT, and sin(dip) (2 or -2 where the angle
  /// bound lies beyond +-90 deg, so that the comparison always or never holds as it would for the angle).
  struct Bounds {
    double norm_enter_low = 0.0, norm_enter_high = 0.0, norm_leave_low = 0.0, norm_leave_high = 0.0;
    double sin_enter_low = 0.0, sin_enter_high = 0.0, sin_leave_low = 0.0, sin_leave_high = 0.0;
  };

  Params params_;
  std::uint64_t min_clean_ns_ = 0;
  Bounds bounds_;
  State state_;
};

/// The detector thresholds' entries of a filter's parameter table (P derives from MagDisturbanceDetector::Params).
template <class P>
constexpr std::array<ParamField<P>, 5> mag_disturbance_param_fields() {
  return {{{"mag_norm_enter", &P::mag_norm_enter},
           {"mag_norm_leave", &P::mag_norm_leave},
           {"mag_dip_enter_rad", &P::mag_dip_enter_rad},
           {"mag_dip_leave_rad", &P::mag_dip_leave_rad},
           {"mag_min_clean_s", &P::mag_min_clean_s}}};
}

}  // namespace bsn::fusion
