// Magnetic-disturbance detection on field magnitude and dip angle (Fan et al. 2018, sections 2.2.1 and 5.1).
// A ferromagnetic object changes |m| and the dip angle of the field. One threshold chatters when the field
// hovers near it, and a filter that takes the samples which happen to dip below it is corrupted (Fan's
// test E), so the detector uses two thresholds and a minimum duration:
//   - disturbed as soon as |m| or the dip leaves the outer band (enter thresholds);
//   - clean again only after both have stayed inside the inner band (leave thresholds) for min_clean_s.
// The reference magnitude and dip are the first ones seen after reset(), unless set explicitly.
// Three rules keep a clean field in motion from looking disturbed, and a long disturbance from costing the heading
// (issue 12; the last two after Laidig & Seel's VQF, 2023):
//   - rate tolerance: a magnetometer reading lags the gyro (it is sampled before it, or averages over its own
//     bandwidth), so while the sensor turns at |w| the field it reports is the field of an orientation |w| * latency
//     ago (one sample, plus its own averaging delay) and its dip, seen with the current vertical, is off by up to |w| *
//     mag_latency_s. Both dip thresholds are widened by that much (at 1000 deg/s and 20 ms: 20 deg); the magnitude,
//     which a lag does not change, is not;
//   - a new field: a disturbance whose field stays the same (within the enter thresholds of the first reading of
//     the run) for mag_max_rejection_s becomes the new reference: a wrong reference (a start next to a magnet, a
//     room whose field differs from where the filter started) would otherwise shut the magnetometer out for good,
//     while a field that keeps changing, like that of a magnet moving near the sensor, is never adopted;
//   - no heading collapse: after mag_accept_after_s of rejection (a budget that refills at twice the speed while the
//     field is clean), the magnetometer is used again with its gain reduced to mag_reduced_gain, so heading error
//     stays bounded by the disturbance instead of growing with gyro drift for ever.
// Per sample in a clean field it takes one square root and no trigonometry: the dip thresholds are compared as
// sines (asin is monotonic), against bounds derived once when the reference is set; only a reading outside the
// inner band while the sensor turns takes an asin.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion {

/// The rejection budget shared by every magnetometer rejection in bsn (MagDisturbanceDetector and the Kalman
/// filters' MagneticRAdaption), after VQF: rejection time is spent while the field is disturbed and refilled at
/// twice the speed while it is clean; once more than `accept_after_s` is spent, a disturbed field is used again
/// with a reduced gain, so the heading error stays bounded by the disturbance instead of growing with gyro drift.
class RejectionBudget {
 public:
  /// Advances by dt_s (>= 0) with the decision of this reading; returns spent().
  bool update(double dt_s, bool disturbed, double accept_after_s) {
    rejected_s_ = disturbed ? rejected_s_ + dt_s : std::max(0.0, rejected_s_ - 2.0 * dt_s);
    spent_ = disturbed && rejected_s_ > accept_after_s;
    return spent_;
  }
  bool spent() const { return spent_; }
  double rejected_s() const { return rejected_s_; }
  void reset() { *this = RejectionBudget{}; }

 private:
  double rejected_s_ = 0.0;
  bool spent_ = false;
};

