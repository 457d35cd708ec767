#include "bsn/fusion/seel_ruppin_filter.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <optional>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/start_orientation.hpp"

namespace bsn::fusion {
namespace {

constexpr const char* kName = "seel_ruppin";
constexpr const char* kName6 = "seel_ruppin6";

using P = SeelRuppinFilter::Params;
constexpr auto kParams =
    join_param_fields(std::to_array<ParamField<P>>({
                          {"tau_acc_s", &P::tau_acc_s},
                          {"tau_mag_s", &P::tau_mag_s},
                          {"zeta", &P::zeta},
                          {"max_acc_error_rad", &P::max_acc_error_rad},
                          {"acc_lowpass_tau_s", &P::acc_lowpass_tau_s},
                          {"rest_bias_lowpass", &P::rest_bias_lowpass},
                          {"max_gyro_bias_rad_s", &P::max_gyro_bias_rad_s},
                          {"mag_rejection", &P::mag_rejection},
                          {"mag_reference_s", &P::mag_reference_s},
                      }),
                      bias_param_fields<P>(), mag_disturbance_param_fields<P>(), rest_param_fields<P>(),
                      sensor_fixed_field_param_fields<P>(), timing_param_fields<P>());

const P& checked(const P& p, const char* name) {
  require_positive(name, p.tau_acc_s, "tau_acc_s");
  require_positive(name, p.tau_mag_s, "tau_mag_s");
  require_non_negative(name, p.zeta, "zeta");
  require_positive(name, p.max_gyro_bias_rad_s, "max_gyro_bias_rad_s");
  require_positive(name, p.max_acc_error_rad, "max_acc_error_rad");
  require_non_negative(name, p.acc_lowpass_tau_s, "acc_lowpass_tau_s");
  require_positive(name, p.mag_reference_s, "mag_reference_s");
  p.MagRejectionParams::check(name);
  require_switch(name, p.rest_bias_lowpass, "rest_bias_lowpass");
  return p;
}

// atan(t) / t for t^2 <= 0.01 by its Taylor series, relative truncation error below 1e-15: the correction
// angles of a filter step are small, and this is several times cheaper than atan2. The usual tiny angles take
// four terms; the rest seven, evaluated in Estrin's scheme (short dependency chains).
constexpr double kSeriesMaxT2 = 1e-2;
inline double atan_over_t(double t2) {
  if (t2 < 1e-4) return 1.0 - t2 * (1.0 / 3 - t2 * (1.0 / 5 - t2 * (1.0 / 7)));
  const double t4 = t2 * t2;
  return (1.0 - t2 * (1.0 / 3)) +
         t4 * ((1.0 / 5 - t2 * (1.0 / 7)) + t4 * ((1.0 / 9 - t2 * (1.0 / 11)) + t4 * (1.0 / 13)));
}

// atan2(y, x), by the series for the usual small angles (|y| < 0.1 x).
double atan2_fast(double y, double x) {
  if (x > 0.0 && y * y < kSeriesMaxT2 * x * x) {
    const double t = y / x;
    return t * atan_over_t(t * t);
  }
  return std::atan2(y, x);
}

// Bounds far beyond any MEMS sensor's range: a value past them is corrupt, and rejecting it keeps every
// quantity of the filter bounded, so no sum or product can overflow.
constexpr double kMaxAccSquared = 1e4 * 1e4;  // (m/s^2)^2: 1000 g
constexpr double kMaxGyrSquared = 1e4 * 1e4;  // (rad/s)^2
constexpr double kMaxMagSquared = 1e5 * 1e5;  // uT^2: 0.1 T
bool physically_possible(const ImuSample& s) {
  return (!s.has_acc || s.acc.squaredNorm() <= kMaxAccSquared) &&
         (!s.has_gyr || s.gyr.squaredNorm() <= kMaxGyrSquared) && (!s.has_mag || s.mag.squaredNorm() <= kMaxMagSquared);
}

// q / |q| for a q whose norm is within rounding of 1 (a product of unit quaternions): one Newton step of
// 1/sqrt(n2) around 1, exact to O((n2 - 1)^2); anything further off is normalised exactly.
Quat renormalised(const Quat& q) {
  const double n2 = q.squaredNorm();
  if (std::abs(n2 - 1.0) < 1e-6) return Quat(q.coeffs() * (1.5 - 0.5 * n2));
  return q.normalized();
}

// Signed angle from v to w about the unit axis n (v and w perpendicular to n, not necessarily unit).
double signed_angle(const Vec3& v, const Vec3& w, const Vec3& n) { return atan2_fast(v.cross(w).dot(n), v.dot(w)); }

}  // namespace

SeelRuppinFilter::SeelRuppinFilter(const Params& params, bool use_magnetometer)
    : FilterBase(use_magnetometer ? kName : kName6, checked(params, use_magnetometer ? kName : kName6)),
      use_magnetometer_(use_magnetometer) {
  state_.rest = RestDetector(params);
  state_.mag_detector = MagDisturbanceDetector(params);
  state_.bias_lowpass = GyroBiasLowPass(params);
  state_.mag_offset = SensorFixedField(params, use_magnetometer ? kName : kName6);
  coeff_.tau_acc_14 = 1.4 * params.tau_acc_s;
  coeff_.tau_mag_14 = 1.4 * params.tau_mag_s;
  coeff_.tau_start_mag_14 = 1.4 * std::min(params.tau_mag_s, params.tau_acc_s);
  coeff_.bias_factor_acc = params.zeta * params.zeta / (160.0 * params.tau_acc_s);
  coeff_.bias_factor_mag = params.zeta * params.zeta / (160.0 * params.tau_mag_s);
  coeff_.mag_reference_ns = seconds_to_ns(params.mag_reference_s);
  coeff_.acc_clip_test = params.max_acc_error_rad < std::numbers::pi;
  coeff_.sin_max_acc_error = std::sin(params.max_acc_error_rad);
  coeff_.cos_max_acc_error = std::cos(params.max_acc_error_rad);
  const double tan_max = params.max_acc_error_rad < std::numbers::pi / 2 ? std::tan(params.max_acc_error_rad) : 1.0;
  coeff_.small_acc_error_tan2 = std::min(kSeriesMaxT2, tan_max * tan_max);
  coeff_.acc_lowpass = params.acc_lowpass_tau_s > 0.0;
  coeff_.acc_lowpass_fc_hz =
      coeff_.acc_lowpass ? std::numbers::sqrt2 / (2.0 * std::numbers::pi * params.acc_lowpass_tau_s) : 0.0;
  coeff_.gyro_integral = coeff_.acc_lowpass || (use_magnetometer && state_.mag_offset.enabled());
  keep_fresh_state();
}

void SeelRuppinFilter::LowPassCache::update(double dt, double fc_hz) {
  if (dt == cached_dt) return;
  cached_dt = dt;
  // The second-order Butterworth low-pass y'' = w0^2 (u - y) - sqrt(2) w0 y' as a continuous state (y, y') in
  // physical units, stepped exactly over dt with the input held: (y - u, y') <- Phi (y - u, y') with
  // Phi = exp(A dt), A = [0 1; -w0^2 -sqrt(2) w0]. Its poles are -s +- i s with s = w0 / sqrt(2), so
  // Phi = e^(-s dt) [cos + sin, sin / s; -2 s sin, cos - sin] (of s dt). The state does not depend on dt, so a
  // sensor that changes its rate keeps the filtered value; a difference-equation form (whose delay states are
  // scaled by the coefficients of one rate) would turn a rate step into a transient of many degrees.
  const double s = 2.0 * std::numbers::pi * fc_hz / std::numbers::sqrt2;
  const double decay = std::exp(-s * dt);
  const double c = std::cos(s * dt), sn = std::sin(s * dt);
  p00 = decay * (c + sn);
  p01 = decay * sn / s;
  p10 = -decay * 2.0 * s * sn;
  p11 = decay * (c - sn);
}

Vec3 SeelRuppinFilter::lowpass_acc(const Vec3& acc, double dt) {
  acc_lp_.update(dt, coeff_.acc_lowpass_fc_hz);
  const Vec3 x = rotate(state_.q_gyr, acc);
  if (state_.acc_lp_warmup_s < params_.acc_lowpass_tau_s) {
    // Start-up: for the first tau the output is the running mean of all inputs, and the low-pass is kept in
    // the steady state of that mean. Started from one sample instead, the low-pass would hold that sample's
    // noise for several tau.
    state_.acc_lp_warmup_s += dt;
    state_.acc_lp_count += 1.0;
    state_.acc_lp_mean += (x - state_.acc_lp_mean) / state_.acc_lp_count;
    state_.acc_lp_y = state_.acc_lp_mean;
    state_.acc_lp_rate = Vec3::Zero();
    return rotate(state_.q_gyr.conjugate(), state_.acc_lp_mean);
  }
  const Vec3 offset = state_.acc_lp_y - x;
  state_.acc_lp_y = x + acc_lp_.p00 * offset + acc_lp_.p01 * state_.acc_lp_rate;
  state_.acc_lp_rate = acc_lp_.p10 * offset + acc_lp_.p11 * state_.acc_lp_rate;
  return rotate(state_.q_gyr.conjugate(), state_.acc_lp_y);
}

double SeelRuppinFilter::GainCache::gain(double dt, double tau_14) {
  if (dt != cached_dt) {
    cached_dt = dt;
    k = dt / (tau_14 + dt);
  }
  return k;
}

UpdateResult SeelRuppinFilter::start(const ImuSample& s) {
  if (!physically_possible(s)) return UpdateResult::kRejected;
  // A restart after a gap keeps the sensor-fixed field (it belongs to the sensor) and starts its fit afresh.
  ImuSample corrected = s;
  if (use_magnetometer_) corrected.mag -= state_.mag_offset.offset();
  state_.mag_offset.restart_block();
  const std::optional<StartOrientation> initial = start_orientation(corrected);
  if (!initial) return UpdateResult::kRejected;
  const bool mag_usable = initial->with_mag;
  state_.q = initial->q;
  state_.q_gyr = Quat::Identity();
  state_.acc_lp_y = state_.acc_lp_rate = Vec3::Zero();
  state_.acc_lp_warmup_s = 0.0;
  state_.acc_lp_count = 1.0;  // the start-up mean begins with this sample (q_gyr = identity)
  state_.acc_lp_mean = s.acc;
  state_.heading_known = mag_usable;
  state_.last_mag_ns = mag_usable ? s.timestamp_ns : 0;
  state_.flags = start_flags(use_magnetometer_ && s.has_mag && !mag_usable);
  state_.rest.reset();
  start_mag_reference(s.timestamp_ns);
  state_.flags.resting = state_.rest.update(s);
  return UpdateResult::kInitialised;
}

// Eqs. 7-10 and the accelerometer part of eq. 13. The accelerometer is not normalised: the error angle
// atan2(|a x r|, a . r) and the clipping test are scale-invariant.
Vec3 SeelRuppinFilter::acc_correction(const Vec3& acc, const Vec3& r_acc, double dt) {
  const Vec3 cross = acc.cross(r_acc);  // |a| sin(alpha) along the correction axis
  const double sin2 = cross.squaredNorm();
  const double cos_err = acc.dot(r_acc);  // |a| cos(alpha)
  const double k = acc_gain_.gain(dt, coeff_.tau_acc_14);
  Vec3 rotation;  // k * alpha * axis, eq. 10
  if (cos_err > 0.0 && sin2 < coeff_.small_acc_error_tan2 * cos_err * cos_err) {
    // The usual case, a small error below the clip: alpha * axis = (atan(t) / t) * cross / cos_err with
    // t^2 = sin2 / cos_err^2: no square root, no atan2, one division.
    const double inv_cos = 1.0 / cos_err;
    rotation = (k * atan_over_t(sin2 * inv_cos * inv_cos) * inv_cos) * cross;
  } else {
    const double sin_err = std::sqrt(sin2);
    // alpha = min(atan2(sin, cos), max) (robust form of the paper's arccos). A clipped error needs no atan2:
    // for max < pi, alpha >= max exactly when sin(alpha - max) >= 0. No clip while initialising: a start in
    // motion can leave a large true error, which the clip would take tens of seconds to remove.
    const bool clip = !state_.flags.initialising;
    const double alpha =
        clip && coeff_.acc_clip_test && sin_err * coeff_.cos_max_acc_error - cos_err * coeff_.sin_max_acc_error >= 0.0
            ? params_.max_acc_error_rad
            : (clip ? std::min(std::atan2(sin_err, cos_err), params_.max_acc_error_rad) : std::atan2(sin_err, cos_err));
    if (alpha < 1e-15) return Vec3::Zero();
    // At 180 deg the axis is undefined; any axis perpendicular to a is a shortest correction.
    const Vec3 axis = sin_err > 1e-12 * std::abs(cos_err) ? Vec3(cross / sin_err) : Vec3(acc.unitOrthogonal());
    rotation = (k * alpha) * axis;
  }
  // Eq. 13 (b = -gyro_bias); not while initialising, when corrections remove the initial error, not a bias.
  if (!state_.flags.initialising) state_.gyro_bias -= coeff_.bias_factor_acc * rotation;
  return rotation;
}

void SeelRuppinFilter::start_mag_reference(std::uint64_t t_ns) {
  state_.mag_detector.reset();
  state_.mag_learning = true;
  state_.mag_learning_since_ns = t_ns;
  state_.mag_norm_sum = state_.mag_dip_sum = state_.mag_learning_count = 0.0;
}

bool SeelRuppinFilter::mag_disturbed(std::uint64_t t_ns, const Vec3& mag, const Vec3& up, double rate_rad_s,
                                     double dt) {
  if (state_.mag_learning) {
    // Learn only once the start-up is over: the dip needs a converged vertical.
    if (state_.flags.initialising) return false;
    if (state_.mag_learning_count == 0.0) state_.mag_learning_since_ns = t_ns;
    state_.mag_norm_sum += mag.norm();
    state_.mag_dip_sum += MagDisturbanceDetector::dip_angle(mag, up);
    state_.mag_learning_count += 1.0;
    if (t_ns - state_.mag_learning_since_ns >= coeff_.mag_reference_ns) {
      state_.mag_detector.set_reference(state_.mag_norm_sum / state_.mag_learning_count,
                                        state_.mag_dip_sum / state_.mag_learning_count, params_.mag_reference_s);
      state_.mag_learning = false;
    }
    return false;
  }
  // Disturbed readings are skipped, unless the rejection has lasted so long that the detector lets them in with a
  // reduced gain (the heading must not drift for ever).
  state_.mag_detector.update(t_ns, mag, up, rate_rad_s, dt);
  return !state_.mag_detector.usable();
}

// Eqs. 11-12 and the magnetometer part of eq. 13: the correction axis is the estimated vertical, so the
// magnetometer turns the heading only.
Vec3 SeelRuppinFilter::mag_correction(const ImuSample& s, const Vec3& mag, const Vec3& r_acc, double rate_rad_s,
                                      double dt) {
  if (params_.mag_rejection != 0.0 && mag_disturbed(s.timestamp_ns, mag, r_acc, rate_rad_s, dt)) {
    state_.flags.mag_rejected = true;
    return Vec3::Zero();
  }
  const Vec3 m_horizontal = mag - mag.dot(r_acc) * r_acc;  // eq. 11
  if (!(m_horizontal.squaredNorm() > 1e-6 * mag.squaredNorm())) {
    state_.flags.mag_rejected = true;  // field (nearly) vertical: no heading information
    return Vec3::Zero();
  }
  const Vec3 r_mag = earth_axis_in_sensor(state_.q, 1);  // ENU: magnetic north is earth y
  const double alpha = signed_angle(m_horizontal, r_mag, r_acc);
  // The gain uses the time since the last used magnetometer reading, so tau_mag holds in seconds even when the
  // magnetometer is slower than the IMU.
  const std::uint64_t since_mag = s.timestamp_ns - state_.last_mag_ns;
  const double dt_mag =
      (state_.last_mag_ns != 0 && since_mag <= max_gap_ns()) ? static_cast<double>(since_mag) * 1e-9 : dt;
  // During the start-up the heading converges as fast as the tilt: an initial heading taken with a wrong
  // vertical (a start in motion) is wrong too.
  const double k_full = !state_.heading_known       ? 1.0
                        : state_.flags.initialising ? start_mag_gain_.gain(dt_mag, coeff_.tau_start_mag_14)
                                                    : mag_gain_.gain(dt_mag, coeff_.tau_mag_14);
  const double k = params_.mag_rejection != 0.0 ? k_full * state_.mag_detector.gain_factor() : k_full;
  const Vec3 rotation = (k * alpha) * r_acc;  // eq. 12
  if (state_.heading_known && !state_.flags.initialising) state_.gyro_bias -= coeff_.bias_factor_mag * rotation;
  state_.heading_known = true;
  state_.last_mag_ns = s.timestamp_ns;
  return rotation;
}

// Flattened: the helpers it calls (series, rotations, the magnetometer's lag compensation) are inlined into one
// function; inlining changes no arithmetic.
[[gnu::flatten]] UpdateResult SeelRuppinFilter::step(const ImuSample& s, double dt) {
  if (!physically_possible(s)) return UpdateResult::kRejected;
  state_.flags.reinitialised = false;
  state_.flags.mag_rejected = false;
  state_.flags.initialising = within_init_period(s.timestamp_ns);

  // Strapdown prediction with the bias-corrected rate (eq. 14), exact for a rate constant over the step.
  if (s.has_gyr) {
    const Quat dq = exp_rotation_vector((s.gyr - state_.gyro_bias) * dt);
    state_.q = state_.q * dq;
    if (coeff_.gyro_integral) state_.q_gyr = renormalised(state_.q_gyr * dq);
  }
  // Both corrections are computed from the predicted orientation and applied as one rotation: each turns the
  // estimate by at most a few milliradians, so taking one after the other would change the other's axis only at
  // second order, and one exponential and one product are saved per sample.
  const Vec3 r_acc = earth_axis_in_sensor(state_.q, 2);  // eq. 7: earth vertical in sensor coordinates
  Vec3 correction = Vec3::Zero();
  if (s.has_acc && s.acc.squaredNorm() > 1e-12) {
    correction = acc_correction(coeff_.acc_lowpass ? lowpass_acc(s.acc, dt) : s.acc, r_acc, dt);
  }
  if (s.has_mag && use_magnetometer_) {
    // The magnetometer's own delay; only the horizontal part of the rate turns the field's dip (a turn about the
    // vertical keeps it).
    const Vec3 rate = s.has_gyr ? Vec3(s.gyr - state_.gyro_bias) : Vec3::Zero();
    Vec3 mag = params_.mag_latency_s > 0.0 ? lag_compensated(s.mag, rate, params_.mag_latency_s) : s.mag;
    if (state_.mag_offset.enabled()) {
      if (state_.mag_offset.update(s.timestamp_ns, state_.q_gyr, mag) && !state_.mag_learning) {
        // The fit's earth field is the detector's reference from now on: with the offset removed the readings show
        // it, whether the offset was there from the start (the reference held it) or came later (a magnet attached).
        const Vec3& h = state_.mag_offset.field_inertial();
        const Vec3 up_inertial = rotate(state_.q_gyr, r_acc);
        state_.mag_detector.set_reference(h.norm(), MagDisturbanceDetector::dip_angle(h, up_inertial),
                                          params_.mag_reference_s);
      }
      mag -= state_.mag_offset.offset();
    }
    correction += mag_correction(s, mag, r_acc, rate.cross(r_acc).norm(), dt);
  }
  state_.q = state_.q * exp_rotation_vector(correction);  // eqs. 10 and 12
  state_.q = renormalised(state_.q);
  const double max_bias = params_.max_gyro_bias_rad_s;
  state_.gyro_bias = state_.gyro_bias.cwiseMax(-max_bias).cwiseMin(max_bias);

  // q is unit and the bias clamped: their sum is finite exactly when every component is.
  const Vec3& b = state_.gyro_bias;
  if (!std::isfinite(state_.q.w() + state_.q.x() + state_.q.y() + state_.q.z() + b.x() + b.y() + b.z())) {
    // Cannot happen with physically possible input (every quantity stays bounded); should it ever, start
    // afresh rather than pass NaN downstream.
    reset();
    return UpdateResult::kRejected;
  }
  if (params_.rest_bias_lowpass != 0.0 && s.has_gyr) {
    state_.bias_lowpass.set_bias(state_.gyro_bias);
    state_.bias_lowpass.update(s.timestamp_ns, dt, s.gyr);
    if (state_.bias_lowpass.updating())
      state_.gyro_bias = state_.bias_lowpass.bias().cwiseMax(-max_bias).cwiseMin(max_bias);
  }
  state_.flags.resting = state_.rest.update(s);
  return UpdateResult::kUpdated;
}

std::unique_ptr<OrientationFilter> make_seel_ruppin_filter(const FilterSpec& spec) {
  return std::make_unique<SeelRuppinFilter>(bind_parameters(kName, spec, kParams), true);
}

std::unique_ptr<OrientationFilter> make_seel_ruppin6_filter(const FilterSpec& spec) {
  return std::make_unique<SeelRuppinFilter>(bind_parameters(kName6, spec, kParams), false);
}

}  // namespace bsn::fusion
