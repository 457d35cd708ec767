#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>

#include "view_state.hpp"

namespace bsn::services {
namespace {

constexpr std::uint64_t kMs = 1'000'000;

bsn::Orientation orientation(const std::string& seg, std::uint64_t ts, std::array<double, 4> q) {
  bsn::Orientation o;
  o.segment(seg);
  o.node_id(seg + "_node");
  o.timestamp_ns(ts);
  o.quat(q);
  return o;
}

TEST(ViewState, PassesOnAtMost30HzPerSegmentAndTheFullRateOfA100HzSource) {
  ViewState state;
  int sent_a = 0, sent_b = 0;
  // 10 s of two segments at 100 Hz.
  for (int i = 0; i < 1000; ++i) {
    const std::uint64_t now = static_cast<std::uint64_t>(i) * 10 * kMs;
    sent_a += state.on_orientation(orientation("a", now, {1, 0, 0, 0}), now).has_value();
    sent_b += state.on_orientation(orientation("b", now, {1, 0, 0, 0}), now).has_value();
  }
  // 30 Hz over 10 s is 300; the grid allows one more at the start. At least 29 Hz: a 100 Hz source must not be
  // thinned to 25 Hz (every 4th sample) by a "now + interval" rule.
  for (int sent : {sent_a, sent_b}) {
    EXPECT_LE(sent, 301);
    EXPECT_GE(sent, 290);
  }
}

TEST(ViewState, ErrorToTruthOfTheSameSample) {
  ViewState state;
  const double half = 10.0 / 2 * std::numbers::pi / 180;  // 10 degrees about z
  state.on_truth(orientation("a", 5, {1, 0, 0, 0}), 0);
  state.on_truth(orientation("a", 6, {std::cos(half), 0, 0, std::sin(half)}), 1);
  const auto m = state.on_orientation(orientation("a", 5, {std::cos(half), 0, 0, std::sin(half)}), 2);
  ASSERT_TRUE(m);
  // The estimate of sample 5 is compared with the truth of sample 5 (10 degrees off), not with the newer one.
  EXPECT_NE(m->find("\"err\":10"), std::string::npos) << *m;
  const auto none = state.on_orientation(orientation("b", 5, {1, 0, 0, 0}), 2);
  ASSERT_TRUE(none);
  EXPECT_NE(none->find("\"err\":null"), std::string::npos) << *none;
}

TEST(ViewState, AnAlignedEstimateIsComparedWithTheTruthOfItsSegmentFrame) {
  ViewState state;
  const double half = 90.0 / 2 * std::numbers::pi / 180;  // a sensor turned 90 degrees about x on its segment
  const std::array<double, 4> segment{1, 0, 0, 0}, sensor{std::cos(half), std::sin(half), 0, 0};
  bsn::Orientation segment_truth = orientation("a", 5, segment);
  segment_truth.flags(bsn::FLAG_SEGMENT_FRAME);
  // Before any estimate the ghost shows the sensor's truth; the segment frame's is kept but not sent.
  EXPECT_TRUE(state.on_truth(orientation("a", 5, sensor), 0));
  EXPECT_FALSE(state.on_truth(segment_truth, 100 * kMs));
  bsn::Orientation aligned = orientation("a", 5, segment);
  aligned.flags(bsn::FLAG_SEGMENT_FRAME);
  const auto m = state.on_orientation(aligned, 200 * kMs);
  ASSERT_TRUE(m);
  EXPECT_NE(m->find("\"err\":0}"), std::string::npos) << "the segment frame's truth, not the sensor's: " << *m;
  // From now on the ghost is the segment frame's truth, flagged so.
  segment_truth.timestamp_ns(6);
  const auto t = state.on_truth(segment_truth, 300 * kMs);
  ASSERT_TRUE(t);
  EXPECT_NE(t->find("\"flags\":32"), std::string::npos) << *t;
  EXPECT_FALSE(state.on_truth(orientation("a", 6, sensor), 400 * kMs));
  // A sensor-frame estimate of the same sample is compared with the sensor's truth.
  const auto raw = state.on_orientation(orientation("a", 5, sensor), 500 * kMs);
  ASSERT_TRUE(raw);
  EXPECT_NE(raw->find("\"err\":0}"), std::string::npos) << *raw;
}

TEST(ViewState, JointMessagesCarryTheNamedAnatomicalAngles) {
  ViewState state;
  bsn::JointAngles j;
  j.joint("knee_l");
  j.axes("zyx");
  j.angles({-0.5, 0.1, 0.2});
  j.anatomy("knee");
  j.side("left");
  j.anatomical_names({"flexion_extension", "adduction_abduction", "internal_external_rotation"});
  j.anatomical({0.5, -0.1, 0.2});
  const auto m = state.on_joint(j, 0);
  ASSERT_TRUE(m);
  EXPECT_NE(m->find("\"names\":[\"flexion_extension\",\"adduction_abduction\",\"internal_external_rotation\"]"),
            std::string::npos)
      << *m;
  EXPECT_NE(m->find("\"anat\":[28.647889"), std::string::npos) << "flexion positive, degrees: " << *m;
  // The next message of the joint leaves the (unchanged) names out; the snapshot and the message a second later
  // have them.
  const auto next = state.on_joint(j, 40 * kMs);
  ASSERT_TRUE(next);
  EXPECT_EQ(next->find("\"names\""), std::string::npos) << *next;
  EXPECT_NE(next->find("\"anat\":[28.647889"), std::string::npos) << *next;
  EXPECT_NE(state.snapshot().back().find("\"names\":[\"flexion_extension\""), std::string::npos);
  const auto later = state.on_joint(j, 1100 * kMs);
  ASSERT_TRUE(later);
  EXPECT_NE(later->find("\"names\":[\"flexion_extension\""), std::string::npos) << *later;
}

TEST(ViewState, RotationAngleIsExactNearZeroAndAtHalfTurns) {
  const double tiny = 1e-6 / 2;  // 1e-6 rad about x
  EXPECT_NEAR(rotation_angle_deg({1, 0, 0, 0}, {std::cos(tiny), std::sin(tiny), 0, 0}), 1e-6 * 180 / std::numbers::pi,
              1e-12);
  EXPECT_NEAR(rotation_angle_deg({1, 0, 0, 0}, {0, 0, 0, 1}), 180.0, 1e-9);
  EXPECT_NEAR(rotation_angle_deg({0, 1, 0, 0}, {0, -1, 0, 0}), 0.0, 1e-9);  // q and -q: the same rotation
}

TEST(ViewState, NonFiniteValuesAreDroppedAndCountedNeverSentAsNaN) {
  ViewState state;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(state.on_orientation(orientation("a", 1, {nan, 0, 0, 0}), 0));
  EXPECT_FALSE(state.on_truth(orientation("a", 1, {1, std::numeric_limits<double>::infinity(), 0, 0}), 0));
  bsn::JointAngles j;
  j.joint("knee");
  j.angles({0, nan, 0});
  EXPECT_FALSE(state.on_joint(j, 0));
  EXPECT_EQ(state.rejected_non_finite(), 3u);
  bsn::Status s;
  s.process_id("p");
  bsn::NodeStatus n;
  n.rate_hz(nan);
  s.nodes().push_back(n);
  const auto m = state.on_status(s);
  ASSERT_TRUE(m);
  EXPECT_EQ(m->find("nan"), std::string::npos) << *m;
}

TEST(ViewState, NamesFromTheNetworkBecomeValidJsonAscii) {
  EXPECT_EQ(json_string("a\"b\\c\n\x1b\xff"), "\"a\\\"b\\\\c\\u000a\\u001b\\u00ff\"");
  ViewState state;
  const auto m = state.on_orientation(orientation(std::string(1000, 'x') + "\"", 1, {1, 0, 0, 0}), 0);
  ASSERT_TRUE(m);
  EXPECT_LT(m->size(), 400u) << "a long name is cut to kMaxNameChars";
  for (unsigned char c : *m) EXPECT_TRUE(c >= 0x20 && c < 0x7f);
}

TEST(ViewState, ManyNamesAreBoundedAndCounted) {
  ViewState state;
  for (std::size_t i = 0; i < ViewState::kMaxKeys + 10; ++i)
    state.on_orientation(orientation("s" + std::to_string(i), 1, {1, 0, 0, 0}), 0);
  EXPECT_EQ(state.rejected_too_many_names(), 10u);
  EXPECT_EQ(state.snapshot().size(), ViewState::kMaxKeys);
}

TEST(ViewState, SnapshotHoldsTheLatestOfEverything) {
  ViewState state;
  state.on_orientation(orientation("a", 1, {1, 0, 0, 0}), 0);
  state.on_truth(orientation("a", 1, {1, 0, 0, 0}), 0);
  bsn::JointAngles j;
  j.joint("knee_l");
  j.parent("thigh_l");
  j.child("shank_l");
  j.axes("zyx");
  j.angles({0.1, 0.2, 0.3});
  state.on_joint(j, 0);
  const auto snap = state.snapshot();
  ASSERT_EQ(snap.size(), 3u);
  EXPECT_NE(snap[2].find("\"joint\":\"knee_l\""), std::string::npos);
  // Degrees on the page: 0.1 rad.
  EXPECT_NE(snap[2].find("5.729577"), std::string::npos) << snap[2];
}

}  // namespace
}  // namespace bsn::services
