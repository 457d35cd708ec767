// SampleGate: every sample either reaches the filter or is counted under one reason.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "bsn/fusion/sample_gate.hpp"

namespace bsn::fusion {
namespace {

constexpr std::uint64_t kMs = 1'000'000;

ImuSample at(std::uint64_t t_ns) {
  ImuSample s;
  s.timestamp_ns = t_ns;
  s.acc = Vec3(0, 0, kGravity);
  s.mag = Vec3(0, 20, -40);
  return s;
}

std::uint64_t rejected(const SampleGate& g, SampleVerdict v) {
  return g.counters().rejected[static_cast<std::size_t>(rejection_index(v))];
}

TEST(SampleGate, AcceptsAStream) {
  SampleGate g;
  for (std::uint64_t k = 0; k < 100; ++k) EXPECT_EQ(g.check(k, at(k * 10 * kMs)), SampleVerdict::kAccepted);
  EXPECT_EQ(g.counters().accepted, 100u);
  EXPECT_EQ(g.counters().received, 100u);
  EXPECT_EQ(g.counters().missing, 0u);
}

TEST(SampleGate, CountsEachRejectionByReasonAndRecovers) {
  SampleGate g;
  std::uint64_t seq = 0, t = 1000 * kMs;
  auto next = [&] {
    ++seq;
    t += 10 * kMs;
    return at(t);
  };
  EXPECT_EQ(g.check(seq, at(t)), SampleVerdict::kAccepted);
  ImuSample nan = next();
  nan.gyr.x() = std::nan("");
  EXPECT_EQ(g.check(seq, nan), SampleVerdict::kNonFinite);
  ImuSample inf = next();
  inf.mag.z() = INFINITY;
  EXPECT_EQ(g.check(seq, inf), SampleVerdict::kNonFinite);
  ImuSample huge = next();
  huge.acc.x() = 1e6;
  EXPECT_EQ(g.check(seq, huge), SampleVerdict::kOutOfRange);
  const ImuSample good = next();  // before the call: the order of a call's arguments is unspecified
  EXPECT_EQ(g.check(seq, good), SampleVerdict::kAccepted);  // good sample right after: recovered
  const std::uint64_t last_good = t;
  EXPECT_EQ(g.check(seq, at(last_good)), SampleVerdict::kDuplicate);
  EXPECT_EQ(g.check(seq + 1, at(last_good - 500 * kMs)), SampleVerdict::kTimeBackward);
  EXPECT_EQ(g.check(seq + 2, at(last_good + 100'000 * kMs)), SampleVerdict::kTimeJump);
  seq += 3;
  t = last_good + 10 * kMs;
  EXPECT_EQ(g.check(seq, at(t)), SampleVerdict::kAccepted);

  EXPECT_EQ(rejected(g, SampleVerdict::kNonFinite), 2u);
  EXPECT_EQ(rejected(g, SampleVerdict::kOutOfRange), 1u);
  EXPECT_EQ(rejected(g, SampleVerdict::kDuplicate), 1u);
  EXPECT_EQ(rejected(g, SampleVerdict::kTimeBackward), 1u);
  EXPECT_EQ(rejected(g, SampleVerdict::kTimeJump), 1u);
  EXPECT_EQ(g.counters().received, g.counters().accepted + 6u);
  // Rejected samples arrived: they are not lost.
  EXPECT_EQ(g.counters().missing, 0u);
}

TEST(SampleGate, MissingSamplesFromSequenceGaps) {
  SampleGate g;
  g.check(0, at(0));
  g.check(1, at(10 * kMs));
  g.check(5, at(50 * kMs));  // 2, 3, 4 lost
  EXPECT_EQ(g.counters().missing, 3u);
  EXPECT_EQ(g.counters().accepted, 3u);
  g.check(3, at(40 * kMs));  // late arrival of a sample counted missing: rejected, and no new loss
  EXPECT_EQ(g.counters().missing, 3u);
}

TEST(SampleGate, SequenceWrapIsNoLoss) {
  // seq is a uint64 that wraps from 2^64 - 1 to 0 like any counter; the wrap loses nothing, a gap across it does.
  SampleGate g;
  constexpr std::uint64_t kTop = std::numeric_limits<std::uint64_t>::max();
  std::uint64_t seq = kTop - 50;
  for (int k = 0; k < 100; ++k) g.check(seq++, at(static_cast<std::uint64_t>(k) * 10 * kMs));
  EXPECT_EQ(g.counters().accepted, 100u);
  EXPECT_EQ(g.counters().missing, 0u);
  g.check(seq + 2, at(100 * 10 * kMs));  // two lost right after the wrap
  EXPECT_EQ(g.counters().missing, 2u);
  SampleGate h;
  h.check(kTop - 1, at(0));
  h.check(1, at(10 * kMs));  // kTop and 0 lost across the wrap
  EXPECT_EQ(h.counters().missing, 2u);
}

TEST(SampleGate, RejectedSamplesDoNotMoveTheSequenceBase) {
  // One hostile sample with seq 2^64 - 1 (or any far number) inside a real stream is rejected and leaves the
  // sequence base where it was: the stream that follows loses nothing.
  constexpr std::uint64_t kTop = std::numeric_limits<std::uint64_t>::max();
  for (const std::uint64_t hostile_seq : {kTop, kTop / 2, std::uint64_t{1} << 40, std::uint64_t{0}}) {
    SampleGate g;
    std::uint64_t t = 1000 * kMs;
    for (std::uint64_t k = 10; k < 20; ++k) g.check(k, at(t += 10 * kMs));
    ImuSample nan = at(t + 5 * kMs);
    nan.acc.x() = std::nan("");
    EXPECT_EQ(g.check(hostile_seq, nan), SampleVerdict::kNonFinite);
    EXPECT_EQ(g.check(hostile_seq, at(t - 5 * kMs)), SampleVerdict::kTimeBackward);
    EXPECT_EQ(g.check(hostile_seq, at(t + 100'000 * kMs)), SampleVerdict::kTimeJump);
    for (std::uint64_t k = 20; k < 1000; ++k) g.check(k, at(t += 10 * kMs));
    EXPECT_EQ(g.counters().missing, 0u) << "hostile seq " << hostile_seq;
    EXPECT_EQ(g.counters().accepted, 990u);
  }
}

TEST(SampleGate, AnImplausibleSequenceJumpIsARestartNotALoss) {
  // An accepted sample whose seq jumps further than max_sequence_gap (a node that renumbered, or a forged seq
  // with a plausible time) restarts the count: it cannot be that many samples lost within max_forward_jump_s.
  SampleGate g;
  std::uint64_t t = 0;
  for (std::uint64_t k = 0; k < 10; ++k) g.check(k, at(t += 10 * kMs));
  g.check(std::uint64_t{1} << 50, at(t += 10 * kMs));
  EXPECT_EQ(g.counters().missing, 0u);
  g.check((std::uint64_t{1} << 50) + 3, at(t += 10 * kMs));  // 2 lost after the restart
  EXPECT_EQ(g.counters().missing, 2u);
  g.check(5, at(t += 10 * kMs));  // renumbered backwards: also a restart
  g.check(6, at(t += 10 * kMs));
  g.check(8, at(t += 10 * kMs));  // 7 lost
  EXPECT_EQ(g.counters().missing, 3u);
  EXPECT_EQ(g.counters().accepted, 15u);
}

TEST(SampleGate, AdoptsANewTimeBaseAfterConsistentSamples) {
  SampleGate::Params p;
  p.rebase_after = 5;
  SampleGate g(p);
  for (std::uint64_t k = 0; k < 10; ++k) g.check(k, at(1'000'000 * kMs + k * 10 * kMs));
  // The node reboots: its clock restarts near zero and keeps going.
  for (std::uint64_t k = 0; k < 4; ++k) EXPECT_EQ(g.check(k, at(k * 10 * kMs)), SampleVerdict::kTimeBackward);
  EXPECT_EQ(g.check(4, at(40 * kMs)), SampleVerdict::kAcceptedClockReset);
  EXPECT_EQ(g.check(5, at(50 * kMs)), SampleVerdict::kAccepted);
  EXPECT_EQ(g.counters().clock_resets, 1u);
  EXPECT_EQ(rejected(g, SampleVerdict::kTimeBackward), 4u);
}

TEST(SampleGate, AnOutageIsAGapNotANewTimeBase) {
  // 100 Hz, then 5 s of silence (a network cut) during which the node kept counting: the first sample after it
  // is 500 numbers and 5 s on. That is a gap: accepted, 499 samples missing, no jump and no clock reset.
  SampleGate g;
  std::uint64_t seq = 0, t = 1000 * kMs;
  for (; seq < 100; ++seq, t += 10 * kMs) g.check(seq, at(t));
  seq += 499;
  t += 499 * 10 * kMs;
  EXPECT_EQ(g.check(seq, at(t)), SampleVerdict::kAccepted);
  EXPECT_EQ(g.check(seq + 1, at(t + 10 * kMs)), SampleVerdict::kAccepted);
  EXPECT_EQ(g.counters().missing, 499u);
  EXPECT_EQ(g.counters().clock_resets, 0u);
  EXPECT_EQ(rejected(g, SampleVerdict::kTimeJump), 0u);
}

TEST(SampleGate, AJumpTheSequenceDoesNotExplainIsStillAJump) {
  SampleGate g;
  std::uint64_t t = 1000 * kMs;
  for (std::uint64_t k = 0; k < 100; ++k, t += 10 * kMs) g.check(k, at(t));
  const std::uint64_t last = t - 10 * kMs;
  EXPECT_EQ(g.check(100, at(last + 5000 * kMs)), SampleVerdict::kTimeJump);  // next number, 5 s later
  EXPECT_EQ(g.check(110, at(last + 5000 * kMs)), SampleVerdict::kTimeJump);  // 10 numbers, 5 s
  EXPECT_EQ(g.check(600, at(last + 5200 * kMs)), SampleVerdict::kTimeJump);  // 500 numbers, 5.2 s: 4 % off
  EXPECT_EQ(g.check(600, at(last + 5050 * kMs)), SampleVerdict::kAccepted);  // 500 numbers, 5.05 s: 1 % off
  EXPECT_EQ(g.counters().clock_resets, 0u);
}

TEST(SampleGate, WithoutAKnownPeriodAJumpIsAJump) {
  // One sample before the silence gives no period: the gap cannot be checked against the numbers.
  SampleGate g;
  g.check(0, at(0));
  EXPECT_EQ(g.check(500, at(5000 * kMs)), SampleVerdict::kTimeJump);
}

TEST(SampleGate, ScatteredBadTimestampsNeverBecomeATimeBase) {
  SampleGate g;
  std::uint64_t t = 0;
  for (std::uint64_t k = 0; k < 200; ++k) {
    t += 10 * kMs;
    if (k % 3 == 1) {
      EXPECT_EQ(g.check(k, at(t + 5'000'000 * kMs)), SampleVerdict::kTimeJump);  // lone glitches, far apart
    } else {
      EXPECT_EQ(g.check(k, at(t)), SampleVerdict::kAccepted);
    }
  }
  EXPECT_EQ(g.counters().clock_resets, 0u);
}

TEST(SampleGate, MissingChannelsAreNotJudged) {
  SampleGate g;
  ImuSample s = at(0);
  s.has_mag = false;
  s.mag = Vec3::Constant(std::nan(""));
  EXPECT_EQ(g.check(0, s), SampleVerdict::kAccepted);
}

TEST(SampleGate, RejectsNonsenseParameters) {
  SampleGate::Params p;
  p.max_forward_jump_s = 0.0;
  EXPECT_THROW(SampleGate{p}, std::invalid_argument);
  p = {};
  p.rebase_after = 0;
  EXPECT_THROW(SampleGate{p}, std::invalid_argument);
  p = {};
  p.outage_tolerance = std::nan("");
  EXPECT_THROW(SampleGate{p}, std::invalid_argument);
}

TEST(SampleGate, ReasonNamesAreStable) {
  // These names are on the wire (bsn/status); changing them breaks subscribers.
  EXPECT_EQ(rejection_reason_name(0), "non_finite");
  EXPECT_EQ(rejection_reason_name(1), "out_of_range");
  EXPECT_EQ(rejection_reason_name(2), "time_backward");
  EXPECT_EQ(rejection_reason_name(3), "time_jump");
  EXPECT_EQ(rejection_reason_name(4), "duplicate");
  EXPECT_EQ(rejection_reason_name(5), "conflicting_source");
  EXPECT_EQ(rejection_reason_name(kRejectionReasonCount), "unknown");
}

}  // namespace
}  // namespace bsn::fusion
