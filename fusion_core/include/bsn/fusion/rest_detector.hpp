// Rest detection: the sensor is resting once the angular rate and the deviation of |acc| from g have stayed
// below their thresholds for a minimum time. Any filter can own one; it only reads samples.
#pragma once

#include <array>
#include <cstdint>
#include <string_view>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/imu_sample.hpp"

namespace bsn::fusion {

class RestDetector {
 public:
  /// Rest detection parameters. Every filter's Params derives from this struct, so the field names are the
  /// filter parameter names (rest_param_fields() lists them).
  struct Params {
    /// |gyr| must stay below this, rad/s. Default 0.05 rad/s (2.9 deg/s): above the noise and residual bias
    /// of a MEMS gyro, below any deliberate human motion.
    double rest_gyr_rad_s = 0.05;
    /// | |acc| - g | must stay below this, m/s^2. Default 0.5 m/s^2.
    double rest_acc_m_s2 = 0.5;
    /// Both must hold for at least this long before `resting` is reported, s. Default 1.5 s.
    double rest_min_s = 1.5;

    /// Throws std::invalid_argument, naming `owner`, unless every field is finite and > 0.
    void check(std::string_view owner) const {
      require_positive(owner, rest_gyr_rad_s, "rest_gyr_rad_s");
      require_positive(owner, rest_acc_m_s2, "rest_acc_m_s2");
      require_positive(owner, rest_min_s, "rest_min_s");
    }
  };

  struct State {
    bool still = false;                ///< the last sample was below both thresholds
    std::uint64_t still_since_ns = 0;  ///< timestamp of the first sample of the current still period
    bool resting = false;
  };

  /// Throws std::invalid_argument on a non-positive or non-finite parameter.
  explicit RestDetector(const Params& params);
  RestDetector() : RestDetector(Params{}) {}

  /// Feeds one (finite) sample; returns resting(). A sample without gyro or accelerometer ends a still period
  /// (rest cannot be confirmed without both).
  bool update(const ImuSample& s) {
    // |gyr| < threshold and | |acc| - g | < threshold, compared squared (no square roots per sample). Inline:
    // every filter calls it once per sample.
    const double acc_sq = s.acc.squaredNorm();
    const bool still_now = s.has_gyr && s.has_acc && s.gyr.squaredNorm() < gyr_threshold_sq_ && acc_sq > acc_low_sq_ &&
                           acc_sq < acc_high_sq_;
    if (!still_now) {
      state_.still = false;
    } else if (!state_.still || s.timestamp_ns < state_.still_since_ns) {
      state_.still = true;
      state_.still_since_ns = s.timestamp_ns;
    }
    state_.resting = state_.still && s.timestamp_ns - state_.still_since_ns >= min_duration_ns_;
    return state_.resting;
  }
  bool resting() const { return state_.resting; }
  void reset() { state_ = State{}; }
  const State& state() const { return state_; }

 private:
  Params params_;
  std::uint64_t min_duration_ns_ = 0;
  double gyr_threshold_sq_ = 0.0;  ///< rest_gyr^2, (rad/s)^2
  double acc_low_sq_ = 0.0;        ///< (g - rest_acc)^2, or -1 when g - rest_acc < 0, (m/s^2)^2
  double acc_high_sq_ = 0.0;       ///< (g + rest_acc)^2, (m/s^2)^2
  State state_;
};

/// The rest parameters' entries of a filter's parameter table (P derives from RestDetector::Params).
template <class P>
constexpr std::array<ParamField<P>, 3> rest_param_fields() {
  return {
      {{"rest_gyr_rad_s", &P::rest_gyr_rad_s}, {"rest_acc_m_s2", &P::rest_acc_m_s2}, {"rest_min_s", &P::rest_min_s}}};
}

}  // namespace bsn::fusion
