// Named anatomical joint angles end to end: two `bsn sim` nodes of the walking lower body, the second started only
// after the first publishes, on one common start time, and a `bsn fusion`. The nodes' samples carry the same
// sensor time for the same scenario instant; bsn/joint_angles and the simulator's bsn/truth/joint_angles carry the
// knee's anatomy and angle names.
#include <gtest/gtest.h>

#include <cmath>
#include <ctime>
#include <map>
#include <mutex>
#include <numbers>
#include <sstream>

#include "bsn/dds/participant.hpp"
#include "bsn/sim/scenario.hpp"
#include "bsn/sim/scenario_file.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

class JointAngles : public ProcessTest {};

struct Seen {
  std::mutex mutex;
  std::map<std::string, std::map<std::uint64_t, std::uint64_t>> raw_time;  ///< node -> seq -> timestamp
  std::size_t truth = 0, estimate = 0;
  bsn::JointAngles last_truth, last_estimate;
};

TEST_F(JointAngles, CommonStartAndNamedAnglesOfTheSimulatorAndTheFusion) {
  const int domain = test_domain(60);
  const std::string d = std::to_string(domain);
  Seen seen;
  dds::Participant participant({domain, "joint angles test"});
  auto raw = participant.make_reader(dds::kRawTopic, [&](const bsn::RawSample& s, const auto&) {
    std::lock_guard lock(seen.mutex);
    seen.raw_time[s.node_id()][s.seq()] = s.timestamp_ns();
  });
  auto truth = participant.make_reader(dds::kTruthJointAnglesTopic, [&](const bsn::JointAngles& j, const auto&) {
    std::lock_guard lock(seen.mutex);
    if (j.joint() != "knee_l") return;
    ++seen.truth;
    seen.last_truth = j;
  });
  auto estimate = participant.make_reader(dds::kJointAnglesTopic, [&](const bsn::JointAngles& j, const auto&) {
    std::lock_guard lock(seen.mutex);
    if (j.joint() != "knee_l") return;
    ++seen.estimate;
    seen.last_estimate = j;
  });
  write_file(dir() / "body.yaml",
             "segments:\n  - name: thigh_l\n  - name: shank_l\n    parent: thigh_l\n    joint: knee_l\n");
  spawn("fusion", {"fusion", "--domain", d, "--body", (dir() / "body.yaml").string()});
  const std::string start_at = std::to_string(std::time(nullptr) + 2);
  const std::string scenario = std::string(BSN_SCENARIO_DIR) + "/gait_lower_body.yaml";
  auto sim = [&](const std::string& node) {
    spawn("sim-" + node, {"sim", "--scenario", scenario, "--node", node, "--domain", d, "--start-at", start_at});
  };
  sim("thigh_l");
  // The shank's node starts late, after the thigh's publishes: it must join the body's time, not start its own.
  ASSERT_TRUE(wait_until(
      [&] {
        std::lock_guard lock(seen.mutex);
        return seen.raw_time["thigh_l"].size() >= 50;
      },
      std::chrono::seconds(30)))
      << read_file(log_path("sim-thigh_l"));
  sim("shank_l");
  ASSERT_TRUE(wait_until(
      [&] {
        std::lock_guard lock(seen.mutex);
        return seen.raw_time["shank_l"].size() >= 200 && seen.truth >= 100 && seen.estimate >= 100;
      },
      std::chrono::seconds(45)))
      << read_file(log_path("sim-shank_l")) << read_file(log_path("fusion"));

  std::lock_guard lock(seen.mutex);
  // The same sequence number is the same scenario instant on both nodes: their sensor times agree to the sampling
  // jitter of the scenario's sensors (20 us SD) and the conversion of the common Unix start to each process's
  // monotonic clock (microseconds). 2 ms is 10 % of a sample period and far below the start skew of the nodes
  // (the shank started at least 0.5 s after the thigh).
  std::size_t common = 0;
  std::int64_t worst_ns = 0;
  for (const auto& [seq, t_shank] : seen.raw_time["shank_l"]) {
    const auto it = seen.raw_time["thigh_l"].find(seq);
    if (it == seen.raw_time["thigh_l"].end()) continue;
    ++common;
    worst_ns = std::max(worst_ns, std::abs(static_cast<std::int64_t>(t_shank - it->second)));
  }
  EXPECT_GE(common, 100u);
  EXPECT_LT(worst_ns, 2'000'000) << "the two nodes' sensor times differ for the same scenario sample";
  // Both carry the knee's convention and names.
  for (const bsn::JointAngles* j : {&seen.last_truth, &seen.last_estimate}) {
    EXPECT_EQ(j->anatomy(), "knee");
    EXPECT_EQ(j->side(), "left");
    ASSERT_EQ(j->anatomical_names().size(), 3u);
    EXPECT_EQ(j->anatomical_names()[0], "flexion_extension");
    EXPECT_EQ(j->anatomical_names()[2], "internal_external_rotation");
  }
  EXPECT_TRUE(seen.last_truth.flags() & bsn::FLAG_SEGMENT_FRAME) << "the truth relates segment frames";
  EXPECT_FALSE(seen.last_estimate.flags() & bsn::FLAG_SEGMENT_FRAME) << "no alignment was given to the fusion";
}

