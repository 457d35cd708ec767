// Small pieces the Kalman filters (MEKF, EKF, DLKF) share. Private to fusion_core.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>

#include "bsn/fusion/imu_sample.hpp"
#include "bsn/fusion/r_adaption.hpp"
#include "bsn/fusion/start_orientation.hpp"

namespace bsn::fusion::kalman_support {

using Mat3 = Eigen::Matrix3d;

/// The gap rule for a gyro-bias covariance block (the bias estimate is kept across a gap): the bias walked unobserved
/// over the gap, so each variance grows by walk_var_per_s * gap_s, but by no more than init_var, the spread of a
/// first start.
template <class Block>
void grow_over_gap(Block&& p_bias, double walk_var_per_s, double gap_s, double init_var) {
  p_bias.diagonal().array() += std::min(walk_var_per_s * gap_s, init_var);
}

/// Throws std::invalid_argument naming `filter` for a bad value of the parameter groups the Kalman filters share (the
/// R-adaption switch, the rest detector) or max_gap_s above 60 s, the longest gap their prediction bridges.
template <class P>
void check_shared_params(std::string_view filter, const P& params) {
  params.MagRejectionParams::check(filter);
  if (params.max_gap_s > 60.0) {
    throw std::invalid_argument(std::string(filter) + ": max_gap_s must be <= 60 s");
  }
  params.RestDetector::Params::check(filter);
}

/// The EKF's and the MEKF's earth field reference from a field in the earth frame: only its horizontal magnitude
/// (along magnetic north, earth y) and its vertical component matter. State has h_ref and h_ref_judged.
template <class State>
void set_magnetic_reference(State& state, const Vec3& mag_earth) {
  state.h_ref = Vec3(0.0, std::hypot(mag_earth.x(), mag_earth.y()), mag_earth.z());
  state.h_ref_judged = MagneticRAdaption::Reference::of(state.h_ref, Vec3::UnitZ());
}

/// The first usable magnetometer reading after a start without one: turns the heading so the field points north and
/// takes it as the reference.
template <class State>
void take_first_heading(State& state, const Vec3& mag) {
  const Vec3 m_earth = state.q * mag;
  state.q = (Quat(Eigen::AngleAxisd(std::atan2(m_earth.x(), m_earth.y()), Vec3::UnitZ())) * state.q).normalized();
  set_magnetic_reference(state, state.q * mag);
}

/// The start the EKF and the MEKF share, on a cleared `state` (q, bias, covariance p whose last three states are the
/// gyro bias, h_ref): the orientation and the field reference from `initial`, P zero but for the bias block. That is
/// init_var per axis on the first start; after a gap (`before` is then the state before the clear) the bias and its
/// covariance block are kept and grow by the walk over the gap (grow_over_gap). The caller sets the attitude block.
template <class State>
void start_with_bias(State& state, const State* before, const StartOrientation& initial, const ImuSample& s,
                     double walk_var_per_s, double gap_s, double init_var) {
  state.q = initial.q;
  if (initial.with_mag) set_magnetic_reference(state, state.q * s.mag);
  state.p.setZero();
  auto p_bias = state.p.template bottomRightCorner<3, 3>();
  if (before) {  // the gap rule: the bias and its covariance are kept
    state.bias = before->bias;
    p_bias = before->p.template bottomRightCorner<3, 3>();
    grow_over_gap(p_bias, walk_var_per_s, gap_s, init_var);
  } else {
    p_bias.diagonal().setConstant(init_var);
  }
}

/// v / |v| as one division and a multiplication per component (Eigen's normalized() divides each component);
/// the caller guarantees |v| > 0.
template <class V>
V unit(const V& v) {
  return v * (1.0 / v.norm());
}

/// q / |q| likewise, for a quaternion that is unit up to rounding after a product.
inline Quat unit(const Quat& q) {
  Quat n;
  n.coeffs() = q.coeffs() * (1.0 / q.coeffs().norm());
  return n;
}

/// Cross-product matrix: skew(a) * b = a x b.
inline Mat3 skew(const Vec3& a) {
  Mat3 m;
  m << 0.0, -a.z(), a.y(), a.z(), 0.0, -a.x(), -a.y(), a.x(), 0.0;
  return m;
}

/// True when acc and mag give a well-defined TRIAD orientation (neither zero nor parallel).
inline bool acc_mag_usable(const Vec3& acc, const Vec3& mag) {
  // |acc| > 1e-6, |mag| > 1e-9 and |acc x mag| > 1e-3 |acc| |mag|, compared squared (no square roots).
  const double na2 = acc.squaredNorm(), nm2 = mag.squaredNorm();
  return na2 > 1e-12 && nm2 > 1e-18 && acc.cross(mag).squaredNorm() > 1e-6 * na2 * nm2;
}

/// Makes a covariance symmetric and clamps its diagonal away from zero and from overflow, so that rounding never
/// lets it lose positive definiteness.
template <class Mat>
void condition_covariance(Mat& p, double min_variance, double max_variance) {
  // Unrolled (a fixed-size P): the triangular loop otherwise costs more in counting than in arithmetic.
  constexpr int n = Mat::ColsAtCompileTime;
#pragma GCC unroll 16
  for (int j = 0; j < n; ++j) {
#pragma GCC unroll 16
    for (int i = 0; i < j; ++i) p(i, j) = p(j, i) = 0.5 * (p(i, j) + p(j, i));
    p(j, j) = std::clamp(p(j, j), min_variance, max_variance);
  }
}

/// Clamps the variances (diagonal) of a covariance that is symmetric by construction, see condition_covariance.
template <class Mat>
void clamp_variances(Mat& p, double min_variance, double max_variance) {
  constexpr int n = Mat::RowsAtCompileTime;
#pragma GCC unroll 16
  for (int i = 0; i < n; ++i) p(i, i) = std::clamp(p(i, i), min_variance, max_variance);
}

/// Zero-rate update for a filter whose last three states are the gyro bias (sensor frame, rad/s): at rest the true
/// rate is zero, so the raw gyro reading measures the bias directly, on all three axes, including the one along the
/// vertical that neither the accelerometer nor (while it is rejected) the magnetometer can see. `residual` is the
/// raw reading minus the bias estimate, `variance` the reading's noise variance per axis. The three rows are processed
/// one at a time (R is diagonal): the batch Kalman update up to rounding. Returns the state correction; P is updated.
template <int N>
Eigen::Matrix<double, N, 1> zero_rate_update(Eigen::Matrix<double, N, N>& p, const Vec3& residual, double variance) {
  using VecN = Eigen::Matrix<double, N, 1>;
  VecN dx = VecN::Zero();
  for (int i = 0; i < 3; ++i) {
    const int b = N - 3 + i;
    const VecN ph = p.col(b);
    const VecN k = ph * (1.0 / (ph(b) + variance));
    dx += k * (residual(i) - dx(b));
    // Column by column (vectorised, the same products as k ph^T): Eigen's outer product here would be the same
    // instantiation as the per-sample updates' and change how the compiler inlines those (ekf: +3 % instructions
    // per update in motion, where this never runs).
    for (int c = 0; c < N; ++c) p.col(c) -= ph(c) * k;
  }
  return dx;
}

}  // namespace bsn::fusion::kalman_support
