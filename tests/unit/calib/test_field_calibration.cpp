#include <gtest/gtest.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "bsn/calib/field_calibration.hpp"
#include "bsn/fusion/rotation.hpp"
#include "calib_test_helpers.hpp"

namespace bsn::calib {
namespace {

using testing::ConsumerGyro;
using testing::PaperSensor;
using testing::Quat;

// The paper gives no field magnitude for its simulation; 500 mG (0.5 G, the earth's field near London, dip 66
// degrees) with Table I's scale of ~1.2 LSB/mG puts the readings ~600 LSB around the 32000 LSB bias.
constexpr double kFieldMg = 500.0;
constexpr double kDipRad = 66.0 * M_PI / 180.0;
const double kNoiseSd = std::sqrt(0.1);  // "zero mean Gaussian ... with variance 0.1"
constexpr int kPoses = 30;
constexpr int kRuns = 1000;

struct Scenario {
  Points3 poses{3, kPoses};
  std::vector<Mat3> rotations;  // exact: orientation of pose j in pose 0's frame
  std::vector<Quat> orientations;
  Vec3 field_vector;  // truth u_0
};

Scenario make_scenario(const PaperSensor& sensor, std::mt19937_64& rng) {
  Scenario s;
  const Vec3 m_earth = testing::earth_field(kFieldMg, kDipRad);
  for (int j = 0; j < kPoses; ++j) {
    const Quat q = testing::random_orientation(rng);
    s.orientations.push_back(q);
    s.poses.col(j) = testing::raw_reading(sensor, q, m_earth, kNoiseSd, rng);
    s.rotations.push_back((s.orientations[0].conjugate() * q).toRotationMatrix());
  }
  s.field_vector = s.orientations[0].conjugate() * m_earth;
  return s;
}

struct Errors {
  double bias = 0.0;       // largest relative error of a component of B
  double transform = 0.0;  // largest relative error of an element of H
  double field = 0.0;      // |u_0 error| / M
};

Errors errors_of(const FieldCalibration& c, const PaperSensor& truth, const Vec3& field_vector) {
  Errors e;
  e.bias = ((c.calibration.bias - truth.bias).array() / truth.bias.array()).abs().maxCoeff();
  // Element errors relative to the size of H (its largest singular value): H(2,3) of Table I is 0.007, so a
  // relative error of that element alone would measure noise against nothing.
  const double h_size = Eigen::JacobiSVD<Mat3>(truth.transform).singularValues()(0);
  e.transform = (c.calibration.transform - truth.transform).cwiseAbs().maxCoeff() / h_size;
  e.field = (c.field_vector - field_vector).norm() / kFieldMg;
  return e;
}

double fraction_below(const std::vector<double>& v, double limit) {
  return static_cast<double>(std::count_if(v.begin(), v.end(), [&](double x) { return x < limit; })) /
         static_cast<double>(v.size());
}

double percentile(std::vector<double> v, double p) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(p * static_cast<double>(v.size() - 1))];
}

// Zhang & Yang 2015, section III.A and Fig. 2: 1000 runs, 30 random orientations, exact relative rotations.
TEST(ZhangYangMonteCarlo, ExactRotationsReachThePapersAccuracy) {
  const PaperSensor sensor = testing::paper_sensor();
  std::vector<double> bias, transform, field;
  for (int run = 0; run < kRuns; ++run) {
    std::mt19937_64 rng(1000 + run);
    const Scenario s = make_scenario(sensor, rng);
    const FieldCalibration c = calibrate_field(s.poses, s.rotations, kFieldMg);
    ASSERT_TRUE(c.ok()) << "run " << run << ": " << c.message;
    const Errors e = errors_of(c, sensor, s.field_vector);
    bias.push_back(e.bias);
    transform.push_back(e.transform);
    field.push_back(e.field);
  }
  std::printf("exact rotations: bias p92 %.5f %% max %.5f %%; H p90 %.4f %% max %.4f %%; u p90 %.4f %% max %.4f %%\n",
              100 * percentile(bias, 0.92), 100 * percentile(bias, 1.0), 100 * percentile(transform, 0.9),
              100 * percentile(transform, 1.0), 100 * percentile(field, 0.9), 100 * percentile(field, 1.0));
  EXPECT_GE(fraction_below(bias, 0.005e-2), 0.92);
  EXPECT_LT(*std::max_element(bias.begin(), bias.end()), 0.012e-2);
  EXPECT_GE(fraction_below(transform, 0.15e-2), 0.90);
  EXPECT_LT(*std::max_element(field.begin(), field.end()), 0.05e-2);
}

