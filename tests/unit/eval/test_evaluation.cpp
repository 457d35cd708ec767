// BROAD's error metrics and the evaluation loop of `bsn eval`.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "bsn/eval/evaluation.hpp"
#include "bsn/eval/tune_runner.hpp"
#include "bsn/sim/scenario.hpp"

namespace bsn::eval {
namespace {

using fusion::Quat;
using fusion::Vec3;
constexpr double kDeg = std::numbers::pi / 180.0;

Quat about(const Vec3& axis, double deg) { return Quat(Eigen::AngleAxisd(deg * kDeg, axis.normalized())); }

TEST(ErrorAngles, PureHeadingError) {
  const Quat ref = fusion::from_yaw_pitch_roll({0.3, 0.4, -0.2});
  const fusion::ErrorAngles e = fusion::error_angles(about(Vec3::UnitZ(), 30) * ref, ref);
  EXPECT_NEAR(e.total, 30 * kDeg, 1e-12);
  EXPECT_NEAR(e.heading, 30 * kDeg, 1e-12);
  EXPECT_NEAR(e.inclination, 0.0, 1e-7);
}

TEST(ErrorAngles, PureInclinationError) {
  const Quat ref = fusion::from_yaw_pitch_roll({1.0, -0.3, 0.2});
  const fusion::ErrorAngles e = fusion::error_angles(about(Vec3(1, 2, 0), 20) * ref, ref);
  EXPECT_NEAR(e.total, 20 * kDeg, 1e-12);
  EXPECT_NEAR(e.heading, 0.0, 1e-12);
  EXPECT_NEAR(e.inclination, 20 * kDeg, 1e-12);
}

TEST(ErrorAngles, HalfTurnOfHeadingAndSignInvariance) {
  const Quat ref = Quat::Identity();
  const fusion::ErrorAngles e = fusion::error_angles(about(Vec3::UnitZ(), 180), ref);
  EXPECT_NEAR(e.heading, std::numbers::pi, 1e-12);
  const Quat est = about(Vec3(1, 1, 1), 40);
  const fusion::ErrorAngles a = fusion::error_angles(est, ref), b = fusion::error_angles(Quat(-est.coeffs()), ref);
  EXPECT_NEAR(a.total, b.total, 1e-12);
  EXPECT_NEAR(a.heading, b.heading, 1e-12);
  EXPECT_NEAR(a.inclination, b.inclination, 1e-12);
}

TEST(ErrorAngles, RmsAccumulator) {
  fusion::RmsErrorAccumulator acc;
  acc.add({3, 0, 4});
  acc.add({4, 0, 3});
  EXPECT_NEAR(acc.rms().total, std::sqrt(12.5), 1e-12);
  EXPECT_EQ(acc.count(), 2u);
  EXPECT_EQ(fusion::RmsErrorAccumulator{}.rms().total, 0.0);
}

// A recording of exact sensor readings of a known motion, with the truth as reference.
io::Recording simulated(double seconds, double rate_hz) {
  return simulate_recording(sim::swing_scenario("sim", 21, rate_hz, seconds), /*ideal=*/true);
}

// With exact readings only the strapdown discretisation remains: a rate sample held over one sample period
// misplaces the orientation by at most |w| dt / 2.
double discretisation_bound(const io::Recording& rec) {
  return rec.gyr.rowwise().norm().maxCoeff() / rec.sampling_rate_hz / 2.0;
}

TEST(RunTrial, ExactReadingsScoreNearZero) {
  const io::Recording rec = simulated(20, 100);
  const TrialResult r = run_trial(rec, "sim", {"complementary", {}}, "complementary");
  EXPECT_EQ(r.scored, rec.size());
  EXPECT_EQ(r.non_finite, 0u);
  EXPECT_LT(r.rmse.total, discretisation_bound(rec));
  EXPECT_LE(r.time_s.size(), 2000u);
}

TEST(RunTrial, ScoresOnlyMovementSamplesWithAFiniteReference) {
  io::Recording rec = simulated(10, 100);
  rec.movement.assign(rec.size(), 0);
  for (std::size_t i = 200; i < 700; ++i) rec.movement[i] = 1;
  rec.opt_quat.row(300).setConstant(std::nan(""));
  // A reference that is wrong outside the movement phase must not count.
  for (Eigen::Index i = 0; i < 200; ++i) rec.opt_quat.row(i) << 0, 1, 0, 0;
  const TrialResult r = run_trial(rec, "sim", {"complementary", {}}, "complementary");
  EXPECT_EQ(r.scored, 499u);
  EXPECT_LT(r.rmse.total, discretisation_bound(rec));
}

TEST(RunTrial, AWrongReferenceShowsInTheError) {
  io::Recording rec = simulated(10, 100);
  // Turn the reference by 10 deg about up: a pure 10 deg heading error.
  for (Eigen::Index i = 0; i < rec.opt_quat.rows(); ++i) {
    const auto r = rec.opt_quat.row(i);
    const Quat q = about(Vec3::UnitZ(), 10) * Quat(r(0), r(1), r(2), r(3));
    rec.opt_quat.row(i) << q.w(), q.x(), q.y(), q.z();
  }
  const TrialResult r = run_trial(rec, "sim", {"complementary", {}}, "complementary");
  EXPECT_NEAR(r.rmse.heading, 10 * kDeg, discretisation_bound(rec));
  EXPECT_LT(r.rmse.inclination, discretisation_bound(rec));
}

TEST(FilterArgument, NameAndParameters) {
  const auto spec = parse_filter_argument("complementary:tau_acc_s=3,tau_mag_s=1e1");
  EXPECT_EQ(spec.name, "complementary");
  ASSERT_EQ(spec.parameters.size(), 2u);
  EXPECT_EQ(spec.parameters[1].second, 10.0);
  EXPECT_TRUE(parse_filter_argument("x").parameters.empty());
  EXPECT_THROW(parse_filter_argument(":a=1"), std::invalid_argument);
  EXPECT_THROW(parse_filter_argument("c:tau"), std::invalid_argument);
  EXPECT_THROW(parse_filter_argument("c:tau=abc"), std::invalid_argument);
  EXPECT_THROW(parse_filter_argument("c:tau=1x"), std::invalid_argument);
}

TEST(Report, JsonHasTheAgreedShape) {
  TrialResult a{"t1", "f", {1 * kDeg, 2 * kDeg, 3 * kDeg}, 10, 0, 0, {}, {}};
  TrialResult b{"t\"2", "f", {3 * kDeg, 4 * kDeg, 5 * kDeg}, 10, 0, 0, {}, {}};
  const std::string json = to_json({a, b});
  EXPECT_EQ(json.rfind("{\"trials\": [{\"trial\": \"t1\", \"filter\": \"f\", \"total_rmse_deg\": 1, ", 0), 0u) << json;
  EXPECT_NE(json.find("\"t\\\"2\""), std::string::npos) << json;  // escaped quote
  EXPECT_NE(json.find("\"means\": [{\"filter\": \"f\", \"total_rmse_deg\": 2, \"heading_rmse_deg\": 3, "
                      "\"inclination_rmse_deg\": 4}]"),
            std::string::npos)
      << json;
}

TEST(Report, TableAndSvg) {
  TrialResult a{"trial_a", "complementary", {1 * kDeg, 2 * kDeg, 3 * kDeg}, 10, 0, 0, {0.0f, 1.0f}, {1.0f, 2.0f}};
  const std::string table = to_table({a});
  EXPECT_NE(table.find("trial_a"), std::string::npos);
  EXPECT_NE(table.find("mean"), std::string::npos);
  const std::string svg = to_svg({a});
  EXPECT_EQ(svg.rfind("<svg", 0), 0u);
  EXPECT_NE(svg.find("<polyline"), std::string::npos);
  EXPECT_NE(svg.find("</svg>"), std::string::npos);
}

}  // namespace
}  // namespace bsn::eval
