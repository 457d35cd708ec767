// Input validation of one node's raw sample stream, before anything reaches a filter. Every sample that is
// not passed on is counted by reason; nothing is dropped silently.
#pragma once

#include <array>
#include <cstdint>
#include <string_view>

#include "bsn/fusion/imu_sample.hpp"

namespace bsn::fusion {

enum class SampleVerdict {
  kAccepted,
  kAcceptedClockReset,  ///< accepted after the node's clock settled on a new time base; the filter must restart
  kNonFinite,           ///< NaN or Inf in a present channel
  kOutOfRange,          ///< a value beyond the physical plausibility limits (saturated or corrupt)
  kTimeBackward,        ///< timestamp older than the last accepted sample (or reordered)
  kTimeJump,            ///< timestamp too far ahead of the last accepted sample
  kDuplicate,           ///< same sequence number and timestamp as the last accepted sample
  kConflictingSource,   ///< from a second writer while the node's first writer is not stale (BodyFusion's check)
};

inline constexpr std::size_t kRejectionReasonCount = 6;

/// Index of a rejection reason in SampleGate::Counters::rejected, or -1 for an accepting verdict.
int rejection_index(SampleVerdict v);

/// Stable snake_case name of a rejection reason, used on bsn/status ("non_finite", "time_jump", ...).
std::string_view rejection_reason_name(std::size_t index);

class SampleGate {
 public:
  struct Params {
    /// A timestamp more than this ahead of the last accepted one is a jump, s. Real gaps shorter than this
    /// pass and the filter bridges or re-initialises. Default 1 s.
    double max_forward_jump_s = 1.0;
    /// After a jump (forward or back), this many consecutive samples that follow each other in time with
    /// steps of at most max_rebase_step_s establish a new time base (a sensor reboot or clock reset).
    /// Default 5.
    int rebase_after = 5;
    /// Largest step between samples that count towards a new time base, s. Default 0.1 s.
    double max_rebase_step_s = 0.1;
    /// Plausibility limits per axis; larger magnitudes are rejected as out of range. Defaults are well
    /// beyond any body-worn MEMS range: 2000 m/s^2 (~200 g), 100 rad/s (~5700 deg/s), 10000 uT.
    double max_abs_acc_m_s2 = 2000.0;
    double max_abs_gyr_rad_s = 100.0;
    double max_abs_mag_ut = 10000.0;
    /// Largest forward step of the sequence number between two accepted samples that counts as lost samples;
    /// a longer step (a node that renumbered, a forged seq) restarts the count instead. Accepted samples are at
    /// most max_forward_jump_s apart, so this is the loss of 1 s at 100 kHz. Default 100000.
    std::uint64_t max_sequence_gap = 100'000;
    /// A timestamp jump after a silence is an outage (a network cut, a radio dropout), not a new time base,
    /// when the sequence numbers account for it: |dt - steps * period| <= this fraction of steps * period, with
    /// the period learned from consecutive samples. The sample is then accepted, the skipped numbers count as
    /// missing and the filter's own gap rule applies. Sensor clocks drift by ppm and sample jitter is far below
    /// 2 % of a gap longer than max_forward_jump_s, while a clock reset moves time by an unrelated amount.
    /// Default 0.02.
    double outage_tolerance = 0.02;
  };

  struct Counters {
    std::uint64_t received = 0;
    std::uint64_t accepted = 0;
    std::uint64_t missing =
        0;  ///< samples lost: sequence numbers skipped between accepted samples, less those rejected
    std::uint64_t clock_resets = 0;                               ///< new time bases adopted
    std::array<std::uint64_t, kRejectionReasonCount> rejected{};  ///< by rejection_index()
  };

  explicit SampleGate(const Params& params);
  SampleGate() : SampleGate(Params{}) {}

  /// Judges one sample with its per-node sequence number.
  SampleVerdict check(std::uint64_t seq, const ImuSample& sample);
  /// Counts a sample refused before the checks (as received and rejected for `reason`) without letting it touch
  /// the stream's state: it belongs to another stream (a conflicting source), so its seq and timestamp mean nothing
  /// here.
  void refuse(SampleVerdict reason);
  /// Forgets the stream (last sample, sequence base, period, candidate time base) but keeps the counters: the next
  /// sample starts a new stream, as from another source after a handover.
  void restart_stream();

  const Counters& counters() const { return counters_; }
  const Params& params() const { return params_; }

 private:
  SampleVerdict reject_time(SampleVerdict reason, std::uint64_t seq, std::uint64_t t_ns);
  SampleVerdict reject(SampleVerdict reason, std::uint64_t seq);
  SampleVerdict accept(SampleVerdict verdict, std::uint64_t seq, std::uint64_t t_ns);
  /// True if a sample far ahead in time is explained by the samples its sequence number says were lost.
  bool explained_by_lost_samples(std::uint64_t seq, std::uint64_t t_ns) const;

  Params params_;
  std::uint64_t max_jump_ns_;
  std::uint64_t max_rebase_step_ns_;
  Counters counters_;
  bool have_last_ = false;
  std::uint64_t last_seq_ = 0;
  std::uint64_t last_ns_ = 0;
  void count_missing(std::uint64_t seq, bool restart);

  // The sequence base moves with accepted samples only, so that no rejected (possibly forged) number moves it.
  // Steps are taken modulo 2^64: a wrap from 2^64 - 1 to 0 is one step.
  std::uint64_t next_seq_ = 0;            ///< the sequence number expected after the last accepted sample
  std::uint64_t rejected_in_window_ = 0;  ///< rejected since the last accepted sample with a plausible seq ahead
  double period_ns_ = 0.0;                ///< sample period from consecutive accepted samples (0: not yet known)
  int candidate_count_ = 0;               ///< consecutive samples on a candidate new time base
  std::uint64_t candidate_ns_ = 0;
};

}  // namespace bsn::fusion
