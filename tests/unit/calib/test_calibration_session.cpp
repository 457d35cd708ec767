// The live calibration session: the same fit as offline for the same samples, lost samples filled in, progress
// and instructions while collecting, "good enough", and every way a collection can fail with its reason.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "bsn/calib/calibration_session.hpp"
#include "calib_test_helpers.hpp"

namespace bsn::calib {
namespace {

using testing::Quat;

constexpr double kFieldMg = 500.0;
constexpr double kDipRad = 66.0 * M_PI / 180.0;
constexpr std::uint64_t kPeriodNs = 10'000'000;  // 100 Hz
constexpr std::uint64_t kStartNs = 1'000'000'000;

testing::HandRecording recording(int poses, std::uint64_t seed, double rest_s = 3.0) {
  std::mt19937_64 rng(seed);
  std::vector<Quat> orientations;
  for (int j = 0; j < poses; ++j) orientations.push_back(testing::random_orientation(rng));
  return testing::hand_turned_recording(orientations, rest_s, 1.5, testing::ConsumerGyro{}, Mat3::Identity(),
                                        Vec3(0.02, -0.015, 0.01), testing::paper_sensor(),
                                        testing::earth_field(kFieldMg, kDipRad), std::sqrt(0.1), rng);
}

SessionSample sample_at(const testing::HandRecording& r, Eigen::Index k) {
  SessionSample s;
  s.seq = static_cast<std::uint64_t>(k) + 7;
  s.timestamp_ns = 5'000'000'000ull + static_cast<std::uint64_t>(k) * kPeriodNs;
  s.gyr = r.rates.col(k);
  s.mag = r.mag.col(k);
  s.acc = Vec3(0, 0, 9.81);
  return s;
}

SessionParams magnetometer_params(std::size_t samples) {
  SessionParams p;
  p.kind = CalibrationKind::magnetometer;
  p.sample_count = samples;
  p.field_magnitude = kFieldMg;
  return p;
}

// Feeds the samples in real time (arrival = start + k periods); `skip(k)` drops sample k.
template <class Skip>
void feed(CalibrationSession& s, const testing::HandRecording& r, Skip skip) {
  for (Eigen::Index k = 0; k < r.rates.cols(); ++k)
    if (!skip(k)) s.add(sample_at(r, k), kStartNs + static_cast<std::uint64_t>(k) * kPeriodNs);
}

double max_relative(const Mat3& a, const Mat3& truth) { return (a - truth).cwiseAbs().maxCoeff() / truth.norm(); }

TEST(CalibrationSession, FitsExactlyAsTheOfflineCalibrationOfTheSameSamples) {
  const auto r = recording(20, 3);
  const auto n = static_cast<std::size_t>(r.rates.cols());
  CalibrationSession s(magnetometer_params(n), kStartNs);
  feed(s, r, [](Eigen::Index) { return false; });
  EXPECT_TRUE(s.collection_over(kStartNs + n * kPeriodNs));
  const SessionResult live = s.finish();
  ASSERT_TRUE(live.success) << live.message;
  const FieldCalibration offline = calibrate_field_from_recording(r.rates, r.mag, 100.0, kFieldMg);
  ASSERT_TRUE(offline.ok());
  // Same samples, same functions; only the sample rate comes from the timestamps (exact here).
  EXPECT_LT((live.field.calibration.bias - offline.calibration.bias).norm(), 1e-9 * offline.calibration.bias.norm());
  EXPECT_LT(max_relative(live.field.calibration.transform, offline.calibration.transform), 1e-9);
  EXPECT_EQ(live.field.quality.pose_count, 20u);
  // And the truth, within the bounds (bias 0.01 %, H 0.2 %) with an exact gyro.
  const auto truth = testing::paper_sensor();
  EXPECT_LT((live.field.calibration.bias - truth.bias).norm() / truth.bias.norm(), 1e-4);
  EXPECT_LT(max_relative(live.field.calibration.transform, truth.transform), 2e-3);
}

TEST(CalibrationSession, LostSamplesAreInterpolatedAndTheFitStaysWithinTheBounds) {
  const auto r = recording(20, 4);
  const auto n = static_cast<std::size_t>(r.rates.cols());
  CalibrationSession s(magnetometer_params(n), kStartNs);
  // One sample in 37 lost, and once three in a row: a lossy network.
  feed(s, r, [](Eigen::Index k) { return k % 37 == 5 || (k >= 1000 && k < 1003); });
  SessionResult live = s.finish();
  ASSERT_TRUE(live.success) << live.message;
  EXPECT_GT(live.interpolated, n / 40);
  EXPECT_EQ(live.samples, n);
  const auto truth = testing::paper_sensor();
  EXPECT_LT((live.field.calibration.bias - truth.bias).norm() / truth.bias.norm(), 1e-4);
  EXPECT_LT(max_relative(live.field.calibration.transform, truth.transform), 2e-3);
}

TEST(CalibrationSession, ALongGapFailsWithItsPlace) {
  const auto r = recording(8, 5);
  CalibrationSession s(magnetometer_params(static_cast<std::size_t>(r.rates.cols())), kStartNs);
  feed(s, r, [](Eigen::Index k) { return k >= 500 && k < 560; });
  const SessionResult res = s.finish();
  EXPECT_FALSE(res.success);
  EXPECT_NE(res.message.find("60 samples lost in a row"), std::string::npos) << res.message;
}

TEST(CalibrationSession, ProgressCountsPosesAndSaysWhatToDo) {
  const auto r = recording(8, 6);
  CalibrationSession s(magnetometer_params(static_cast<std::size_t>(r.rates.cols())), kStartNs);
  EXPECT_NE(s.progress(kStartNs).instruction.find("waiting"), std::string::npos);
  // Pose k lasts 300 samples of rest then 150 of turning.
  std::size_t last_poses = 0;
  bool said_hold = false, said_turn = false, said_recorded = false;
  for (Eigen::Index k = 0; k < r.rates.cols(); ++k) {
    const std::uint64_t now = kStartNs + static_cast<std::uint64_t>(k) * kPeriodNs;
    s.add(sample_at(r, k), now);
    if (k % 25 != 24) continue;  // 4 Hz
    const SessionProgress p = s.progress(now);
    EXPECT_GE(p.poses, last_poses);
    last_poses = p.poses;
    const Eigen::Index in_cycle = k % 450;
    if (in_cycle > 20 && in_cycle < 100) said_hold |= p.instruction == "hold still";
    if (in_cycle > 200 && in_cycle < 290) said_recorded |= p.instruction.rfind("pose ", 0) == 0;
    if (in_cycle > 320 && in_cycle < 440) said_turn |= p.instruction.rfind("turn to a new orientation", 0) == 0;
  }
  EXPECT_TRUE(said_hold);
  EXPECT_TRUE(said_recorded);
  EXPECT_TRUE(said_turn);
  const SessionProgress end = s.progress(kStartNs + static_cast<std::uint64_t>(r.rates.cols()) * kPeriodNs);
  EXPECT_EQ(end.poses, 8u);
  EXPECT_GT(end.octants, 0);
  EXPECT_GT(end.sphere_coverage, 0.0);
  EXPECT_DOUBLE_EQ(end.fraction, 1.0);
  EXPECT_TRUE(end.collection_over);
}

TEST(CalibrationSession, UntilGoodEndsOnceThePosesCoverTheSphere) {
  const auto r = recording(30, 7);
  SessionParams p = magnetometer_params(static_cast<std::size_t>(r.rates.cols()));
  p.until_good = true;
  CalibrationSession s(p, kStartNs);
  Eigen::Index ended_at = -1;
  for (Eigen::Index k = 0; k < r.rates.cols() && ended_at < 0; ++k) {
    const std::uint64_t now = kStartNs + static_cast<std::uint64_t>(k) * kPeriodNs;
    s.add(sample_at(r, k), now);
    if (k % 50 == 49 && s.progress(now).collection_over) ended_at = k;
  }
  ASSERT_GT(ended_at, 0) << "never good enough";
  EXPECT_LT(ended_at, r.rates.cols() * 2 / 3);
  const SessionResult res = s.finish();
  ASSERT_TRUE(res.success) << res.message;
  EXPECT_GE(res.field.quality.pose_count, p.good_poses);
  EXPECT_GE(res.field.quality.octants_covered, p.good_octants);
  EXPECT_TRUE(res.field.quality.warnings.empty());
}

TEST(CalibrationSession, ASilentNodeEndsAtTheDurationWithoutASample) {
  SessionParams p;
  p.duration_s = 1.5;
  CalibrationSession s(p, kStartNs);
  EXPECT_FALSE(s.collection_over(kStartNs + 1'400'000'000));
  EXPECT_TRUE(s.collection_over(kStartNs + 1'500'000'000));
  const SessionResult res = s.finish();
  EXPECT_FALSE(res.success);
  EXPECT_EQ(res.message, "no sample arrived");
}

TEST(CalibrationSession, ANodeThatStopsSendingEndsTheCollection) {
  const auto r = recording(3, 8);
  SessionParams p = magnetometer_params(100000);
  CalibrationSession s(p, kStartNs);
  for (Eigen::Index k = 0; k < 100; ++k) s.add(sample_at(r, k), kStartNs + static_cast<std::uint64_t>(k) * kPeriodNs);
  const std::uint64_t last = kStartNs + 99 * kPeriodNs;
  EXPECT_FALSE(s.collection_over(last + 1'900'000'000));
  EXPECT_TRUE(s.collection_over(last + 2'000'000'000));
}

TEST(CalibrationSession, BadDataFailWithTheReasonOfTheQualityReport) {
  {  // too few poses
    const auto r = recording(3, 9);
    CalibrationSession s(magnetometer_params(static_cast<std::size_t>(r.rates.cols())), kStartNs);
    feed(s, r, [](Eigen::Index) { return false; });
    const SessionResult res = s.finish();
    EXPECT_FALSE(res.success);
    EXPECT_NE(res.message.find("too few poses"), std::string::npos) << res.message;
  }
  {  // poses in one plane: every turn about the sensor's z axis
    std::mt19937_64 rng(10);
    std::vector<Quat> orientations;
    for (int j = 0; j < 10; ++j) orientations.emplace_back(Eigen::AngleAxisd(0.6 * j, Vec3::UnitZ()));
    const auto r = testing::hand_turned_recording(orientations, 3.0, 1.5, testing::ConsumerGyro{}, Mat3::Identity(),
                                                  Vec3::Zero(), testing::paper_sensor(),
                                                  testing::earth_field(kFieldMg, kDipRad), std::sqrt(0.1), rng);
    CalibrationSession s(magnetometer_params(static_cast<std::size_t>(r.rates.cols())), kStartNs);
    feed(s, r, [](Eigen::Index) { return false; });
    const SessionResult res = s.finish();
    EXPECT_FALSE(res.success);
    EXPECT_NE(res.message.find("plane"), std::string::npos) << res.message;
  }
  {  // a sensor that never moves: one long rest
    const auto r = recording(1, 11, 20.0);
    CalibrationSession s(magnetometer_params(static_cast<std::size_t>(r.rates.cols())), kStartNs);
    feed(s, r, [](Eigen::Index) { return false; });
    const SessionResult res = s.finish();
    EXPECT_FALSE(res.success);
    EXPECT_FALSE(res.message.empty());
  }
  {  // NaN in a sample
    const auto r = recording(8, 12);
    CalibrationSession s(magnetometer_params(static_cast<std::size_t>(r.rates.cols())), kStartNs);
    for (Eigen::Index k = 0; k < r.rates.cols(); ++k) {
      SessionSample x = sample_at(r, k);
      if (k == 700) x.mag.y() = std::numeric_limits<double>::quiet_NaN();
      s.add(x, kStartNs + static_cast<std::uint64_t>(k) * kPeriodNs);
    }
    const SessionResult res = s.finish();
    EXPECT_FALSE(res.success);
    EXPECT_NE(res.message.find("NaN"), std::string::npos) << res.message;
    EXPECT_NE(res.message.find("seq 707"), std::string::npos) << res.message;
  }
}

TEST(CalibrationSession, GyroBiasIsTheMeanRateAtRest) {
  const auto r = recording(1, 13, 6.0);  // 6 s still, bias (0.02, -0.015, 0.01) rad/s
  SessionParams p;
  p.kind = CalibrationKind::gyro_bias;
  p.sample_count = static_cast<std::size_t>(r.rates.cols());
  CalibrationSession s(p, kStartNs);
  feed(s, r, [](Eigen::Index) { return false; });
  const SessionResult res = s.finish();
  ASSERT_TRUE(res.success) << res.message;
  // 0.01 deg/s/sqrt(Hz) white noise over ~5 s: the mean errs ~1e-4 rad/s per axis.
  EXPECT_LT((res.gyro.bias - Vec3(0.02, -0.015, 0.01)).norm(), 5e-4);
}

TEST(CalibrationSession, ParametersThatCannotEndAreRefused) {
  SessionParams p;
  EXPECT_NE(validate(p).find("neither"), std::string::npos);
  p.duration_s = -1.0;
  EXPECT_NE(validate(p).find("duration_s"), std::string::npos);
  p.duration_s = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(validate(p).find("duration_s"), std::string::npos);
  p.duration_s = 1e9;
  EXPECT_NE(validate(p).find("absurd"), std::string::npos);
  p.duration_s = 10.0;
  EXPECT_EQ(validate(p), "");
  p.field_magnitude = -3.0;
  EXPECT_NE(validate(p).find("field_magnitude"), std::string::npos);
  EXPECT_THROW(CalibrationSession(p, 0), std::invalid_argument);
  EXPECT_EQ(parse_kind("gyro-bias"), CalibrationKind::gyro_bias);
  EXPECT_EQ(parse_kind("compass"), std::nullopt);
  EXPECT_EQ(parse_kind("gyro_bias"), std::nullopt);  // one spelling per kind: kind_name's
}

}  // namespace
}  // namespace bsn::calib
