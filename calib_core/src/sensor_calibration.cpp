#include "bsn/calib/sensor_calibration.hpp"

namespace bsn::calib {

Vec3 gyro_bias_from_rest(const Eigen::Ref<const Eigen::Matrix3Xd>& rates) {
  // Non-finite samples (dropouts) are left out rather than spoiling the mean.
  Vec3 sum = Vec3::Zero();
  Eigen::Index count = 0;
  for (Eigen::Index k = 0; k < rates.cols(); ++k) {
    if (!rates.col(k).allFinite()) continue;
    sum += rates.col(k);
    ++count;
  }
  return count > 0 ? Vec3(sum / static_cast<double>(count)) : Vec3::Zero();
}

}  // namespace bsn::calib
