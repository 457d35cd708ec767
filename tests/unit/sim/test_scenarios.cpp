// Every shipped scenario file loads, and each disturbance shows in the field's magnitude or dip (or, for the
// heading changes of Seel & Ruppin, in its heading alone) exactly where the scenario puts it. Scenario file
// validation names file, line and key.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <numbers>
#include <set>

#include "bsn/sim/scenario_file.hpp"

namespace bsn::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

struct FieldIndicators {
  double magnitude_ut, dip_deg, heading_deg;
};

FieldIndicators indicators(const Vec3& b) {
  const MagnitudeDip md = magnitude_and_dip(b);
  return {md.magnitude_ut, md.dip_rad / kDeg, std::atan2(-b.x(), b.y()) / kDeg};
}

struct Expectation {
  std::string file;
  std::string segment;
  std::vector<double> clean_s;      ///< times where the field at the sensor is the clean earth field
  std::vector<double> disturbed_s;  ///< times where the disturbance must show
  double heading_change_deg = 0.0;  ///< != 0: a pure heading change (magnitude and dip unchanged)
  double max_magnitude_change_ut = std::numeric_limits<double>::infinity();
};

const std::vector<Expectation>& expectations() {
  static const std::vector<Expectation> table = {
      {"fan_a", "imu", {1, 10, 30, 50, 69}, {}},
      {"fan_b", "imu", {1, 6.2, 10.2, 14.2, 18.2, 22, 24.9}, {4.3, 8.3, 12.3, 16.3, 20.3}},
      {"fan_c", "imu", {1, 30}, {40, 600, 1199}},
      // Test D: below typical magnitude thresholds (< 2 % of 49 uT), visible in the dip.
      {"fan_d", "imu", {1, 24.9}, {30, 60, 119}, 0.0, 0.02 * 49.0},
      {"fan_e", "imu", {5, 30, 40, 90, 184}, {17, 60, 130}},
      // The lower body's version: the shank sensor is deep in the region, the thigh sensor in its fading top.
      {"fan_e_knee", "shank_l", {5, 30, 40, 90, 184}, {17, 60, 130}},
      {"fan_e_knee", "thigh_l", {5, 30, 40, 90, 184}, {17, 60, 130}},
      {"fan_e_knee", "pelvis", {5, 17, 60, 130}, {}},
      {"seel_ruppin_3_1_weak", "imu", {1, 19.99}, {21, 79}, 50.0},
      {"seel_ruppin_3_1_strong", "imu", {1, 19.99}, {21, 79}, 179.0},
      {"seel_ruppin_3_2", "imu", {1, 19.99}, {21, 79}, 50.0},
      {"mag_calibration_session", "imu", {1, 100, 224}, {}},
      {"nez_slow", "imu", {1, 300, 611}, {}},
      {"nez_intermediate", "imu", {1, 300, 611}, {}},
      {"nez_fast", "imu", {1, 300, 611}, {}},
      {"allan_static_30min", "imu", {1, 900, 1799}, {}},
      {"gait_lower_body", "foot_l", {5, 40}, {21, 23}},
      {"gait_lower_body", "thigh_l", {5, 21, 23}, {}},
      {"gait_alignment", "foot_r", {1, 10, 40}, {}},
      {"gait_session", "foot_r", {1, 10, 40, 100}, {}},
      {"reach_upper_body", "hand_r", {}, {1, 30}},
      {"reach_upper_body", "hand_l", {1, 30}, {}},
      {"hinge_chain_disturbed", "base", {1, 30, 59}, {}},
      {"hinge_chain_disturbed", "link_1", {}, {1, 30, 59}},
      {"hinge_chain_disturbed", "link_2", {}, {1, 30, 59}},
  };
  return table;
}

std::string path_of(const std::string& name) { return std::string(BSN_SCENARIO_DIR) + "/" + name + ".yaml"; }

