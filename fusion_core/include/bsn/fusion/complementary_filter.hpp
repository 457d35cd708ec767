// A plain complementary filter: strapdown gyro integration, a tilt correction towards the accelerometer
// and a heading-only correction towards the horizontal magnetic field, each a first-order low-pass with
// an interpretable time constant. It is the reference the seed filters must beat. Two additions keep it usable with
// a consumer gyro in human motion, each with a switch back to the plain filter: the gyro bias is learned
// at rest only (Fan et al.'s low-pass, GyroBiasLowPass; no bias estimation in motion), and one tilt correction acts
// on at most max_acc_error_rad of the angle to the accelerometer's up (as seel_ruppin's clip). The magnetometer is
// judged by the shared MagDisturbanceDetector (|m| and dip, with its rules for a lagging magnetometer and for a long
// disturbance, see mag_disturbance_detector.hpp), and each reading is brought forward by mag_latency_s, as in the
// other filters that reject it.
#pragma once

#include <string_view>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/gyro_bias_lowpass.hpp"
#include "bsn/fusion/mag_disturbance_detector.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/rest_detector.hpp"

namespace bsn::fusion {

class ComplementaryFilter final : public OrientationFilter {
 public:
  /// Own fields below; the rest bias low-pass, rest detection and the gap and start-up timing come from the base
  /// structs (documented there). During the start-up period (init_period_s) the tilt correction is not clipped.
  struct Params : GyroBiasLowPass::Params, MagDisturbanceDetector::Params, RestDetector::Params, FilterTimingParams {
    /// Time constant of the tilt correction towards the accelerometer, s. Larger trusts the gyro longer
    /// (less sensitive to accelerations), smaller removes gyro drift faster. Default 2 s.
    double tau_acc_s = 2.0;
    /// Time constant of the heading correction towards the magnetometer, s. Default 4 s.
    double tau_mag_s = 4.0;
    /// The accelerometer is skipped when | |acc| - g | exceeds this, m/s^2 (strong external acceleration); 0 =
    /// never. Default 0: the clip (max_acc_error_rad) already bounds what one sample can do, and the acceleration of
    /// a sustained motion averages out over time (its velocity stays bounded) while gravity does not, so skipping the
    /// accelerometer throws away the only tilt information there is and the tilt drifts with the gyro. Simulated Nez
    /// fast motion (|a| 4 +- 2 g for 10 min, Opal-like sensor, bsn_bench_nez_sources --write): inclination RMSE 29.2
    /// deg with 3 m/s^2 (the former default), 14.5 deg never skipped; Nez intermediate 12.5 -> 6.2 deg total RMSE;
    /// the eight BROAD trials 3.97 -> 3.89 deg mean total RMSE (inclination 1.73 -> 1.04, heading 3.43 -> 3.65).
    double acc_rejection_m_s2 = 0.0;
    /// 1 = skip the magnetometer while the shared disturbance detector flags it, 0 = always use it. Default 1. The
    /// detector replaces the filter's own test (|m| off its value at the start by more than 20 %), which missed a
    /// field that changes the dip more than the magnitude (Fan's test B: 0 % of the magnet's samples caught, now
    /// 88 %), and the reading is brought forward by mag_latency_s as in the others. On the eight BROAD trials (the
    /// accelerometer never skipped): 3.89 -> 2.73 deg mean total RMSE; the attached magnet (trial 33) 8.63 -> 2.56
    /// deg, the stationary one (trial 31) 7.02 -> 4.51 deg. Fan's C (20 min in a strong disturbance) goes 0.50 ->
    /// 13.1 deg, as for every filter with the detector: after mag_accept_after_s the field is used again with a
    /// reduced gain (the old test rejected it for ever, leaving the heading to the gyro).
    double mag_rejection = 1.0;
    /// Largest angle between the estimated and the accelerometer's up that one tilt correction acts on, rad: the
    /// correction turns by gain_acc times min(angle, this). Between corrections the gyro lets the tilt drift by
    /// no more than its error (tenths of a degree per second), so a larger angle is external acceleration: 1 g
    /// sideways shows as 45 deg, and unclipped every such sample pulls by gain_acc times that (simulated translation
    /// at 1 g, test_clean_field_motion: inclination error 14 deg, heading 6.2 deg RMS, through the tilt's leak into
    /// the horizontal field). Clipped, a correction turns by at most max_acc_error_rad / tau_acc_s rad/s (1.4 deg/s),
    /// still well above any drift. Default 0.05 rad (2.9 deg, seel_ruppin's value); pi = unclipped. With the bias
    /// low-pass, on the eight BROAD trials: 0.1 rad 4.36 deg mean total RMSE, 0.05 rad 3.97, 0.02 rad 3.95, unclipped
    /// 12.45 (the fast-translation trial).
    double max_acc_error_rad = 0.05;
    /// 1 = remove the gyro bias learned at rest by the low-pass of Fan et al. eqs. 11-12 (GyroBiasLowPass, as
    /// madgwick and iecf); 0 = raw gyro (the plain filter). Without it a consumer gyro's 0.5 deg/s bias leaves a
    /// standing error of bias times tau: simulated, 2.4 deg RMS heading error with no translation at all. Default
    /// 1 (BROAD with the clip: 8.54 -> 3.97 deg mean total RMSE).
    double gyro_bias_lowpass = 1.0;
  };

