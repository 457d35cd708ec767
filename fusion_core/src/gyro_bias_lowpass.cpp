#include "bsn/fusion/gyro_bias_lowpass.hpp"

#include <cmath>
#include <numbers>

#include "bsn/fusion/filter_params.hpp"

namespace bsn::fusion {

GyroBiasLowPass::GyroBiasLowPass(const Params& params) : params_(params) {
  require_positive("gyro bias low-pass", params.corner_frequency_hz, "bias_corner_frequency_hz");
  require_positive("gyro bias low-pass", params.omega_min_rad_s, "bias_omega_min_rad_s");
  require_positive("gyro bias low-pass", params.min_static_s, "bias_min_static_s");
  omega_c_ = 2.0 * std::numbers::pi * params.corner_frequency_hz;
  min_static_ns_ = static_cast<std::uint64_t>(std::llround(params.min_static_s * 1e9));
}

void GyroBiasLowPass::update(std::uint64_t t_ns, double dt, const Vec3& gyr) {
  const bool still_now = gyr.allFinite() && gyr.cwiseAbs().maxCoeff() < params_.omega_min_rad_s;
  if (!still_now) {
    state_.still = false;
  } else if (!state_.still || t_ns < state_.still_since_ns) {
    state_.still = true;
    state_.still_since_ns = t_ns;
  }
  state_.updating = state_.still && t_ns - state_.still_since_ns > min_static_ns_;
  if (state_.updating && dt > 0.0 && std::isfinite(dt)) {
    if (dt != cached_dt_) {  // dt is nearly always the same from sample to sample
      cached_dt_ = dt;
      cached_gain_ = 1.0 - std::exp(-omega_c_ * dt);  // exact step of the first-order low-pass
    }
    state_.bias += cached_gain_ * (gyr - state_.bias);
  }
}

}  // namespace bsn::fusion
