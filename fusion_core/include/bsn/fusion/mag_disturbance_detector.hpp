// Magnetic-disturbance detection on field magnitude and dip angle (Fan et al. 2018, sections 2.2.1 and 5.1), shared
// by every filter that rejects the magnetometer (seel_ruppin, iecf, complementary, and through MagneticRAdaption ekf,
// mekf and dlkf).
// A ferromagnetic object changes |m| and the dip angle of the field. After Laidig & Seel's VQF (2023) both are
// low-passed before they are judged (mag_lowpass_tau_s): the decision then rests on the field, not on one reading's
// noise, so the thresholds can sit well below the disturbances to be caught and well above the noise (Fan's test B
// brings a magnet that changes |m| by 7.6 % and the dip by 7.4 deg; a single reading's noise is 0.9 % and 0.5 deg).
//   - disturbed as soon as the low-passed |m| or dip leaves the outer band (enter thresholds);
//   - clean again only after both have stayed inside the inner band (leave thresholds) for mag_min_clean_s (one
//     threshold chatters, and a filter that takes the samples which happen to dip below it is corrupted: Fan's E);
//   - the reference magnitude and dip start as the first reading after reset() (or as set_reference()) and then
//     follow the low-passed field while it is clean, as a running mean over the first mag_reference_tau_s and an
//     exponential one afterwards (VQF's magRefTau): one reading's noise does not stay in every later decision.
// Three rules keep a clean field in motion from looking disturbed, and a long disturbance from costing the heading
// (the last two after VQF):
//   - rate tolerance: a magnetometer reading lags the gyro (it is sampled before it, or averages over its own
//     bandwidth), so while the sensor turns at |w| the field it reports is the field of an orientation |w| * latency
//     ago (one sample, plus its own averaging delay) and its dip, seen with the current vertical, is off by up to |w| *
//     mag_latency_s. Both dip thresholds are widened by that much (held over the low-pass's memory); the magnitude,
//     which a lag does not change, is not;
//   - a new field (off by default, see mag_max_rejection_s): a disturbance whose field stays the same (within the
//     enter thresholds of the first reading of the run) for mag_max_rejection_s becomes the new reference, while a
//     field that keeps changing, like that of a magnet moving near the sensor, is never adopted;
//   - no heading collapse: after mag_accept_after_s of rejection (a budget that refills at twice the speed while the
//     field is clean), the magnetometer is used again with its gain reduced to mag_reduced_gain, so heading error
//     stays bounded by the disturbance instead of growing with gyro drift for ever.
// Per reading in a clean field it takes one square root, no division and no trigonometry: |m| sin(dip) is low-passed
// and judged against the sines of the band limits (asin is monotonic) times |m|, bounds derived from the reference's
// sine and cosine; only a reading outside the inner band while the sensor turns, or a disturbed one, takes an asin.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string_view>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/imu_sample.hpp"
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

/// A magnetometer reading that lags the gyro by lag_s, brought forward to the gyro's time with the current angular
/// rate (sensor frame, rad/s): a field fixed in the earth turns in the sensor frame as dm/dt = -w x m, so
/// m(t) = m(t - lag) - lag w x m(t - lag) to first order (at 1000 deg/s and 6.4 ms the neglected term is 0.6 %).
inline Vec3 lag_compensated(const Vec3& mag, const Vec3& rate_rad_s, double lag_s) {
  return mag - lag_s * rate_rad_s.cross(mag);
}

/// The magnetometer reading of `s` at its gyro's time: brought forward by lag_s with the bias-corrected rate
/// (lag_compensated), so that a fast turn does not pull the heading towards where the sensor pointed lag_s ago;
/// s.mag as it is without a magnetometer or gyro reading, or without lag.
inline Vec3 mag_at_gyro_time(const ImuSample& s, const Vec3& gyro_bias, double lag_s) {
  return s.has_mag && s.has_gyr && lag_s > 0.0 ? lag_compensated(s.mag, s.gyr - gyro_bias, lag_s) : s.mag;
}

