// Simulated regression cases: a clean (undisturbed) earth field, a consumer MEMS sensor whose
// magnetometer is calibrated (no hard or soft iron left) but whose gyro has its scale and misalignment errors, and
// whose magnetometer lags the gyro by one sample and has its own bandwidth. Two kinds of motion that made filters
// reject a clean field, or lose the heading, on real recordings:
//   - fast rotation up to 1000 deg/s: the magnetometer must be accepted on >= 95 % of the samples;
//   - translation with external accelerations up to 1 g: the heading error must stay below 2 deg.
// Every filter that uses the magnetometer runs both (6D-only filters have no heading to keep). A third case, for
// every filter, is sustained strong acceleration (SustainedMotion, at the end): the tilt may never collapse.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <numbers>
#include <ostream>
#include <string>
#include <vector>

#include "bsn/fusion/orientation_error.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/rotation.hpp"
#include "bsn/sim/scenario.hpp"
#include "bsn/sim/sensor_model.hpp"
#include "filter_test_util.hpp"

namespace bsn::fusion {

void PrintTo(const FilterInfo& info, std::ostream* os);

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
// Both cases start with the sensor still for kRestS, as a recording does: a consumer gyro's bias of 0.5 deg/s is
// learned at rest in seconds, while in motion it takes minutes and meanwhile turns the heading by bias * tau_mag
// (3 deg at tau_mag 4 s): that would measure the start, not the motion. Scoring starts with the motion.
constexpr double kRestS = 8.0;
constexpr double kStartupS = kRestS;

struct RunFigures {
  double mag_accepted_fraction = 0.0;  ///< of the scored samples with a magnetometer reading
  double max_heading_error = 0.0;      ///< rad, scored samples
  double rms_heading_error = 0.0;      ///< rad, scored samples (BROAD's metric)
  double max_inclination_error = 0.0;  ///< rad
  double max_rate = 0.0;               ///< |gyr| seen, rad/s
  double max_external_acc = 0.0;       ///< | |acc| - g | seen, m/s^2 (a lower bound of |a_ext|)
};

/// withhold_mag: the magnetometer readings after the first sample are not given to the filter at all (the rejection
/// of a filter that has no rejection of its own).
RunFigures run(const FilterInfo& info, const sim::ScenarioSpec& spec,
               const std::vector<std::pair<std::string, double>>& parameters = {}, double startup_s = kStartupS,
               bool withhold_mag = false) {
  auto filter = info.make({info.name, parameters});
  sim::ScenarioRunner runner(spec, {}, false);
  std::vector<sim::ScenarioSample> out;
  RunFigures f;
  double scored_mag = 0.0, accepted_mag = 0.0, heading_sq = 0.0, scored = 0.0;
  bool first = true;
  while (runner.next(out)) {
    sim::ScenarioSample s = out.front();
    if (withhold_mag && !first) s.sample.has_mag = false;
    first = false;
    filter->update(s.sample);
    if (static_cast<double>(s.sample.timestamp_ns) * 1e-9 < startup_s) continue;
    f.max_rate = std::max(f.max_rate, s.sample.gyr.norm());
    f.max_external_acc = std::max(f.max_external_acc, std::abs(s.sample.acc.norm() - kGravity));
    const ErrorAngles e = error_angles(filter->orientation(), s.truth);
    f.max_heading_error = std::max(f.max_heading_error, e.heading);
    heading_sq += e.heading * e.heading;
    scored += 1.0;
    f.max_inclination_error = std::max(f.max_inclination_error, e.inclination);
    if (s.sample.has_mag) {
      scored_mag += 1.0;
      if (!filter->flags().mag_rejected) accepted_mag += 1.0;
    }
  }
  f.mag_accepted_fraction = scored_mag > 0.0 ? accepted_mag / scored_mag : 0.0;
  f.rms_heading_error = scored > 0.0 ? std::sqrt(heading_sq / scored) : 0.0;
  return f;
}

// A free body still for kRestS, then turning in every direction: random harmonics of 0.5-2 Hz with an RMS rate of
// 400 deg/s, so that the peaks reach about 1000 deg/s (the fastest BROAD trials reach 900 deg/s).
sim::ScenarioSpec fast_rotation() {
  sim::ScenarioSpec spec;
  spec.name = "fast rotation, clean field";
  spec.duration_s = 60.0;
  spec.seed = 12;
  sim::RandomMotion m;
  m.angular_rate_rms_rad_s = 400.0 * kDeg;
  m.min_frequency_hz = 0.5;
  m.max_frequency_hz = 2.0;
  m.active = {{kRestS - 1.0, 1e9, 1.0}};  // ramped in over 1 s
  m.seed = 12;
  spec.free_motion.random = m;
  spec.sensors = filter_test::consumer_mems_lagging_magnetometer();
  return spec;
}

// A free body carried back and forth by 1.5 m in 0.94 s each way along changing horizontal and vertical
// directions (minimum jerk: peak acceleration 5.77 d / T^2 = 9.8 m/s^2, 1 g), a 1 s pause after each return, turning
// slowly meanwhile (RMS 30 deg/s), after kRestS of rest.
sim::ScenarioSpec translation(std::uint64_t seed = 13, double rest_s = kRestS) {
  sim::ScenarioSpec spec;
  spec.name = "translation, clean field";
  spec.duration_s = 60.0;
  spec.seed = seed;
  sim::RandomMotion m;
  m.angular_rate_rms_rad_s = 30.0 * kDeg;
  m.min_frequency_hz = 0.1;
  m.max_frequency_hz = 0.5;
  m.active = {{rest_s - 1.0, 1e9, 1.0}};
  m.seed = seed;
  spec.free_motion.random = m;
  const Vec3 directions[] = {Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0.6, 0.6, 0.53), Vec3(-0.7, 0.3, 0.65)};
  constexpr double kDistance = 1.5, kDuration = 0.94, kPause = 1.0;
  int i = 0;
  for (double t = rest_s; t + 2 * kDuration < spec.duration_s; t += 2 * kDuration + kPause, ++i) {
    const Vec3 d = directions[i % 4].normalized() * kDistance;
    spec.free_motion.moves.push_back({d, t, kDuration});
    spec.free_motion.moves.push_back({-d, t + kDuration, kDuration});
  }
  spec.sensors = filter_test::consumer_mems_lagging_magnetometer();
  return spec;
}

