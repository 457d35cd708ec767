// Parameters the Kalman filters with a gyro bias state (EKF, MEKF) share under the same names.
#pragma once

#include <array>
#include <string_view>

#include "bsn/fusion/filter_params.hpp"

namespace bsn::fusion {

/// The initial covariance. The Params of EKF and MEKF derive from this struct, so the field names are the filter
/// parameter names (kalman_init_param_fields() lists them).
struct KalmanInitParams {
  /// Initial standard deviation of each attitude error component, rad. Default 0.1 rad (5.7 deg): larger than
  /// the error of the first TRIAD solution for accelerometer noise below ~1 m/s^2.
  double init_attitude_sigma_rad = 0.1;
  /// Initial standard deviation of each gyro bias component, rad/s. Default 0.01 rad/s (0.57 deg/s), a
  /// typical turn-on bias of a calibrated MEMS gyro.
  double init_bias_sigma_rad_s = 0.01;
};

/// The initial covariance's entries of a filter's parameter table (P derives from KalmanInitParams).
template <class P>
constexpr std::array<ParamField<P>, 2> kalman_init_param_fields() {
  return {
      {{"init_attitude_sigma_rad", &P::init_attitude_sigma_rad}, {"init_bias_sigma_rad_s", &P::init_bias_sigma_rad_s}}};
}

/// Throws std::invalid_argument, naming `owner`, unless both initial sigmas are finite and > 0.
inline void check_kalman_init(std::string_view owner, const KalmanInitParams& params) {
  require_positive_fields(owner, params, kalman_init_param_fields<KalmanInitParams>());
}

}  // namespace bsn::fusion
