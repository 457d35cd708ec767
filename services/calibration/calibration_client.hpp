// `bsn calibrate --live`: the client of the calibration service. It sends one request, shows the progress, prints
// the results; Ctrl-C cancels the request on the service (a request with cancel = true and the same id).
#pragma once

#include <string>

namespace bsn::services {

struct LiveCalibrationOptions {
  std::string node;                   ///< node id, or a comma-separated list
  bool all_nodes = false;             ///< every node publishing on bsn/raw (node_id "*")
  std::string kind = "magnetometer";  ///< magnetometer, gyro-bias, accelerometer, alignment
  double duration_s = 60.0;           ///< collection time, s (0: sample_count only)
  unsigned sample_count = 0;          ///< or this many samples per node
  bool until_good = false;            ///< end as soon as the quality report is good enough
  double field_magnitude = 0.0;       ///< |calibrated magnetometer| in uT (0: the service's default, 50)
  std::string request_id;             ///< "" = <host>-<pid>-<time>
  double service_timeout_s = 5.0;     ///< give up when no calibration service is found within this, s
  int domain = 0;
  std::string body_path;  ///< alignment: the body model file ("" = the default lower body)
  double pose_s = 0.0;    ///< alignment: the N-pose's length, s (0: the service's default, 3 s)
};

/// Runs the client; returns the exit code: 0 every node calibrated, 1 a failure, refusal, cancel or a lost
/// service (with the reason on stderr), 2 a usage error.
int run_live_calibration(const LiveCalibrationOptions& options);

/// `bsn demo --calibrate`: one simulated node with a hard-iron offset, fusion and the calibration service; shows
/// the heading error before and after the live calibration. Exit 0 when the heading error after it is < 2 deg.
int run_calibration_demo(double speed, double duration_s, int domain);

}  // namespace bsn::services