TEST(SimScenarios, EveryShippedScenarioLoadsAndIsChecked) {
  std::set<std::string> checked;
  for (const Expectation& e : expectations()) checked.insert(e.file);
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(BSN_SCENARIO_DIR)) {
    if (entry.path().extension() != ".yaml") continue;
    ++files;
    const std::string stem = entry.path().stem().string();
    ScenarioSpec spec;
    ASSERT_NO_THROW(spec = load_scenario(entry.path().string())) << stem;
    EXPECT_EQ(spec.name, stem);
    EXPECT_FALSE(spec.description.empty()) << stem;
    EXPECT_NO_THROW(ScenarioRunner(spec, {}, false)) << stem;
    EXPECT_TRUE(checked.count(stem)) << stem << " has no disturbance expectations in this test";
  }
  EXPECT_EQ(files, 19);
}

TEST(SimScenarios, DisturbancesShowWhereTheScenarioPutsThem) {
  for (const Expectation& e : expectations()) {
    SCOPED_TRACE(e.file + " / " + e.segment);
    const ScenarioSpec spec = load_scenario(path_of(e.file));
    MagneticEnvironment earth_only;
    earth_only.magnitude_ut = spec.magnetic.magnitude_ut;
    earth_only.dip_deg = spec.magnetic.dip_deg;
    const FieldIndicators clean = indicators(earth_only.earth_field(0.0));
    // What an ideal magnetometer reads (R^T field + attached magnets, see SimMagnetic.IdealMagnetometer...),
    // turned back into the earth frame.
    const Body body = build_body(spec);
    const std::size_t segment = body.find(e.segment).value();
    std::vector<SegmentState> states;
    auto field_at = [&](double t) {
      body.evaluate(t, states);
      const SegmentState& s = states[segment];
      return indicators(s.q_sensor * spec.magnetic.sensor_field(segment, s.position, s.q_sensor, t));
    };
    std::vector<std::pair<double, bool>> times;
    for (double t : e.clean_s) times.emplace_back(t, false);
    for (double t : e.disturbed_s) times.emplace_back(t, true);
    for (const auto& [t, disturbed] : times) {
      const FieldIndicators f = field_at(t);
      const double d_mag = std::abs(f.magnitude_ut - clean.magnitude_ut), d_dip = std::abs(f.dip_deg - clean.dip_deg);
      const double d_heading = std::remainder(f.heading_deg - clean.heading_deg, 360.0);
      if (!disturbed) {
        EXPECT_LT(d_mag, 0.1) << "t=" << t;
        EXPECT_LT(d_dip, 0.1) << "t=" << t;
        EXPECT_LT(std::abs(d_heading), 0.1) << "t=" << t;
      } else if (e.heading_change_deg != 0.0) {
        EXPECT_LT(d_mag, 1e-9) << "t=" << t;
        EXPECT_LT(d_dip, 1e-9) << "t=" << t;
        EXPECT_NEAR(d_heading, e.heading_change_deg, 1e-6) << "t=" << t;
      } else {
        // Fan et al. plot magnitude and dip as the indicators of a disturbance.
        EXPECT_TRUE(d_mag > 1.0 || d_dip > 0.5) << "t=" << t << " |B| change " << d_mag << " uT, dip change " << d_dip;
        EXPECT_LT(d_mag, e.max_magnitude_change_ut) << "t=" << t;
      }
    }
  }
}

TEST(SimScenarios, NezScenariosUseTheirIntensityAndOpalNoise) {
  const ScenarioSpec fast = load_scenario(path_of("nez_fast"));
  ASSERT_TRUE(fast.free_motion.random.has_value());
  EXPECT_NEAR(fast.free_motion.random->angular_rate_rms_rad_s, std::hypot(700.0, 400.0) * kDeg, 1e-9);
  EXPECT_EQ(fast.rate_hz, 128.0);
  EXPECT_EQ(fast.sensors.gyr.white_density, 1e-3);
  EXPECT_EQ(fast.movement.size(), 1u);
}