class MagDisturbanceDetector {
 public:
  /// Detector thresholds. The Params of a filter that uses the detector derive from this struct, so the field
  /// names are the filter parameter names (mag_disturbance_param_fields() lists them).
  struct Params {
    /// Disturbed when | |m|_lp - ref | / ref exceeds this fraction. Default 0.10 (VQF's magNormTh): on the BROAD
    /// trials in a clean field |m| varies with the orientation by up to 6 % (90th percentile of the fast translation;
    /// residual calibration and the room's gradient), so a tighter bound rejects a clean field.
    double mag_norm_enter = 0.10;
    /// Clean again only below this fraction (<= mag_norm_enter). Default 0.07: above what a clean BROAD field
    /// shows on most samples (90th percentile 3-6 %), so a disturbance that has gone is trusted again.
    double mag_norm_leave = 0.07;
    /// Disturbed when |dip_lp - ref_dip| exceeds this, rad. Default 0.105 rad (6 deg): above the dip's spread in a
    /// clean field with the filter's own vertical, below the 7.4 deg by which Fan et al.'s test B magnet turns it
    /// (while |m| changes by only 7.6 %, so the dip is what catches it).
    double mag_dip_enter_rad = 0.105;
    /// Clean again only below this, rad (<= mag_dip_enter_rad). Default 0.07 rad (4 deg).
    double mag_dip_leave_rad = 0.07;
    /// Both must stay inside the leave band this long before the field is trusted again, s. Default 0.5 s (VQF's
    /// magMinUndisturbedTime).
    double mag_min_clean_s = 0.5;
    /// Time constant of the first-order low-pass of |m| and of the dip's sine, s; 0 = judge each reading. Default
    /// 0.02 s: it takes the noise of a 50 Hz reading down by 1.7x (VQF's magCurrentTau is 0.05 s; shorter here, so
    /// that a magnet approaching in tenths of a second, as in Fan's test B, is flagged within two readings).
    double mag_lowpass_tau_s = 0.02;
    /// The reference follows the clean low-passed field with this time constant, s (a running mean until then).
    /// Default 20 s (VQF's magRefTau): long against any disturbance that should be caught, short against a session.
    double mag_reference_tau_s = 20.0;
    /// The magnetometer's own delay behind the gyro beyond one sample, s: the dip test tolerates a lag of one sample
    /// interval (a reading taken just before the gyro's) plus this, i.e. both dip thresholds widen by
    /// |w_h| (dt + mag_latency_s); seel_ruppin, iecf, complementary, ekf and mekf also bring each reading forward by
    /// it (lag_compensated). 0 = a magnetometer in step with the gyro. Default 0.0064 s: the group delay
    /// 1 / (2 pi f_c) of a magnetometer averaging with a first-order corner f_c = 25 Hz (a part sampled at 100 Hz
    /// averages well below its 50 Hz Nyquist limit).
    double mag_latency_s = 0.0064;
    /// A disturbance whose field stays the same for this long becomes the new reference field, s; 0 = never. Default
    /// 0 (off): a steady disturbed field cannot be told from a new earth field by |m| and the dip alone, and adopting
    /// it costs the heading for the rest of the disturbance and again once it ends (Fan et al.'s test E). A wrong
    /// reference (a start next to a magnet) still cannot shut the magnetometer out for good: mag_accept_after_s lets
    /// it in again.
    double mag_max_rejection_s = 0.0;
    /// After this much rejection time the magnetometer is used again with the reduced gain, s. Default 60 s
    /// (VQF's magMaxRejectionTime): a minute of gyro-only heading drifts by well under 1 deg with a bias
    /// estimate, while an unending rejection lets the heading drift without bound.
    double mag_accept_after_s = 60.0;
    /// The gain factor for a field used after mag_accept_after_s, 0..1. Default 0.5 (VQF's magRejectionFactor 2).
    double mag_reduced_gain = 0.5;
  };

  /// Bounds of the two bands for the current reference: |m| in uT, and sin(dip) (2 or -2 where the angle
  /// bound lies beyond +-90 deg, so that the comparison always or never holds as it would for the angle).
  /// Derived from the reference whenever it moves, so they belong to the state.
  struct Bounds {
    double norm_enter_low = 0.0, norm_enter_high = 0.0, norm_leave_low = 0.0, norm_leave_high = 0.0;
    double sin_enter_low = 0.0, sin_enter_high = 0.0, sin_leave_low = 0.0, sin_leave_high = 0.0;
  };

  struct State {
    bool reference_known = false;
    double ref_norm = 0.0;          ///< reference |m|, uT
    double ref_sin_dip = 0.0;       ///< sine of the reference dip angle (positive: field points below horizontal)
    double ref_cos_dip = 1.0;       ///< its cosine (>= 0)
    double ref_clean_s = 0.0;       ///< clean time the reference has averaged over, s (capped at mag_reference_tau_s)
    double ref_pending_s = 0.0;     ///< clean time not yet taken into the reference, s
    double ref_pending_norm = 0.0;  ///< its integral of |m|_lp, uT s
    double ref_pending_down = 0.0;  ///< its integral of |m|_lp sin(dip), uT s
    double lowpass_dt = -1.0;       ///< the reading interval the low-pass step was derived for, s
    double lowpass_k = 0.0;         ///< that step, dt / (mag_lowpass_tau_s + dt)
    bool lowpass_started = false;
    double lp_norm = 0.0;        ///< low-passed |m|, uT
    double lp_down = 0.0;        ///< low-passed |m| sin(dip) = -(m . up), uT
    double dip_tolerance = 0.0;  ///< rad: the lag tolerance, held over the low-pass's memory
    bool disturbed = false;
    bool inside_leave_band = false;     ///< the last sample was inside the inner band
    std::uint64_t inside_since_ns = 0;  ///< start of the current stay inside the inner band
    std::uint64_t last_ns = 0;          ///< time of the last valid reading (0: none since reset)
    RejectionBudget budget;             ///< rejection time spent (see mag_accept_after_s)
    double candidate_norm = 0.0;        ///< uT: the field of the current disturbance, a candidate reference
    double candidate_dip = 0.0;         ///< rad
    std::uint64_t candidate_since_ns = 0;
    bool candidate = false;  ///< a candidate is being timed
    Bounds bounds;           ///< of the current reference
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

