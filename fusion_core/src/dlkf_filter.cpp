#include "bsn/fusion/dlkf_filter.hpp"

#include <algorithm>
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

constexpr const char* kName = "dlkf";
using kalman_support::skew;
using Mat3 = Eigen::Matrix3d;
using dlkf::Mat6;
using dlkf::Vec6;

// Keeps Q positive definite along v, where a rotation does not move the vector.
constexpr double kMinProcessVariance = 1e-14;

using P = DlkfFilter::Params;
constexpr auto kParams =
    join_param_fields(std::to_array<ParamField<P>>({
                          {"sigma_g", &P::sigma_g},
                          {"sigma_a", &P::sigma_a},
                          {"sigma_ext_acc", &P::sigma_ext_acc},
                          {"tau_ext_acc_s", &P::tau_ext_acc_s},
                          {"acc_rejection_m_s2", &P::acc_rejection_m_s2},
                          {"acc_rejection_lowpass_s", &P::acc_rejection_lowpass_s},
                          {"sustained_acc_tau_s", &P::sustained_acc_tau_s},
                          {"sustained_acc_sigma", &P::sustained_acc_sigma},
                          {"sigma_m", &P::sigma_m},
                          {"sigma_mag_disturbance", &P::sigma_mag_disturbance},
                          {"tau_mag_disturbance_s", &P::tau_mag_disturbance_s},
                          {"gyro_bias_lowpass", &P::gyro_bias_lowpass},
                          {"bias_corner_frequency_hz", &P::bias_corner_frequency_hz},
                          {"bias_omega_min_rad_s", &P::bias_omega_min_rad_s},
                          {"bias_min_static_s", &P::bias_min_static_s},
                      }),
                      mag_rejection_param_fields<P>(), timing_param_fields<P>(), rest_param_fields<P>());

// Rotation matrix exp(-[w x] dt): an earth-fixed vector seen from a sensor turning at w.
// Rodrigues: exp(-[v x]) = I - (sin a / a) [v x] + ((1 - cos a) / a^2) [v x]^2 with v = w dt, a = |v|.
Mat3 sensor_frame_turn(const Vec3& w, double dt) {
  const Vec3 v = w * dt;
  const double a2 = v.squaredNorm();
  double s1, c1;
  if (a2 < 0.05 * 0.05) {
    // Taylor series, truncation error below 1e-16 at a = 0.05 rad per step.
    // Products with constant reciprocals: a division by a constant is not folded.
    s1 = 1.0 - a2 * (1.0 / 6.0) * (1.0 - a2 * (1.0 / 20.0) * (1.0 - a2 * (1.0 / 42.0) * (1.0 - a2 * (1.0 / 72.0))));
    c1 = 0.5 *
         (1.0 - a2 * (1.0 / 12.0) * (1.0 - a2 * (1.0 / 30.0) * (1.0 - a2 * (1.0 / 56.0) * (1.0 - a2 * (1.0 / 90.0)))));
  } else {
    const double a = std::sqrt(a2);
    s1 = std::sin(a) / a;
    c1 = (1.0 - std::cos(a)) / a2;
  }
  // [v x]^2 = v v^T - a^2 I.
  Mat3 turn = c1 * v * v.transpose() - s1 * skew(v);
  turn.diagonal().array() += 1.0 - c1 * a2;
  return turn;
}

// TRIAD for a unit up vector t1 (DlkfFilter::triad). Measured triad (eq. 2) in the sensor frame: t1 = up,
// t2 = up x field, t3 = t1 x t2.
Quat triad_from_unit_up(const Vec3& t1, const Vec3& field) {
  const Vec3 t2 = kalman_support::unit(Vec3(t1.cross(field)));
  const Vec3 t3 = t1.cross(t2);
  // The reference triad (eq. 1) in the earth frame is constant: [z, z x y, z x (z x y)] = [z, -x, -y]. So
  // A^T = M_ref M_meas^T (eq. 3, sensor-to-earth) has the rows -t2^T, -t3^T, t1^T.
  Mat3 m;
  m.row(0) = -t2.transpose();
  m.row(1) = -t3.transpose();
  m.row(2) = t1.transpose();
  // m is orthonormal, so the quaternion is unit up to rounding: only the sign is made canonical (w >= 0).
  Quat q(m);
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();
  return q;
}

}  // namespace

