#include "bsn/fusion/complementary_filter.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

#include "bsn/fusion/filter_params.hpp"

namespace bsn::fusion {
namespace {

constexpr const char* kName = "complementary";

constexpr ParamField<ComplementaryFilter::Params> kParams[] = {
    {"tau_acc_s", &ComplementaryFilter::Params::tau_acc_s},
    {"tau_mag_s", &ComplementaryFilter::Params::tau_mag_s},
    {"max_gap_s", &ComplementaryFilter::Params::max_gap_s},
    {"acc_rejection_m_s2", &ComplementaryFilter::Params::acc_rejection_m_s2},
    {"mag_norm_tolerance", &ComplementaryFilter::Params::mag_norm_tolerance},
    {"rest_gyr_rad_s", &ComplementaryFilter::Params::rest_gyr_rad_s},
    {"rest_acc_m_s2", &ComplementaryFilter::Params::rest_acc_m_s2},
    {"rest_min_s", &ComplementaryFilter::Params::rest_min_s},
    {"init_period_s", &ComplementaryFilter::Params::init_period_s},
};

std::uint64_t seconds_to_ns(double s) { return static_cast<std::uint64_t>(std::llround(s * 1e9)); }

// Gain of a first-order low-pass with time constant tau for a step dt: exact for any dt.
double step_gain(double dt, double inv_tau) { return 1.0 - std::exp(-dt * inv_tau); }

}  // namespace

ComplementaryFilter::ComplementaryFilter(const Params& params) : params_(params) {
  require_positive(kName, params.tau_acc_s, "tau_acc_s");
  require_positive(kName, params.tau_mag_s, "tau_mag_s");
  require_positive(kName, params.max_gap_s, "max_gap_s");
  require_positive(kName, params.acc_rejection_m_s2, "acc_rejection_m_s2");
  require_positive(kName, params.mag_norm_tolerance, "mag_norm_tolerance");
  require_positive(kName, params.rest_gyr_rad_s, "rest_gyr_rad_s");
  require_positive(kName, params.rest_acc_m_s2, "rest_acc_m_s2");
  require_positive(kName, params.rest_min_s, "rest_min_s");
  require_positive(kName, params.init_period_s, "init_period_s");
  coeff_.inv_tau_acc = 1.0 / params.tau_acc_s;
  coeff_.inv_tau_mag = 1.0 / params.tau_mag_s;
  coeff_.max_gap_ns = seconds_to_ns(params.max_gap_s);
  coeff_.rest_min_ns = seconds_to_ns(params.rest_min_s);
  coeff_.init_period_ns = seconds_to_ns(params.init_period_s);
}

UpdateResult ComplementaryFilter::initialise(const ImuSample& s) {
  // An orientation needs at least the direction of gravity.
  if (!s.has_acc || s.acc.norm() < 1e-6) return UpdateResult::kRejected;
  const bool mag_usable =
      s.has_mag && s.mag.cross(s.acc).norm() > 1e-6 * s.mag.norm() * s.acc.norm() && s.mag.norm() > 1e-9;
  state_.q = mag_usable ? orientation_from_acc_mag(s.acc, s.mag) : orientation_from_acc(s.acc);
  state_.mag_ref_norm = mag_usable ? s.mag.norm() : 0.0;
  state_.initialised = true;
  state_.last_ns = s.timestamp_ns;
  state_.init_ns = s.timestamp_ns;
  state_.still = false;
  state_.flags = FilterFlags{};
  state_.flags.initialising = true;
  state_.flags.reinitialised = true;
  state_.flags.mag_rejected = s.has_mag && !mag_usable;
  return UpdateResult::kInitialised;
}

void ComplementaryFilter::update_rest(const ImuSample& s) {
  const bool still_now = s.has_gyr && s.has_acc && s.gyr.norm() < params_.rest_gyr_rad_s &&
                         std::abs(s.acc.norm() - kGravity) < params_.rest_acc_m_s2;
  if (!still_now) {
    state_.still = false;
  } else if (!state_.still) {
    state_.still = true;
    state_.still_since_ns = s.timestamp_ns;
  }
  state_.flags.resting = state_.still && s.timestamp_ns - state_.still_since_ns >= coeff_.rest_min_ns;
}

UpdateResult ComplementaryFilter::update(const ImuSample& s) {
  if (!s.finite()) return UpdateResult::kRejected;
  if (!state_.initialised) return initialise(s);
  if (s.timestamp_ns <= state_.last_ns) return UpdateResult::kRejected;
  if (s.timestamp_ns - state_.last_ns > coeff_.max_gap_ns) return initialise(s);

  const double dt = static_cast<double>(s.timestamp_ns - state_.last_ns) * 1e-9;
  state_.last_ns = s.timestamp_ns;
  state_.flags.reinitialised = false;

  // Strapdown prediction: exact for a rate constant over the step (sensor-frame increment on the right).
  if (s.has_gyr) state_.q = (state_.q * exp_rotation_vector(s.gyr * dt)).normalized();

  // Tilt correction: turn the earth-frame image of the measured up direction towards earth z.
  if (s.has_acc && std::abs(s.acc.norm() - kGravity) < params_.acc_rejection_m_s2) {
    const Vec3 up_est = state_.q * s.acc.normalized();
    const Vec3 axis = up_est.cross(Vec3::UnitZ());
    const double angle = std::atan2(axis.norm(), up_est.z());
    if (axis.norm() > 1e-12) {
      const double k = step_gain(dt, coeff_.inv_tau_acc);
      state_.q = (Quat(Eigen::AngleAxisd(k * angle, axis.normalized())) * state_.q).normalized();
    }
  }

  // Heading correction about earth z only, so the magnetometer never tilts the estimate.
  state_.flags.mag_rejected = false;
  if (s.has_mag) {
    const double norm = s.mag.norm();
    if (state_.mag_ref_norm <= 0.0 && norm > 1e-9) state_.mag_ref_norm = norm;
    const Vec3 m_earth = state_.q * s.mag;
    const double horizontal = std::hypot(m_earth.x(), m_earth.y());
    const bool disturbed = std::abs(norm - state_.mag_ref_norm) > params_.mag_norm_tolerance * state_.mag_ref_norm;
    if (disturbed || horizontal < 1e-6 * norm || norm <= 1e-9) {
      state_.flags.mag_rejected = true;
    } else {
      // Angle that takes the horizontal field onto earth y (north).
      const double heading_error = std::atan2(m_earth.x(), m_earth.y());
      const double k = step_gain(dt, coeff_.inv_tau_mag);
      state_.q = (Quat(Eigen::AngleAxisd(k * heading_error, Vec3::UnitZ())) * state_.q).normalized();
    }
  }

  update_rest(s);
  state_.flags.initialising = s.timestamp_ns - state_.init_ns < coeff_.init_period_ns;
  return UpdateResult::kUpdated;
}

std::unique_ptr<OrientationFilter> make_complementary_filter(const FilterSpec& spec) {
  return std::make_unique<ComplementaryFilter>(bind_parameters(kName, spec, kParams));
}

}  // namespace bsn::fusion