class CleanFieldMotion : public ::testing::TestWithParam<FilterInfo> {};

bool is_one_of(const FilterInfo& info, std::initializer_list<const char*> names) {
  for (const char* n : names) {
    if (std::string(info.name) == n) return true;
  }
  return false;
}

// Plain strapdown integration of the raw gyro from the true start orientation: what is left when nothing corrects
// the gyro (its full bias, scale and misalignment errors), the bound of the no-collapse cases below.
class GyroIntegral {
 public:
  /// Advances to the sample (the first one sets the truth) and returns the integrated orientation.
  const Quat& advance(const sim::ScenarioSample& s) {
    if (!started_) {
      q_ = s.truth;
      started_ = true;
    } else {
      const double dt = static_cast<double>(s.sample.timestamp_ns - last_ns_) * 1e-9;
      q_ = (q_ * exp_rotation_vector(s.sample.gyr * dt)).normalized();
    }
    last_ns_ = s.sample.timestamp_ns;
    return q_;
  }

 private:
  Quat q_ = Quat::Identity();
  bool started_ = false;
  std::uint64_t last_ns_ = 0;
};

// The filters whose rejection can be forced on by its thresholds (the registry's rejects_magnetometer), with those
// parameters (a band of 1e-6 that any noise leaves; no new reference, no reduced-gain acceptance).
std::vector<std::pair<std::string, double>> always_rejecting(const FilterInfo& info) {
  if (info.rejects_magnetometer) {
    return {{"mag_norm_enter", 1e-6},
            {"mag_norm_leave", 1e-6},
            {"mag_reference_tau_s", 1e6},
            {"mag_max_rejection_s", 1e6},
            {"mag_accept_after_s", 1e6}};
  }
  return {};
}

