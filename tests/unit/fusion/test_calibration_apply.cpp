#include <gtest/gtest.h>

#include "bsn/calib/sensor_calibration.hpp"

namespace bsn::calib {
namespace {

TEST(ChannelCalibration, AppliesBiasThenTransform) {
  ChannelCalibration c;
  c.bias = Vec3(1, -2, 3);
  c.transform << 2, 0, 0, 0, 1, 0.5, 0, 0, 1;
  const Vec3 u = apply(c, Vec3(3, 0, 5));  // raw - B = (2, 2, 2)
  EXPECT_EQ(u, Vec3(4, 3, 2));
}

TEST(ChannelCalibration, IdentityByDefault) {
  const Vec3 raw(0.1, 0.2, 0.3);
  EXPECT_EQ(apply(ChannelCalibration{}, raw), raw);
}

TEST(GyroBias, MeanOfARestingRecording) {
  Eigen::Matrix3Xd rates(3, 4);
  rates << 1, 2, 3, 4, 0, 0, 0, 0, -1, -1, -1, -1;
  EXPECT_TRUE(gyro_bias_from_rest(rates).isApprox(Vec3(2.5, 0, -1)));
  EXPECT_EQ(gyro_bias_from_rest(Eigen::Matrix3Xd(3, 0)), Vec3::Zero());
}

}  // namespace
}  // namespace bsn::calib
