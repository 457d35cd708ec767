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

/// The complementary filter's parameters: own fields below; the rest bias low-pass and the magnetometer rejection with
/// their switches, rest detection and the gap and start-up timing come from the base structs (documented there).
/// During the start-up period (init_period_s) the tilt correction is not clipped.
struct ComplementaryParams : GyroBiasRemovalParams, MagRejectionParams, RestDetector::Params, FilterTimingParams {
  /// Time constant of the tilt correction towards the accelerometer, s. Larger trusts the gyro longer
  /// (less sensitive to accelerations), smaller removes gyro drift faster. Default 2 s.
  double tau_acc_s = 2.0;
  /// Time constant of the heading correction towards the magnetometer, s. Default 4 s.
  double tau_mag_s = 4.0;
  /// The accelerometer is skipped when | |acc| - g | exceeds this, m/s^2; 0 = never. Default 0: the clip
  /// (max_acc_error_rad) already bounds what one sample does, and the external acceleration of a sustained motion
  /// averages out while gravity does not, so skipping the accelerometer leaves the tilt to the gyro.
  double acc_rejection_m_s2 = 0.0;
  /// Largest angle between the estimated and the accelerometer's up that one tilt correction acts on, rad: the
  /// correction turns by gain_acc times min(angle, this); pi = unclipped. Default 0.05 rad (2.9 deg, seel_ruppin's
  /// value): between corrections the gyro drifts by far less, so a larger angle is external acceleration (1 g
  /// sideways shows as 45 deg), which the clip lets turn the estimate by at most max_acc_error_rad / tau_acc_s rad/s.
  double max_acc_error_rad = 0.05;
};

/// Everything the complementary filter keeps between samples.
struct ComplementaryState {
  Quat q = Quat::Identity();            ///< sensor-to-earth
  double gain_dt_s = -1.0;              ///< step for which gain_acc and gain_mag hold (dt rarely changes), s
  double gain_acc = 0.0;                ///< 1 - exp(-dt / tau_acc)
  double gain_mag = 0.0;                ///< 1 - exp(-dt / tau_mag)
  RestDetector rest;                    ///< still-sensor detection (flags().resting, the bias updates' gate)
  GyroBiasLowPass bias_lowpass;         ///< the gyro bias estimate at rest
  MagDisturbanceDetector mag_detector;  ///< magnetometer rejection
  FilterFlags flags;
};

class ComplementaryFilter final : public FilterBase<ComplementaryParams, ComplementaryState> {
 public:
  /// Quantities derived once from Params.
  struct Coefficients {
    double inv_tau_acc = 0.0;  ///< 1/tau_acc, 1/s; gain per sample is 1 - exp(-dt/tau)
    double inv_tau_mag = 0.0;  ///< 1/tau_mag, 1/s
    bool bias_lowpass = true;  ///< gyro_bias_lowpass = 1
  };

  /// Throws std::invalid_argument on a non-positive or non-finite parameter.
  explicit ComplementaryFilter(const Params& params);
  ComplementaryFilter() : ComplementaryFilter(Params{}) {}

  /// The magnetic-disturbance detector's state (reference field, low-passed |m| and dip, rejection budget).
  const MagDisturbanceDetector& mag_detector() const { return state_.mag_detector; }

 private:
  UpdateResult start(const ImuSample& s) override;
  UpdateResult step(const ImuSample& s, double dt) override;

  Coefficients coeff_;
};

/// Factory entry: "complementary" with the Params fields as parameter names.
std::unique_ptr<OrientationFilter> make_complementary_filter(const FilterSpec& spec);

}  // namespace bsn::fusion