  /// Sets the reference instead of taking the first reading; it then follows the clean field as described above,
  /// weighted as a mean over averaged_s of clean field.
  void set_reference(double norm_uT, double dip_rad, double averaged_s = 0.0);
  /// The same from the sine of the dip (positive downwards), as the Kalman filters hold their reference field.
  void set_reference_sine(double norm_uT, double sin_dip, double averaged_s = 0.0);

  bool disturbed() const { return state_.disturbed; }
  /// | |m|_lp - ref | / ref after the last sample (computed on demand).
  double last_norm_deviation() const;
  /// |dip_lp - ref_dip| after the last sample, rad (computed on demand).
  double last_dip_deviation() const;
  const Params& params() const { return params_; }
  void reset() { state_ = State{}; }
  const State& state() const { return state_; }
  void set_state(const State& state) { state_ = state; }

 private:
  /// The reference from its magnitude and the sine of its dip, and the bands' bounds derived without trigonometry
  /// (what the clean field's following moves; the public setters also restart that averaging).
  void set_reference_bounds(double norm_uT, double sin_dip);
  /// The new-field rule for a reading judged disturbed (after the band decision and the rejection budget).
  void track_new_field(std::uint64_t t_ns);

  Params params_;
  std::uint64_t min_clean_ns_ = 0;
  std::uint64_t max_rejection_ns_ = 0;
  double sin_enter_ = 0.0, cos_enter_ = 1.0, sin_leave_ = 0.0, cos_leave_ = 1.0;  ///< of the dip thresholds
  bool enter_beyond_pi_ = false, leave_beyond_pi_ = false;                        ///< a dip threshold >= pi: never out
  State state_;
};

/// The detector thresholds' entries of a filter's parameter table (P derives from MagDisturbanceDetector::Params).
template <class P>
constexpr std::array<ParamField<P>, 11> mag_disturbance_param_fields() {
  return {{{"mag_norm_enter", &P::mag_norm_enter},
           {"mag_norm_leave", &P::mag_norm_leave},
           {"mag_dip_enter_rad", &P::mag_dip_enter_rad},
           {"mag_dip_leave_rad", &P::mag_dip_leave_rad},
           {"mag_min_clean_s", &P::mag_min_clean_s},
           {"mag_lowpass_tau_s", &P::mag_lowpass_tau_s},
           {"mag_reference_tau_s", &P::mag_reference_tau_s},
           {"mag_latency_s", &P::mag_latency_s},
           {"mag_max_rejection_s", &P::mag_max_rejection_s},
           {"mag_accept_after_s", &P::mag_accept_after_s},
           {"mag_reduced_gain", &P::mag_reduced_gain}}};
}

/// The magnetometer rejection of a filter under its filter parameter names: the detector's thresholds and rules and
/// the switch. The Params of every filter that rejects the magnetometer derive from it (seel_ruppin, iecf,
/// complementary, and the Kalman filters through MagneticRAdaption).
struct MagRejectionParams : MagDisturbanceDetector::Params {
  /// 1 = the magnetometer is not used (a Kalman filter gives it infinite variance, Fan eq. 10) while the detector
  /// flags the field; 0 = always use it (the papers' filters). Default 1: a magnet near the sensor otherwise turns
  /// the heading (Fan et al.'s test B).
  double mag_rejection = 1.0;

  const MagDisturbanceDetector::Params& thresholds() const { return *this; }
  /// Throws std::invalid_argument, naming `owner`, unless mag_rejection is 0 or 1 (the detector checks the
  /// thresholds).
  void check(std::string_view owner) const { require_switch(owner, mag_rejection, "mag_rejection"); }
};

/// The switch and the detector thresholds' entries of a filter's parameter table (P derives from MagRejectionParams).
template <class P>
constexpr std::array<ParamField<P>, 12> mag_rejection_param_fields() {
  return join_param_fields<P>(std::array<ParamField<P>, 1>{{{"mag_rejection", &P::mag_rejection}}},
                              mag_disturbance_param_fields<P>());
}

}  // namespace bsn::fusion
