#include "bsn/fusion/iecf_filter.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <new>
#include <type_traits>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/start_orientation.hpp"

namespace bsn::fusion {
namespace {

// Room for a copy of the detector that is made only when needed. A default-constructed std::optional would do, but
// GCC 12 fills its storage with zeros (GCC bug 86173): 400 bytes, 50 stores, on every sample.
struct DeferredDetector {
  DeferredDetector() {}  // leaves `detector` unconstructed (it is trivially destructible)
  union {
    MagDisturbanceDetector detector;
  };
};
static_assert(std::is_trivially_destructible_v<MagDisturbanceDetector>);

using P = IecfFilter::Params;
constexpr auto kParams = join_param_fields(std::to_array<ParamField<P>>({
                                               {"gain", &P::gain},
                                               {"initial_gain", &P::initial_gain},
                                               {"gyro_bias_lowpass", &P::gyro_bias_lowpass},
                                               {"mag_rejection", &P::mag_rejection},
                                           }),
                                           bias_param_fields<P>(), mag_disturbance_param_fields<P>(),
                                           rest_param_fields<P>(), timing_param_fields<P>());

const P& checked(const P& p, std::string_view name) {
  require_positive(name, p.gain, "gain");
  require_positive(name, p.initial_gain, "initial_gain");
  p.GyroBiasRemovalParams::check(name);
  p.MagRejectionParams::check(name);
  return p;
}

}  // namespace

IecfFilter::IecfFilter(const Params& params, bool use_magnetometer)
    : FilterBase(use_magnetometer ? "iecf" : "iecf6", checked(params, use_magnetometer ? "iecf" : "iecf6")),
      use_magnetometer_(use_magnetometer) {
  state_.rest = RestDetector(params);
  state_.bias_lowpass = GyroBiasLowPass(params);
  state_.mag_detector = MagDisturbanceDetector(params);
  // |gain e dt| <= gain (|e_a| + weight |e_m|) dt <= gain (dt + max_gap_s) <= 2 gain max_gap_s (unit crosses).
  coeff_.correction_bounded = 2.0 * std::max(params.gain, params.initial_gain) * params.max_gap_s < 1e149;
  keep_fresh_state();
}

double IecfFilter::gain_at(double since_init_s) const {
  if (!(since_init_s < params_.init_period_s)) return params_.gain;
  const double fraction = std::max(0.0, since_init_s) / params_.init_period_s;
  return params_.initial_gain + (params_.gain - params_.initial_gain) * fraction;
}

UpdateResult IecfFilter::start(const ImuSample& s) {
  // IECF6 too takes its initial heading from the magnetometer when there is one (Fan's IECF6 "with the
  // alignment of the initial yaw angle"); afterwards it never reads it again.
  const std::optional<StartOrientation> initial = start_orientation(s);
  if (!initial) return UpdateResult::kRejected;
  const bool with_mag = initial->with_mag;
  state_.q = initial->q;
  state_.heading_known = with_mag;
  state_.last_mag_ns = with_mag ? s.timestamp_ns : 0;
  state_.flags = start_flags(use_magnetometer_ && s.has_mag && !with_mag);
  state_.rest.reset();
  state_.mag_detector.reset();
  if (with_mag && use_magnetometer_) state_.mag_detector.update(s.timestamp_ns, s.mag, s.acc.normalized());
  state_.flags.resting = state_.rest.update(s);
  return UpdateResult::kInitialised;
}

// Flattened: the helpers it calls (series, rotations, the magnetometer's lag compensation) are inlined into one
// function; inlining changes no arithmetic.
[[gnu::flatten]] UpdateResult IecfFilter::step(const ImuSample& s, double dt) {
  const Vec3 mag =
      mag_at_gyro_time(s, state_.bias_lowpass.bias(), params_.mag_latency_s);  // the magnetometer's own delay
  const std::uint64_t dt_ns = s.timestamp_ns - clock().last_ns;
  const std::uint64_t since_init_ns = s.timestamp_ns - clock().init_ns;
  const double gain =
      since_init_ns >= init_period_ns() ? params_.gain : gain_at(static_cast<double>(since_init_ns) * 1e-9);
  const Vec3 rate = !s.has_gyr                         ? Vec3::Zero()
                    : params_.gyro_bias_lowpass != 0.0 ? Vec3(s.gyr - state_.bias_lowpass.bias())
                                                       : s.gyr;
  const Vec3 gyro_step = rate * dt;
  // The step can only overflow (and the sample be rejected) for an absurd rate or gain: only then is the detector
  // saved, to be restored on rejection.
  DeferredDetector detector_before;
  const bool save_detector = !(gyro_step.squaredNorm() < 1e300) || !coeff_.correction_bounded;
  if (save_detector) new (&detector_before.detector) MagDisturbanceDetector(state_.mag_detector);
  Quat q = state_.q;
  bool mag_used = false;
  bool mag_rejected = false;

  Vec3 error = Vec3::Zero();
  const double acc_squared_norm = s.has_acc ? s.acc.squaredNorm() : 0.0;
  if (acc_squared_norm > 1e-12) {
    const Vec3 a = s.acc * (1.0 / std::sqrt(acc_squared_norm));
    const Vec3 up_est = earth_axis_in_sensor(q, 2);
    error += a.cross(up_est);  // e_a: measured x predicted up
    // heading_from_mag_possible(s), with the norms computed once: |m| > 1e-9 and |m x a| > 1e-3 |m| |a|, squared, a
    // unit.
    const double mag_squared_norm = use_magnetometer_ && s.has_mag ? mag.squaredNorm() : 0.0;
    const Vec3 m_cross_a = mag.cross(a);
    const double m_cross_a_squared_norm = m_cross_a.squaredNorm();
    if (mag_squared_norm > 1e-18 && m_cross_a_squared_norm > 1e-6 * mag_squared_norm) {
      double mag_weight = 1.0;
      if (params_.mag_rejection != 0.0) {
        state_.mag_detector.update(s.timestamp_ns, mag, up_est, rate.cross(up_est).norm(), dt);  // horizontal rate
        mag_weight = state_.mag_detector.gain_factor();  // < 1 for a field used after a long rejection
      }
      if (params_.mag_rejection != 0.0 && !state_.mag_detector.usable()) {
        mag_rejected = true;
      } else if (!state_.heading_known) {
        q = orientation_from_acc_mag(s.acc, mag);  // first heading after a start without magnetometer
        mag_used = true;
      } else {
        const Vec3 east_measured = m_cross_a * (1.0 / std::sqrt(m_cross_a_squared_norm));  // north x up = east
        const Vec3 east_predicted = earth_axis_in_sensor(q, 0);
        // Weighted by the time since the last used reading, so the heading gain holds per second with a
        // magnetometer slower than the IMU (1 exactly when the last sample had one).
        const std::uint64_t since_mag = s.timestamp_ns - state_.last_mag_ns;
        const double weight = (state_.last_mag_ns == 0 || since_mag > max_gap_ns()) ? 1.0
                              : since_mag == dt_ns                                  ? 1.0
                                                   : static_cast<double>(since_mag) * 1e-9 / dt;
        error += (mag_weight * weight) * east_measured.cross(east_predicted);  // e_m (virtual east, section 2.1.2)
        mag_used = true;
      }
    } else if (use_magnetometer_ && s.has_mag) {
      mag_rejected = true;  // zero field or field along gravity: no heading information
    }
  }

  q = q * exp_rotation_vector(gyro_step + (gain * dt) * error);         // eqs. 14-15, exact for the step
  q.coeffs() *= inverse_sqrt_near_one(q.coeffs().squaredNorm());        // a product of unit quaternions
  if (!std::isfinite(q.w() + q.x() + q.y() + q.z())) {                  // normalised: finite sum = finite components
    if (save_detector) state_.mag_detector = detector_before.detector;  // extreme finite input: keep the state
    return UpdateResult::kRejected;
  }

  state_.q = q;
  if (mag_used) {
    state_.heading_known = true;
    state_.last_mag_ns = s.timestamp_ns;
  }
  state_.flags.reinitialised = false;
  state_.flags.mag_rejected = mag_rejected;
  if (s.has_gyr && params_.gyro_bias_lowpass != 0.0) state_.bias_lowpass.update(s.timestamp_ns, dt, s.gyr);
  return updated(s);
}

std::unique_ptr<OrientationFilter> make_iecf_filter(const FilterSpec& spec) {
  return std::make_unique<IecfFilter>(bind_parameters("iecf", spec, kParams), true);
}

std::unique_ptr<OrientationFilter> make_iecf6_filter(const FilterSpec& spec) {
  return std::make_unique<IecfFilter>(bind_parameters("iecf6", spec, kParams), false);
}

}  // namespace bsn::fusion
