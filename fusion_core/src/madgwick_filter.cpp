#include "bsn/fusion/madgwick_filter.hpp"

#include <cmath>

#include "bsn/fusion/filter_params.hpp"

namespace bsn::fusion {
namespace {

using P = MadgwickFilter::Params;
constexpr ParamField<P> kParams[] = {
    {"beta", &P::beta},
    {"gyro_bias_lowpass", &P::gyro_bias_lowpass},
    {"bias_corner_frequency_hz", &P::bias_corner_frequency_hz},
    {"bias_omega_min_rad_s", &P::bias_omega_min_rad_s},
    {"bias_min_static_s", &P::bias_min_static_s},
    {"max_gap_s", &P::max_gap_s},
    {"rest_gyr_rad_s", &P::rest_gyr_rad_s},
    {"rest_acc_m_s2", &P::rest_acc_m_s2},
    {"rest_min_s", &P::rest_min_s},
    {"init_period_s", &P::init_period_s},
};

std::uint64_t seconds_to_ns(double s) { return static_cast<std::uint64_t>(std::llround(s * 1e9)); }

const P& checked(const P& p, std::string_view name) {
  require_positive(name, p.beta, "beta");
  require_positive(name, p.max_gap_s, "max_gap_s");
  require_positive(name, p.init_period_s, "init_period_s");
  if (p.gyro_bias_lowpass != 0.0 && p.gyro_bias_lowpass != 1.0) {
    throw std::invalid_argument(std::string(name) + ": parameter gyro_bias_lowpass must be 0 or 1, got " +
                                std::to_string(p.gyro_bias_lowpass));
  }
  return p;
}

bool mag_usable(const ImuSample& s) {
  return s.has_mag && s.has_acc && s.mag.norm() > 1e-9 && s.acc.norm() > 1e-6 &&
         s.mag.cross(s.acc).norm() > 1e-3 * s.mag.norm() * s.acc.norm();
}

// mag_usable() for a sample whose channels are present and already normalised (|m x a| > 1e-3 |m| |a|).
bool mag_usable_units(double mag_squared_norm, double acc_squared_norm, const Vec3& mag_unit, const Vec3& acc_unit) {
  return mag_squared_norm > 1e-18 && acc_squared_norm > 1e-12 && mag_unit.cross(acc_unit).squaredNorm() > 1e-6;
}

// The accelerometer part of gradient(), J(q, up)^T f(q, up, a), written out: the terms of the general form that
// multiply a zero component of up = (0, 0, 1) vanish exactly (Madgwick eqs. 25-26).
Eigen::Vector4d gravity_gradient(const Quat& q, const Vec3& a) {
  const double w = q.w(), x = q.x(), y = q.y(), z = q.z();
  const double f0 = 2 * (x * z - w * y) - a.x();
  const double f1 = 2 * (y * z + w * x) - a.y();
  const double f2 = 1 - 2 * (x * x + y * y) - a.z();
  return Eigen::Vector4d(-2 * y * f0 + 2 * x * f1, 2 * z * f0 + 2 * w * f1 - 4 * x * f2,
                         -2 * w * f0 + 2 * z * f1 - 4 * y * f2, 2 * x * f0 + 2 * y * f1);
}

// The magnetometer part of gradient(), J(q, b)^T f(q, b, m), written out for b = (0, b1, b2) (the terms with
// b0 = 0 vanish exactly; Madgwick eqs. 29-30 in ENU).
Eigen::Vector4d field_gradient(const Quat& q, const Vec3& b, const Vec3& m) {
  const double w = q.w(), x = q.x(), y = q.y(), z = q.z();
  const double b1 = b.y(), b2 = b.z();
  const double f0 = 2 * (x * y + w * z) * b1 + 2 * (x * z - w * y) * b2 - m.x();
  const double f1 = (1 - 2 * (x * x + z * z)) * b1 + 2 * (y * z + w * x) * b2 - m.y();
  const double f2 = 2 * (y * z - w * x) * b1 + (1 - 2 * (x * x + y * y)) * b2 - m.z();
  return Eigen::Vector4d(2 * (z * b1 - y * b2) * f0 + 2 * (x * b2) * f1 + 2 * (-x * b1) * f2,
                         2 * (y * b1 + z * b2) * f0 + 2 * (-2 * x * b1 + w * b2) * f1 + 2 * (-w * b1 - 2 * x * b2) * f2,
                         2 * (x * b1 - w * b2) * f0 + 2 * (z * b2) * f1 + 2 * (z * b1 - 2 * y * b2) * f2,
                         2 * (w * b1 + x * b2) * f0 + 2 * (-2 * z * b1 + y * b2) * f1 + 2 * (y * b1) * f2);
}

}  // namespace

MadgwickFilter::MadgwickFilter(const Params& params, bool use_magnetometer)
    : params_(checked(params, use_magnetometer ? "madgwick" : "madgwick6")),
      use_magnetometer_(use_magnetometer),
      rest_({params.rest_gyr_rad_s, params.rest_acc_m_s2, params.rest_min_s}),
      bias_({params.bias_corner_frequency_hz, params.bias_omega_min_rad_s, params.bias_min_static_s}) {
  coeff_.max_gap_ns = seconds_to_ns(params.max_gap_s);
  coeff_.init_period_ns = seconds_to_ns(params.init_period_s);
}

// R(q)^T d for a unit q = (w, x, y, z) in the paper's form (diagonal terms 1 - 2(..)), and its Jacobian as the
// paper differentiates it (eqs. 25-26 and 29-30 generalised to any reference d).
Vec3 MadgwickFilter::objective(const Quat& q, const Vec3& d, const Vec3& s) {
  const double w = q.w(), x = q.x(), y = q.y(), z = q.z();
  return Vec3((1 - 2 * (y * y + z * z)) * d.x() + 2 * (x * y + w * z) * d.y() + 2 * (x * z - w * y) * d.z(),
              2 * (x * y - w * z) * d.x() + (1 - 2 * (x * x + z * z)) * d.y() + 2 * (y * z + w * x) * d.z(),
              2 * (x * z + w * y) * d.x() + 2 * (y * z - w * x) * d.y() + (1 - 2 * (x * x + y * y)) * d.z()) -
         s;
}

MadgwickFilter::Jacobian MadgwickFilter::jacobian(const Quat& q, const Vec3& d) {
  const double w = q.w(), x = q.x(), y = q.y(), z = q.z();
  const double d0 = d.x(), d1 = d.y(), d2 = d.z();
  Jacobian j;
  j << 2 * (z * d1 - y * d2), 2 * (y * d1 + z * d2), 2 * (-2 * y * d0 + x * d1 - w * d2),
      2 * (-2 * z * d0 + w * d1 + x * d2),  //
      2 * (-z * d0 + x * d2), 2 * (y * d0 - 2 * x * d1 + w * d2), 2 * (x * d0 + z * d2),
      2 * (-w * d0 - 2 * z * d1 + y * d2),  //
      2 * (y * d0 - x * d1), 2 * (z * d0 - w * d1 - 2 * x * d2), 2 * (w * d0 + z * d1 - 2 * y * d2),
      2 * (x * d0 + y * d1);
  return j;
}

Vec3 MadgwickFilter::magnetic_reference(const Quat& q, const Vec3& m_unit) {
  const Vec3 h = q * m_unit;
  return Vec3(0.0, std::sqrt(h.x() * h.x() + h.y() * h.y()), h.z());  // h is unit: no hypot needed
}

Eigen::Vector4d MadgwickFilter::gradient(const Quat& q, const Vec3& acc_unit, const Vec3& mag_unit, bool use_mag) {
  const Vec3 up = Vec3::UnitZ();
  Eigen::Vector4d grad = jacobian(q, up).transpose() * objective(q, up, acc_unit);
  if (use_mag) {
    const Vec3 b = magnetic_reference(q, mag_unit);
    grad += jacobian(q, b).transpose() * objective(q, b, mag_unit);
  }
  return grad;
}

void MadgwickFilter::reset() {
  state_ = State{};
  rest_.reset();
  bias_.reset();
}

UpdateResult MadgwickFilter::initialise(const ImuSample& s) {
  if (!s.has_acc || !(s.acc.norm() > 1e-6)) return UpdateResult::kRejected;
  // The 6D variant too takes its initial heading from the magnetometer when there is one (an absolute start,
  // as Fan's IECF6 with its initial yaw aligned); afterwards it never reads it again.
  const bool with_mag = mag_usable(s);
  state_.q = with_mag ? orientation_from_acc_mag(s.acc, s.mag) : orientation_from_acc(s.acc);
  state_.initialised = true;
  state_.last_ns = s.timestamp_ns;
  state_.init_ns = s.timestamp_ns;
  state_.flags = FilterFlags{};
  state_.flags.initialising = true;
  state_.flags.reinitialised = true;
  state_.flags.mag_rejected = use_magnetometer_ && s.has_mag && !with_mag;
  state_.held_mag = with_mag && use_magnetometer_ ? Vec3(s.mag.normalized()) : Vec3::Zero();
  state_.held_mag_ns = with_mag && use_magnetometer_ ? s.timestamp_ns : 0;
  rest_.reset();
  state_.flags.resting = rest_.update(s);
  return UpdateResult::kInitialised;
}

UpdateResult MadgwickFilter::update(const ImuSample& s) {
  if (!s.finite()) return UpdateResult::kRejected;
  if (!state_.initialised) return initialise(s);
  if (s.timestamp_ns <= state_.last_ns) return UpdateResult::kRejected;
  if (s.timestamp_ns - state_.last_ns > coeff_.max_gap_ns) return initialise(s);

  const double dt = static_cast<double>(s.timestamp_ns - state_.last_ns) * 1e-9;
  Quat q = state_.q;
  Vec3 held_mag = state_.held_mag;
  // Gyro part, integrated exactly for a rate constant over the step (the paper's Euler step of
  // q_dot = q (x) (0, w) / 2 is its first-order approximation).
  if (s.has_gyr) {
    const Vec3 rate = params_.gyro_bias_lowpass != 0.0 ? Vec3(s.gyr - bias_.bias()) : s.gyr;
    const Quat increment = exp_rotation_vector(rate * dt);
    q = q * increment;
    if (use_magnetometer_) held_mag = increment.conjugate() * held_mag;  // a fixed earth vector, turned sensor
  }
  // Each norm once: the unit vectors serve both the usability test and the gradient.
  const double acc_squared_norm = s.has_acc ? s.acc.squaredNorm() : 0.0;
  const bool acc_usable = acc_squared_norm > 1e-12;
  const Vec3 acc_unit = acc_usable ? Vec3(s.acc / std::sqrt(acc_squared_norm)) : Vec3::Zero();
  bool with_mag = false;
  if (use_magnetometer_ && s.has_mag && acc_usable) {
    const double mag_squared_norm = s.mag.squaredNorm();
    const Vec3 mag_unit = s.mag / std::sqrt(mag_squared_norm);
    with_mag = mag_usable_units(mag_squared_norm, acc_squared_norm, mag_unit, acc_unit);
    if (with_mag) held_mag = mag_unit;
  }
  const bool use_mag = with_mag || (use_magnetometer_ && !s.has_mag && state_.held_mag_ns != 0 &&
                                    s.timestamp_ns - state_.held_mag_ns <= coeff_.max_gap_ns);
  if (acc_usable) {
    Eigen::Vector4d grad = gravity_gradient(q, acc_unit);  // = gradient(q, acc_unit, held_mag, use_mag)
    if (use_mag) {
      const Vec3 b = magnetic_reference(q, held_mag);
      grad += field_gradient(q, b, held_mag);
    }
    const double norm = grad.norm();
    if (norm > 1e-12) {
      const Eigen::Vector4d step = -params_.beta * dt / norm * grad;      // normalised gradient step
      q.coeffs() += Eigen::Vector4d(step[1], step[2], step[3], step[0]);  // Eigen stores (x, y, z, w)
    }
  }
  q.normalize();
  if (!q.coeffs().allFinite()) return UpdateResult::kRejected;  // extreme finite input: keep the state

  state_.q = q;
  state_.held_mag = held_mag;
  if (with_mag) state_.held_mag_ns = s.timestamp_ns;
  if (use_magnetometer_ && s.has_mag && !with_mag) state_.held_mag_ns = 0;  // a bad reading ends the hold
  state_.last_ns = s.timestamp_ns;
  state_.flags.reinitialised = false;
  state_.flags.mag_rejected = use_magnetometer_ && s.has_mag && !with_mag;
  if (s.has_gyr && params_.gyro_bias_lowpass != 0.0) bias_.update(s.timestamp_ns, dt, s.gyr);
  state_.flags.resting = rest_.update(s);
  state_.flags.initialising = s.timestamp_ns - state_.init_ns < coeff_.init_period_ns;
  return UpdateResult::kUpdated;
}

std::unique_ptr<OrientationFilter> make_madgwick_filter(const FilterSpec& spec) {
  return std::make_unique<MadgwickFilter>(bind_parameters("madgwick", spec, kParams), true);
}

std::unique_ptr<OrientationFilter> make_madgwick6_filter(const FilterSpec& spec) {
  return std::make_unique<MadgwickFilter>(bind_parameters("madgwick6", spec, kParams), false);
}

}  // namespace bsn::fusion