  /// Quantities derived once from Params.
  struct Coefficients {
    double inv_tau_acc = 0.0;  ///< 1/tau_acc, 1/s; gain per sample is 1 - exp(-dt/tau)
    double inv_tau_mag = 0.0;  ///< 1/tau_mag, 1/s
    bool bias_lowpass = true;  ///< gyro_bias_lowpass = 1
  };

  struct State {
    Quat q = Quat::Identity();            ///< sensor-to-earth
    double gain_dt_s = -1.0;              ///< step for which gain_acc and gain_mag hold (dt rarely changes), s
    double gain_acc = 0.0;                ///< 1 - exp(-dt / tau_acc)
    double gain_mag = 0.0;                ///< 1 - exp(-dt / tau_mag)
    RestDetector rest;                    ///< still-sensor detection (flags().resting, the bias updates' gate)
    GyroBiasLowPass bias_lowpass;         ///< the gyro bias estimate at rest
    MagDisturbanceDetector mag_detector;  ///< magnetometer rejection
    FilterFlags flags;
  };

  /// Throws std::invalid_argument on a non-positive or non-finite parameter.
  explicit ComplementaryFilter(const Params& params);
  ComplementaryFilter() : ComplementaryFilter(Params{}) {}

  Quat orientation() const override { return state_.q; }
  FilterFlags flags() const override { return state_.flags; }
  Vec3 gyro_bias() const override { return state_.bias_lowpass.bias(); }  // zero without the low-pass
  std::string_view name() const override { return "complementary"; }

  const Params& params() const { return params_; }
  const State& state() const { return state_; }
  /// Continues from a state() of a filter with the same parameters.
  void set_state(const State& state) { state_ = state; }
  /// The magnetic-disturbance detector's state (reference field, low-passed |m| and dip, rejection budget).
  const MagDisturbanceDetector& mag_detector() const { return state_.mag_detector; }

 private:
  UpdateResult start(const ImuSample& s) override;
  UpdateResult step(const ImuSample& s, double dt) override;
  std::unique_ptr<FilterSnapshot> save_state() const override { return state_snapshot(state_); }
  void restore_state(const FilterSnapshot& snapshot) override { state_ = snapshot_state<State>(snapshot); }
  void clear() override { state_ = initial_; }

  Params params_;
  Coefficients coeff_;
  State state_;
  State initial_;  ///< a fresh filter's (reset())
};

/// Factory entry: "complementary" with the Params fields as parameter names.
std::unique_ptr<OrientationFilter> make_complementary_filter(const FilterSpec& spec);

}  // namespace bsn::fusion
