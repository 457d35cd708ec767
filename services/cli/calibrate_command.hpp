// `bsn calibrate`: offline calibration of a recording (Zhang-Yang magnetometer, accelerometer, gyro bias) and
// Allan-deviation noise identification.
#pragma once

#include "command.hpp"

namespace bsn::services {

/// `bsn calibrate`: its options and what runs it.
Command calibrate_command();

}  // namespace bsn::services
