// The fusion service applies a node's calibration file (body-model key `calibration:`) to every raw sample:
// a magnetometer with a hard-iron offset spoils the heading, and its calibration restores it.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <mutex>
#include <numbers>
#include <thread>

#include "bsn/dds/conversions.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/fusion/orientation_error.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

// A sensor turned by hand in a clean field; its magnetometer reads the field plus a hard-iron offset of
// |(25, -15, 10)| = 31 uT, which is 63 % of the 49 uT earth field. Every other sensor error is off.
constexpr const char* kScenario = R"(name: hard_iron
duration_s: 40
rate_hz: 100
seed: 3
sensors:
  preset: ideal
  mag: {hard_iron: [25, -15, 10]}
body:
  kind: free
  segment: imu
  pose: {position_m: [0, 0, 1]}
  random:
    angular_rate_rms_deg_s: 40
    acceleration_rms_m_s2: 0.2
    frequency_hz: [0.2, 1.0]
magnetic: {magnitude_ut: 49, dip_deg: 64}
)";

class CalibrationApply : public ProcessTest {
 protected:
  // Runs the scenario live into `bsn fusion` with `body_yaml`; returns the RMS heading error (deg) over the
  // estimates after 10 s of scenario time, matched to the truth by timestamp.
  double heading_rmse_deg(int domain, const std::string& name, const std::string& body_yaml) {
    write_file(dir() / "scenario.yaml", kScenario);
    write_file(dir() / (name + ".yaml"), body_yaml);
    std::mutex mutex;
    std::map<std::uint64_t, fusion::Quat> truth, estimate;
    dds::Participant participant({domain, "calibration apply test"});
    auto est_reader = participant.make_reader(dds::kOrientationTopic, [&](const bsn::Orientation& o, const auto&) {
      std::lock_guard lock(mutex);
      estimate[o.timestamp_ns()] = dds::to_quat(o.quat());
    });
    auto truth_reader =
        participant.make_reader(dds::kTruthOrientationTopic, [&](const bsn::Orientation& o, const auto&) {
          std::lock_guard lock(mutex);
          truth[o.timestamp_ns()] = dds::to_quat(o.quat());
        });
    const std::string d = std::to_string(domain);
    spawn(name + "-fusion", {"fusion", "--domain", d, "--body", (dir() / (name + ".yaml")).string()});
    // Let the fusion service match before the scenario starts, so it sees the sensor from its first sample.
    std::this_thread::sleep_for(std::chrono::seconds(2));
    spawn(name + "-sim",
          {"sim", "--scenario", (dir() / "scenario.yaml").string(), "--node", "imu", "--speed", "4", "--domain", d});
    const auto st = child(name + "-sim").wait_for(std::chrono::seconds(40));
    EXPECT_TRUE(exited_cleanly(st)) << describe_status(st) << read_file(log_path(name + "-sim"));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    std::lock_guard lock(mutex);
    fusion::RmsErrorAccumulator acc;
    for (const auto& [t, q] : estimate) {
      if (t < 10'000'000'000ull) continue;
      if (auto it = truth.find(t); it != truth.end()) acc.add(fusion::error_angles(q, it->second));
    }
    EXPECT_GT(acc.count(), 2000u) << name << ": estimates matched to truth after 10 s";
    return acc.rms().heading * kDeg;
  }
};

TEST_F(CalibrationApply, HardIronCalibrationRestoresHeading) {
  write_file(dir() / "imu.calib.yaml",
             "node: imu\nmagnetometer:\n  bias: [25, -15, 10]\n"
             "  transform: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n");
  const double raw = heading_rmse_deg(test_domain(10), "uncalibrated", "segments:\n  - name: imu\n");
  const double calibrated =
      heading_rmse_deg(test_domain(11), "calibrated", "segments:\n  - name: imu\n    calibration: imu.calib.yaml\n");
  std::printf("[ measure  ] heading RMSE: %.2f deg without calibration, %.2f deg with\n", raw, calibrated);
  // Exact channels once the offset is removed: the live accuracy bound of the project (2 deg) holds. With an
  // offset of 63 % of the field the heading is off by tens of degrees.
  EXPECT_LT(calibrated, 2.0);
  EXPECT_GT(raw, 10.0);
}

}  // namespace
}  // namespace bsn::integration
