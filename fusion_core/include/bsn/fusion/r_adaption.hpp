// R-adaption for the Kalman filters (Fan et al. 2018, §2.2.1 eq. 10): while the magnetic field is disturbed the
// magnetometer's measurement variance is set to infinity, so the filter does not trust it; otherwise it keeps its
// nominal value. The disturbance is judged on the field magnitude and the dip angle against their reference values,
// with two thresholds (enter > exit) and a minimum clean duration before the magnetometer is trusted again,
// because a single threshold chatters (Fan §2.2.1 and §5.1).
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <string_view>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/mag_disturbance_detector.hpp"
#include "bsn/fusion/rotation.hpp"

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
    /// The magnetometer's delay beyond one sample, s: both dip thresholds widen by |w_h| (dt + latency_s) while
    /// the sensor turns (lag_dip_tolerance; reason and default as mag_latency_s of MagDisturbanceDetector::Params).
    /// Default 0.0064 s.
    double latency_s = 0.0064;
    /// After this much rejection (RejectionBudget) the magnetometer is used again with its variance multiplied by
    /// 1 / reduced_gain^2, so the heading error stays bounded, s. Default 60 s (VQF).
    double accept_after_s = 60.0;
    /// Default 0.5 (VQF's rejection factor 2): the variance of such a reading is 4 times the nominal one.
    double reduced_gain = 0.5;
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

  /// A reference field as the judgement needs it: magnitude and dip, the dip as sine and cosine so that readings
  /// are judged without inverse trigonometry.
  struct Reference {
    double norm = 0.0;     ///< |h_ref|, uT; 0 = not known yet
    double sin_dip = 0.0;  ///< sine of the dip below the horizontal, positive downwards
    double cos_dip = 1.0;  ///< its cosine (>= 0: dips lie within +-90 deg)
    /// The reference of field m in a frame whose unit upward vertical is `up`.
    static Reference of(const Vec3& m, const Vec3& up);
  };
  /// Judges reading m against `ref`, with `up` the estimated unit vertical in m's frame (Fan eq. 17): the
  /// magnitude ratio |m| / ref.norm and the dip deviation, compared by its cosine. rate_rad_s = |w| widens the dip
  /// thresholds by lag_dip_tolerance(). After accept_after_s of rejection it returns 1 / reduced_gain^2 instead of
  /// infinity.
  double update(std::uint64_t t_ns, const Vec3& m, const Vec3& up, const Reference& ref, double rate_rad_s = 0.0,
                double dt_s = 0.0);

  /// True while the field is judged disturbed (including the clean waiting period).
  bool disturbed() const { return disturbed_; }

  /// Forgets the history: the next sample is judged on its own.
  void reset() {
    disturbed_ = false;
    clean_since_valid_ = false;
    budget_.reset();
    last_ns_ = 0;
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
  RejectionBudget budget_;
  std::uint64_t last_ns_ = 0;  ///< time of the last reading judged by update(m, up, ref)
};

/// The R-adaption parameters of a Kalman filter under their filter parameter names (the Params of EKF, MEKF and
/// DLKF derive from this struct; r_adaption_param_fields() lists the names).
struct RAdaptionFilterParams {
  /// 1 = infinite magnetometer variance (the magnetometer is ignored) while the field's magnitude or dip deviates
  /// from the reference (Fan eq. 10); 0 = always use it (Fan's test B). Default 1.
  double mag_rejection = 1.0;
  /// The thresholds of MagneticRAdaption::Params (meaning and defaults there): relative magnitude 0.1 / 0.05, dip
  /// 0.1745 / 0.0873 rad (10 / 5 deg), clean time 0.2 s.
  double mag_magnitude_enter = 0.1;
  double mag_magnitude_exit = 0.05;
  double mag_dip_enter_rad = 0.1745;
  double mag_dip_exit_rad = 0.0873;
  double mag_min_clean_s = 0.2;
  /// The lag tolerance and the long-rejection rule of MagneticRAdaption::Params (latency_s, accept_after_s,
  /// reduced_gain): 0.0064 s, 60 s, 0.5.
  double mag_latency_s = 0.0064;
  double mag_accept_after_s = 60.0;
  double mag_reduced_gain = 0.5;

  MagneticRAdaption::Params thresholds() const {
    return {mag_magnitude_enter, mag_magnitude_exit, mag_dip_enter_rad,  mag_dip_exit_rad,
            mag_min_clean_s,     mag_latency_s,      mag_accept_after_s, mag_reduced_gain};
  }
  /// Throws std::invalid_argument, naming `owner`, unless mag_rejection is 0 or 1 (MagneticRAdaption checks the
  /// thresholds).
  void check(std::string_view owner) const {
    if (mag_rejection != 0.0 && mag_rejection != 1.0) {
      throw std::invalid_argument(std::string(owner) + ": parameter mag_rejection must be 0 or 1");
    }
  }
};

/// The R-adaption parameters' entries of a filter's parameter table (P derives from RAdaptionFilterParams).
template <class P>
constexpr std::array<ParamField<P>, 9> r_adaption_param_fields() {
  return {{{"mag_rejection", &P::mag_rejection},
           {"mag_magnitude_enter", &P::mag_magnitude_enter},
           {"mag_magnitude_exit", &P::mag_magnitude_exit},
           {"mag_dip_enter_rad", &P::mag_dip_enter_rad},
           {"mag_dip_exit_rad", &P::mag_dip_exit_rad},
           {"mag_min_clean_s", &P::mag_min_clean_s},
           {"mag_latency_s", &P::mag_latency_s},
           {"mag_accept_after_s", &P::mag_accept_after_s},
           {"mag_reduced_gain", &P::mag_reduced_gain}}};
}

}  // namespace bsn::fusion
