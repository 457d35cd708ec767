#include "bsn/fusion/mag_disturbance_detector.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "bsn/fusion/filter_params.hpp"

namespace bsn::fusion {

MagDisturbanceDetector::MagDisturbanceDetector(const Params& params) : params_(params) {
  constexpr const char* kName = "magnetic disturbance detector";
  require_positive(kName, params.mag_norm_enter, "mag_norm_enter");
  require_positive(kName, params.mag_norm_leave, "mag_norm_leave");
  require_positive(kName, params.mag_dip_enter_rad, "mag_dip_enter_rad");
  require_positive(kName, params.mag_dip_leave_rad, "mag_dip_leave_rad");
  require_positive(kName, params.mag_min_clean_s, "mag_min_clean_s");
  if (params.mag_norm_leave > params.mag_norm_enter || params.mag_dip_leave_rad > params.mag_dip_enter_rad) {
    throw std::invalid_argument(std::string(kName) +
                                ": a leave threshold must not exceed its enter threshold (mag_norm_leave <= "
                                "mag_norm_enter, mag_dip_leave_rad <= mag_dip_enter_rad)");
  }
  require_non_negative(kName, params.mag_latency_s, "mag_latency_s");
  require_non_negative(kName, params.mag_lowpass_tau_s, "mag_lowpass_tau_s");
  require_positive(kName, params.mag_reference_tau_s, "mag_reference_tau_s");
  require_non_negative(kName, params.mag_max_rejection_s, "mag_max_rejection_s");
  require_positive(kName, params.mag_accept_after_s, "mag_accept_after_s");
  if (!(params.mag_reduced_gain >= 0.0 && params.mag_reduced_gain <= 1.0)) {
    throw std::invalid_argument(std::string(kName) + ": parameter mag_reduced_gain must be in [0, 1], got " +
                                std::to_string(params.mag_reduced_gain));
  }
  min_clean_ns_ = seconds_to_ns(params.mag_min_clean_s);
  max_rejection_ns_ = seconds_to_ns(params.mag_max_rejection_s);
  constexpr double kPi = 3.14159265358979323846;
  enter_beyond_pi_ = params.mag_dip_enter_rad >= kPi;
  leave_beyond_pi_ = params.mag_dip_leave_rad >= kPi;
  sin_enter_ = std::sin(params.mag_dip_enter_rad);
  cos_enter_ = std::cos(params.mag_dip_enter_rad);
  sin_leave_ = std::sin(params.mag_dip_leave_rad);
  cos_leave_ = std::cos(params.mag_dip_leave_rad);
}

double MagDisturbanceDetector::dip_angle(const Vec3& m, const Vec3& up) {
  const double norm = m.norm();
  if (!(norm > 0.0)) return 0.0;
  return std::asin(std::clamp(-m.dot(up) / norm, -1.0, 1.0));
}

namespace {

// Bounds on sin(dip) equivalent to dip > ref + th (high) and dip < ref - th (low), for a dip in [-pi/2, pi/2] and
// 0 < th < pi, from the reference's sine and cosine (cos_ref >= 0): where the angle bound lies beyond +-pi/2 (its
// cosine is negative) the comparison always or never holds, which +-2 reproduces (|sin(dip)| <= 1).
struct SineBounds {
  double low, high;
};
SineBounds sine_bounds(double sin_ref, double cos_ref, double sin_th, double cos_th, bool th_beyond_pi) {
  if (th_beyond_pi) return {-2.0, 2.0};
  const double cos_high = cos_ref * cos_th - sin_ref * sin_th;  // cos(ref + th)
  const double cos_low = cos_ref * cos_th + sin_ref * sin_th;   // cos(ref - th)
  return {cos_low > 0.0 ? sin_ref * cos_th - cos_ref * sin_th : -2.0,
          cos_high > 0.0 ? sin_ref * cos_th + cos_ref * sin_th : 2.0};
}

double asin_clamped(double x) { return std::asin(std::clamp(x, -1.0, 1.0)); }

}  // namespace

void MagDisturbanceDetector::set_reference(double norm_uT, double dip_rad, double averaged_s) {
  set_reference_sine(norm_uT, std::isfinite(dip_rad) ? std::sin(dip_rad) : dip_rad, averaged_s);
}

void MagDisturbanceDetector::set_reference_sine(double norm_uT, double sin_dip, double averaged_s) {
  set_reference_bounds(norm_uT, sin_dip);
  state_.ref_clean_s = std::clamp(averaged_s, 0.0, params_.mag_reference_tau_s);
  state_.ref_pending_s = state_.ref_pending_norm = state_.ref_pending_down = 0.0;
}

void MagDisturbanceDetector::set_reference_bounds(double norm_uT, double sin_dip) {
  state_.reference_known = norm_uT > 0.0 && std::isfinite(norm_uT) && std::isfinite(sin_dip);
  state_.ref_norm = state_.reference_known ? norm_uT : 0.0;
  state_.ref_sin_dip = state_.reference_known ? std::clamp(sin_dip, -1.0, 1.0) : 0.0;
  state_.ref_cos_dip = std::sqrt(1.0 - state_.ref_sin_dip * state_.ref_sin_dip);
  const double ref = state_.ref_norm;
  state_.bounds.norm_enter_low = ref * (1.0 - params_.mag_norm_enter);
  state_.bounds.norm_enter_high = ref * (1.0 + params_.mag_norm_enter);
  state_.bounds.norm_leave_low = ref * (1.0 - params_.mag_norm_leave);
  state_.bounds.norm_leave_high = ref * (1.0 + params_.mag_norm_leave);
  const SineBounds enter =
      sine_bounds(state_.ref_sin_dip, state_.ref_cos_dip, sin_enter_, cos_enter_, enter_beyond_pi_);
  const SineBounds leave =
      sine_bounds(state_.ref_sin_dip, state_.ref_cos_dip, sin_leave_, cos_leave_, leave_beyond_pi_);
  state_.bounds.sin_enter_low = enter.low;
  state_.bounds.sin_enter_high = enter.high;
  state_.bounds.sin_leave_low = leave.low;
  state_.bounds.sin_leave_high = leave.high;
}

double MagDisturbanceDetector::last_norm_deviation() const {
  return state_.reference_known ? std::abs(state_.lp_norm - state_.ref_norm) / state_.ref_norm : 0.0;
}

double MagDisturbanceDetector::last_dip_deviation() const {
  if (!state_.lowpass_started) return 0.0;
  return std::abs(asin_clamped(state_.lp_down / state_.lp_norm) - asin_clamped(state_.ref_sin_dip));
}

void MagDisturbanceDetector::track_new_field(std::uint64_t t_ns) {
  // A field that stays the same (within the enter thresholds of the run's first reading) for mag_max_rejection_s
  // becomes the new reference; a field that keeps changing never does.
  const double norm = state_.lp_norm, dip = asin_clamped(state_.lp_down / state_.lp_norm);
  if (!state_.candidate || std::abs(norm - state_.candidate_norm) > params_.mag_norm_enter * state_.candidate_norm ||
      std::abs(dip - state_.candidate_dip) > params_.mag_dip_enter_rad + state_.dip_tolerance) {
    state_.candidate = true;
    state_.candidate_norm = norm;
    state_.candidate_dip = dip;
    state_.candidate_since_ns = t_ns;
  } else if (max_rejection_ns_ > 0 && t_ns - state_.candidate_since_ns >= max_rejection_ns_) {
    set_reference(state_.candidate_norm, state_.candidate_dip);
    state_.disturbed = false;
    state_.inside_leave_band = true;
    state_.inside_since_ns = t_ns;
    state_.candidate = false;
    state_.budget.update(0.0, false, params_.mag_accept_after_s);
  }
}

bool MagDisturbanceDetector::update(std::uint64_t t_ns, const Vec3& mag, const Vec3& up, double rate_rad_s,
                                    double dt_s) {
  const double norm = mag.norm();
  if (!std::isfinite(norm) || !(norm > 1e-9) || !up.allFinite() || !std::isfinite(rate_rad_s) || !std::isfinite(dt_s)) {
    state_.disturbed = true;
    state_.inside_leave_band = false;
    return true;
  }
  const double down = -mag.dot(up);  // |m| sin(dip)
  const double dt_mag =
      state_.lowpass_started && t_ns > state_.last_ns ? static_cast<double>(t_ns - state_.last_ns) * 1e-9 : 0.0;
  // First-order low-pass of |m| and of |m| sin(dip); the step dt / (tau + dt) needs no exponential and is exact to
  // first order in dt / tau. The lag tolerance is held as long as the low-pass remembers the readings it widened.
  const double tolerance = lag_dip_tolerance(rate_rad_s, dt_s + params_.mag_latency_s);
  if (!state_.lowpass_started || params_.mag_lowpass_tau_s == 0.0) {
    state_.lp_norm = norm;
    state_.lp_down = down;
    state_.dip_tolerance = tolerance;
    state_.lowpass_started = true;
  } else {
    if (dt_mag != state_.lowpass_dt) {  // a steady rate: the step is derived once
      state_.lowpass_dt = dt_mag;
      state_.lowpass_k = dt_mag / (params_.mag_lowpass_tau_s + dt_mag);
    }
    const double k = state_.lowpass_k;
    state_.lp_norm += k * (norm - state_.lp_norm);
    state_.lp_down += k * (down - state_.lp_down);
    state_.dip_tolerance = std::max(tolerance, (1.0 - k) * state_.dip_tolerance);
  }
  if (!state_.reference_known) set_reference_sine(state_.lp_norm, state_.lp_down / state_.lp_norm);
  const double n = state_.lp_norm, n_down = state_.lp_down;

  // |dev| > enter and |dev| < leave for the magnitude, and the same for the dip as its sine, |m| sin(dip) against
  // the sines of the band limits times |m| (no division).
  const bool norm_outside_enter = n > state_.bounds.norm_enter_high || n < state_.bounds.norm_enter_low;
  const bool norm_inside_leave = n < state_.bounds.norm_leave_high && n > state_.bounds.norm_leave_low;
  bool dip_outside_enter = n_down > state_.bounds.sin_enter_high * n || n_down < state_.bounds.sin_enter_low * n;
  bool dip_inside_leave = n_down < state_.bounds.sin_leave_high * n && n_down > state_.bounds.sin_leave_low * n;
  if (state_.dip_tolerance > 0.0 && !dip_inside_leave) {
    // Turning: the bands widened by the lag tolerance, on the angle itself.
    const double dev = std::abs(asin_clamped(n_down / n) - asin_clamped(state_.ref_sin_dip));
    dip_outside_enter = dev > params_.mag_dip_enter_rad + state_.dip_tolerance;
    dip_inside_leave = dev < params_.mag_dip_leave_rad + state_.dip_tolerance;
  }
  const bool outside_enter_band = norm_outside_enter || dip_outside_enter;
  const bool inside_leave_band = norm_inside_leave && dip_inside_leave;
  if (!inside_leave_band) {
    state_.inside_leave_band = false;
  } else if (!state_.inside_leave_band || t_ns < state_.inside_since_ns) {
    state_.inside_leave_band = true;
    state_.inside_since_ns = t_ns;
  }

  if (outside_enter_band) {
    state_.disturbed = true;
  } else if (state_.disturbed && state_.inside_leave_band && t_ns - state_.inside_since_ns >= min_clean_ns_) {
    state_.disturbed = false;
  }
  // The rules for a long disturbance (reduced gain, new field), here rather than in a call: a clean reading, nearly
  // every one, only pays back the budget.
  state_.budget.update(dt_mag, state_.disturbed, params_.mag_accept_after_s);
  if (state_.disturbed) {
    track_new_field(t_ns);
  } else {
    state_.candidate = false;
  }
  if (!state_.disturbed && state_.inside_leave_band && dt_mag > 0.0) {
    // The reference follows the clean field: a running mean, then exponential with mag_reference_tau_s. The clean
    // readings are summed and taken in every kReferenceStepS (the reference moves by a fraction dt / tau per
    // reading; its bounds need not be derived anew for each).
    constexpr double kReferenceStepS = 0.1;
    state_.ref_pending_s += dt_mag;
    state_.ref_pending_norm += dt_mag * n;
    state_.ref_pending_down += dt_mag * n_down;
    if (state_.ref_pending_s >= kReferenceStepS) {
      const double clean_s = std::min(state_.ref_clean_s + state_.ref_pending_s, params_.mag_reference_tau_s);
      const double k = state_.ref_pending_s / clean_s;
      set_reference_bounds(
          state_.ref_norm + k * (state_.ref_pending_norm / state_.ref_pending_s - state_.ref_norm),
          state_.ref_sin_dip + k * (state_.ref_pending_down / state_.ref_pending_norm - state_.ref_sin_dip));
      state_.ref_clean_s = clean_s;
      state_.ref_pending_s = state_.ref_pending_norm = state_.ref_pending_down = 0.0;
    }
  }
  state_.last_ns = t_ns;
  return state_.disturbed;
}

}  // namespace bsn::fusion
