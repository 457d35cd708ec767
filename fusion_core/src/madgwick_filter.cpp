#include "bsn/fusion/madgwick_filter.hpp"

#include <array>
#include <cmath>
#include <optional>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/start_orientation.hpp"

namespace bsn::fusion {
namespace {

using P = MadgwickFilter::Params;
constexpr auto kParams = join_param_fields(std::to_array<ParamField<P>>({
                                               {"beta", &P::beta},
                                               {"gyro_bias_lowpass", &P::gyro_bias_lowpass},
                                           }),
                                           bias_param_fields<P>(), rest_param_fields<P>(), timing_param_fields<P>());

const P& checked(const P& p, std::string_view name) {
  require_positive(name, p.beta, "beta");
  p.GyroBiasRemovalParams::check(name);
  return p;
}
}  // namespace

MadgwickFilter::MadgwickFilter(const Params& params, bool use_magnetometer)
    : FilterBase(use_magnetometer ? "madgwick" : "madgwick6",
                 checked(params, use_magnetometer ? "madgwick" : "madgwick6")),
      use_magnetometer_(use_magnetometer) {
  state_.rest = RestDetector(params);
  // Fan's plain low-pass, without the running mean of the first still time: madgwick has no other bound on its
  // tilt under sustained acceleration, and in Nez's fast motion (the Opal's zero-mean Gauss-Markov bias, 100 s
  // correlation, which a frozen rest estimate matches worse than zero after about a minute) the full estimate
  // took its inclination above the gyro's own integral (seed 12: 10.16 against 9.80 deg; 9.36 with the plain one).
  state_.bias_lowpass = GyroBiasLowPass(params, false);
  coeff_.bias_lowpass = params.gyro_bias_lowpass != 0.0;
  keep_fresh_state();
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

UpdateResult MadgwickFilter::start(const ImuSample& s) {
  // The 6D variant too takes its initial heading from the magnetometer when there is one (an absolute start,
  // as Fan's IECF6 with its initial yaw aligned); afterwards it never reads it again.
  const std::optional<StartOrientation> initial = start_orientation(s);
  if (!initial) return UpdateResult::kRejected;
  const bool with_mag = initial->with_mag;
  state_.q = initial->q;
  state_.flags = start_flags(use_magnetometer_ && s.has_mag && !with_mag);
  state_.held_mag = with_mag && use_magnetometer_ ? s.mag : Vec3::Zero();
  state_.held_mag_ns = with_mag && use_magnetometer_ ? s.timestamp_ns : 0;
  state_.rest.reset();
  state_.flags.resting = state_.rest.update(s);
  return UpdateResult::kInitialised;
}

// Flattened: the helpers it calls (series, rotations, the bias low-pass) are inlined into one function; inlining
// changes no arithmetic.
[[gnu::flatten]] UpdateResult MadgwickFilter::step(const ImuSample& s, double dt) {
  Quat q = state_.q;
  // A held reading is used by a sample without magnetometer within max_gap_s of the last usable one.
  const bool hold =
      use_magnetometer_ && !s.has_mag && state_.held_mag_ns != 0 && s.timestamp_ns - state_.held_mag_ns <= max_gap_ns();
  Vec3 held_mag = state_.held_mag;
  // Gyro part, integrated exactly for a rate constant over the step (the paper's Euler step of
  // q_dot = q (x) (0, w) / 2 is its first-order approximation).
  if (s.has_gyr) {
    const Vec3 rate = coeff_.bias_lowpass ? Vec3(s.gyr - state_.bias_lowpass.bias()) : s.gyr;
    const Quat increment = exp_rotation_vector(rate * dt);
    q = q * increment;
    if (hold) held_mag = rotate(increment.conjugate(), held_mag);  // a fixed earth vector, turned sensor
  }
  // Squared norms only: the field part of the gradient is computed on the raw reading and scaled by 1/|m|^2
  // (it is bilinear in the field), so the magnetometer needs no square root.
  const double acc_squared_norm = s.has_acc ? s.acc.squaredNorm() : 0.0;
  const bool acc_usable = acc_squared_norm > 1e-12;
  const Vec3 acc_unit = acc_usable ? Vec3(s.acc * (1.0 / std::sqrt(acc_squared_norm))) : Vec3::Zero();
  bool with_mag = false;
  if (use_magnetometer_ && s.has_mag && acc_usable) {
    // heading_from_mag_possible(): |m| > 1e-9 and |m x a| > 1e-3 |m| |a|, squared, with a unit.
    const double mag_squared_norm = s.mag.squaredNorm();
    with_mag = mag_squared_norm > 1e-18 && s.mag.cross(acc_unit).squaredNorm() > 1e-6 * mag_squared_norm;
    if (with_mag) held_mag = s.mag;
  }
  const bool use_mag = with_mag || hold;
  if (acc_usable) {
    // The gradient J(q, d)^T f of both objectives, with the Jacobian linear in the reference d: J(q, e_z) has the
    // rows 2 (-y, z, -w, x), 2 (x, w, z, y), 2 (0, -2x, -2y, 0) as (w, x, y, z), and J(q, e_y) the rows 2 (z, y, x, w),
    // 2 (0, -2x, 0, -2z), 2 (-x, -w, z, y) (Madgwick eqs. 25-26 and 29-30 in ENU). So the gradient is
    // sum_i c_i J_z.row(i) + d_i J_y.row(i) with c = f_a + b2 f_m, d = b1 f_m. The common factor 2 is dropped: only
    // the direction of the gradient is used.
    const double w = q.w(), x = q.x(), y = q.y(), z = q.z();
    const double r20 = 2 * (x * z - w * y), r21 = 2 * (y * z + w * x), r22 = 1 - 2 * (x * x + y * y);
    // Accelerometer residual f_a = R^T e_z - a.
    double c0 = r20 - acc_unit.x(), c1 = r21 - acc_unit.y(), c2 = r22 - acc_unit.z();
    double d0 = 0.0, d1 = 0.0, d2 = 0.0;
    if (use_mag) {
      // Field residual f_m = R^T b - m for b = (0, |h_xy|, h_z), h = R m, on the raw m: J(q, b)^T f_m is bilinear
      // in (b, f_m), so it is scaled by 1/|m|^2.
      const Vec3& m = held_mag;
      const double r00 = 1 - 2 * (y * y + z * z), r01 = 2 * (x * y - w * z), r02 = 2 * (x * z + w * y);
      const double r10 = 2 * (x * y + w * z), r11 = 1 - 2 * (x * x + z * z), r12 = 2 * (y * z - w * x);
      const double hx = r00 * m.x() + r01 * m.y() + r02 * m.z();
      const double hy = r10 * m.x() + r11 * m.y() + r12 * m.z();
      const double b1 = std::sqrt(hx * hx + hy * hy);
      const double b2 = r20 * m.x() + r21 * m.y() + r22 * m.z();
      const double e0 = r10 * b1 + r20 * b2 - m.x();
      const double e1 = r11 * b1 + r21 * b2 - m.y();
      const double e2 = r12 * b1 + r22 * b2 - m.z();
      const double inv_m2 = 1.0 / m.squaredNorm();
      const double k1 = inv_m2 * b1, k2 = inv_m2 * b2;
      c0 += k2 * e0;
      c1 += k2 * e1;
      c2 += k2 * e2;
      d0 = k1 * e0;
      d1 = k1 * e1;
      d2 = k1 * e2;
    }
    const double g0 = x * (c1 - d2) - y * c0 + z * d0;
    const double g1 = z * c0 + w * (c1 - d2) - 2 * x * (c2 + d1) + y * d0;
    const double g2 = z * (c1 + d2) - w * c0 - 2 * y * c2 + x * d0;
    const double g3 = x * c0 + y * (c1 + d2) + w * d0 - 2 * z * d1;
    const double grad_squared_norm = g0 * g0 + g1 * g1 + g2 * g2 + g3 * g3;
    if (grad_squared_norm > 0.25e-24) {  // |J^T f| > 1e-12 with the factor 2
      // Normalised gradient step of beta dt, and the norm of the result without a second square root:
      // |q + s g|^2 = |q|^2 + 2 s (q . g) + (beta dt)^2 for s = -beta dt / |g|. sqrt and 1/|g|^2 run in parallel.
      const double beta_dt = params_.beta * dt;
      const double step = -beta_dt * std::sqrt(grad_squared_norm) * (1.0 / grad_squared_norm);
      const double q_dot_g = w * g0 + x * g1 + y * g2 + z * g3;
      const double squared_norm = (w * w + x * x + y * y + z * z) + 2 * step * q_dot_g + beta_dt * beta_dt;
      q = Quat(w + step * g0, x + step * g1, y + step * g2, z + step * g3);
      // The formula is exact to rounding near 1 (the usual small step); far from it (beta dt ~ 1) it could cancel.
      q.coeffs() *=
          inverse_sqrt_near_one(std::abs(squared_norm - 1.0) < 1e-3 ? squared_norm : q.coeffs().squaredNorm());
    } else {
      q.coeffs() *= inverse_sqrt_near_one(q.coeffs().squaredNorm());
    }
  } else {
    q.coeffs() *= inverse_sqrt_near_one(q.coeffs().squaredNorm());
  }
  // Extreme finite input: keep the state. q is normalised, so its sum is finite exactly when every component is.
  if (!std::isfinite(q.w() + q.x() + q.y() + q.z())) return UpdateResult::kRejected;

  state_.q = q;
  if (use_magnetometer_) state_.held_mag = held_mag;  // (madgwick6 never holds one)
  if (with_mag) state_.held_mag_ns = s.timestamp_ns;
  if (use_magnetometer_ && s.has_mag && !with_mag) state_.held_mag_ns = 0;  // a bad reading ends the hold
  state_.flags.reinitialised = false;
  state_.flags.mag_rejected = use_magnetometer_ && s.has_mag && !with_mag;
  if (s.has_gyr && coeff_.bias_lowpass) state_.bias_lowpass.update(s.timestamp_ns, dt, s.gyr);
  return updated(s);
}

std::unique_ptr<OrientationFilter> make_madgwick_filter(const FilterSpec& spec) {
  return std::make_unique<MadgwickFilter>(bind_parameters("madgwick", spec, kParams), true);
}

std::unique_ptr<OrientationFilter> make_madgwick6_filter(const FilterSpec& spec) {
  return std::make_unique<MadgwickFilter>(bind_parameters("madgwick6", spec, kParams), false);
}

}  // namespace bsn::fusion