namespace dlkf {

void SplitKalman::initialise(const Vec3& y, double var_noise, double var_disturbance) {
  x.head<3>() = y;
  x.tail<3>().setZero();
  p.setZero();
  p.topLeftCorner<3, 3>().diagonal().setConstant(var_disturbance + var_noise);
  p.topRightCorner<3, 3>().diagonal().setConstant(-var_disturbance);
  p.bottomLeftCorner<3, 3>().diagonal().setConstant(-var_disturbance);
  p.bottomRightCorner<3, 3>().diagonal().setConstant(var_disturbance);
}

void SplitKalman::predict(const Mat3& turn, double gyro_var_dt, double c, double var_disturbance) {
  x.head<3>() = turn * x.head<3>();
  x.tail<3>() *= c;
  // P <- F P F^T + Q with F = diag(turn, c I), block by block on P = [A B; B^T C]. The gyro term of Q is
  // gyro_var_dt [v x][v x]^T = gyro_var_dt (|v|^2 I - v v^T). A is computed on its lower triangle and mirrored,
  // so P stays exactly symmetric (correct() keeps it so too) and needs no symmetrisation.
  const Vec3 v = x.head<3>();
  const Mat3 ta = turn * p.topLeftCorner<3, 3>();
  const double diagonal_noise = gyro_var_dt * v.squaredNorm() + kMinProcessVariance;
#pragma GCC unroll 3
  for (int j = 0; j < 3; ++j) {
#pragma GCC unroll 3
    for (int i = j; i < 3; ++i) {
      const double a_ij = ta.row(i).dot(turn.row(j)) - gyro_var_dt * v(i) * v(j) + (i == j ? diagonal_noise : 0.0);
      p(i, j) = a_ij;
      p(j, i) = a_ij;
    }
  }
  const Mat3 b_next = c * (turn * p.topRightCorner<3, 3>());
  p.topRightCorner<3, 3>() = b_next;
  p.bottomLeftCorner<3, 3>() = b_next.transpose();
  p.bottomRightCorner<3, 3>() *= c * c;
  p.bottomRightCorner<3, 3>().diagonal().array() += var_disturbance * (1.0 - c * c) + kMinProcessVariance;
}

void SplitKalman::correct(const Vec3& y, double var_noise) {
  // H = [I I] and R = var_noise I (diagonal): the three axes are processed one at a time, each a scalar
  // measurement with h = e_i + e_(i+3). This is the batch update up to rounding, without inverting S. Each axis:
  // P <- P - u u^T with u = P h^T / sqrt(s), exactly symmetric.
  for (int i = 0; i < 3; ++i) {
    const Vec6 ph = p.col(i) + p.col(i + 3);
    const double s = ph(i) + ph(i + 3) + var_noise;
    const double inv_sqrt_s = 1.0 / std::sqrt(s);
    const Vec6 u = inv_sqrt_s * ph;
    x += (inv_sqrt_s * (y(i) - x(i) - x(i + 3))) * u;
    p.noalias() -= u * u.transpose();
  }
}

}  // namespace dlkf

Quat DlkfFilter::triad(const Vec3& up, const Vec3& field) {
  return triad_from_unit_up(kalman_support::unit(up), field);
}

DlkfFilter::DlkfFilter(const Params& params) : FilterBase(kName, params) {
  state_.bias_lowpass =
      GyroBiasLowPass({params.bias_corner_frequency_hz, params.bias_omega_min_rad_s, params.bias_min_static_s});
  state_.r_adaption = MagneticRAdaption(params.thresholds());
  require_positive(kName, params.sigma_g, "sigma_g");
  require_positive(kName, params.sigma_a, "sigma_a");
  require_positive(kName, params.sigma_ext_acc, "sigma_ext_acc");
  require_positive(kName, params.tau_ext_acc_s, "tau_ext_acc_s");
  require_non_negative(kName, params.acc_rejection_m_s2, "acc_rejection_m_s2");
  require_non_negative(kName, params.acc_rejection_lowpass_s, "acc_rejection_lowpass_s");
  require_non_negative(kName, params.sustained_acc_tau_s, "sustained_acc_tau_s");
  require_positive(kName, params.sustained_acc_sigma, "sustained_acc_sigma");
  require_positive(kName, params.sigma_m, "sigma_m");
  require_positive(kName, params.sigma_mag_disturbance, "sigma_mag_disturbance");
  require_positive(kName, params.tau_mag_disturbance_s, "tau_mag_disturbance_s");
  require_switch(kName, params.gyro_bias_lowpass, "gyro_bias_lowpass");
  kalman_support::check_shared_params(kName, params);
  coeff_.var_g = params.sigma_g * params.sigma_g;
  coeff_.var_a = params.sigma_a * params.sigma_a;
  coeff_.var_ext = params.sigma_ext_acc * params.sigma_ext_acc;
  coeff_.var_sustained = params.sustained_acc_sigma * params.sustained_acc_sigma;
  coeff_.var_m = params.sigma_m * params.sigma_m;
  coeff_.var_dist = params.sigma_mag_disturbance * params.sigma_mag_disturbance;
  coeff_.inv_tau_ext = 1.0 / params.tau_ext_acc_s;
  coeff_.inv_tau_dist = 1.0 / params.tau_mag_disturbance_s;
  const double acc_low = std::max(kGravity - params.acc_rejection_m_s2, 0.0);
  coeff_.acc_accept_min2 = acc_low * acc_low;
  coeff_.acc_accept_max2 = (kGravity + params.acc_rejection_m_s2) * (kGravity + params.acc_rejection_m_s2);
  state_.rest = RestDetector(params);  // after the checks above, so their errors name the filter
  keep_fresh_state();
}

