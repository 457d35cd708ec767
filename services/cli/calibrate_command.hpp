// `bsn calibrate`: offline calibration of a recording (Zhang-Yang magnetometer, accelerometer, gyro bias) and
// Allan-deviation noise identification.
#pragma once

#include <string>

namespace bsn::services {

struct CalibrateOptions {
  std::string input;              ///< recording to calibrate (CSV or BROAD HDF5): hand-turned poses
  std::string allan;              ///< static recording for the Allan deviation instead
  double field_magnitude = 1.0;   ///< M: |calibrated magnetometer| (1 = normalised; 50 for uT, ...)
  bool json = false;              ///< print the JSON object instead of the text report
  std::string output;             ///< calibration file to write ("" = INPUT with extension .calib.yaml)
  std::string node;               ///< node id written into the file
  bool accelerometer = false;     ///< also calibrate the accelerometer (|g| = 9.80665 m/s^2)
  bool gyro_bias = false;         ///< also write the gyro bias from the rests
  double rest_rate_rad_s = 0.05;  ///< rest threshold on |gyro - bias|, rad/s
  double min_pose_s = 1.0;        ///< shortest rest that counts as a pose, s
  std::string plot;               ///< with --allan: write the curves as an SVG here
};

/// Runs the command; returns the process exit code (0 ok, 1 the data do not calibrate, 2 unreadable input).
int run_calibrate(const CalibrateOptions& options);

}  // namespace bsn::services
