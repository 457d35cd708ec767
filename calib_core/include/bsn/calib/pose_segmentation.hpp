// Calibration by hand: the user turns the sensor into a number of still poses. The recording is segmented into
// poses by rest detection on the gyro, each pose is averaged (the paper uses pose means), and the gyro, with
// its bias from the rest samples removed, is integrated between poses to give the relative rotations that the
// Zhang-Yang transformation step needs.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "bsn/calib/field_calibration.hpp"

namespace bsn::calib {

struct PoseSegmentationParams {
  double rest_rate_rad_s = 0.05;  ///< rad/s: still when the smoothed |gyro - bias| stays below this (default 0.05)
  double smoothing_s = 0.1;       ///< s: window of the moving mean of |gyro| for rest detection (default 0.1)
  double min_pose_s = 1.0;        ///< s: shorter rests are not poses (default 1.0)
  double edge_trim_s = 0.2;       ///< s: dropped at both ends of a rest before averaging (default 0.2)
};

/// The static poses of a recording.
struct PoseSegmentation {
  FitStatus status = FitStatus::failed;
  std::string message;             ///< why it failed, empty when ok
  std::vector<std::size_t> begin;  ///< first sample of each pose (after trimming)
  std::vector<std::size_t> end;    ///< one past the last sample of each pose
  Points3 means{3, 0};             ///< mean reading of each pose (columns); poses without readings are dropped
  std::vector<Mat3> rotations;     ///< orientation of pose j's sensor frame in pose 0's (gyro integrated)
  Vec3 gyro_bias = Vec3::Zero();   ///< rad/s, mean gyro over all rest samples
  std::size_t rest_samples = 0;
  bool ok() const { return status == FitStatus::ok; }
};

/// Segments `readings` (the calibrated channel, raw unit; a column with NaN = no reading at that sample) into
/// static poses using `rates` (gyro, rad/s, same sample count, all finite), sampled uniformly at
/// `sample_rate_hz`.
PoseSegmentation segment_poses(const Eigen::Ref<const Points3>& rates, const Eigen::Ref<const Points3>& readings,
                               double sample_rate_hz, const PoseSegmentationParams& params = {});

/// Segments and calibrates: the ellipsoid is fitted to every finite reading (moving ones too: more directions),
/// H and u from the pose means and the gyro rotations. `segmentation`, when given, receives the poses.
FieldCalibration calibrate_field_from_recording(const Eigen::Ref<const Points3>& rates,
                                                const Eigen::Ref<const Points3>& readings, double sample_rate_hz,
                                                double field_magnitude, const PoseSegmentationParams& params = {},
                                                PoseSegmentation* segmentation = nullptr);

}  // namespace bsn::calib