void DlkfFilter::restart_keeping_bias() {
  const GyroBiasLowPass bias_lowpass = state_.bias_lowpass;
  state_ = fresh_state();
  state_.bias_lowpass = bias_lowpass;
}

void DlkfFilter::initialise_magnetic(const Vec3& mag) {
  state_.magnetic.initialise(mag, coeff_.var_m, coeff_.var_dist);
  state_.have_mag = true;
  state_.mag_ref = MagneticRAdaption::Reference::of(mag, state_.gravity.vector().normalized());
}

UpdateResult DlkfFilter::start(const ImuSample& s) {
  const std::optional<StartOrientation> initial = start_orientation(s);
  if (!initial) return UpdateResult::kRejected;
  const bool mag_usable = initial->with_mag;
  restart_keeping_bias();  // the gap rule
  state_.gravity.initialise(s.acc, coeff_.var_a, coeff_.var_ext);
  if (mag_usable) {
    initialise_magnetic(s.mag);
  } else {
    // No heading reference yet: carry earth north (zero yaw) with the gyro until a magnetometer sample arrives.
    state_.magnetic.initialise(initial->q.conjugate() * Vec3::UnitY(), coeff_.var_m, coeff_.var_dist);
  }
  state_.q = triad(state_.gravity.vector(), state_.magnetic.vector());
  state_.gyr_prev = s.gyr;
  state_.have_gyr_prev = s.has_gyr;
  state_.flags = start_flags(s.has_mag && !mag_usable);
  return UpdateResult::kInitialised;
}

// Flattened: the steps it calls and their small fixed-size Eigen products are inlined into one function (Eigen's
// products are otherwise calls of their own, which cost more than their arithmetic); inlining changes no arithmetic.
[[gnu::flatten]] UpdateResult DlkfFilter::step(const ImuSample& s, double dt) {
  state_.flags.reinitialised = false;
  const Mat3 turn = predict(s, dt);
  update_gravity(s, turn);
  update_magnetic(s, dt, turn);

  // TRIAD, gravity dominant. A degenerate pair (field along gravity, or a vanished vector) keeps the last q.
  const Vec3 g = state_.gravity.vector();
  const double g_norm = g.norm();
  const Vec3 up = g_norm > 0.0 ? Vec3(g * (1.0 / g_norm)) : g;
  const Vec3 h = state_.magnetic.vector();
  if (up.allFinite() && h.allFinite() && kalman_support::acc_mag_usable(g, h)) state_.q = triad_from_unit_up(up, h);
  return updated(s);
}

Mat3 DlkfFilter::predict(const ImuSample& s, double dt) {
  if (s.has_gyr && params_.gyro_bias_lowpass != 0.0) state_.bias_lowpass.update(s.timestamp_ns, dt, s.gyr);
  // Mean of the previous and the current rate: second-order accurate over the step.
  const Vec3 w_now = s.has_gyr ? Vec3(s.gyr - state_.bias_lowpass.bias()) : Vec3::Zero();
  const Vec3 w = state_.have_gyr_prev ? Vec3(0.5 * (w_now + state_.gyr_prev - state_.bias_lowpass.bias())) : w_now;
  state_.gyr_prev = s.gyr;
  state_.have_gyr_prev = s.has_gyr;
  const Mat3 turn = sensor_frame_turn(w, dt);
  const double gyro_var_dt = coeff_.var_g * dt;
  if (dt != state_.decay_dt) {  // the step is nearly always the same: the exponentials are computed once
    state_.decay_dt = dt;
    state_.decay_ext = std::exp(-dt * coeff_.inv_tau_ext);
    state_.decay_dist = std::exp(-dt * coeff_.inv_tau_dist);
    state_.acc_lowpass_k = dt / (params_.acc_rejection_lowpass_s + dt);
    state_.acc_earth_k = dt / (params_.sustained_acc_tau_s + dt);
  }

  // Filter 1: gravity and external acceleration.
  state_.gravity.predict(turn, gyro_var_dt, state_.decay_ext, coeff_.var_ext);
  return turn;
}

