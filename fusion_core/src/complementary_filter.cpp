#include "bsn/fusion/complementary_filter.hpp"

#include <array>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/start_orientation.hpp"

namespace bsn::fusion {
namespace {

constexpr const char* kName = "complementary";

using P = ComplementaryFilter::Params;
constexpr auto kParams = join_param_fields(std::to_array<ParamField<P>>({
                                               {"tau_acc_s", &P::tau_acc_s},
                                               {"tau_mag_s", &P::tau_mag_s},
                                               {"acc_rejection_m_s2", &P::acc_rejection_m_s2},
                                               {"mag_rejection", &P::mag_rejection},
                                               {"max_acc_error_rad", &P::max_acc_error_rad},
                                               {"gyro_bias_lowpass", &P::gyro_bias_lowpass},
                                           }),
                                           bias_param_fields<P>(), mag_disturbance_param_fields<P>(),
                                           rest_param_fields<P>(), timing_param_fields<P>());

// Gain of a first-order low-pass with time constant tau for a step dt: exact for any dt.
double step_gain(double dt, double inv_tau) { return 1.0 - std::exp(-dt * inv_tau); }

// atan2(y, x) / y for y != 0. Without trigonometry for the small angles of per-sample
// corrections (x > 0, (y/x)^2 < 0.01): atan(t)/t = 1 - t^2/3 + t^4/5 - ..., truncated after t^16 (error < 1e-17
// relative); larger angles take atan2.
double atan2_over_y(double y, double x) {
  if (x > 0.0) {
    const double inv_x = 1.0 / x;
    const double t2 = y * y * inv_x * inv_x;
    if (t2 < 1e-2) {
      const double t4 = t2 * t2, t8 = t4 * t4;
      const double low = (1.0 - t2 * (1.0 / 3)) + t4 * ((1.0 / 5) - t2 * (1.0 / 7));
      const double high = ((1.0 / 9) - t2 * (1.0 / 11)) + t4 * ((1.0 / 13) - t2 * (1.0 / 15));
      return inv_x * (low + t8 * (high + t8 * (1.0 / 17)));
    }
  }
  return std::atan2(y, x) / y;
}

}  // namespace

ComplementaryFilter::ComplementaryFilter(const Params& params) : FilterBase(kName, params) {
  state_.rest = RestDetector(params);
  state_.bias_lowpass = GyroBiasLowPass(params);
  state_.mag_detector = MagDisturbanceDetector(params);
  require_positive(kName, params.tau_acc_s, "tau_acc_s");
  require_positive(kName, params.tau_mag_s, "tau_mag_s");
  require_non_negative(kName, params.acc_rejection_m_s2, "acc_rejection_m_s2");
  params.MagRejectionParams::check(kName);
  require_positive(kName, params.max_acc_error_rad, "max_acc_error_rad");
  params.GyroBiasRemovalParams::check(kName);
  params.RestDetector::Params::check(kName);
  coeff_.inv_tau_acc = 1.0 / params.tau_acc_s;
  coeff_.inv_tau_mag = 1.0 / params.tau_mag_s;
  coeff_.bias_lowpass = params.gyro_bias_lowpass != 0.0;
  keep_fresh_state();
}

UpdateResult ComplementaryFilter::start(const ImuSample& s) {
  // An orientation needs at least the direction of gravity. Any field not parallel to it gives a heading.
  const std::optional<StartOrientation> initial = start_orientation(s, 1e-6);
  if (!initial) return UpdateResult::kRejected;
  const bool mag_usable = initial->with_mag;
  state_.q = initial->q;
  state_.flags = start_flags(s.has_mag && !mag_usable);
  state_.rest.reset();
  state_.mag_detector.reset();
  if (mag_usable) state_.mag_detector.update(s.timestamp_ns, s.mag, s.acc.normalized());  // the reference field
  return UpdateResult::kInitialised;
}

// Flattened: the helpers it calls (series, rotations, the magnetometer's lag compensation) are inlined into one
// function; inlining changes no arithmetic.
[[gnu::flatten]] UpdateResult ComplementaryFilter::step(const ImuSample& s, double dt) {
  state_.flags.reinitialised = false;
  if (dt != state_.gain_dt_s) {  // dt is nearly always the same from sample to sample
    state_.gain_dt_s = dt;
    state_.gain_acc = step_gain(dt, coeff_.inv_tau_acc);
    state_.gain_mag = step_gain(dt, coeff_.inv_tau_mag);
  }
  // Every factor below is a unit quaternion: one normalisation at the end suffices.
  Quat q = state_.q;

  // Strapdown prediction: exact for a rate constant over the step (sensor-frame increment on the right).
  // The bias estimate stays zero without the low-pass.
  if (s.has_gyr) q = q * exp_rotation_vector((s.gyr - state_.bias_lowpass.bias()) * dt);

  // Tilt correction: turn the earth-frame image of the measured up direction towards earth z, by the fraction
  // gain_acc of the angle between them (at most max_acc_error_rad after the start-up), about their common
  // perpendicular.
  if (s.has_acc) {
    const double acc_norm = s.acc.norm();
    // A reading of (nearly) zero, free fall, has no direction to correct towards.
    if (acc_norm > 1e-3 &&
        (params_.acc_rejection_m_s2 == 0.0 || std::abs(acc_norm - kGravity) < params_.acc_rejection_m_s2)) {
      const Vec3 up_est = rotate(q, s.acc * (1.0 / acc_norm));
      const Vec3 axis(up_est.y(), -up_est.x(), 0.0);  // up_est x earth z
      const double axis_squared_norm = axis.squaredNorm();
      if (axis_squared_norm > 1e-24) {
        const double sin_angle = std::sqrt(axis_squared_norm);
        double angle_over_sin = atan2_over_y(sin_angle, up_est.z());
        if (angle_over_sin * sin_angle > params_.max_acc_error_rad && !within_init_period(s.timestamp_ns)) {
          angle_over_sin = params_.max_acc_error_rad / sin_angle;
        }
        q = exp_rotation_vector((state_.gain_acc * angle_over_sin) * axis) * q;
      }
    }
  }

  // Heading correction about earth z only, so the magnetometer never tilts the estimate.
  state_.flags.mag_rejected = false;
  if (s.has_mag) {
    const Vec3 mag =
        mag_at_gyro_time(s, state_.bias_lowpass.bias(), params_.mag_latency_s);  // the magnetometer's own delay
    const double norm = mag.norm();
    const Vec3 m_earth = rotate(q, mag);
    const double horizontal_squared = m_earth.x() * m_earth.x() + m_earth.y() * m_earth.y();
    double gain_factor = 1.0;
    bool disturbed = false;
    if (params_.mag_rejection != 0.0) {
      const Vec3 up = earth_axis_in_sensor(q, 2);
      const double horizontal_rate = s.has_gyr ? (s.gyr - state_.bias_lowpass.bias()).cross(up).norm() : 0.0;
      // A clean field (update() returns false, nearly every reading) is used at full gain: only a disturbed one asks
      // the detector more.
      if (state_.mag_detector.update(s.timestamp_ns, mag, up, horizontal_rate, dt)) {
        disturbed = !state_.mag_detector.usable();
        gain_factor = state_.mag_detector.gain_factor();  // < 1 for a field used after a long rejection
      }
    }
    if (disturbed || horizontal_squared < 1e-12 * norm * norm || norm <= 1e-9) {
      state_.flags.mag_rejected = true;
    } else {
      // Angle that takes the horizontal field onto earth y (north): atan2(m_x, m_y).
      const double heading_error = m_earth.x() != 0.0 ? m_earth.x() * atan2_over_y(m_earth.x(), m_earth.y())
                                                      : std::atan2(m_earth.x(), m_earth.y());
      q = exp_rotation_vector(Vec3(0.0, 0.0, gain_factor * state_.gain_mag * heading_error)) * q;
    }
  }
  state_.q.coeffs() = q.coeffs() * inverse_sqrt_near_one(q.coeffs().squaredNorm());

  if (s.has_gyr && coeff_.bias_lowpass) state_.bias_lowpass.update(s.timestamp_ns, dt, s.gyr);
  return updated(s);
}

std::unique_ptr<OrientationFilter> make_complementary_filter(const FilterSpec& spec) {
  return std::make_unique<ComplementaryFilter>(bind_parameters(kName, spec, kParams));
}

}  // namespace bsn::fusion
