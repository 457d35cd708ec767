// Every filter on the real BROAD recordings, one fixed parameter set (the defaults) for all trials.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>
#include <string>
#include <vector>

#include "broad_data.hpp"
#include "bsn/eval/evaluation.hpp"

namespace bsn {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

// Mean total RMSE bar per filter, degrees: the mean total RMSE that `bsn eval ../shared/data/broad --filter NAME`
// measures with the defaults, plus 10 %, so a regression of accuracy fails here. A new
// filter must get its bar.
const std::map<std::string, double> kMeanTotalRmseBarDeg = {
    {"complementary", 3.00}, {"seel_ruppin", 2.28},   {"seel_ruppin6", 4.90}, {"madgwick", 3.51},
    {"madgwick6", 4.73},     {"iecf", 3.44},          {"iecf6", 5.16},        {"ekf", 2.67},
    {"mekf", 2.72},          {"mekf_adaptive", 2.68}, {"dlkf", 3.98},
};

// The best filter's mean total and inclination RMSE (seel_ruppin), measured + 10 % as above.
constexpr double kBestTotalBarDeg = 2.28;
constexpr double kBestInclinationBarDeg = 0.67;

// Every filter with its defaults on every shared trial, run once for the tests below.
struct Run {
  eval::TrialResult result;
  std::size_t samples = 0;  ///< of the trial
};
const std::vector<Run>& runs_of_every_filter() {
  static const std::vector<Run> runs = [] {
    std::vector<Run> out;
    for (const auto& f : testing::broad_files()) {
      const io::Recording trial = io::read_broad_hdf5(f.string());
      for (const auto& filter : fusion::filter_names()) {
        out.push_back({eval::run_trial(trial, f.stem().string(), {filter, {}}, filter), trial.size()});
      }
    }
    return out;
  }();
  return runs;
}

std::vector<eval::TrialResult> results_of(const std::vector<Run>& runs) {
  std::vector<eval::TrialResult> out;
  for (const auto& run : runs) out.push_back(run.result);
  return out;
}

TEST(BroadFilters, EveryFilterRunsEveryTrialUnderItsBar) {
  BSN_REQUIRE_BROAD();
  const std::vector<eval::TrialResult> results = results_of(runs_of_every_filter());
  for (const auto& run : runs_of_every_filter()) {
    EXPECT_EQ(run.result.non_finite, 0u) << run.result.filter << " on " << run.result.trial;
    EXPECT_GT(run.result.scored, run.samples / 4) << run.result.filter << " on " << run.result.trial;
  }
  std::printf("%s", eval::to_table(results).c_str());
  for (const auto& m : eval::means_by_filter(results)) {
    const auto bar = kMeanTotalRmseBarDeg.find(m.filter);
    if (bar == kMeanTotalRmseBarDeg.end()) {
      ADD_FAILURE() << "no accuracy bar for filter '" << m.filter << "'; measured mean total RMSE "
                    << m.mean_rmse.total * kDeg << " deg";
      continue;
    }
    EXPECT_LT(m.mean_rmse.total * kDeg, bar->second) << m.filter;
  }
  const auto means = eval::means_by_filter(results);
  const auto best = std::min_element(
      means.begin(), means.end(), [](const auto& a, const auto& b) { return a.mean_rmse.total < b.mean_rmse.total; });
  ASSERT_NE(best, means.end());
  std::printf("best filter: %s, mean total %.2f deg, inclination %.2f deg (target 2.5 / 0.6)\n", best->filter.c_str(),
              best->mean_rmse.total * kDeg, best->mean_rmse.inclination * kDeg);
  EXPECT_LT(best->mean_rmse.total * kDeg, kBestTotalBarDeg);
  EXPECT_LT(best->mean_rmse.inclination * kDeg, kBestInclinationBarDeg);
}

// The rule against heading collapse: no filter's total RMSE on any trial exceeds 3x its mean over the eight, in
// quadrature with what the magnetometer itself gets wrong on that trial: delta, the mean heading of the field it reads,
// seen in the reference's frame, over the scored samples. A filter that uses the magnetometer (a 6D one at its start)
// follows a field that points delta off north, whatever else it does well; only learning the offset removes it, and
// the gyro reveals an offset only through the rotations of the trial (SensorFixedField). delta is 0.0-1.8 deg on six
// trials (the bound within 0.5 deg of 3x the mean), 6.2 deg on trial 31 (the magnet in the room, which the filters
// reject: none of them needs the wider bound there) and 6.2 deg on trial 27, where a phone lying on the sensor adds
// about 1.7 uT fixed to it while it turns by only +-20 deg: in 1.2 uT of noise its gyro test is the same as that of
// the undisturbed translation trials, every 9D filter follows it (6.4-7.3 deg), and seel_ruppin's 6.7 deg is 3.2x its
// mean only because its mean is the lowest (bound 8.8 deg).
double mag_heading_offset_rad(const io::Recording& trial) {
  double c = 0.0, sn = 0.0;
  for (std::size_t i = 0; i < trial.size(); ++i) {
    const auto row = static_cast<Eigen::Index>(i);
    if ((!trial.movement.empty() && trial.movement[i] == 0) || !trial.opt_quat.row(row).allFinite() ||
        !trial.mag.row(row).allFinite()) {
      continue;
    }
    const auto r = trial.opt_quat.row(row);
    const fusion::Vec3 field =
        fusion::Quat(r(0), r(1), r(2), r(3)).normalized() * fusion::Vec3(trial.mag.row(row).transpose());
    const double heading = std::atan2(field.x(), field.y());  // ENU: magnetic north is earth y
    c += std::cos(heading);
    sn += std::sin(heading);
  }
  return std::atan2(sn, c);
}

TEST(BroadFilters, NoTrialExceedsThreeTimesTheFiltersMeanBeyondTheMagnetometersOwnOffset) {
  BSN_REQUIRE_BROAD();
  std::map<std::string, double> offset;
  for (const auto& f : testing::broad_files()) {
    offset[f.stem().string()] = mag_heading_offset_rad(io::read_broad_hdf5(f.string()));
    std::printf("%-34s magnetometer heading offset %+.2f deg\n", f.stem().string().c_str(),
                offset[f.stem().string()] * kDeg);
  }
  const std::vector<eval::TrialResult> results = results_of(runs_of_every_filter());
  for (const auto& m : eval::means_by_filter(results)) {
    double worst_ratio = 0.0;
    for (const auto& r : results) {
      if (r.filter != m.filter) continue;
      const double bound = std::hypot(3.0 * m.mean_rmse.total, offset.at(r.trial));
      worst_ratio = std::max(worst_ratio, r.rmse.total / bound);
      EXPECT_LE(r.rmse.total, bound) << r.filter << " on " << r.trial << ": " << r.rmse.total * kDeg
                                     << " deg against a mean of " << m.mean_rmse.total * kDeg
                                     << " deg and a magnetometer offset of " << offset.at(r.trial) * kDeg << " deg";
    }
    std::printf("%-14s worst trial at %.2f of its bound\n", m.filter.c_str(), worst_ratio);
  }
}

// The 6D filters: the best one's inclination, held at measured + 10 % like the 9D best (VQF 6D's on these trials: 0.61
// deg), and each one's heading drift reported per minute: the least-squares slope of the signed heading error over a
// trial's scored samples, deg/min, its mean magnitude over the trials (the drift a 6D joint accumulates; its heading is
// otherwise only the magnetometer's reading at the start).
constexpr double kBestSixDInclinationBarDeg = 0.67;

double heading_drift_deg_per_min(const io::Recording& trial, const std::string& filter) {
  auto f = fusion::make_filter({filter, {}});
  double n = 0, st = 0, sh = 0, stt = 0, sth = 0;
  for (std::size_t i = 0; i < trial.size(); ++i) {
    f->update(trial.sample(i));
    if (!f->initialised() || (!trial.movement.empty() && trial.movement[i] == 0)) continue;
    const auto r = trial.opt_quat.row(static_cast<Eigen::Index>(i));
    if (!r.allFinite()) continue;
    const fusion::Quat e = f->orientation() * fusion::Quat(r(0), r(1), r(2), r(3)).conjugate();
    const double heading = 2.0 * std::atan(e.z() / e.w()) * kDeg;  // signed, |heading| < 180 deg
    const double t_min = static_cast<double>(trial.time_ns(i)) * 1e-9 / 60.0;
    n += 1;
    st += t_min;
    sh += heading;
    stt += t_min * t_min;
    sth += t_min * heading;
  }
  const double denominator = n * stt - st * st;
  return denominator > 0 ? (n * sth - st * sh) / denominator : 0.0;
}

TEST(BroadFilters, BestSixDFilterHoldsItsInclinationAndEachReportsItsHeadingDrift) {
  BSN_REQUIRE_BROAD();
  const std::vector<eval::TrialResult> results = results_of(runs_of_every_filter());
  double best_inclination = 1e9;
  std::string best;
  for (const auto& m : eval::means_by_filter(results)) {
    const auto info = std::find_if(fusion::filter_registry().begin(), fusion::filter_registry().end(),
                                   [&](const fusion::FilterInfo& i) { return m.filter == i.name; });
    ASSERT_NE(info, fusion::filter_registry().end()) << m.filter;
    if (!info->six_d_only) continue;
    double drift = 0.0;
    for (const auto& f : testing::broad_files()) {
      drift += std::abs(heading_drift_deg_per_min(io::read_broad_hdf5(f.string()), m.filter));
    }
    drift /= static_cast<double>(testing::broad_files().size());
    EXPECT_TRUE(std::isfinite(drift)) << m.filter;
    std::printf("%-14s inclination %.2f deg, heading drift %.2f deg/min (mean |slope| over the trials)\n",
                m.filter.c_str(), m.mean_rmse.inclination * kDeg, drift);
    if (m.mean_rmse.inclination * kDeg < best_inclination) {
      best_inclination = m.mean_rmse.inclination * kDeg;
      best = m.filter;
    }
  }
  ASSERT_FALSE(best.empty()) << "no 6D filter registered";
  EXPECT_LT(best_inclination, kBestSixDInclinationBarDeg) << best;
}

}  // namespace
}  // namespace bsn
