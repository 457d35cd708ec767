#include "bsn/fusion/sensor_fixed_field.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "bsn/fusion/imu_sample.hpp"

namespace bsn::fusion {

SensorFixedField::SensorFixedField(const Params& params, const char* filter) {
  require_switch(filter, params.mag_offset_learning, "mag_offset_learning");
  require_positive(filter, params.mag_offset_block_s, "mag_offset_block_s");
  require_positive(filter, params.mag_offset_row_s, "mag_offset_row_s");
  require_positive(filter, params.mag_offset_min_spread, "mag_offset_min_spread");
  require_positive(filter, params.mag_offset_max_residual_ratio, "mag_offset_max_residual_ratio");
  require_non_negative(filter, params.mag_offset_min_gain_ut2, "mag_offset_min_gain_ut2");
  if (params.mag_offset_row_s >= params.mag_offset_block_s) {
    throw std::invalid_argument("filter '" + std::string(filter) +
                                "': mag_offset_row_s must be shorter than mag_offset_block_s");
  }
  enabled_ = params.mag_offset_learning != 0.0;
  block_ns_ = seconds_to_ns(params.mag_offset_block_s);
  row_ns_ = seconds_to_ns(params.mag_offset_row_s);
  min_spread_ = params.mag_offset_min_spread;
  max_ratio_ = params.mag_offset_max_residual_ratio;
  min_gain_ = params.mag_offset_min_gain_ut2;
}

void SensorFixedField::restart_block() {
  in_block_ = false;
  n_ = 0.0;
  sum_r_.setZero();
  sum_m_.setZero();
  sum_rtm_.setZero();
  sum_mm_ = 0.0;
}

bool SensorFixedField::add_row(std::uint64_t t_ns, const Quat& q_gyr, const Vec3& mag) {
  if (!in_block_ || t_ns < last_row_ns_) {
    restart_block();
    in_block_ = true;
    block_start_ns_ = t_ns;
  }
  last_row_ns_ = t_ns;
  const Eigen::Matrix3d r = q_gyr.toRotationMatrix();
  const Vec3 m_inertial = r * mag;
  n_ += 1.0;
  sum_r_ += r;
  sum_m_ += m_inertial;
  sum_rtm_ += r.transpose() * m_inertial;
  sum_mm_ += m_inertial.squaredNorm();
  if (t_ns - block_start_ns_ < block_ns_) return false;
  const Vec3 before = offset_;
  decide();
  restart_block();
  return offset_ != before;
}

void SensorFixedField::decide() {
  if (n_ < 10.0) return;
  // With h_I eliminated (its best value for a given b is (sum m_I - sum R b) / n), the normal equations in b are
  // M b = v with M = n I - (sum R)^T (sum R) / n, the scatter of the rotations, and v = sum R^T m_I - (sum R)^T sum
  // m_I / n.
  const Eigen::Matrix3d m = n_ * Eigen::Matrix3d::Identity() - sum_r_.transpose() * sum_r_ / n_;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen;
  eigen.computeDirect(m, Eigen::EigenvaluesOnly);
  if (!(eigen.eigenvalues()(0) >= min_spread_ * n_)) return;
  ++judged_;
  const Vec3 v = sum_rtm_ - sum_r_.transpose() * sum_m_ / n_;
  const Vec3 fitted = m.inverse() * v;
  // Residual per row with offset b and h_I at its best: (sum |m_I|^2 - |sum m_I|^2 / n - 2 b.v + b^T M b) / n.
  const double base = sum_mm_ - sum_m_.squaredNorm() / n_;
  const auto residual = [&](const Vec3& b) { return (base - 2.0 * b.dot(v) + b.dot(m * b)) / n_; };
  const double in_use = residual(offset_), with_fit = residual(fitted);
  if (fitted.allFinite() && with_fit <= max_ratio_ * in_use && in_use - with_fit >= min_gain_) {
    offset_ = fitted;
    field_inertial_ = (sum_m_ - sum_r_ * fitted) / n_;
    ++changes_;
  }
}

}  // namespace bsn::fusion
