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
  require_positive(kName, params.mag_max_rejection_s, "mag_max_rejection_s");
  require_positive(kName, params.mag_accept_after_s, "mag_accept_after_s");
  if (!(params.mag_reduced_gain >= 0.0 && params.mag_reduced_gain <= 1.0)) {
    throw std::invalid_argument(std::string(kName) + ": parameter mag_reduced_gain must be in [0, 1], got " +
                                std::to_string(params.mag_reduced_gain));
  }
  min_clean_ns_ = seconds_to_ns(params.mag_min_clean_s);
  max_rejection_ns_ = seconds_to_ns(params.mag_max_rejection_s);
}

double MagDisturbanceDetector::dip_angle(const Vec3& m, const Vec3& up) {
  const double norm = m.norm();
  if (!(norm > 0.0)) return 0.0;
  return std::asin(std::clamp(-m.dot(up) / norm, -1.0, 1.0));
}

namespace {

// Bound on sin(dip) equivalent to dip > angle (greater = true) or dip < angle (greater = false), for a dip in
// [-pi/2, pi/2]: beyond +-pi/2 the comparison always or never holds, which +-2 reproduces (|sin(dip)| <= 1).
double sine_bound(double angle, bool greater) {
  constexpr double kHalfPi = 1.5707963267948966;
  if (greater ? angle >= kHalfPi : angle > kHalfPi) return 2.0;
  if (greater ? angle < -kHalfPi : angle <= -kHalfPi) return -2.0;
  return std::sin(angle);
}

}  // namespace

void MagDisturbanceDetector::set_reference(double norm_uT, double dip_rad) {
  state_.reference_known = norm_uT > 0.0 && std::isfinite(norm_uT) && std::isfinite(dip_rad);
  state_.ref_norm = state_.reference_known ? norm_uT : 0.0;
  state_.ref_dip = state_.reference_known ? dip_rad : 0.0;
  const double ref = state_.ref_norm, dip = state_.ref_dip;
  bounds_.norm_enter_low = ref * (1.0 - params_.mag_norm_enter);
  bounds_.norm_enter_high = ref * (1.0 + params_.mag_norm_enter);
  bounds_.norm_leave_low = ref * (1.0 - params_.mag_norm_leave);
  bounds_.norm_leave_high = ref * (1.0 + params_.mag_norm_leave);
  bounds_.sin_enter_low = sine_bound(dip - params_.mag_dip_enter_rad, false);
  bounds_.sin_enter_high = sine_bound(dip + params_.mag_dip_enter_rad, true);
  bounds_.sin_leave_low = sine_bound(dip - params_.mag_dip_leave_rad, true);
  bounds_.sin_leave_high = sine_bound(dip + params_.mag_dip_leave_rad, false);
}

double MagDisturbanceDetector::last_norm_deviation() const {
  return state_.reference_known ? std::abs(state_.last_norm - state_.ref_norm) / state_.ref_norm : 0.0;
}

double MagDisturbanceDetector::last_dip_deviation() const {
  if (!(state_.last_norm > 0.0)) return 0.0;
  return std::abs(std::asin(std::clamp(state_.last_down / state_.last_norm, -1.0, 1.0)) - state_.ref_dip);
}

void MagDisturbanceDetector::track_disturbance(std::uint64_t t_ns, double norm, double dip) {
  const double dt =
      state_.last_ns != 0 && t_ns > state_.last_ns ? static_cast<double>(t_ns - state_.last_ns) * 1e-9 : 0.0;
  state_.budget.update(dt, state_.disturbed, params_.mag_accept_after_s);
  if (!state_.disturbed) {
    state_.candidate = false;
    return;
  }
  // A field that stays the same (within the enter thresholds of the run's first reading) for mag_max_rejection_s
  // becomes the new reference; a field that keeps changing never does.
  if (!state_.candidate || std::abs(norm - state_.candidate_norm) > params_.mag_norm_enter * state_.candidate_norm ||
      std::abs(dip - state_.candidate_dip) > params_.mag_dip_enter_rad + state_.dip_tolerance) {
    state_.candidate = true;
    state_.candidate_norm = norm;
    state_.candidate_dip = dip;
    state_.candidate_since_ns = t_ns;
  } else if (t_ns - state_.candidate_since_ns >= max_rejection_ns_) {
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
  if (!state_.reference_known) set_reference(norm, dip_angle(mag, up));
  state_.last_norm = norm;
  state_.last_down = down;
  state_.dip_tolerance = lag_dip_tolerance(rate_rad_s, dt_s + params_.mag_latency_s);

  // |dev| > enter and |dev| < leave for the magnitude, and the same for the dip as sin(dip) = down / |m|
  // compared against the sines of the band limits (multiplied through by |m| > 0).
  const bool norm_outside_enter = norm > bounds_.norm_enter_high || norm < bounds_.norm_enter_low;
  const bool norm_inside_leave = norm < bounds_.norm_leave_high && norm > bounds_.norm_leave_low;
  bool dip_outside_enter = down > bounds_.sin_enter_high * norm || down < bounds_.sin_enter_low * norm;
  bool dip_inside_leave = down < bounds_.sin_leave_high * norm && down > bounds_.sin_leave_low * norm;
  auto dip_of_reading = [&] { return std::asin(std::clamp(down / norm, -1.0, 1.0)); };
  double dip = 0.0;
  bool dip_known = false;
  if (state_.dip_tolerance > 0.0 && !dip_inside_leave) {
    dip = dip_of_reading();
    dip_known = true;
    // Turning: the bands widened by the lag tolerance, on the angle itself.
    const double dev = std::abs(dip - state_.ref_dip);
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
  if (state_.disturbed && !dip_known) dip = dip_of_reading();  // the new-field rule needs it
  track_disturbance(t_ns, norm, dip);
  state_.last_ns = t_ns;
  return state_.disturbed;
}

}  // namespace bsn::fusion