TEST(SimScenarios, CalibrationSessionHasThirtyStaticPosesOfAtLeastFiveSeconds) {
  const ScenarioSpec spec = load_scenario(path_of("mag_calibration_session"));
  ScenarioRunner runner(spec, {}, true);
  std::vector<ScenarioSample> out;
  int poses = 0;
  double still_for = 0.0;
  while (runner.next(out)) {
    if (out[0].sample.gyr.norm() < 1e-9) {
      still_for += 1.0 / spec.rate_hz;
    } else {
      if (still_for >= 5.0) ++poses;
      still_for = 0.0;
    }
  }
  if (still_for >= 5.0) ++poses;
  EXPECT_EQ(poses, 30);
}

TEST(SimScenarios, ValidationNamesFileLineAndKey) {
  auto message = [](const std::string& text) {
    try {
      parse_scenario(text, "s.yaml");
    } catch (const ScenarioError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(message("duration_s: 10\nbody:\n  kind: free\n  spin: 3\n"),
            "s.yaml:4: unknown key 'spin' in body (known keys: kind, segment, pose, random, rotations, moves, "
            "pose_sequence, gait, reaching, mounting)");
  EXPECT_NE(message("duration_s: 10\nmagnetic:\n  dipoles:\n    - {position_m: [0, 0, 1], moment: [1, 0, 0]}\n")
                .find("s.yaml:4: unknown key 'moment' in a dipole"),
            std::string::npos);
  EXPECT_NE(message("duration_s: 10\nsensors: {preset: opal, gyr: {white_densty: 1}}\n")
                .find("s.yaml:2: unknown key 'white_densty'"),
            std::string::npos);
  EXPECT_NE(message("rate_hz: 100\n").find("s.yaml:1: the scenario needs duration_s"), std::string::npos);
  EXPECT_NE(message("duration_s: -1\n").find("s.yaml:1: duration_s must be > 0"), std::string::npos);
  EXPECT_NE(message("duration_s: 1\nsensors: perfect\n").find("s.yaml:2: unknown sensor preset 'perfect'"),
            std::string::npos);
  EXPECT_NE(message("duration_s: 1\nbody: {kind: free, gait: {}}\n").find("'gait' needs body kind lower_body"),
            std::string::npos);
  EXPECT_NE(message("duration_s: 1\nbody: {kind: upper_body}\nmagnetic:\n  attached_magnets:\n    - {segment: foot_l, "
                    "offset_m: [0, 0.02, 0], moment_am2: [0, 0.01, 0]}\n")
                .find("s.yaml:5: no segment 'foot_l'"),
            std::string::npos);
  EXPECT_NE(
      message("duration_s: 1\nbody:\n  kind: lower_body\n  gait: {speed_m_s: 1, active: [{from_s: 1, to_s: 2}]}\n")
          .find("s.yaml:4: active windows need speed_m_s: 0"),
      std::string::npos);
  EXPECT_NE(message("duration_s: 1\nbody:\n  kind: lower_body\n  moves: [{by_m: [1, 0, 0], start_s: 0}]\n")
                .find("s.yaml:4: 'moves' of a lower body needs a gait"),
            std::string::npos);
  EXPECT_NE(message("duration_s: 1\nbody:\n  kind: upper_body\n  moves: [{by_m: [1, 0, 0], start_s: 0}]\n")
                .find("'moves' needs body kind free or lower_body"),
            std::string::npos);
  EXPECT_NE(message("duration_s: 1\nmagnetic: {dip_deg: [1, 2}\n").find("s.yaml:"), std::string::npos);
  EXPECT_NE(message("duration_s: nan\n").find("duration_s must be"), std::string::npos);
  EXPECT_THROW(load_scenario("/nonexistent/x.yaml"), ScenarioError);
}

}  // namespace
}  // namespace bsn::sim