/// The dip tolerance for a magnetometer that lags the gyro by up to latency_s while the sensor turns at
/// rate_rad_s: the field it reports is that of an orientation rate * latency ago, so its dip seen with the current
/// vertical is off by up to that angle, rad.
inline double lag_dip_tolerance(double rate_rad_s, double latency_s) { return std::abs(rate_rad_s) * latency_s; }

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
    /// The magnetometer's own delay behind the gyro beyond one sample, s: the dip test tolerates a lag of one
    /// sample interval (a reading taken just before the gyro's) plus this, i.e. both dip thresholds widen by
    /// |w_h| (dt + mag_latency_s). Default 0.0064 s: the group delay 1 / (2 pi f_c) of a magnetometer averaging
    /// with a first-order corner f_c = 25 Hz (a part sampled at 100 Hz averages well below its 50 Hz Nyquist
    /// limit). The simulated case (1000 deg/s, one sample of lag, 25 Hz bandwidth) is accepted on >= 95 % with it.
    double mag_latency_s = 0.0064;
    /// A disturbance whose field stays the same for this long becomes the new reference field, s. Default 20 s
    /// (VQF's magNewTime; longer than any magnet held near a sensor in Fan's tests B and E).
    double mag_max_rejection_s = 20.0;
    /// After this much rejection time the magnetometer is used again with the reduced gain, s. Default 60 s
    /// (VQF's magMaxRejectionTime): a minute of gyro-only heading drifts by well under 1 deg with a bias
    /// estimate, while an unending rejection lets the heading drift without bound.
    double mag_accept_after_s = 60.0;
    /// The gain factor for a field used after mag_accept_after_s, 0..1. Default 0.5 (VQF's magRejectionFactor 2).
    double mag_reduced_gain = 0.5;
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
    double dip_tolerance = 0.0;         ///< rad: |w| mag_latency_s of the last sample
    std::uint64_t last_ns = 0;          ///< time of the last valid reading (0: none since reset)
    RejectionBudget budget;             ///< rejection time spent (see mag_accept_after_s)
    double candidate_norm = 0.0;        ///< uT: the field of the current disturbance, a candidate reference
    double candidate_dip = 0.0;         ///< rad
    std::uint64_t candidate_since_ns = 0;
    bool candidate = false;  ///< a candidate is being timed
  };

  /// Throws std::invalid_argument on a non-positive or non-finite parameter, or a leave threshold above its
  /// enter threshold.
  explicit MagDisturbanceDetector(const Params& params);
  MagDisturbanceDetector() : MagDisturbanceDetector(Params{}) {}

  /// Dip angle of the field m seen from a frame whose unit "up" is up, rad: asin(-(m . up) / |m|).
  static double dip_angle(const Vec3& m, const Vec3& up);

  /// Feeds one magnetometer reading (sensor frame), taken dt_s after the previous sample, the unit up direction in the
  /// same frame (e.g. from the filter's current orientation, as in Fan's eq. 17) and the horizontal part of the
  /// sensor's angular rate |w x up|, rad/s, the part that turns the dip (0: no rate tolerance). Returns disturbed(). A
  /// zero or non-finite field counts as disturbed; the first valid reading after reset() becomes the reference.
  bool update(std::uint64_t t_ns, const Vec3& mag, const Vec3& up, double rate_rad_s = 0.0, double dt_s = 0.0);

  /// True when the filter may use the reading: clean, or disturbed for longer than mag_accept_after_s.
  bool usable() const { return !state_.disturbed || state_.budget.spent(); }
  /// The factor for the filter's magnetometer gain: 1 clean, mag_reduced_gain when used after a long rejection.
  double gain_factor() const { return state_.disturbed && state_.budget.spent() ? params_.mag_reduced_gain : 1.0; }

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

  /// The rules for a long disturbance (new field, reduced gain) after the band decision of a reading.
  void track_disturbance(std::uint64_t t_ns, double norm, double dip);

  Params params_;
  std::uint64_t min_clean_ns_ = 0;
  std::uint64_t max_rejection_ns_ = 0;
  Bounds bounds_;
  State state_;
};

/// The detector thresholds' entries of a filter's parameter table (P derives from MagDisturbanceDetector::Params).
template <class P>
constexpr std::array<ParamField<P>, 9> mag_disturbance_param_fields() {
  return {{{"mag_norm_enter", &P::mag_norm_enter},
           {"mag_norm_leave", &P::mag_norm_leave},
           {"mag_dip_enter_rad", &P::mag_dip_enter_rad},
           {"mag_dip_leave_rad", &P::mag_dip_leave_rad},
           {"mag_min_clean_s", &P::mag_min_clean_s},
           {"mag_latency_s", &P::mag_latency_s},
           {"mag_max_rejection_s", &P::mag_max_rejection_s},
           {"mag_accept_after_s", &P::mag_accept_after_s},
           {"mag_reduced_gain", &P::mag_reduced_gain}}};
}

}  // namespace bsn::fusion
