#include "bsn/fusion/gyro_bias_lowpass.hpp"

#include <cmath>
#include <numbers>

#include "bsn/fusion/filter_params.hpp"

namespace bsn::fusion {

GyroBiasLowPass::GyroBiasLowPass(const Params& params, bool running_mean_start) : params_(params) {
  require_positive("gyro bias low-pass", params.bias_corner_frequency_hz, "bias_corner_frequency_hz");
  require_positive("gyro bias low-pass", params.bias_omega_min_rad_s, "bias_omega_min_rad_s");
  require_positive("gyro bias low-pass", params.bias_min_static_s, "bias_min_static_s");
  omega_c_ = 2.0 * std::numbers::pi * params.bias_corner_frequency_hz;
  time_constant_s_ = running_mean_start ? 1.0 / omega_c_ : 0.0;
  min_static_ns_ = seconds_to_ns(params.bias_min_static_s);
}

void GyroBiasLowPass::cache_gain(double dt) {
  cached_dt_ = dt;
  cached_gain_ = 1.0 - std::exp(-omega_c_ * dt);
}

}  // namespace bsn::fusion
