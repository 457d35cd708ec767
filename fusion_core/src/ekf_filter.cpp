#include "bsn/fusion/ekf_filter.hpp"

#include <array>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/start_orientation.hpp"
#include "kalman_support.hpp"

namespace bsn::fusion {
namespace {

constexpr const char* kName = "ekf";
using kalman_support::skew;
using Mat3 = Eigen::Matrix3d;
using Mat4 = Eigen::Matrix4d;
using Mat43 = Eigen::Matrix<double, 4, 3>;
using Mat34 = Eigen::Matrix<double, 3, 4>;
using Mat7 = EkfFilter::Mat7;

// Keeps the covariance positive definite along the (unobservable) norm direction of the quaternion.
constexpr double kNormDirectionVariance = 1e-12;

using P = EkfFilter::Params;
constexpr auto kParams = join_param_fields(std::to_array<ParamField<P>>({
                                               {"sigma_g", &P::sigma_g},
                                               {"sigma_bg", &P::sigma_bg},
                                               {"sigma_a", &P::sigma_a},
                                               {"sigma_m", &P::sigma_m},
                                               {"acc_variance_cap", &P::acc_variance_cap},
                                               {"rest_bias_update", &P::rest_bias_update},
                                           }),
                                           kalman_init_param_fields<P>(), mag_rejection_param_fields<P>(),
                                           timing_param_fields<P>(), rest_param_fields<P>());

// q (x) (0, v) = xi(q) v.
Mat43 xi(const Quat& q) {
  Mat43 m;
  m.row(0) = -q.vec().transpose();
  m.bottomRows<3>() = q.w() * Mat3::Identity() + skew(q.vec());
  return m;
}

// q (x) p = right(p) [w x y z]^T of q.
Mat4 right_multiplication(const Quat& p) {
  Mat4 m;
  m(0, 0) = p.w();
  m.block<1, 3>(0, 1) = -p.vec().transpose();
  m.block<3, 1>(1, 0) = p.vec();
  m.block<3, 3>(1, 1) = p.w() * Mat3::Identity() - skew(p.vec());
  return m;
}

Eigen::Vector4d as_vector(const Quat& q) { return {q.w(), q.x(), q.y(), q.z()}; }

// Jacobian of R(q)^T v = (w^2 - |u|^2) v + 2 (u.v) u - 2 w (u x v) with respect to (w, u).
Mat34 rotate_to_sensor_jacobian(const Quat& q, const Vec3& v) {
  const double w = q.w();
  const Vec3 u = q.vec();
  Mat34 j;
  j.col(0) = 2.0 * w * v - 2.0 * u.cross(v);
  j.rightCols<3>() =
      -2.0 * v * u.transpose() + 2.0 * u.dot(v) * Mat3::Identity() + 2.0 * u * v.transpose() + 2.0 * w * skew(v);
  return j;
}

}  // namespace

EkfFilter::EkfFilter(const Params& params) : FilterBase(kName, params) {
  state_.r_adaption = MagneticRAdaption(params.thresholds());
  require_positive(kName, params.sigma_g, "sigma_g");
  require_positive(kName, params.sigma_bg, "sigma_bg");
  require_positive(kName, params.sigma_a, "sigma_a");
  require_positive(kName, params.sigma_m, "sigma_m");
  if (!(params.acc_variance_cap >= 1.0) || !std::isfinite(params.acc_variance_cap)) {
    throw std::invalid_argument("ekf: parameter acc_variance_cap must be finite and >= 1");
  }
  require_switch(kName, params.rest_bias_update, "rest_bias_update");
  check_kalman_init(kName, params);
  kalman_support::check_shared_params(kName, params);
  coeff_.var_a = params.sigma_a * params.sigma_a;
  coeff_.var_m = params.sigma_m * params.sigma_m;
  coeff_.var_a_max = params.acc_variance_cap * coeff_.var_a;
  coeff_.var_g_per_s = params.sigma_g * params.sigma_g;
  state_.rest = RestDetector(params);  // after the checks above, so their errors name the filter
  keep_fresh_state();
}

EkfFilter::Mat6 EkfFilter::error_covariance() const {
  Eigen::Matrix<double, 6, 7> t = Eigen::Matrix<double, 6, 7>::Zero();
  t.topLeftCorner<3, 4>() = 2.0 * xi(state_.q).transpose();
  t.bottomRightCorner<3, 3>() = Mat3::Identity();
  return t * state_.p * t.transpose();
}

UpdateResult EkfFilter::start(const ImuSample& s) {
  const std::optional<StartOrientation> initial = start_orientation(s);
  if (!initial) return UpdateResult::kRejected;
  const State before = state_;
  clear();
  const double gap_s = static_cast<double>(s.timestamp_ns - clock().last_ns) * 1e-9;
  kalman_support::start_with_bias(state_, initialised() ? &before : nullptr, *initial, s,
                                  params_.sigma_bg * params_.sigma_bg, gap_s,
                                  params_.init_bias_sigma_rad_s * params_.init_bias_sigma_rad_s);
  const Mat43 x = xi(state_.q);
  const Eigen::Vector4d qv = as_vector(state_.q);
  const double var_att = params_.init_attitude_sigma_rad * params_.init_attitude_sigma_rad;
  state_.p.topLeftCorner<4, 4>() = 0.25 * var_att * x * x.transpose() + kNormDirectionVariance * qv * qv.transpose();
  state_.gyr_prev = s.gyr;
  state_.have_gyr_prev = s.has_gyr;
  state_.flags = start_flags(s.has_mag && !initial->with_mag);
  return UpdateResult::kInitialised;
}

// Flattened: Eigen's small products in it (P's quaternion columns times h) are otherwise calls of their own, which
// cost more than their 28 multiplications; inlining changes no arithmetic.
template <int M>
[[gnu::flatten]] void EkfFilter::correct(const Eigen::Matrix<double, M, 1>& residual,
                                         const Eigen::Matrix<double, M, 4>& h_q,
                                         const Eigen::Matrix<double, M, 1>& variances, bool hold_bias) {
  // R is diagonal, so the M rows are processed one at a time against the same linearisation: this is the batch
  // Kalman update exactly (up to rounding) without forming or inverting S. H = [h_q 0] touches only the
  // quaternion columns of P. Each row: P <- P - (P h^T)(P h^T)^T / s, symmetric by construction.
  using Vec7 = Eigen::Matrix<double, 7, 1>;
  Vec7 dx = Vec7::Zero();
  // The gain and the q rows of P never read the bias block, so holding the bias is the plain update with the bias
  // block of P put back and the bias step dropped: exactly the consider update with a zero bias gain.
  const Mat3 p_bias = state_.p.bottomRightCorner<3, 3>();
  for (int i = 0; i < M; ++i) {
    const Eigen::Vector4d h = h_q.row(i).transpose();
    const Vec7 ph = state_.p.template leftCols<4>() * h;
    const double s = h.dot(ph.template head<4>()) + variances(i);
    const Vec7 k = ph * (1.0 / s);
    dx += k * (residual(i) - h.dot(dx.template head<4>()));
    state_.p.noalias() -= k * ph.transpose();
  }
  const Eigen::Vector4d q = as_vector(state_.q) + dx.head<4>();
  if (hold_bias) {
    state_.p.bottomRightCorner<3, 3>() = p_bias;
  } else {
    state_.bias += dx.tail<3>();
  }
  const double n = q.norm();
  const double inv_n = 1.0 / n;
  state_.q = n > 1e-9 ? Quat(q(0) * inv_n, q(1) * inv_n, q(2) * inv_n, q(3) * inv_n) : state_.q;
}

void EkfFilter::learn_bias_at_rest(const Vec3& gyr, double dt) {
  // At rest the reading is the bias plus the gyro's white noise of this step (see rest_bias_update).
  const Eigen::Matrix<double, 7, 1> dx =
      kalman_support::zero_rate_update<7>(state_.p, gyr - state_.bias, coeff_.var_g_per_s / dt);
  state_.q.coeffs() += Eigen::Vector4d(dx(1), dx(2), dx(3), dx(0));  // Eigen stores (x, y, z, w)
  state_.q = kalman_support::unit(state_.q);
  state_.bias += dx.tail<3>();
}

UpdateResult EkfFilter::step(const ImuSample& s_in, double dt) {
  ImuSample s_fwd = s_in;
  s_fwd.mag = mag_at_gyro_time(s_in, state_.bias, params_.mag_latency_s);  // the magnetometer's own delay
  const ImuSample& s = s_fwd;
  state_.flags.reinitialised = false;

  predict(s, dt);
  state_.flags.resting = state_.rest.update(s);
  if (state_.flags.resting && params_.rest_bias_update != 0.0) learn_bias_at_rest(s.gyr, dt);
  const MagnetometerUse mag = judge_magnetometer(s, dt);
  update_accelerometer_and_magnetometer(s, mag);
  project_covariance_to_unit_norm();

  state_.flags.initialising = within_init_period(s.timestamp_ns);
  return UpdateResult::kUpdated;
}

// Flattened as correct(): its small fixed-size products and helpers (xi, right_multiplication) inlined.
[[gnu::flatten]] void EkfFilter::predict(const ImuSample& s, double dt) {
  // Prediction: q <- q (x) exp(w dt), b random walk; F and Q linearised at the new estimate. w is the mean of the
  // previous and the current bias-corrected rate: second-order accurate, where the current rate alone leaves an
  // apparent bias of half the angular acceleration times dt.
  const Vec3 w_now = s.has_gyr ? Vec3(s.gyr - state_.bias) : Vec3::Zero();
  const Vec3 w = state_.have_gyr_prev ? Vec3(0.5 * (w_now + state_.gyr_prev - state_.bias)) : w_now;
  state_.gyr_prev = s.gyr;
  state_.have_gyr_prev = s.has_gyr;
  const Quat dq = exp_rotation_vector(w * dt);
  state_.q = state_.q * dq;  // unit up to rounding; the correction (or the end of update) normalises it
  const Mat43 x = xi(state_.q);
  {
    // P <- F P F^T + Q_d on blocks: F = [R Y; 0 I] with R = right(dq), Y = -dt/2 Xi(q); P = [A B; B^T C].
    const Mat4 rot = right_multiplication(dq);
    const Mat43 y = -0.5 * dt * x;
    const Mat4 a = state_.p.topLeftCorner<4, 4>();
    const Mat43 b = state_.p.topRightCorner<4, 3>();
    const Mat3 c = state_.p.bottomRightCorner<3, 3>();
    const Mat43 top_right = rot * b + y * c;
    const Mat4 n_top = rot * a + y * b.transpose();
    // A' = n_top R^T + top_right Y^T + (sigma_g^2 dt / 4) Xi Xi^T, and Y = -dt/2 Xi folds the noise term into the
    // second product: A' = n_top R^T + (top_right - sigma_g^2 / 2 Xi) Y^T. It is symmetric: the lower triangle is
    // computed and mirrored.
    const Mat43 g = top_right - (0.5 * params_.sigma_g * params_.sigma_g) * x;
    for (int j = 0; j < 4; ++j) {
      for (int i = j; i < 4; ++i) {
        const double a_ij = n_top.row(i).dot(rot.row(j)) + g.row(i).dot(y.row(j));
        state_.p(i, j) = a_ij;
        state_.p(j, i) = a_ij;
      }
    }
    state_.p.topRightCorner<4, 3>() = top_right;
    state_.p.bottomLeftCorner<3, 4>() = top_right.transpose();
    state_.p.bottomRightCorner<3, 3>().diagonal().array() += params_.sigma_bg * params_.sigma_bg * dt;
  }
}

EkfFilter::MagnetometerUse EkfFilter::judge_magnetometer(const ImuSample& s, double dt) {
  // Magnetometer: usable unless the R-adaption sets its variance to infinity.
  MagnetometerUse m;
  state_.flags.mag_rejected = false;
  // One rotation matrix for every earth-to-sensor rotation below: its transpose maps earth to sensor.
  m.to_sensor = state_.q.toRotationMatrix().transpose();
  Vec3 up = m.to_sensor.col(2);
  if (s.has_mag) {
    if (state_.h_ref.isZero()) {
      // Initialised without a magnetometer: the first usable one sets the heading and the reference.
      if (kalman_support::acc_mag_usable(up, s.mag)) {
        kalman_support::take_first_heading(state_, s.mag);
        m.to_sensor = state_.q.toRotationMatrix().transpose();
        up = m.to_sensor.col(2);
      } else {
        state_.flags.mag_rejected = true;
      }
    } else {
      m.use = true;
      if (params_.mag_rejection != 0.0) {
        const double rate = s.has_gyr ? (s.gyr - state_.bias).cross(up).norm() : 0.0;  // horizontal rate
        const double scale = state_.r_adaption.update(s.timestamp_ns, s.mag, up, state_.h_ref_judged, rate, dt);
        m.use = std::isfinite(scale);
        if (m.use) m.variance_factor = scale;
        state_.flags.mag_rejected = !m.use;
      }
    }
  }
  return m;
}

void EkfFilter::update_accelerometer_and_magnetometer(const ImuSample& s, const MagnetometerUse& mag) {
  const bool use_mag = mag.use;
  const double mag_variance_factor = mag.variance_factor;
  const Mat3& to_sensor = mag.to_sensor;
  const Vec3 up = to_sensor.col(2);
  const bool use_acc = s.has_acc && s.acc.squaredNorm() > 1e-12;
  const Vec3 g_earth(0.0, 0.0, kGravity);
  // The accelerometer's variance counts the external acceleration its residual shows, up to the cap.
  const Vec3 acc_residual = s.acc - kGravity * up;
  const double var_a = use_acc ? std::min(coeff_.var_a + acc_residual.squaredNorm(), coeff_.var_a_max) : coeff_.var_a;
  if (use_acc && use_mag) {
    // One joint update: this is what couples the magnetometer into roll and pitch.
    Eigen::Matrix<double, 6, 1> r, var;
    Eigen::Matrix<double, 6, 4> h;
    r.head<3>() = acc_residual;
    r.tail<3>() = s.mag - to_sensor * state_.h_ref;
    h.topRows<3>() = rotate_to_sensor_jacobian(state_.q, g_earth);
    h.bottomRows<3>() = rotate_to_sensor_jacobian(state_.q, state_.h_ref);
    const double var_m = coeff_.var_m * mag_variance_factor;
    var << var_a, var_a, var_a, var_m, var_m, var_m;
    correct<6>(r, h, var);
  } else if (use_acc || use_mag) {
    const Vec3 ref = use_acc ? g_earth : state_.h_ref;
    const Vec3 meas = use_acc ? s.acc : s.mag;
    const Mat34 h = rotate_to_sensor_jacobian(state_.q, ref);
    const Vec3 r = meas - to_sensor * ref;
    const Quat q_before = state_.q;
    // The accelerometer cannot see a rotation about the vertical; what it turns there comes from correlations in
    // P, and with the magnetometer out nothing turns it back: under external accelerations the heading then drifts
    // far faster than the gyro would (simulated translation at 1 g: 26 deg against 10 deg of gyro-only drift). So
    // while the magnetometer is rejected the correction keeps the tilt part only: the rotation about the vertical is
    // removed. And it leaves the bias alone: the accelerometer alone under external acceleration teaches it wrong
    // (started after 1 s of rest, at 1 g: up to 0.6 deg/s off, turned into the vertical as the body turns, 34 deg of
    // heading against 13 deg of gyro-only drift), while a bias walks slowly (sigma_bg: 0.05 deg/s in a minute) and is
    // learned again at rest (rest_bias_update) and once the magnetometer is back.
    const bool accelerometer_alone = use_acc && s.has_mag && state_.flags.mag_rejected;
    correct<3>(r, h, Vec3::Constant(use_acc ? var_a : coeff_.var_m * mag_variance_factor), accelerometer_alone);
    if (accelerometer_alone) {
      const Quat d = q_before.conjugate() * state_.q;
      Vec3 turn = (d.w() >= 0.0 ? 2.0 : -2.0) * d.vec();  // the (small) correction as a rotation vector
      const Vec3 up_s = to_sensor.col(2);
      turn -= turn.dot(up_s) * up_s;
      state_.q = (q_before * exp_rotation_vector(turn)).normalized();
    }
  } else {
    state_.q = kalman_support::unit(state_.q);
  }
}

// Flattened as correct(): the 4x4 products and condition_covariance inlined.
[[gnu::flatten]] void EkfFilter::project_covariance_to_unit_norm() {
  // The norm is not a degree of freedom: project the covariance onto the tangent space of the unit sphere,
  // J = diag(I - q q^T, I). With a = A q: J A J = A - q a^T - a q^T + (q^T a) q q^T, and J B = B - q (q^T B).
  const Eigen::Vector4d qv = as_vector(state_.q);
  const Eigen::Vector4d aq = state_.p.topLeftCorner<4, 4>() * qv;
  const double qaq = qv.dot(aq);
  state_.p.topLeftCorner<4, 4>() +=
      (qaq + kNormDirectionVariance) * qv * qv.transpose() - qv * aq.transpose() - aq * qv.transpose();
  const Eigen::RowVector3d qb = qv.transpose() * state_.p.topRightCorner<4, 3>();
  state_.p.topRightCorner<4, 3>() -= qv * qb;
  state_.p.bottomLeftCorner<3, 4>() = state_.p.topRightCorner<4, 3>().transpose();
  kalman_support::condition_covariance(state_.p, 1e-18, 1e6);
}

std::unique_ptr<OrientationFilter> make_ekf_filter(const FilterSpec& spec) {
  return std::make_unique<EkfFilter>(bind_parameters(kName, spec, kParams));
}

}  // namespace bsn::fusion
