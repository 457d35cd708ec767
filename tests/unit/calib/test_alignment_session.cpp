// The live alignment of a body (AlignmentSession): the simulated lower body, every sensor strapped on at a random
// orientation, consumer MEMS errors, sends its samples as a calibration service receives them (N-pose, flexions,
// walking). The session finds the pose, says what to do, and aligns every node; a silent node, a node on another
// clock and a session without a pose fail with their reason.
#include <gtest/gtest.h>

#include <numbers>

#include "alignment_scenario.hpp"
#include "bsn/calib/alignment_session.hpp"
#include "bsn/fusion/rotation.hpp"
#include "bsn/sim/scenario.hpp"

namespace bsn {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr std::uint64_t kSecond = 1'000'000'000ull;

/// The session's nodes of the simulated body: node ids are segment names; knee -1, hip and ankle +1.
std::vector<calib::AlignmentNode> nodes_of(const sim::Body& body) {
  std::vector<calib::AlignmentNode> nodes;
  for (std::size_t i = 0; i < body.size(); ++i) {
    const sim::SegmentDef& s = body.segment(i);
    const int sign = s.joint.starts_with("knee") ? -1 : s.joint.empty() ? 0 : 1;
    nodes.push_back({s.name, s.name, s.joint, s.parent, sign});
  }
  return nodes;
}

calib::SessionSample session_sample(const sim::ScenarioSample& s, std::uint64_t seq, std::int64_t clock_offset_ns) {
  calib::SessionSample out;
  out.seq = seq;
  out.timestamp_ns = static_cast<std::uint64_t>(static_cast<std::int64_t>(s.sample.timestamp_ns) + clock_offset_ns);
  out.acc = s.sample.acc;
  out.gyr = s.sample.gyr;
  out.mag = s.sample.mag;
  out.has_mag = s.sample.has_mag;
  return out;
}

/// Runs the scenario into a session as the samples arrive (arrival = sensor time + 5 ms), from `from_s` on; node
/// `silent` (if any) never sends, node `offset_node` runs on a clock `offset_ns` ahead. Returns the phases seen.
struct Fed {
  std::vector<calib::AlignmentPhase> phases;
  std::vector<std::string> instructions;
  std::uint64_t end_ns = 0;
  sim::Body body;
};

Fed feed(calib::AlignmentSession& session, const sim::ScenarioSpec& spec, double from_s = 0.0,
         const std::string& silent = "", const std::string& offset_node = "", std::int64_t offset_ns = 0) {
  sim::ScenarioRunner runner(spec, {}, false);
  Fed fed{{}, {}, 0, runner.body()};
  std::vector<sim::ScenarioSample> out;
  std::uint64_t k = 0;
  const std::uint64_t start = 1000 * kSecond;  // the arrival clock: monotonic, not the sensor's
  while (runner.next(out)) {
    const std::uint64_t t = out[0].sample.timestamp_ns;
    const std::uint64_t now = start + t + 5'000'000;
    if (static_cast<double>(t) * 1e-9 >= from_s) {
      for (std::size_t i = 0; i < out.size(); ++i) {
        const std::string& name = runner.segment_names()[i];
        if (out[i].dropped || name == silent) continue;
        session.add(i, session_sample(out[i], k, name == offset_node ? offset_ns : 0), now);
      }
    }
    ++k;
    fed.end_ns = now;
    if (k % 25 == 0) {  // progress four times a second, as the service asks
      const calib::AlignmentProgress p = session.progress(now);
      if (fed.phases.empty() || fed.phases.back() != p.phase) {
        fed.phases.push_back(p.phase);
        fed.instructions.push_back(p.instruction);
      }
      if (p.collection_over) break;
    }
  }
  return fed;
}

TEST(AlignmentSession, AlignsEveryNodeOfTheLabProcedureAndSaysWhatToDo) {
  const sim::ScenarioSpec spec = calib::testing::alignment_session_scenario(31, 6.0);
  sim::ScenarioRunner probe(spec, {}, false);
  calib::AlignmentSessionParams params;
  params.duration_s = spec.duration_s + 10.0;  // ends by the scenario's end, not by time
  calib::AlignmentSession session(nodes_of(probe.body()), params, 1000 * kSecond);
  const Fed fed = feed(session, spec);
  // The procedure's phases in order: N-pose, flexions, then enough movement.
  ASSERT_GE(fed.phases.size(), 3u);
  EXPECT_EQ(fed.phases[0], calib::AlignmentPhase::pose);
  EXPECT_NE(fed.instructions[0].find("N-pose"), std::string::npos) << fed.instructions[0];
  EXPECT_EQ(fed.phases[1], calib::AlignmentPhase::moves);
  EXPECT_NE(fed.instructions[1].find("Flex"), std::string::npos) << fed.instructions[1];
  EXPECT_EQ(fed.phases.back(), calib::AlignmentPhase::good_enough);

  const calib::AlignmentSessionResult r = session.finish(fed.end_ns);
  ASSERT_EQ(r.problem, "");
  // The simulated N-pose lasts pose_s from the start; its end is found within the rest threshold's lag.
  EXPECT_NEAR(r.pose_end_s, spec.gait->alignment->pose_s, 0.3);
  // The flexions used end where the body stands still again before walking (the hips walk as ball joints).
  const sim::AlignmentMoves& moves = *spec.gait->alignment;
  EXPECT_NEAR(r.moves_end_s, moves.walk_start_s() - moves.pose_s, 0.5);
  for (std::size_t i = 0; i < r.nodes.size(); ++i) {
    SCOPED_TRACE(fed.body.segment(i).name);
    ASSERT_TRUE(r.nodes[i].success) << r.nodes[i].message;
    // The bound of the offline alignment test (test_segment_alignment.cpp): a few degrees with consumer MEMS.
    EXPECT_LT(
        fusion::angle_between(r.nodes[i].sensor_to_segment, sim::true_sensor_to_segment(fed.body.segment(i))) / kDeg,
        5.0)
        << r.nodes[i].source;
    EXPECT_EQ(r.nodes[i].source.rfind("pose+", 0), 0u) << r.nodes[i].source;
    if (r.nodes[i].source.find("hinge") != std::string::npos) {
      EXPECT_GE(r.nodes[i].axis_observability, params.fit.min_observability);
      EXPECT_LT(r.nodes[i].relative_residual, params.fit.max_relative_residual);
    }
  }
  // The knees are hinges in flexion: both their segments take the knee's axis.
  const auto shank = *fed.body.find("shank_l");
  EXPECT_NE(r.nodes[shank].source.find("hinge"), std::string::npos) << r.nodes[shank].source;
}

TEST(AlignmentSession, UntilGoodEndsOnceEveryJointHasMoved) {
  const sim::ScenarioSpec spec = calib::testing::alignment_session_scenario(32, 6.0);
  sim::ScenarioRunner probe(spec, {}, false);
  calib::AlignmentSessionParams params;
  params.duration_s = 300.0;
  params.until_good = true;
  calib::AlignmentSession session(nodes_of(probe.body()), params, 1000 * kSecond);
  const Fed fed = feed(session, spec);
  EXPECT_TRUE(session.collection_over(fed.end_ns));
  // It ended before the walking: the flexions alone gave every joint its minimum of movement.
  EXPECT_LT(static_cast<double>(fed.end_ns - 1000 * kSecond) * 1e-9, spec.gait->alignment->walk_start_s());
  const calib::AlignmentSessionResult r = session.finish(fed.end_ns);
  EXPECT_EQ(r.problem, "");
  for (const auto& n : r.nodes) EXPECT_TRUE(n.success) << n.message;
}

TEST(AlignmentSession, ANodeThatNeverSendsEndsTheCollectionWithItsName) {
  const sim::ScenarioSpec spec = calib::testing::alignment_session_scenario(33, 1.0);
  sim::ScenarioRunner probe(spec, {}, false);
  calib::AlignmentSessionParams params;
  params.duration_s = 60.0;
  calib::AlignmentSession session(nodes_of(probe.body()), params, 1000 * kSecond);
  const Fed fed = feed(session, spec, 0.0, "foot_r");
  // Over at the start timeout (5 s), long before the 60 s.
  EXPECT_TRUE(session.collection_over(fed.end_ns));
  EXPECT_LT(static_cast<double>(fed.end_ns - 1000 * kSecond) * 1e-9, params.start_timeout_s + 1.0);
  EXPECT_EQ(fed.phases.front(), calib::AlignmentPhase::waiting);
  EXPECT_NE(fed.instructions.front().find("foot_r"), std::string::npos) << fed.instructions.front();
  const calib::AlignmentSessionResult r = session.finish(fed.end_ns);
  EXPECT_NE(r.problem.find("'foot_r' sent no sample"), std::string::npos) << r.problem;
  for (const auto& n : r.nodes) EXPECT_FALSE(n.success);
}

TEST(AlignmentSession, NodesOnDifferentClocksAreRefusedWithTheOffset) {
  const sim::ScenarioSpec spec = calib::testing::alignment_session_scenario(34, 1.0);
  sim::ScenarioRunner probe(spec, {}, false);
  calib::AlignmentSessionParams params;
  params.duration_s = 10.0;
  calib::AlignmentSession session(nodes_of(probe.body()), params, 1000 * kSecond);
  // 15 s off in a 19 s session: a few seconds still overlap in time, with the wrong instants.
  const Fed fed = feed(session, spec, 0.0, "", "shank_l", 15 * static_cast<std::int64_t>(kSecond));
  const calib::AlignmentSessionResult r = session.finish(fed.end_ns);
  EXPECT_NE(r.problem.find("one clock"), std::string::npos) << r.problem;
  EXPECT_NE(r.problem.find("'shank_l' starts 15.0 s"), std::string::npos) << r.problem;
  for (const auto& n : r.nodes) EXPECT_FALSE(n.success);
}

TEST(AlignmentSession, NoStillStartIsNoPose) {
  // From the first flexion on: the body never stands still for the 3 s of the pose before the walking.
  const sim::ScenarioSpec spec = calib::testing::alignment_session_scenario(35, 4.0);
  sim::ScenarioRunner probe(spec, {}, false);
  calib::AlignmentSessionParams params;
  params.duration_s = 60.0;
  params.pose_s = 4.0;  // longer than the simulated second rest (3 s) too
  calib::AlignmentSession session(nodes_of(probe.body()), params, 1000 * kSecond);
  const Fed fed = feed(session, spec, spec.gait->alignment->pose_s + 0.2);
  const calib::AlignmentSessionResult r = session.finish(fed.end_ns);
  EXPECT_NE(r.problem.find("no N-pose"), std::string::npos) << r.problem;
  for (const auto& n : r.nodes) EXPECT_FALSE(n.success);
}

TEST(AlignmentSession, RefusesParametersAndNodesThatCannotWork) {
  calib::AlignmentSessionParams p;
  p.duration_s = 2.0;
  p.pose_s = 3.0;
  EXPECT_NE(calib::validate(p).find("pose_s"), std::string::npos);
  p.duration_s = -1.0;
  EXPECT_NE(calib::validate(p).find("duration_s"), std::string::npos);
  p.duration_s = 1e6;
  EXPECT_NE(calib::validate(p).find("absurd"), std::string::npos);
  EXPECT_EQ(calib::validate(calib::AlignmentSessionParams{}), "");
  EXPECT_NE(calib::validate(std::vector<calib::AlignmentNode>{}), "");
  const std::vector<calib::AlignmentNode> twice{{"a", "a", "", -1, 0}, {"a", "b", "j", 0, 1}};
  EXPECT_NE(calib::validate(twice).find("twice"), std::string::npos);
  const std::vector<calib::AlignmentNode> order{{"a", "a", "j", 1, 0}, {"b", "b", "", -1, 1}};
  EXPECT_NE(calib::validate(order).find("parent"), std::string::npos);
  EXPECT_THROW(calib::AlignmentSession(twice, calib::AlignmentSessionParams{}, 0), std::invalid_argument);
}

}  // namespace
}  // namespace bsn