TEST_P(CleanFieldMotion, FastRotationKeepsTheMagnetometer) {
  const RunFigures f = run(GetParam(), fast_rotation());
  ASSERT_GT(f.max_rate, 800.0 * kDeg);  // the case is as fast as it claims
  ASSERT_LT(f.max_rate, 1200.0 * kDeg);
  EXPECT_GE(f.mag_accepted_fraction, 0.95) << "max heading error " << f.max_heading_error / kDeg << " deg";
  RecordProperty("mag_accepted_percent", std::to_string(100.0 * f.mag_accepted_fraction));
  if (is_one_of(GetParam(), {"seel_ruppin"})) {
    // The case needs the magnetometer's own delay in the tolerance (mag_latency_s; one sample of lag alone is not
    // enough with seel_ruppin's 8 deg dip thresholds): without it a clean field is rejected on more than 5 %.
    const RunFigures without = run(GetParam(), fast_rotation(), {{"mag_latency_s", 0.0}});
    EXPECT_LT(without.mag_accepted_fraction, 0.95);
    RecordProperty("mag_accepted_percent_without_lag_tolerance", std::to_string(100.0 * without.mag_accepted_fraction));
  }
}

// The heading error is BROAD's (the heading part of the error quaternion), RMS over the scored samples as every
// target figure; its worst single sample is reported. Accelerations of 1 g tilt every filter's inclination by
// several degrees for tenths of a second, which leaks into the heading through the horizontal projection of the
// field; 2 deg RMS is the target (the failure it fixes is heading collapse: 150 deg).
TEST_P(CleanFieldMotion, TranslationKeepsTheHeading) {
  const RunFigures f = run(GetParam(), translation());
  ASSERT_GT(f.max_external_acc, 0.8 * kGravity);  // accelerations near 1 g, as the case claims
  RecordProperty("rms_heading_deg", std::to_string(f.rms_heading_error / kDeg));
  RecordProperty("max_heading_deg", std::to_string(f.max_heading_error / kDeg));
  EXPECT_LT(f.rms_heading_error, 2.0 * kDeg)
      << "magnetometer accepted on " << 100.0 * f.mag_accepted_fraction << " %, max heading error "
      << f.max_heading_error / kDeg << " deg, max inclination error " << f.max_inclination_error / kDeg << " deg";
}

// The worst heading error of the gyro's own integral over the scored part of `spec` (from startup_s on).
double gyro_integral_worst_heading(const sim::ScenarioSpec& spec, double startup_s) {
  sim::ScenarioRunner runner(spec, {}, false);
  std::vector<sim::ScenarioSample> out;
  GyroIntegral integral;
  double worst = 0.0;
  while (runner.next(out)) {
    const sim::ScenarioSample& s = out.front();
    const Quat& q = integral.advance(s);
    if (static_cast<double>(s.sample.timestamp_ns) * 1e-9 >= startup_s) {
      worst = std::max(worst, error_angles(q, s.truth).heading);
    }
  }
  return worst;
}

// Six motion and noise realisations: a collapse through the bias shows on some and not on others (ekf before its
// rest_bias_update: seeds 15 and 16 over the bound by 17 and 24 deg, while seed 13 passed by 4.6 deg).
// A filter that never rejects the magnetometer (madgwick) runs the same case with the readings withheld after the
// first: its heading then rests on the gyro alone just as a rejecting filter's does.
void expect_heading_within_the_gyro_integral(const FilterInfo& info, double rest_s) {
  const auto parameters = always_rejecting(info);
  for (std::uint64_t seed = 13; seed <= 18; ++seed) {
    const sim::ScenarioSpec spec = translation(seed, rest_s);
    const RunFigures f = run(info, spec, parameters, rest_s, parameters.empty());
    // The rejection was forced (seel_ruppin started in motion takes the field while it learns its reference: 4 %).
    EXPECT_LT(f.mag_accepted_fraction, 0.05) << "seed " << seed;
    const double worst = gyro_integral_worst_heading(spec, rest_s);
    if (seed == 13) {
      ::testing::Test::RecordProperty("max_heading_deg", std::to_string(f.max_heading_error / kDeg));
      ::testing::Test::RecordProperty("gyro_integral_max_heading_deg", std::to_string(worst / kDeg));
    }
    EXPECT_LT(f.max_heading_error, worst + 2.0 * kDeg)
        << "seed " << seed << ", " << rest_s << " s of rest first: the gyro integral alone errs " << worst / kDeg
        << " deg";
  }
}

// No heading collapse: with the magnetometer rejected throughout (forced by the thresholds), the heading may only
// degrade as the gyro's own integral does. The reference is plain strapdown integration of the raw gyro from the
// true start orientation: it carries the full bias, scale and misalignment errors; a filter may do better (bias
// estimated at rest) but not worse than that plus 2 deg (what the tilt errors of 1 g accelerations leak into the
// heading, see TranslationKeepsTheHeading).
TEST_P(CleanFieldMotion, LongRejectionDegradesTheHeadingLikeGyroDrift) {
  expect_heading_within_the_gyro_integral(GetParam(), kRestS);
}