// The same study with the relative rotations integrated from a consumer-grade gyro while the sensor is turned
// from pose to pose (2 s per turn, 100 Hz). Gyro errors, not magnetometer noise, now dominate.
TEST(ZhangYangMonteCarlo, GyroRotationsFromAConsumerGradeGyro) {
  const PaperSensor sensor = testing::paper_sensor();
  const ConsumerGyro gyro;
  std::vector<double> bias, transform, field;
  constexpr int kGyroRuns = 200;
  for (int run = 0; run < kGyroRuns; ++run) {
    std::mt19937_64 rng(5000 + run);
    Scenario s = make_scenario(sensor, rng);
    std::normal_distribution<double> n(0.0, 1.0);
    Mat3 error_matrix = Mat3::Identity();
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) error_matrix(i, k) += (i == k ? gyro.scale_error_sd : gyro.misalignment_sd) * n(rng);
    const Vec3 residual_bias = gyro.residual_bias_sd * Vec3(n(rng), n(rng), n(rng));
    Quat estimate = Quat::Identity();
    for (int j = 1; j < kPoses; ++j) {
      estimate = estimate * testing::integrate_turn(s.orientations[j - 1], s.orientations[j], 2.0, gyro, error_matrix,
                                                    residual_bias, rng);
      s.rotations[j] = estimate.normalized().toRotationMatrix();
    }
    const FieldCalibration c = calibrate_field(s.poses, s.rotations, kFieldMg);
    ASSERT_TRUE(c.ok()) << "run " << run << ": " << c.message;
    const Errors e = errors_of(c, sensor, s.field_vector);
    bias.push_back(e.bias);
    transform.push_back(e.transform);
    field.push_back(e.field);
  }
  std::printf(
      "consumer gyro: bias max %.5f %%; H median %.3f %% p90 %.3f %% max %.3f %%; u median %.3f %% p90 %.3f %%\n",
      100 * percentile(bias, 1.0), 100 * percentile(transform, 0.5), 100 * percentile(transform, 0.9),
      100 * percentile(transform, 1.0), 100 * percentile(field, 0.5), 100 * percentile(field, 0.9));
  // The bias comes from the ellipsoid alone: the gyro cannot spoil it.
  EXPECT_LT(*std::max_element(bias.begin(), bias.end()), 0.012e-2);
  // A turn of ~120 degrees with 0.2 % scale error and 0.1 % misalignment misses by ~0.3 degrees; 29 turns in
  // a row random-walk to ~1.5 degrees, i.e. ~2.6 % of |u| across H's elements in the worst direction.
  EXPECT_LT(percentile(transform, 0.9), 0.01);
  EXPECT_LT(percentile(field, 0.9), 0.03);
}

// Heading from the corrected field of a tilted, rotated sensor (tilt from the exact gravity direction).
TEST(ZhangYangCalibration, HeadingErrorBelowHalfADegreeAfterCalibrationManyDegreesWithout) {
  const PaperSensor sensor = testing::paper_sensor();
  std::mt19937_64 rng(7);
  const Scenario s = make_scenario(sensor, rng);
  const FieldCalibration c = calibrate_field(s.poses, s.rotations, kFieldMg);
  ASSERT_TRUE(c.ok()) << c.message;
  // Reference frame of the calibration: pose 0's orientation carries the earth frame into the calibrated sensor
  // frame, so heading is measured in the inertial sensor frame of the paper's model.
  const Vec3 m_earth = testing::earth_field(kFieldMg, kDipRad);
  ChannelCalibration bias_only;
  bias_only.bias = c.calibration.bias;
  double worst_calibrated = 0.0, worst_bias_only = 0.0;
  std::uniform_real_distribution<double> angle(-M_PI, M_PI), tilt(-1.0, 1.0);
  for (int k = 0; k < 100; ++k) {
    const double yaw = angle(rng);
    const Quat q = fusion::from_yaw_pitch_roll({yaw, tilt(rng), tilt(rng)});
    const Vec3 acc = q.conjugate() * Vec3(0, 0, fusion::kGravity);
    const Vec3 raw = testing::raw_reading(sensor, q, m_earth, kNoiseSd, rng);
    auto heading_error = [&](const Vec3& mag) {
      const double est = fusion::to_yaw_pitch_roll(fusion::orientation_from_acc_mag(acc, mag)).yaw;
      return std::abs(std::remainder(est - yaw, 2 * M_PI)) * 180.0 / M_PI;
    };
    worst_calibrated = std::max(worst_calibrated, heading_error(apply(c.calibration, raw)));
    worst_bias_only = std::max(worst_bias_only, heading_error(apply(bias_only, raw)));
  }
  std::printf("heading error: calibrated max %.3f deg, bias removed only max %.1f deg\n", worst_calibrated,
              worst_bias_only);
  EXPECT_LT(worst_calibrated, 0.5);
  EXPECT_GT(worst_bias_only, 5.0);
}

// ----- degenerate input: a clear failure, never an exception, never NaN -----

void expect_clean_failure(const FieldCalibration& c, const std::string& words) {
  EXPECT_FALSE(c.ok());
  EXPECT_NE(c.message.find(words), std::string::npos) << c.message;
  EXPECT_TRUE(c.calibration.bias.allFinite());
  EXPECT_TRUE(c.calibration.transform.allFinite());
  EXPECT_TRUE(c.field_vector.allFinite());
}

