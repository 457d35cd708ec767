// R-adaption for the Kalman filters (Fan et al. 2018, §2.2.1 eq. 10): while the magnetic field is disturbed the
// magnetometer's measurement variance is set to infinity, so the filter does not trust it; otherwise it keeps its
// nominal value. The disturbance is judged on the field magnitude and the dip angle against their reference values,
// with two thresholds (enter > exit) and a minimum clean duration before the magnetometer is trusted again,
// because a single threshold chatters (Fan §2.2.1 and §5.1).
#pragma once

#include <cstdint>
#include <limits>

namespace bsn::fusion {

class MagneticRAdaption {
 public:
  struct Params {
    /// Relative magnitude deviation | |m| / |h_ref| - 1 | above which the field counts as disturbed. Default 0.1
    /// (10 %): a clean indoor field varies by ~2 % (Fan §3), a magnet or steel nearby by tens of percent.
    double magnitude_enter = 0.1;
    /// The deviation must fall below this to count as clean again, fraction. Default 0.05 (5 %).
    double magnitude_exit = 0.05;
    /// Dip-angle deviation above which the field counts as disturbed, rad. Default 0.1745 (10 deg).
    double dip_enter_rad = 0.1745;
    /// Dip-angle deviation below which it counts as clean again, rad. Default 0.0873 (5 deg).
    double dip_exit_rad = 0.0873;
    /// After a disturbance, both deviations must stay below their exit thresholds this long before the
    /// magnetometer is trusted again, s. Default 0.2 s: on the BROAD trials a longer wait (1 s) kept the
    /// magnetometer out for most of the fast trials and cost the Kalman filters several degrees of heading.
    double min_clean_s = 0.2;
  };

  /// Throws std::invalid_argument unless 0 < exit <= enter for both quantities and min_clean_s >= 0.
  explicit MagneticRAdaption(const Params& params);
  MagneticRAdaption() : MagneticRAdaption(Params{}) {}

  /// Judges one magnetometer sample at time t_ns: magnitude_ratio = |m| / |h_ref|, dip_deviation_rad = measured
  /// minus reference dip. Returns the factor for the nominal measurement variance: 1 (trusted) or +infinity
  /// (disturbed, eq. 10). Non-finite inputs count as disturbed.
  double update(std::uint64_t t_ns, double magnitude_ratio, double dip_deviation_rad);
  /// The same judgement from the cosine of the dip deviation instead of the angle (|dev| > threshold exactly when
  /// cos(dev) < cos(threshold), for deviations within +-180 deg), so that the filters need no inverse sine.
  double update_from_cosine(std::uint64_t t_ns, double magnitude_ratio, double cos_dip_deviation);

  /// True while the field is judged disturbed (including the clean waiting period).
  bool disturbed() const { return disturbed_; }

  /// Forgets the history: the next sample is judged on its own.
  void reset() {
    disturbed_ = false;
    clean_since_valid_ = false;
  }

  const Params& params() const { return params_; }

  static constexpr double kInfiniteVariance = std::numeric_limits<double>::infinity();

 private:
  double judge(std::uint64_t t_ns, double magnitude_ratio, bool finite, bool dip_over_enter, bool dip_under_exit);

  Params params_;
  std::uint64_t min_clean_ns_ = 0;
  double cos_dip_enter_ = 0.0;  ///< cos(dip_enter_rad), or -2 (never reached) when the threshold is >= 180 deg
  double cos_dip_exit_ = 0.0;   ///< cos(dip_exit_rad), or -2 likewise
  bool disturbed_ = false;
  bool clean_since_valid_ = false;  ///< a clean period has started while disturbed_
  std::uint64_t clean_since_ns_ = 0;
};

}  // namespace bsn::fusion
