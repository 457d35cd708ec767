// Sample sources in BodyFusion: the first writer heard owns a node; samples from a second writer are rejected as
// conflicting_source without touching the owner's stream or freshness; another writer takes over only after the
// owner went stale (a handover, counted, with a new stream and a restarted filter); the counters add up.
#include <gtest/gtest.h>

#include <numeric>
#include <string>

#include "bsn/fusion/body_fusion.hpp"

namespace bsn::fusion {
namespace {

constexpr std::uint64_t kStepNs = 10'000'000;  // 100 Hz
constexpr std::uint64_t kSecondNs = 1'000'000'000;
constexpr std::uint64_t kStaleNs = 300'000'000;  // BodyFusion's default stale timeout, 0.3 s
// Exact samples: the only error is floating-point rounding over a few hundred updates, far below this.
constexpr double kExactRad = 1e-9;
const Vec3 kEarthField(0.0, 20.0, -44.0);  // uT, ENU

ImuSample exact_sample_at_ns(const Quat& q, std::uint64_t t_ns) {
  ImuSample s;
  s.timestamp_ns = t_ns;
  s.acc = q.conjugate() * Vec3(0.0, 0.0, kGravity);
  s.gyr = Vec3::Zero();
  s.mag = q.conjugate() * kEarthField;
  return s;
}

SourceId source(std::uint8_t last) {
  SourceId id;
  id.bytes[0] = 0x01;  // any non-zero byte makes it known
  id.bytes[15] = last;
  return id;
}

BodyModel one_segment_body() {
  BodyModel body;
  SegmentSpec s;
  s.name = "solo";
  s.node = "n";
  body.segments = {s};
  return body;
}

std::uint64_t conflicting(const BodyFusion& f) {
  return f.segment(0).gate.counters().rejected[static_cast<std::size_t>(
      rejection_index(SampleVerdict::kConflictingSource))];
}

TEST(SampleSource, ReasonHasAStableName) {
  const int index = rejection_index(SampleVerdict::kConflictingSource);
  ASSERT_GE(index, 0);
  EXPECT_EQ(rejection_reason_name(static_cast<std::size_t>(index)), "conflicting_source");
}

TEST(SampleSource, SecondWriterIsRejectedAndCountedWhileTheFirstFlows) {
  BodyFusion f(one_segment_body(), {}, {}, 0);
  const Quat owner_q = from_yaw_pitch_roll({0.3, 0.1, -0.2});
  const Quat rogue_q = from_yaw_pitch_roll({2.0, -0.5, 0.7});  // far from the owner's: a leak would show
  const SourceId owner = source(1), rogue = source(2), rogue2 = source(3);
  std::uint64_t new_conflicts = 0;
  for (std::uint64_t k = 0; k < 200; ++k) {
    const std::uint64_t t = kSecondNs + k * kStepNs;
    const SampleResult& a = f.process({"n", k, exact_sample_at_ns(owner_q, t)}, t, owner);
    ASSERT_EQ(a.outcome, SampleOutcome::kEstimated) << k;
    EXPECT_LT(angle_between(a.orientation, owner_q), kExactRad) << k;
    if (k < 20) continue;
    // The rogue interleaves its own stream: timestamps a little ahead, its own sequence numbers from 0.
    const SampleResult& b =
        f.process({"n", k - 20, exact_sample_at_ns(rogue_q, t + kStepNs / 2)}, t, k % 2 ? rogue : rogue2);
    EXPECT_EQ(b.outcome, SampleOutcome::kGateRejected) << k;
    EXPECT_EQ(b.verdict, SampleVerdict::kConflictingSource) << k;
    new_conflicts += b.new_conflicting_source;
  }
  EXPECT_EQ(conflicting(f), 180u);
  const auto& c = f.segment(0).gate.counters();
  // The rogue's samples neither count as the owner's losses nor move its stream.
  EXPECT_EQ(c.missing, 0u);
  EXPECT_EQ(c.accepted, 200u);
  EXPECT_EQ(c.received, 380u);
  EXPECT_EQ(std::accumulate(c.rejected.begin(), c.rejected.end(), std::uint64_t{0}), 180u);
  EXPECT_EQ(c.received, c.accepted + 180u) << "counters add up";
  EXPECT_EQ(f.segment(0).source, owner);
  EXPECT_EQ(f.segment(0).source_handovers, 0u);
  // Alternating rogues: each sample's writer differs from the last one rejected.
  EXPECT_EQ(new_conflicts, 180u);
  ASSERT_TRUE(f.segment(0).conflicting_source);
}

TEST(SampleSource, OneConflictEventPerNewWriter) {
  BodyFusion f(one_segment_body(), {}, {}, 0);
  const Quat q = Quat::Identity();
  f.process({"n", 0, exact_sample_at_ns(q, kSecondNs)}, kSecondNs, source(1));
  int events = 0;
  for (std::uint64_t k = 1; k < 50; ++k) {
    const std::uint64_t t = kSecondNs + k * kStepNs;
    f.process({"n", k, exact_sample_at_ns(q, t)}, t, source(1));
    events += f.process({"n", k, exact_sample_at_ns(q, t + 1)}, t, source(2)).new_conflicting_source;
  }
  EXPECT_EQ(events, 1);
}

TEST(SampleSource, RejectedSamplesDoNotKeepTheNodeFresh) {
  BodyFusion f(one_segment_body(), {}, {}, 0);
  const Quat q = Quat::Identity();
  const std::uint64_t t0 = 10 * kSecondNs;
  f.process({"n", 0, exact_sample_at_ns(q, t0)}, t0, source(1));
  // Only the rogue sends now, every 10 ms, each rejected while the owner is not yet stale.
  std::uint64_t t = t0;
  for (std::uint64_t k = 0; t + kStepNs <= t0 + kStaleNs; ++k) {
    t += kStepNs;
    EXPECT_EQ(f.process({"n", k, exact_sample_at_ns(q, t)}, t, source(2)).verdict, SampleVerdict::kConflictingSource);
  }
  const auto turned = f.check_stale(t0 + kStaleNs + 1);
  ASSERT_EQ(turned.size(), 1u) << "the owner's silence is seen although the rogue sends";
}

TEST(SampleSource, HandoverOnlyAfterTheOwnerWentStale) {
  BodyFusion f(one_segment_body(), {}, {}, 0);
  const Quat owner_q = from_yaw_pitch_roll({0.3, 0.1, -0.2});
  const Quat next_q = from_yaw_pitch_roll({-1.2, 0.2, 0.4});
  const std::uint64_t t0 = 10 * kSecondNs;
  std::uint64_t k = 0;
  for (; k < 100; ++k) f.process({"n", k, exact_sample_at_ns(owner_q, t0 + k * kStepNs)}, t0 + k * kStepNs, source(1));
  const std::uint64_t owner_last = t0 + (k - 1) * kStepNs;

  // Just within the stale timeout: still the owner's node.
  EXPECT_EQ(f.process({"n", 0, exact_sample_at_ns(next_q, 5 * kSecondNs)}, owner_last + kStaleNs, source(2)).verdict,
            SampleVerdict::kConflictingSource);
  EXPECT_EQ(f.segment(0).source_handovers, 0u);

  // Past it (without a check_stale call in between): the next writer takes over, on its own clock and count.
  const std::uint64_t arrival = owner_last + kStaleNs + 1;
  const SampleResult& r = f.process({"n", 0, exact_sample_at_ns(next_q, 5 * kSecondNs)}, arrival, source(2));
  EXPECT_TRUE(r.source_handover);
  EXPECT_EQ(r.previous_source, source(1));
  ASSERT_EQ(r.outcome, SampleOutcome::kEstimated);
  // The filter restarted from this sample: carried on it could not turn by this much in one step.
  EXPECT_TRUE(r.flags.reinitialised);
  EXPECT_LT(angle_between(r.orientation, next_q), kExactRad);
  EXPECT_EQ(f.segment(0).source, source(2));
  EXPECT_EQ(f.segment(0).source_handovers, 1u);

  // The new stream is judged on its own: its clock (5 s, behind the old 11 s) and sequence are not time_backward
  // or losses, and a clock reset is not counted.
  for (std::uint64_t j = 1; j < 50; ++j) {
    const SampleResult& n =
        f.process({"n", j, exact_sample_at_ns(next_q, 5 * kSecondNs + j * kStepNs)}, arrival + j * kStepNs, source(2));
    ASSERT_EQ(n.outcome, SampleOutcome::kEstimated) << j;
  }
  // The old owner is now the conflicting one.
  EXPECT_EQ(
      f.process({"n", k, exact_sample_at_ns(owner_q, t0 + k * kStepNs)}, arrival + 50 * kStepNs, source(1)).verdict,
      SampleVerdict::kConflictingSource);
  const auto& c = f.segment(0).gate.counters();
  EXPECT_EQ(c.missing, 0u);
  EXPECT_EQ(c.clock_resets, 0u);
  EXPECT_EQ(c.received, 100u + 1u + 50u + 1u);
  EXPECT_EQ(c.accepted, 150u);
  EXPECT_EQ(conflicting(f), 2u);
  EXPECT_EQ(std::accumulate(c.rejected.begin(), c.rejected.end(), std::uint64_t{0}), 2u) << "counters add up";
}

TEST(SampleSource, UnknownSourcesAreNotChecked) {
  // An offline pipeline without writer ids: samples are judged by the gate alone, as before.
  BodyFusion f(one_segment_body(), {}, {}, 0);
  for (std::uint64_t k = 0; k < 10; ++k)
    EXPECT_EQ(f.process({"n", k, exact_sample_at_ns(Quat::Identity(), k * kStepNs)}, 0).outcome,
              SampleOutcome::kEstimated);
  EXPECT_FALSE(f.segment(0).source);
  EXPECT_EQ(conflicting(f), 0u);
}

}  // namespace
}  // namespace bsn::fusion