TEST(ZhangYangDegenerate, FewerThanFivePoses) {
  const PaperSensor sensor = testing::paper_sensor();
  std::mt19937_64 rng(1);
  const Scenario s = make_scenario(sensor, rng);
  const std::vector<Mat3> four(s.rotations.begin(), s.rotations.begin() + 4);
  // The ellipsoid from all 30 readings, but only 4 poses for H.
  expect_clean_failure(calibrate_field(s.poses.leftCols(4), four, kFieldMg, s.poses), "too few poses");
}

TEST(ZhangYangDegenerate, TooFewSamplesForTheEllipsoid) {
  const PaperSensor sensor = testing::paper_sensor();
  std::mt19937_64 rng(2);
  const Scenario s = make_scenario(sensor, rng);
  const std::vector<Mat3> six(s.rotations.begin(), s.rotations.begin() + 6);
  expect_clean_failure(calibrate_field(s.poses.leftCols(6), six, kFieldMg), "too few samples");
}

TEST(ZhangYangDegenerate, NaNRow) {
  const PaperSensor sensor = testing::paper_sensor();
  std::mt19937_64 rng(3);
  Scenario s = make_scenario(sensor, rng);
  s.poses(1, 17) = std::numeric_limits<double>::quiet_NaN();
  expect_clean_failure(calibrate_field(s.poses, s.rotations, kFieldMg), "column 17");
}

TEST(ZhangYangDegenerate, ConstantData) {
  Points3 same = Vec3(32000, 32000, 32000).replicate(1, 30);
  expect_clean_failure(calibrate_field(same, std::vector<Mat3>(30, Mat3::Identity()), kFieldMg), "constant");
}

TEST(ZhangYangDegenerate, AllPosesInOnePlane) {
  // Turned about the vertical only: the readings trace an ellipse, not an ellipsoid.
  const PaperSensor sensor = testing::paper_sensor();
  std::mt19937_64 rng(4);
  const Vec3 m_earth = testing::earth_field(kFieldMg, kDipRad);
  Points3 poses(3, 30);
  std::vector<Mat3> rotations;
  for (int j = 0; j < 30; ++j) {
    const Quat q(Eigen::AngleAxisd(0.2 * j, Vec3::UnitZ()));
    poses.col(j) = testing::raw_reading(sensor, q, m_earth, kNoiseSd, rng);
    rotations.push_back(q.toRotationMatrix());
  }
  expect_clean_failure(calibrate_field(poses, rotations, kFieldMg), "one plane");
}

TEST(ZhangYangDegenerate, BadFieldMagnitudeAndMismatchedRotations) {
  const PaperSensor sensor = testing::paper_sensor();
  std::mt19937_64 rng(5);
  const Scenario s = make_scenario(sensor, rng);
  expect_clean_failure(calibrate_field(s.poses, s.rotations, std::numeric_limits<double>::quiet_NaN()),
                       "field magnitude");
  expect_clean_failure(calibrate_field(s.poses, std::vector<Mat3>(3, Mat3::Identity()), kFieldMg), "rotations");
}

TEST(ZhangYangCalibration, QualityReportOfAGoodFit) {
  const PaperSensor sensor = testing::paper_sensor();
  std::mt19937_64 rng(6);
  const Scenario s = make_scenario(sensor, rng);
  const FieldCalibration c = calibrate_field(s.poses, s.rotations, kFieldMg);
  ASSERT_TRUE(c.ok()) << c.message;
  EXPECT_EQ(c.quality.pose_count, 30u);
  // Noise sd 0.32 LSB on a ~600 LSB radius: |u| - M of about 0.3 mG.
  EXPECT_LT(c.quality.residual_rms, 1.0);
  EXPECT_GT(c.quality.sphere_coverage, 0.3);
  EXPECT_GE(c.quality.octants_covered, 6);
  EXPECT_LT(c.quality.ellipsoid_consistency, 0.01);
  EXPECT_TRUE(c.quality.warnings.empty());
  EXPECT_GT(c.quality.transform_condition, 1.0);
  EXPECT_GT(c.field_vector.norm(), 0.0);
  EXPECT_NEAR(c.field_vector.norm(), kFieldMg, 1e-9 * kFieldMg);
}

TEST(ZhangYangCalibration, WithoutRotationsGivesBiasAndASymmetricTransform) {
  const PaperSensor sensor = testing::paper_sensor();
  std::mt19937_64 rng(8);
  const Scenario s = make_scenario(sensor, rng);
  const FieldCalibration c = calibrate_field_without_rotations(s.poses, kFieldMg);
  ASSERT_TRUE(c.ok()) << c.message;
  EXPECT_LT(((c.calibration.bias - sensor.bias).array() / sensor.bias.array()).abs().maxCoeff(), 0.012e-2);
  // K^T K = H^T H (eq. 21): same magnitudes everywhere, different rotation.
  const Mat3 hth = sensor.transform.transpose() * sensor.transform;
  EXPECT_LT((c.calibration.transform.transpose() * c.calibration.transform - hth).norm() / hth.norm(), 2e-3);
  EXPECT_TRUE(c.calibration.transform.isApprox(c.calibration.transform.transpose()));
}

}  // namespace
}  // namespace bsn::calib
