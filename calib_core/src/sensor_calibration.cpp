#include "bsn/calib/sensor_calibration.hpp"

namespace bsn::calib {

Vec3 gyro_bias_from_rest(const Eigen::Ref<const Eigen::Matrix3Xd>& rates) {
  if (rates.cols() == 0) return Vec3::Zero();
  return rates.rowwise().mean();
}

}  // namespace bsn::calib
