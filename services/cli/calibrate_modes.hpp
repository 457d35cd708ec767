// `bsn calibrate`'s options and its offline modes beside the hand-turned fit (calibrate_command.cpp): the Allan
// deviation of a static recording (calibrate_allan.cpp) and the alignment of a recorded lab procedure
// (calibrate_alignment.cpp). Each mode returns the process exit code (0 ok, 1 the data do not calibrate, 2 unreadable
// input).
#pragma once

#include <string>

#include "calibration_client.hpp"

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
  bool live = false;              ///< calibrate through the calibration service instead
  std::string alignment;          ///< a folder of per-node recordings to align (<node>.hdf5) instead
  bool field_magnitude_given = false;
  LiveCalibrationOptions live_options;
};

/// `--allan FILE`: the noise figures of a static recording per axis, and the curves as SVG with --plot.
int run_allan(const CalibrateOptions& opt);
/// `--alignment DIR|SESSION`: the sensor-to-segment alignment of every node of the body.
int run_offline_alignment(const CalibrateOptions& opt);

}  // namespace bsn::services