void DlkfFilter::update_gravity(const ImuSample& s, const Mat3& turn) {
  // | |acc| - g | <= acc_rejection_m_s2, compared squared (no square root).
  const double acc2 = s.acc.squaredNorm();
  bool sustained = false;  // the low-passed deviation beyond the threshold: strong motion going on
  if (s.has_acc && params_.acc_rejection_m_s2 != 0.0 && params_.acc_rejection_lowpass_s > 0.0) {
    state_.acc_deviation_lp += state_.acc_lowpass_k * (std::abs(std::sqrt(acc2) - kGravity) - state_.acc_deviation_lp);
    sustained = state_.acc_deviation_lp > params_.acc_rejection_m_s2;
  }
  // A correction turns the estimated gravity, i.e. the estimated orientation, so the field vector turns with it while
  // no magnetometer steers it. Left alone it would keep the gyro's tilt error that the accelerometer just removed from
  // gravity, and TRIAD would read that tilt error through the field's dip as heading: started after 1 s of rest with
  // the magnetometer rejected, under 1 g translations, 26-35 deg of heading error against 10-13 deg of the gyro's own
  // integral (test_clean_field_motion); with the turn, within it.
  const auto correct_gravity = [&](const Vec3& measured, double variance) {
    const Vec3 g_before = state_.gravity.vector();
    state_.gravity.correct(measured, variance);
    if (!state_.have_mag || state_.r_adaption.disturbed()) {  // (never disturbed with mag_rejection 0: never judged)
      state_.magnetic.x.head<3>() =
          Quat::FromTwoVectors(g_before, state_.gravity.vector()) * state_.magnetic.x.head<3>();
    }
  };
  if (s.has_acc && params_.sustained_acc_tau_s > 0.0) {
    // The specific force averaged in the earth frame of the estimate: gravity plus the mean external acceleration of
    // a body whose velocity stays bounded (zero), seen through the estimate's tilt error. q is the last step's
    // estimate; `turn` brings a vector from that step's sensor frame to this one's.
    const Vec3 f_earth = state_.q._transformVector(turn.transpose() * s.acc);
    state_.acc_earth_lp = state_.acc_earth_started
                              ? Vec3(state_.acc_earth_lp + state_.acc_earth_k * (f_earth - state_.acc_earth_lp))
                              : f_earth;
    state_.acc_earth_started = true;
    if (sustained)
      correct_gravity(turn * state_.q.conjugate()._transformVector(state_.acc_earth_lp), coeff_.var_sustained);
  }
  if (s.has_acc && !sustained &&
      (params_.acc_rejection_m_s2 == 0.0 || (acc2 >= coeff_.acc_accept_min2 && acc2 <= coeff_.acc_accept_max2))) {
    correct_gravity(s.acc, coeff_.var_a);
  }
}

void DlkfFilter::update_magnetic(const ImuSample& s, double dt, const Mat3& turn) {
  // Filter 2: geomagnetic field and magnetic disturbance, predicted after the gravity correction has turned it (see
  // update_gravity). Before the first magnetometer sample it only carries earth north with the gyro: its covariance
  // is restarted by initialise_magnetic() anyway, so a 6D stream pays for one rotation, not the 6x6 covariance
  // prediction.
  if (state_.have_mag) {
    state_.magnetic.predict(turn, coeff_.var_g * dt, state_.decay_dist, coeff_.var_dist);
  } else {
    state_.magnetic.x.head<3>() = turn * state_.magnetic.x.head<3>();
  }
  state_.flags.mag_rejected = false;
  const Vec3 g = state_.gravity.vector();
  const double g_norm = g.norm();
  const Vec3 up = g_norm > 0.0 ? Vec3(g * (1.0 / g_norm)) : g;
  if (s.has_mag) {
    if (!state_.have_mag) {
      if (kalman_support::acc_mag_usable(up, s.mag)) {
        initialise_magnetic(s.mag);
      } else {
        state_.flags.mag_rejected = true;
      }
    } else {
      bool use = true;
      double scale = 1.0;  // > 1 for a field used after a long rejection (RejectionBudget)
      if (params_.mag_rejection != 0.0) {
        scale = state_.r_adaption.update(s.timestamp_ns, s.mag, up, state_.mag_ref,
                                         s.has_gyr ? s.gyr.cross(up).norm() : 0.0, dt);
        use = std::isfinite(scale);
      }
      if (use) {
        state_.magnetic.correct(s.mag, coeff_.var_m * scale);
      } else {
        state_.flags.mag_rejected = true;
      }
    }
  }
  // Both covariances are exactly symmetric by construction: only their variances need clamping.
  kalman_support::clamp_variances(state_.gravity.p, 1e-18, 1e8);
  kalman_support::clamp_variances(state_.magnetic.p, 1e-18, 1e8);
}

std::unique_ptr<OrientationFilter> make_dlkf_filter(const FilterSpec& spec) {
  return std::make_unique<DlkfFilter>(bind_parameters(kName, spec, kParams));
}

}  // namespace bsn::fusion
