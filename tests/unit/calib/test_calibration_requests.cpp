// The calibration service's bookkeeping without DDS: requests answered once, refusals said again, a node collected
// by one request at a time, "*" as the nodes heard lately, a collection ended by its sample count, by its duration, by
// a cancel or by the service stopping, progress at its period.
#include <gtest/gtest.h>

#include <random>

#include "bsn/calib/calibration_requests.hpp"

namespace bsn::calib {
namespace {

constexpr std::uint64_t kStartNs = 1'000'000'000'000;
constexpr std::uint64_t kMs = 1'000'000;
constexpr std::uint64_t kSampleNs = 10 * kMs;  // 100 Hz

const Vec3 kGyroBias(0.02, -0.015, 0.01);  // rad/s

CalibrationRequest gyro_bias_request(const std::string& id, const std::string& nodes, std::size_t samples) {
  CalibrationRequest r;
  r.id = id;
  r.kind = CalibrationKind::gyro_bias;
  r.node_list = nodes;
  r.session.sample_count = samples;
  return r;
}

/// A sensor at rest, k-th sample: the gyro reads its bias plus white noise (0.01 deg/s/sqrt(Hz) at 100 Hz).
SessionSample still_sample(std::uint64_t k, std::mt19937_64& rng) {
  std::normal_distribution<double> noise(0.0, 0.01 * M_PI / 180.0 * 10.0);
  SessionSample s;
  s.seq = k;
  s.timestamp_ns = k * kSampleNs;
  s.gyr = kGyroBias + Vec3(noise(rng), noise(rng), noise(rng));
  s.acc = Vec3(0.0, 0.0, 9.81);
  s.mag = Vec3(20.0, 0.0, -40.0);
  return s;
}

TEST(CalibrationRequests, ACollectionEndsWithItsLastSampleAndFreesItsNode) {
  CalibrationRequests requests({});
  const RequestDecision d = requests.request(gyro_bias_request("r1", "thigh", 400), kStartNs);
  ASSERT_EQ(d.outcome, RequestDecision::Outcome::started) << (d.progress ? d.progress->message : "");
  ASSERT_TRUE(d.progress);
  EXPECT_EQ(d.progress->phase, RequestPhase::waiting);
  EXPECT_EQ(d.progress->seconds_left, -1.0);  // ends by sample count only
  EXPECT_EQ(requests.running(), 1U);

  std::mt19937_64 rng(7);
  std::optional<FinishedRequest> finished;
  std::uint64_t k = 0;
  for (; k < 400 && !finished; ++k) {
    // Another node's samples are heard but collected by no request.
    EXPECT_FALSE(requests.sample("shank", still_sample(k, rng), kStartNs + k * kSampleNs));
    finished = requests.sample("thigh", still_sample(k, rng), kStartNs + k * kSampleNs);
  }
  ASSERT_TRUE(finished);
  EXPECT_EQ(k, 400U);  // the 400th sample ended it, not the next tick
  EXPECT_EQ(requests.running(), 0U);
  ASSERT_EQ(finished->calibrations.size(), 1U);
  const SessionResult& r = finished->calibrations[0].result;
  ASSERT_TRUE(r.success) << r.message;
  EXPECT_EQ(r.samples, 400U);
  // The mean of ~400 rest samples with 1.7e-3 rad/s noise per sample: within 5e-4 rad/s of the bias.
  EXPECT_LT((r.gyro.bias - kGyroBias).norm(), 5e-4);
  EXPECT_EQ(finished->done.phase, RequestPhase::done);
  EXPECT_EQ(finished->done.instruction, "done: 1 of 1 nodes calibrated");
  ASSERT_EQ(finished->done.nodes.size(), 1U);
  EXPECT_EQ(finished->done.nodes[0].samples, 400U);

  // The node is free again: a new request on it starts.
  EXPECT_EQ(requests.request(gyro_bias_request("r2", "thigh", 100), kStartNs + 5'000 * kMs).outcome,
            RequestDecision::Outcome::started);
}

TEST(CalibrationRequests, AnIdIsAnsweredOnceAndARefusalIsSaidAgain) {
  CalibrationRequests requests({});
  EXPECT_EQ(requests.request(gyro_bias_request("a", "thigh", 100), kStartNs).outcome,
            RequestDecision::Outcome::started);
  EXPECT_EQ(requests.request(gyro_bias_request("a", "shank", 100), kStartNs).outcome,
            RequestDecision::Outcome::repeat_ignored);
  EXPECT_EQ(requests.running(), 1U);

  CalibrationRequest bad = gyro_bias_request("b", "thigh", 0);  // neither a duration nor a sample count
  const RequestDecision refused = requests.request(bad, kStartNs);
  ASSERT_EQ(refused.outcome, RequestDecision::Outcome::refused);
  ASSERT_TRUE(refused.progress);
  EXPECT_EQ(refused.progress->phase, RequestPhase::refused);
  EXPECT_FALSE(refused.progress->message.empty());
  // Sent again even when the repeat would now be valid: the id was answered with that refusal.
  const RequestDecision again = requests.request(gyro_bias_request("b", "shank", 100), kStartNs);
  ASSERT_EQ(again.outcome, RequestDecision::Outcome::refusal_repeated);
  EXPECT_EQ(again.progress->message, refused.progress->message);

  CalibrationRequest unknown = gyro_bias_request("c", "thigh", 100);
  unknown.kind.reset();
  unknown.kind_value = 9;
  const RequestDecision u = requests.request(unknown, kStartNs);
  ASSERT_EQ(u.outcome, RequestDecision::Outcome::refused);
  EXPECT_NE(u.progress->message.find("unknown kind 9"), std::string::npos) << u.progress->message;

  EXPECT_EQ(requests.request(gyro_bias_request("", "thigh", 100), kStartNs).outcome, RequestDecision::Outcome::refused);
}

TEST(CalibrationRequests, ANodeIsCollectedByOneRequestAtATime) {
  CalibrationRequests requests({});
  ASSERT_EQ(requests.request(gyro_bias_request("first", "thigh, shank", 100), kStartNs).outcome,
            RequestDecision::Outcome::started);
  const RequestDecision d = requests.request(gyro_bias_request("second", "foot,shank", 100), kStartNs);
  ASSERT_EQ(d.outcome, RequestDecision::Outcome::refused);
  EXPECT_NE(d.progress->message.find("node 'shank' is being calibrated by request 'first'"), std::string::npos)
      << d.progress->message;

  const RequestDecision long_id = requests.request(gyro_bias_request("third", std::string(64, 'n'), 100), kStartNs);
  ASSERT_EQ(long_id.outcome, RequestDecision::Outcome::refused);
  EXPECT_NE(long_id.progress->message.find("longer than 63"), std::string::npos);
  EXPECT_EQ(requests.request(gyro_bias_request("fourth", " , ", 100), kStartNs).outcome,
            RequestDecision::Outcome::refused);
}

TEST(CalibrationRequests, EveryNodeMeansTheNodesHeardWithinTheWindow) {
  CalibrationRequests requests({});
  EXPECT_EQ(requests.request(gyro_bias_request("none", "*", 100), kStartNs).outcome, RequestDecision::Outcome::refused);
  std::mt19937_64 rng(1);
  requests.sample("old", still_sample(0, rng), kStartNs);
  requests.sample("b", still_sample(0, rng), kStartNs + 1'500 * kMs);
  requests.sample("a", still_sample(0, rng), kStartNs + 1'900 * kMs);
  const RequestDecision d = requests.request(gyro_bias_request("all", "*", 100), kStartNs + 2'000 * kMs);
  ASSERT_EQ(d.outcome, RequestDecision::Outcome::started);
  ASSERT_EQ(d.progress->nodes.size(), 2U);  // "old" was last heard 2 s ago, beyond the 1 s window
  EXPECT_EQ(d.progress->nodes[0].node, "a");
  EXPECT_EQ(d.progress->nodes[1].node, "b");
}

TEST(CalibrationRequests, ANodeThatNeverSendsFailsAtTheDurationAndProgressComesAtItsPeriod) {
  CalibrationRequests requests({});
  CalibrationRequest r = gyro_bias_request("quiet", "thigh", 0);
  r.session.duration_s = 3.0;
  ASSERT_EQ(requests.request(r, kStartNs).outcome, RequestDecision::Outcome::started);
  EXPECT_TRUE(requests.tick(kStartNs + 100 * kMs).progress.empty());  // the first progress came with the start
  const TickOutcome due = requests.tick(kStartNs + 250 * kMs);
  ASSERT_EQ(due.progress.size(), 1U);
  EXPECT_EQ(due.progress[0].phase, RequestPhase::waiting);
  EXPECT_NEAR(due.progress[0].seconds_left, 2.75, 1e-9);
  EXPECT_TRUE(due.finished.empty());
  EXPECT_TRUE(requests.tick(kStartNs + 2'990 * kMs).finished.empty());
  // No sample by the end of the duration: a failure that names the node and the wait.
  const TickOutcome over = requests.tick(kStartNs + 3'000 * kMs);
  ASSERT_EQ(over.finished.size(), 1U);
  ASSERT_EQ(over.finished[0].calibrations.size(), 1U);
  EXPECT_FALSE(over.finished[0].calibrations[0].result.success);
  EXPECT_EQ(over.finished[0].calibrations[0].result.message, "node 'thigh': no sample arrived within 3.00 s");
  EXPECT_EQ(over.finished[0].done.instruction, "done: 0 of 1 nodes calibrated");
  EXPECT_EQ(requests.running(), 0U);
}

TEST(CalibrationRequests, ACancelAndTheServiceStoppingEndRunsWithoutAFit) {
  CalibrationRequests requests({});
  CalibrationRequest ghost;
  ghost.id = "ghost";
  ghost.cancel = true;
  EXPECT_EQ(requests.request(ghost, kStartNs).outcome, RequestDecision::Outcome::cancel_not_running);
  ASSERT_EQ(requests.request(gyro_bias_request("x", "thigh", 1000), kStartNs).outcome,
            RequestDecision::Outcome::started);
  ASSERT_EQ(requests.request(gyro_bias_request("y", "shank", 1000), kStartNs).outcome,
            RequestDecision::Outcome::started);
  CalibrationRequest cancel;
  cancel.id = "x";
  cancel.cancel = true;
  const RequestDecision d = requests.request(cancel, kStartNs + kMs);
  ASSERT_EQ(d.outcome, RequestDecision::Outcome::cancelled);
  ASSERT_TRUE(d.finished);
  EXPECT_TRUE(d.finished->aborted);
  EXPECT_EQ(d.finished->calibrations.at(0).result.message, "node 'thigh': cancelled by the requester");

  const std::vector<FinishedRequest> stopped = requests.abort_all("the calibration service stopped", kStartNs + kMs);
  ASSERT_EQ(stopped.size(), 1U);
  EXPECT_EQ(stopped[0].id, "y");
  EXPECT_EQ(stopped[0].calibrations.at(0).result.message, "node 'shank': the calibration service stopped");
  EXPECT_EQ(requests.running(), 0U);
}

CalibrationRequest alignment_request(const std::string& id, const std::string& nodes) {
  CalibrationRequest r;
  r.id = id;
  r.kind = CalibrationKind::alignment;
  r.node_list = nodes;
  r.alignment_nodes = {{"pelvis", "pelvis", "", -1, 0}, {"thigh", "thigh_r", "hip_r", 0, 1}};
  return r;
}

TEST(CalibrationRequests, AnAlignmentRefusalNamesItsNodesAndAnAlignmentHoldsItsNodes) {
  CalibrationRequests requests({});
  CalibrationRequest unparsed = alignment_request("bad body", "pelvis,thigh");
  unparsed.body_problem = "the request's body does not parse: line 3";
  const RequestDecision d = requests.request(unparsed, kStartNs);
  ASSERT_EQ(d.outcome, RequestDecision::Outcome::refused);
  EXPECT_EQ(d.progress->message, unparsed.body_problem);
  EXPECT_EQ(d.refused_alignment_nodes, (std::vector<std::string>{"pelvis", "thigh"}));

  const RequestDecision started = requests.request(alignment_request("align", "*"), kStartNs);
  ASSERT_EQ(started.outcome, RequestDecision::Outcome::started);
  ASSERT_EQ(started.progress->nodes.size(), 2U);
  const RequestDecision busy = requests.request(gyro_bias_request("gyro", "thigh", 100), kStartNs);
  ASSERT_EQ(busy.outcome, RequestDecision::Outcome::refused);
  EXPECT_NE(busy.progress->message.find("request 'align'"), std::string::npos);

  // No node ever sends: the start timeout (5 s) fails the body, each node's result says why.
  const TickOutcome over = requests.tick(kStartNs + 5'100 * kMs);
  ASSERT_EQ(over.finished.size(), 1U);
  const FinishedRequest& f = over.finished[0];
  ASSERT_EQ(f.alignments.size(), 2U);
  EXPECT_FALSE(f.alignments[0].alignment.success);
  EXPECT_FALSE(f.alignments[0].message.empty());
  EXPECT_EQ(f.alignments[1].segment, "thigh_r");
  EXPECT_EQ(f.done.instruction.rfind("done: 0 of 2 nodes aligned", 0), 0U) << f.done.instruction;
  EXPECT_EQ(requests.running(), 0U);
}

TEST(CalibrationRequests, ANodeListIsSplitTrimmedAndWithoutRepeats) {
  EXPECT_EQ(split_node_list(" a, b ,a,, c"), (std::vector<std::string>{"a", "b", "c"}));
  EXPECT_TRUE(split_node_list("").empty());
}

}  // namespace
}  // namespace bsn::calib
