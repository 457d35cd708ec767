// A magnetic field that moves with the sensor (a magnet or a phone fixed near it): an offset b in the sensor frame
// that the magnetometer's calibration does not know, m = R^T h + b. Learned only when the gyro confirms it.
//
// In the almost inertial frame of the gyro's own strapdown integral (q_gyr, sensor-to-inertial), a reading is
//   q_gyr m = h_I + R_gyr b,
// with h_I the earth field there (constant while the integral does not drift, seconds) and R_gyr the rotation of
// q_gyr. Over a block of mag_offset_block_s, every mag_offset_row_s one reading gives three rows of a linear
// least-squares problem in (h_I, b). A field fixed to the earth, however inhomogeneous, is constant in that frame only
// where the sensor stays; a field fixed to the sensor turns with R_gyr; the fit tells them apart through the rotations
// alone. The block's estimate replaces the offset in use only when the gyro confirms it beyond doubt:
//   - the rotations of the block are large about every axis: the smallest eigenvalue of sum (R - mean R)^T (R - mean
//     R), per row, is at least mag_offset_min_spread (0 at rest; turns of +-30 deg about each axis give about 0.1);
//   - the fitted offset explains the block: its residual per row is at most mag_offset_max_residual_ratio of the
//     residual with the offset in use, and lower by at least mag_offset_min_gain_ut2.
// On the eight BROAD trials the ratio is 0.75-1.0 in every block of the undisturbed and room-magnet trials (gyro
// scale errors, the field's gradient along the path, noise) and below 0.01 when a magnet is attached to the sensor or
// taken off it. A small offset the rotations do not reveal (a phone whose 2 uT change the reading's heading by +-1 deg
// over +-20 deg of turning, in 1.2 uT of noise) is left alone: the rule cannot tell it from the room.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion {

class SensorFixedField {
 public:
  /// Parameters; a filter's Params derive from this struct, so the field names are its parameter names
  /// (sensor_fixed_field_param_fields() lists them).
  struct Params {
    /// 1 = learn a field fixed to the sensor and subtract it from each reading; 0 = off. Default 1.
    double mag_offset_learning = 1.0;
    /// Length of one block of the fit, s. Long enough for several turns of human motion, short enough that the gyro
    /// integral does not drift (a bias error of 0.1 deg/s turns h_I by 1 deg). Default 10 s.
    double mag_offset_block_s = 10.0;
    /// Time between the readings that enter the fit, s. Default 0.05 s (200 rows per block).
    double mag_offset_row_s = 0.05;
    /// Least rotational spread of a block that may decide (the smallest eigenvalue of the rotation's scatter, per
    /// row, 0..2). Default 0.02: turns of about +-13 deg about each axis, which a hand's slow motion gives (Nez et
    /// al.'s slow intensity); the residual and gain tests still keep a carried sensor's changing field out.
    double mag_offset_min_spread = 0.02;
    /// The fitted offset is taken when the block's residual with it is at most this fraction of the residual with
    /// the offset in use. Default 0.25.
    double mag_offset_max_residual_ratio = 0.25;
    /// ... and lower than that by at least this, uT^2 per row (a tiny offset in a noise-free field is no reason to
    /// change). Default 4 uT^2.
    double mag_offset_min_gain_ut2 = 4.0;
  };

  SensorFixedField() = default;
  /// Throws std::invalid_argument (naming `filter`) on an out-of-range parameter.
  SensorFixedField(const Params& params, const char* filter);

  bool enabled() const { return enabled_; }
  /// One magnetometer reading `mag` (uT, sensor frame, as read: the offset not yet removed) at t_ns, with the gyro's
  /// strapdown integral q_gyr at the same time. Returns true when the offset in use changed with this reading.
  bool update(std::uint64_t t_ns, const Quat& q_gyr, const Vec3& mag) {
    // Most readings fall between two rows: decided here, without a call.
    if (!enabled_ || (in_block_ && t_ns >= last_row_ns_ && t_ns - last_row_ns_ < row_ns_)) return false;
    return add_row(t_ns, q_gyr, mag);
  }
  /// The field fixed to the sensor in use, uT, sensor frame: subtract it from a reading.
  const Vec3& offset() const { return offset_; }
  /// The earth field in q_gyr's frame that the fit which set the offset found, uT (zero before the first change).
  const Vec3& field_inertial() const { return field_inertial_; }
  /// Times the offset in use changed.
  std::uint32_t changes() const { return changes_; }
  /// Blocks whose rotations were large enough to decide (whether or not the offset changed).
  std::uint32_t blocks_judged() const { return judged_; }
  /// Starts a new block (the gyro integral restarts, e.g. after a gap); keeps the offset in use, which belongs to the
  /// sensor.
  void restart_block();

 private:
  bool add_row(std::uint64_t t_ns, const Quat& q_gyr, const Vec3& mag);
  void decide();

  bool enabled_ = false;
  std::uint64_t block_ns_ = 0;
  std::uint64_t row_ns_ = 0;
  double min_spread_ = 0.0;
  double max_ratio_ = 0.0;
  double min_gain_ = 0.0;

  // The block's sums: n rows, sum R, sum m_I, sum R^T m_I, sum |m_I|^2.
  bool in_block_ = false;
  std::uint64_t block_start_ns_ = 0;
  std::uint64_t last_row_ns_ = 0;
  double n_ = 0.0;
  Eigen::Matrix3d sum_r_ = Eigen::Matrix3d::Zero();
  Vec3 sum_m_ = Vec3::Zero();
  Vec3 sum_rtm_ = Vec3::Zero();
  double sum_mm_ = 0.0;

  Vec3 offset_ = Vec3::Zero();
  Vec3 field_inertial_ = Vec3::Zero();
  std::uint32_t changes_ = 0;
  std::uint32_t judged_ = 0;
};

/// The learning's entries of a filter's parameter table (P derives from SensorFixedField::Params).
template <class P>
constexpr std::array<ParamField<P>, 6> sensor_fixed_field_param_fields() {
  return {{{"mag_offset_learning", &P::mag_offset_learning},
           {"mag_offset_block_s", &P::mag_offset_block_s},
           {"mag_offset_row_s", &P::mag_offset_row_s},
           {"mag_offset_min_spread", &P::mag_offset_min_spread},
           {"mag_offset_max_residual_ratio", &P::mag_offset_max_residual_ratio},
           {"mag_offset_min_gain_ut2", &P::mag_offset_min_gain_ut2}}};
}

}  // namespace bsn::fusion
