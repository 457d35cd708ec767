#include "calibration_wire.hpp"

namespace bsn::services {

calib::SessionSample session_sample(const fusion::ImuSample& imu, std::uint64_t seq) {
  calib::SessionSample s;
  s.seq = seq;
  s.timestamp_ns = imu.timestamp_ns;
  s.acc = imu.acc;
  s.gyr = imu.gyr;
  s.mag = imu.mag;
  s.has_acc = imu.has_acc;
  s.has_gyr = imu.has_gyr;
  s.has_mag = imu.has_mag;
  return s;
}

bsn::CalibrationKind to_wire(calib::CalibrationKind kind) {
  switch (kind) {
    case calib::CalibrationKind::magnetometer:
      return bsn::CALIBRATION_MAGNETOMETER;
    case calib::CalibrationKind::gyro_bias:
      return bsn::CALIBRATION_GYRO_BIAS;
    case calib::CalibrationKind::accelerometer:
      return bsn::CALIBRATION_ACCELEROMETER;
    case calib::CalibrationKind::alignment:
      return bsn::CALIBRATION_SEGMENT_ALIGNMENT;
  }
  return bsn::CALIBRATION_MAGNETOMETER;
}

std::optional<calib::CalibrationKind> from_wire(bsn::CalibrationKind kind) {
  switch (kind) {
    case bsn::CALIBRATION_MAGNETOMETER:
      return calib::CalibrationKind::magnetometer;
    case bsn::CALIBRATION_GYRO_BIAS:
      return calib::CalibrationKind::gyro_bias;
    case bsn::CALIBRATION_ACCELEROMETER:
      return calib::CalibrationKind::accelerometer;
    case bsn::CALIBRATION_SEGMENT_ALIGNMENT:
      return calib::CalibrationKind::alignment;
  }
  return std::nullopt;
}

}  // namespace bsn::services
