// Improved explicit complementary filter (IECF, Fan et al. 2018 sections 2.4.4-2.4.5, after Madgwick's
// successor to the GDA): a Mahony-type filter q_dot = q (x) (0, w - b + K e) / 2 (eqs. 14-15) whose error
// e = e_a + e_m (eq. 16) is the cross product of measured and predicted up (accelerometer) plus the cross
// product of measured and predicted *virtual east* (a x m direction, section 2.1.2). East is horizontal by
// construction, so the magnetometer cannot tilt the estimate. Around it:
//   - a start-up gain ramp: K falls linearly from initial_gain to gain over init_period_s;
//   - the low-pass gyro bias of eqs. 11-12 (GyroBiasLowPass);
//   - magnetometer threshold rejection (MagDisturbanceDetector: magnitude and dip, two thresholds, minimum
//     clean time).
// Two factory names: "iecf" (9D) and "iecf6" (never uses the magnetometer).
#pragma once

#include <cstdint>
#include <string_view>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/gyro_bias_lowpass.hpp"
#include "bsn/fusion/mag_disturbance_detector.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/rest_detector.hpp"

namespace bsn::fusion {

/// The IECF's parameters: own fields below, the shared groups from the base structs (documented there).
/// init_period_s is also the length of the start-up gain ramp.
struct IecfParams : GyroBiasRemovalParams, MagRejectionParams, RestDetector::Params, FilterTimingParams {
  /// K: gain on the error after start-up, rad/s per unit error; the correction time constant is 1/K. Default 0.1
  /// (10 s), the optimum on the eight BROAD trials; Fan et al.'s 0.5 suits their sensors.
  double gain = 0.1;
  /// Gain right after (re)initialisation, ramping down to `gain` over init_period_s. Default 10.
  double initial_gain = 10.0;
};

/// Everything an IECF keeps between samples.
struct IecfState {
  Quat q = Quat::Identity();            ///< sensor-to-earth
  bool heading_known = false;           ///< false after an initialisation without magnetometer
  std::uint64_t last_mag_ns = 0;        ///< last used magnetometer reading
  RestDetector rest;                    ///< still-sensor detection (flags().resting, the bias updates' gate)
  GyroBiasLowPass bias_lowpass;         ///< the gyro bias estimate at rest
  MagDisturbanceDetector mag_detector;  ///< magnetometer rejection
  FilterFlags flags;
};

class IecfFilter final : public FilterBase<IecfParams, IecfState> {
 public:
  /// Quantities derived once from Params.
  struct Coefficients {
    /// The correction gain * e * dt stays below 1e150 rad per step: with a gyro step below that too, the update
    /// cannot overflow, and the detector need not be saved for a rollback.
    bool correction_bounded = true;
  };

  /// Throws std::invalid_argument on an out-of-range parameter.
  IecfFilter(const Params& params, bool use_magnetometer);
  IecfFilter() : IecfFilter(Params{}, true) {}

  /// Gain K at time since_init_s after (re)initialisation (the start-up ramp).
  double gain_at(double since_init_s) const;

 private:
  UpdateResult start(const ImuSample& s) override;
  UpdateResult step(const ImuSample& s, double dt) override;

  bool use_magnetometer_;
  Coefficients coeff_;
};

/// Factory entries: "iecf" (9D) and "iecf6" (6D), with the Params fields as parameter names.
std::unique_ptr<OrientationFilter> make_iecf_filter(const FilterSpec& spec);
std::unique_ptr<OrientationFilter> make_iecf6_filter(const FilterSpec& spec);

}  // namespace bsn::fusion
