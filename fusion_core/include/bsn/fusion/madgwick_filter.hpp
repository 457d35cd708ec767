// Madgwick's gradient descent algorithm (GDA; Madgwick et al. 2011, Fan et al. 2018 section 2.4.3), from the
// paper's equations: strapdown rate of change plus one normalised gradient-descent step of size beta on the
// objective f = [R(q)^T g_E - a ; R(q)^T b_E - m] (unit vectors), where the earth reference of the field b_E
// has the same norm and vertical component as the measured field rotated into the earth frame.
//
// Not ported from the widely copied C code: that code keeps |b_E| at half the measured norm (it stores b
// where its variable names and formulas expect 2b), so its objective never vanishes at the true orientation.
// Here f and its gradient are exactly zero at the truth (tested).
//
// ENU: gravity reference earth z (specific force, up), field reference in the y-z plane (y = magnetic north);
// the paper's x-north frame differs only in which horizontal axis carries the field.
//
// Two factory names: "madgwick" (9D: uses the magnetometer whenever a sample has one) and "madgwick6" (6D:
// never uses it). The gyro bias is removed by the low-pass estimate of Fan et al. (GyroBiasLowPass), as in
// Fan's comparison, instead of Madgwick's integral bias term.
#pragma once

#include <cstdint>
#include <string_view>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/gyro_bias_lowpass.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/rest_detector.hpp"

namespace bsn::fusion {

/// The GDA's parameters: own fields below; the shared groups come from the base structs (documented there). Between
/// readings of a magnetometer slower than the IMU, the 9D step uses the last reading turned by the gyro since then, for
/// at most max_gap_s, so the heading gain does not drop with the magnetometer rate.
struct MadgwickParams : GyroBiasRemovalParams, RestDetector::Params, FilterTimingParams {
  /// beta: magnitude of the gradient-descent step, rad/s (the quaternion rate of the correction; the orientation
  /// turns at up to 2 beta rad/s towards the measurements). Default 0.02, the optimum on the eight BROAD trials;
  /// Madgwick's and Fan et al.'s 0.1 suits their sensors.
  double beta = 0.02;
};

/// Everything the GDA keeps between samples.
struct MadgwickState {
  Quat q = Quat::Identity();      ///< sensor-to-earth
  Vec3 held_mag = Vec3::Zero();   ///< last usable magnetometer reading, uT; turned into the current sensor frame
                                  ///< while a sample without magnetometer uses it
  std::uint64_t held_mag_ns = 0;  ///< its timestamp; 0 = none
  RestDetector rest;              ///< still-sensor detection (flags().resting, the bias updates' gate)
  GyroBiasLowPass bias_lowpass;   ///< the gyro bias estimate at rest
  FilterFlags flags;
};

class MadgwickFilter final : public FilterBase<MadgwickParams, MadgwickState> {
 public:
  /// Quantities derived once from Params.
  struct Coefficients {
    bool bias_lowpass = true;  ///< gyro_bias_lowpass = 1
  };

  using Jacobian = Eigen::Matrix<double, 3, 4>;  ///< d f / d (w, x, y, z)

  /// Throws std::invalid_argument on an out-of-range parameter.
  MadgwickFilter(const Params& params, bool use_magnetometer);
  MadgwickFilter() : MadgwickFilter(Params{}, true) {}

  /// Objective of one reference: R(q)^T d - s, i.e. q* (x) d (x) q - s (d earth frame, s sensor frame).
  static Vec3 objective(const Quat& q, const Vec3& d, const Vec3& s);
  /// Jacobian of objective() with respect to (w, x, y, z), in the paper's unit-quaternion form.
  static Jacobian jacobian(const Quat& q, const Vec3& d);
  /// Earth-frame field reference for a unit measured field m: h = q (x) m (x) q*, b = (0, |h_xy|, h_z).
  static Vec3 magnetic_reference(const Quat& q, const Vec3& m_unit);
  /// Gradient J^T f of the (6D or 9D) objective, as (w, x, y, z); mag_unit ignored when use_mag is false.
  static Eigen::Vector4d gradient(const Quat& q, const Vec3& acc_unit, const Vec3& mag_unit, bool use_mag);

 private:
  UpdateResult start(const ImuSample& s) override;
  UpdateResult step(const ImuSample& s, double dt) override;

  bool use_magnetometer_;
  Coefficients coeff_;
};

/// Factory entries: "madgwick" (9D) and "madgwick6" (6D), with the Params fields as parameter names.
std::unique_ptr<OrientationFilter> make_madgwick_filter(const FilterSpec& spec);
std::unique_ptr<OrientationFilter> make_madgwick6_filter(const FilterSpec& spec);

}  // namespace bsn::fusion
