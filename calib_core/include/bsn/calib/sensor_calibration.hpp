// Calibration of one sensor channel, in the model of Zhang & Yang 2015: u = H (raw - B).
// Fitting comes in calib_core's own issue; applying is the tiny pure function the fusion service calls per
// sample.
#pragma once

#include <Eigen/Core>
#include <optional>

namespace bsn::calib {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

struct ChannelCalibration {
  Vec3 bias = Vec3::Zero();           ///< B, in the channel's unit
  Mat3 transform = Mat3::Identity();  ///< H: scale, misalignment and soft iron
};

/// u = H (raw - B).
inline Vec3 apply(const ChannelCalibration& c, const Vec3& raw) { return c.transform * (raw - c.bias); }

/// The calibrations of one sensor node; a channel without one is used as it comes.
struct SensorCalibration {
  std::optional<ChannelCalibration> accelerometer;  ///< m/s^2 after applying
  std::optional<ChannelCalibration> gyroscope;      ///< rad/s after applying
  std::optional<ChannelCalibration> magnetometer;   ///< the unit of the fit's field magnitude after applying
  bool empty() const { return !accelerometer && !gyroscope && !magnetometer; }
};

/// Gyro bias as the mean rate over a resting recording (rad/s). `rates` holds one sample per column; non-finite
/// columns are skipped; no finite sample gives zero.
Vec3 gyro_bias_from_rest(const Eigen::Ref<const Eigen::Matrix3Xd>& rates);

}  // namespace bsn::calib