TEST_F(JointAngles, KinematicHeadingModeShowsOnTheWire) {
  // A body file asks for `heading: kinematic` on the knee: bsn/joint_angles flags it and carries the estimated
  // offset and its observability.
  const int domain = test_domain(61);
  const std::string d = std::to_string(domain);
  std::mutex mutex;
  std::size_t estimates = 0;
  bsn::JointAngles last;
  dds::Participant participant({domain, "kinematic heading test"});
  auto estimate = participant.make_reader(dds::kJointAnglesTopic, [&](const bsn::JointAngles& j, const auto&) {
    std::lock_guard lock(mutex);
    if (j.joint() != "knee_l") return;
    ++estimates;
    last = j;
  });
  // The hinge axis is the segment frames' Z: the sensors' mountings (the scenario straps them on at random) must be
  // known, here exactly as after a perfect alignment.
  const std::string scenario = std::string(BSN_SCENARIO_DIR) + "/gait_lower_body.yaml";
  const sim::Body body = sim::build_body(sim::load_scenario(scenario));
  auto mounting = [&](const char* segment) {
    const fusion::Quat q = sim::true_sensor_to_segment(body.segment(*body.find(segment)));
    std::ostringstream out;
    out.precision(17);
    out << "    sensor_to_segment: [" << q.w() << ", " << q.x() << ", " << q.y() << ", " << q.z() << "]\n";
    return out.str();
  };
  write_file(dir() / "body.yaml", "segments:\n  - name: thigh_l\n" + mounting("thigh_l") +
                                      "  - name: shank_l\n    parent: thigh_l\n    joint: knee_l\n" +
                                      mounting("shank_l") + "    heading: kinematic\n");
  spawn("fusion", {"fusion", "--domain", d, "--body", (dir() / "body.yaml").string()});
  const std::string start_at = std::to_string(std::time(nullptr) + 2);
  for (const char* node : {"thigh_l", "shank_l"})
    spawn(std::string("sim-") + node,
          {"sim", "--scenario", scenario, "--node", node, "--domain", d, "--start-at", start_at});
  // 1000 joint samples: 10 s of walking. The filters start in motion and take some seconds to converge (their
  // inclinations too, which the hinge constraint relies on); then ten windows of the estimator.
  ASSERT_TRUE(wait_until(
      [&] {
        std::lock_guard lock(mutex);
        return estimates >= 1000;
      },
      std::chrono::seconds(50)))
      << read_file(log_path("sim-shank_l")) << read_file(log_path("fusion"));
  // bsn echo shows what the mode did.
  spawn("echo", {"echo", "bsn/joint_angles", "--count", "1", "--timeout", "20", "--domain", d});
  EXPECT_EQ(exit_code(child("echo").wait_for(std::chrono::seconds(30))), 0) << read_file(log_path("echo"));
  const std::string echoed = read_file(log_path("echo"));
  EXPECT_NE(echoed.find(" heading_offset="), std::string::npos) << echoed;
  EXPECT_NE(echoed.find("heading_kinematic"), std::string::npos) << echoed;
  std::lock_guard lock(mutex);
  EXPECT_TRUE(last.flags() & bsn::FLAG_HEADING_KINEMATIC);
  // Walking, the knee axis stays within a few degrees of horizontal: observability cos^2 of that, near 1.
  EXPECT_GT(last.heading_observability(), 0.9);
  EXPECT_LE(last.heading_observability(), 1.0);
  // The first 17 s are in a clean field, where the converged filters' headings err by a few degrees at most (Fan's
  // test A: about 2 deg): their difference, the offset, stays well below 10 deg.
  EXPECT_LT(std::abs(last.heading_offset()), 10.0 * std::numbers::pi / 180.0);
}

}  // namespace
}  // namespace bsn::integration
