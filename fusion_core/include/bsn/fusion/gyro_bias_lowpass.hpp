// Low-pass gyro bias estimate (Fan et al. 2018, section 2.3.3, eqs. 11-12): while every component of the
// measured rate has stayed below omega_min for longer than t_b, the bias follows the measured rate through a
// first-order low-pass with corner frequency f_c; during motion it is frozen.
//
// Eq. 11 as printed, w_bias = 2 pi f_c * integral(p * w dt), lacks the feedback term: integrated literally it
// would grow without bound at rest. The text calls it a low-pass filter with corner frequency f_c, so we
// implement exactly that: d(w_bias)/dt = 2 pi f_c * p * (w - w_bias), discretised exactly for any dt.
// By default, over the first 1 / (2 pi f_c) of still time after reset() the estimate is the running mean of the still
// readings instead (the larger of the two gains): with nothing known yet the mean is the best estimate of a constant
// bias, while the low-pass started from zero keeps (1 - e^-t/tau) of the bias unlearned for many seconds. A short rest
// before motion (Fan's test A: 5 s, 3 of them usable) then yields the bias, not half of it.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string_view>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion {

class GyroBiasLowPass {
 public:
  /// Low-pass bias parameters. The Params of Seel-Ruppin and (through GyroBiasRemovalParams) of complementary,
  /// Madgwick and IECF derive from this struct, so the field names are the filter parameter names
  /// (bias_param_fields() lists them); DLKF keeps its own copy (see there).
  struct Params {
    /// Corner frequency f_c of the low-pass, Hz. Default 0.05 Hz (Fan et al.): time constant 3.2 s.
    double bias_corner_frequency_hz = 0.05;
    /// omega_min: the sensor counts as still while every gyro component is below this, rad/s. Default
    /// 3 deg/s (Fan et al.).
    double bias_omega_min_rad_s = 3.0 * 0.017453292519943295;
    /// t_b: minimum still time before the bias is updated, s. Default 2 s (Fan et al.).
    double bias_min_static_s = 2.0;
  };

  struct State {
    Vec3 bias = Vec3::Zero();          ///< estimate, sensor frame, rad/s (measured = true + bias)
    bool still = false;                ///< every component below omega_min at the last sample
    std::uint64_t still_since_ns = 0;  ///< start of the current still period
    bool updating = false;             ///< p of eq. 12 at the last sample
    double averaged_s = 0.0;           ///< still time averaged since reset(), s (counted up to 1 / (2 pi f_c))
  };

  /// Throws std::invalid_argument on a non-positive or non-finite parameter. running_mean_start = false keeps Fan's
  /// low-pass from the first still reading on (madgwick: see there).
  explicit GyroBiasLowPass(const Params& params, bool running_mean_start = true);
  GyroBiasLowPass() : GyroBiasLowPass(Params{}) {}

  /// Feeds the raw measured rate of a sample at t_ns, dt seconds after the previous one (dt <= 0 or
  /// non-finite input changes nothing but the still timer).
  EIGEN_ALWAYS_INLINE void update(std::uint64_t t_ns, double dt, const Vec3& gyr) {
    // Always inlined: every filter of the family calls it once per sample.
    // Every component below omega_min; NaN and Inf fail the comparison, so non-finite input is never still.
    const double limit = params_.bias_omega_min_rad_s;
    const bool still_now = std::abs(gyr.x()) < limit && std::abs(gyr.y()) < limit && std::abs(gyr.z()) < limit;
    if (!still_now) {
      state_.still = false;
    } else if (!state_.still || t_ns < state_.still_since_ns) {
      state_.still = true;
      state_.still_since_ns = t_ns;
    }
    state_.updating = state_.still && t_ns - state_.still_since_ns > min_static_ns_;
    if (state_.updating && dt > 0.0 && std::isfinite(dt)) {
      if (dt != cached_dt_) cache_gain(dt);  // dt is nearly always the same from sample to sample
      double gain = cached_gain_;
      if (state_.averaged_s < time_constant_s_) {  // the running mean of the first still time
        state_.averaged_s += dt;
        gain = std::max(gain, dt / state_.averaged_s);
      }
      state_.bias += gain * (gyr - state_.bias);
    }
  }
  const Vec3& bias() const { return state_.bias; }
  /// Overwrites the estimate (a filter that also estimates the bias by other means keeps this one in step).
  void set_bias(const Vec3& bias) { state_.bias = bias; }
  bool updating() const { return state_.updating; }
  void reset() { state_ = State{}; }
  const State& state() const { return state_; }

 private:
  /// Sets cached_gain_ = 1 - exp(-omega_c dt), the exact step of the first-order low-pass, for dt.
  void cache_gain(double dt);

  Params params_;
  double omega_c_ = 0.0;          ///< 2 pi f_c, rad/s
  double time_constant_s_ = 0.0;  ///< 1 / omega_c, s
  std::uint64_t min_static_ns_ = 0;
  double cached_dt_ = -1.0;   ///< dt of the last low-pass step
  double cached_gain_ = 0.0;  ///< 1 - exp(-omega_c dt) for cached_dt_
  State state_;
};

/// The low-pass bias parameters' entries of a filter's parameter table (P derives from GyroBiasLowPass::Params).
template <class P>
constexpr std::array<ParamField<P>, 3> bias_param_fields() {
  return {{{"bias_corner_frequency_hz", &P::bias_corner_frequency_hz},
           {"bias_omega_min_rad_s", &P::bias_omega_min_rad_s},
           {"bias_min_static_s", &P::bias_min_static_s}}};
}

/// The gyro bias removal of a filter whose only bias estimate is the rest low-pass (complementary, madgwick, iecf),
/// under its filter parameter names: the low-pass's parameters and the switch.
struct GyroBiasRemovalParams : GyroBiasLowPass::Params {
  /// 1 = remove the gyro bias learned at rest by the low-pass of Fan et al. eqs. 11-12; 0 = raw gyro (the plain
  /// filter). Default 1: a consumer gyro's bias of 0.5 deg/s otherwise leaves a standing error of the bias times the
  /// filter's correction time constant.
  double gyro_bias_lowpass = 1.0;

  void check(std::string_view owner) const { require_switch(owner, gyro_bias_lowpass, "gyro_bias_lowpass"); }
};

}  // namespace bsn::fusion