// The same started after 1 s of rest only, as when a service starts while the person already moves: the gyro bias
// is not yet known, and a filter must not learn a wrong one from the accelerations either. Two filters exceeded the
// bound: dlkf by 13-23 deg, before its field vector turned with the accelerometer's correction while the
// magnetometer is out, and ekf on five of the six seeds (up to 34 deg against 13 deg of gyro drift), before its
// accelerometer-alone update left the bias alone.
TEST_P(CleanFieldMotion, LongRejectionStartedInMotionDegradesTheHeadingLikeGyroDrift) {
  expect_heading_within_the_gyro_integral(GetParam(), 1.0);
}

std::vector<FilterInfo> nine_d_filters() {
  std::vector<FilterInfo> out;
  for (const FilterInfo& f : filter_registry()) {
    if (!f.six_d_only) out.push_back(f);
  }
  return out;
}

INSTANTIATE_TEST_SUITE_P(NineDFilters, CleanFieldMotion, ::testing::ValuesIn(nine_d_filters()),
                         [](const ::testing::TestParamInfo<FilterInfo>& info) { return std::string(info.param.name); });

// Sustained strong acceleration: Nez et al. 2018's fast intensity (|a| 4 +- 2 g, |w| 360 +- 220 deg/s, their Table 1)
// for 10 minutes with their Opal-like sensor in a clean field, after 10 s at rest, on three motion seeds. The
// acceleration of a sustained motion averages out over time (its velocity stays bounded) while gravity does not, so
// a filter must go on correcting the tilt even when no single reading is near g: its inclination error may never be
// worse than the gyro's own integral from the true start (no collapse, at worst gyro drift; the integral errs 16.5 /
// 33.0 / 9.8 deg RMS). A filter that skips the accelerometer beyond a threshold falls below that: complementary
// did with its former 3 m/s^2 (32.2 / 54.8 / 21.3 deg), because the few readings near g in such motion are not
// gravity either and nothing else corrects them. So did dlkf, which skips its accelerometer beyond 2 m/s^2 (24 / 52 /
// 14 deg), until it took the specific force low-passed in its earth frame while the motion stays strong (6.7 / 9.0 /
// 4.6 deg). Every filter runs it, the 6D ones too.
class SustainedMotion : public ::testing::TestWithParam<FilterInfo> {};

TEST_P(SustainedMotion, StrongAccelerationNeverTiltsWorseThanTheGyroIntegral) {
  for (const std::uint64_t seed : {9, 10, 12}) {
    const sim::ScenarioSpec spec =
        filter_test::nez_random_motion(sim::Intensity::kFast, seed, 610.0, 1e9, *sim::sensor_preset("opal"));
    auto filter = GetParam().make({GetParam().name, {}});
    sim::ScenarioRunner runner(spec, {}, false);
    std::vector<sim::ScenarioSample> out;
    GyroIntegral integral;
    double filter_sq = 0.0, integral_sq = 0.0, scored = 0.0;
    while (runner.next(out)) {
      const sim::ScenarioSample& s = out.front();
      filter->update(s.sample);
      const Quat& q_integral = integral.advance(s);
      if (static_cast<double>(s.sample.timestamp_ns) * 1e-9 < 10.0) continue;
      filter_sq += std::pow(error_angles(filter->orientation(), s.truth).inclination, 2);
      integral_sq += std::pow(error_angles(q_integral, s.truth).inclination, 2);
      scored += 1.0;
    }
    const double filter_rms = std::sqrt(filter_sq / scored), integral_rms = std::sqrt(integral_sq / scored);
    EXPECT_LT(filter_rms, integral_rms) << "seed " << seed << ": inclination RMS " << filter_rms / kDeg
                                        << " deg, the gyro integral " << integral_rms / kDeg << " deg";
  }
}

INSTANTIATE_TEST_SUITE_P(AllFilters, SustainedMotion,
                         ::testing::ValuesIn(filter_registry().begin(), filter_registry().end()),
                         [](const ::testing::TestParamInfo<FilterInfo>& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace bsn::fusion
