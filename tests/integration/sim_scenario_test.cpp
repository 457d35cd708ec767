// `bsn sim --scenario` as a user runs it: offline to BROAD-layout HDF5 that `bsn eval` scores, and live on DDS.
#include <gtest/gtest.h>

#include <mutex>

#include "bsn/dds/participant.hpp"
#include "bsn/io/recording.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

class SimScenario : public ProcessTest {
 protected:
  std::optional<int> run(const std::string& name, const std::vector<std::string>& args) {
    spawn(name, args);
    return child(name).wait_for(std::chrono::seconds(120));
  }
};

const std::string kScenarios = BSN_SCENARIO_DIR;

TEST_F(SimScenario, OfflineFilesAreBroadLayoutAndScoreWell) {
  const std::string out = (dir() / "out").string();
  ASSERT_TRUE(exited_cleanly(run("sim", {"sim", "--scenario", kScenarios + "/fan_a.yaml", "--out", out, "--ideal"})))
      << read_file(log_path("sim"));
  const io::Recording rec = io::read_broad_hdf5(out + "/imu.hdf5");
  EXPECT_EQ(rec.sampling_rate_hz, 100.0);
  EXPECT_EQ(rec.size(), 7000u);  // 70 s at 100 Hz
  EXPECT_EQ(static_cast<std::size_t>(rec.opt_quat.rows()), rec.size());
  // Exact channels: any filter of the project tracks the truth closely.
  ASSERT_TRUE(exited_cleanly(run("eval", {"eval", out + "/imu.hdf5", "--filter", "seel_ruppin", "--json"})))
      << read_file(log_path("eval"));
  const std::string json = read_file(log_path("eval"));
  const auto pos = json.find("\"total_rmse_deg\": ");
  ASSERT_NE(pos, std::string::npos) << json;
  EXPECT_LT(std::stod(json.substr(pos + 18)), 1.0) << json;
}

TEST_F(SimScenario, LivePublishesTheScenarioSegmentAndItsTruth) {
  const int kDomain = test_domain(9);
  std::mutex mutex;
  std::size_t raw = 0, truth = 0;
  dds::Participant participant({kDomain, "sim scenario test"});
  auto raw_reader = participant.make_reader(dds::kRawTopic, [&](const bsn::RawSample& s, const auto&) {
    std::lock_guard lock(mutex);
    raw += s.node_id() == "imu" ? 1 : 0;
  });
  auto truth_reader = participant.make_reader(dds::kTruthOrientationTopic, [&](const bsn::Orientation& o, const auto&) {
    std::lock_guard lock(mutex);
    truth += o.segment() == "imu" ? 1 : 0;
  });
  spawn("sim", {"sim", "--scenario", kScenarios + "/fan_b.yaml", "--node", "imu", "--speed", "10", "--domain",
                std::to_string(kDomain)});
  EXPECT_TRUE(wait_until(
      [&] {
        std::lock_guard lock(mutex);
        return raw >= 500 && truth >= 500;
      },
      std::chrono::seconds(20)))
      << "raw " << raw << " truth " << truth << "\n"
      << read_file(log_path("sim"));
}

}  // namespace
}  // namespace bsn::integration
