#include "bsn/fusion/sample_gate.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace bsn::fusion {
namespace {

constexpr std::string_view kReasonNames[kRejectionReasonCount] = {"non_finite", "out_of_range", "time_backward",
                                                                  "time_jump",  "duplicate",    "conflicting_source"};

bool within(const Vec3& v, double limit) { return v.cwiseAbs().maxCoeff() <= limit; }

}  // namespace

int rejection_index(SampleVerdict v) {
  switch (v) {
    case SampleVerdict::kNonFinite:
      return 0;
    case SampleVerdict::kOutOfRange:
      return 1;
    case SampleVerdict::kTimeBackward:
      return 2;
    case SampleVerdict::kTimeJump:
      return 3;
    case SampleVerdict::kDuplicate:
      return 4;
    case SampleVerdict::kConflictingSource:
      return 5;
    case SampleVerdict::kAccepted:
    case SampleVerdict::kAcceptedClockReset:
      break;
  }
  return -1;
}

std::string_view rejection_reason_name(std::size_t index) {
  return index < kRejectionReasonCount ? kReasonNames[index] : std::string_view("unknown");
}

SampleGate::SampleGate(const Params& params) : params_(params) {
  if (!(params.max_forward_jump_s > 0.0) || !(params.max_rebase_step_s > 0.0) || params.rebase_after < 1 ||
      !(params.max_abs_acc_m_s2 > 0.0) || !(params.max_abs_gyr_rad_s > 0.0) || !(params.max_abs_mag_ut > 0.0) ||
      params.max_sequence_gap < 1 || !(params.outage_tolerance >= 0.0 && params.outage_tolerance < 1.0)) {
    throw std::invalid_argument("sample gate: every limit must be > 0 and rebase_after >= 1");
  }
  max_jump_ns_ = seconds_to_ns(params.max_forward_jump_s);
  max_rebase_step_ns_ = seconds_to_ns(params.max_rebase_step_s);
}

SampleVerdict SampleGate::check(std::uint64_t seq, const ImuSample& s) {
  ++counters_.received;
  SampleVerdict verdict = SampleVerdict::kAccepted;
  if (!s.values_finite()) {
    verdict = SampleVerdict::kNonFinite;
  } else if ((s.has_acc && !within(s.acc, params_.max_abs_acc_m_s2)) ||
             (s.has_gyr && !within(s.gyr, params_.max_abs_gyr_rad_s)) ||
             (s.has_mag && !within(s.mag, params_.max_abs_mag_ut))) {
    verdict = SampleVerdict::kOutOfRange;
  } else if (!have_last_) {
    return accept(SampleVerdict::kAccepted, seq, s.timestamp_ns);
  } else if (s.timestamp_ns == last_ns_ && seq == last_seq_) {
    verdict = SampleVerdict::kDuplicate;
  } else if (s.timestamp_ns <= last_ns_) {
    return reject_time(SampleVerdict::kTimeBackward, seq, s.timestamp_ns);
  } else if (s.timestamp_ns - last_ns_ > max_jump_ns_) {
    if (explained_by_lost_samples(seq, s.timestamp_ns)) return accept(SampleVerdict::kAccepted, seq, s.timestamp_ns);
    return reject_time(SampleVerdict::kTimeJump, seq, s.timestamp_ns);
  } else {
    return accept(SampleVerdict::kAccepted, seq, s.timestamp_ns);
  }
  return reject(verdict, seq);
}

void SampleGate::refuse(SampleVerdict reason) {
  const int index = rejection_index(reason);
  if (index < 0) return;  // not a rejection: nothing to count
  ++counters_.received;
  ++counters_.rejected[static_cast<std::size_t>(index)];
}

void SampleGate::restart_stream() {
  have_last_ = false;
  last_seq_ = last_ns_ = next_seq_ = 0;
  rejected_in_window_ = 0;
  period_ns_ = 0.0;
  candidate_count_ = 0;
  candidate_ns_ = 0;
}

SampleVerdict SampleGate::reject(SampleVerdict verdict, std::uint64_t seq) {
  ++counters_.rejected[static_cast<std::size_t>(rejection_index(verdict))];
  // A rejected sample arrived, so its number is not lost, but it leaves the base alone: it only offsets the
  // next gap, if its number lies in the plausible window ahead.
  if (have_last_ && seq - next_seq_ < params_.max_sequence_gap) ++rejected_in_window_;
  return verdict;
}

void SampleGate::count_missing(std::uint64_t seq, bool restart) {
  // Lost samples are the numbers skipped since the last accepted sample (modulo 2^64) that no rejected sample
  // carried. A number behind the base (reordering, a node restarting its count) or implausibly far ahead restarts
  // the count: no loss.
  const std::uint64_t step = seq - next_seq_;
  if (have_last_ && !restart && step < params_.max_sequence_gap)
    counters_.missing += step - std::min(step, rejected_in_window_);
  next_seq_ = seq + 1;
  rejected_in_window_ = 0;
}

SampleVerdict SampleGate::reject_time(SampleVerdict reason, std::uint64_t seq, std::uint64_t t_ns) {
  // Consecutive samples that agree with each other but not with the old time base are a clock reset.
  if (candidate_count_ > 0 && t_ns > candidate_ns_ && t_ns - candidate_ns_ <= max_rebase_step_ns_) {
    ++candidate_count_;
  } else {
    candidate_count_ = 1;
  }
  candidate_ns_ = t_ns;
  if (candidate_count_ >= params_.rebase_after) {
    ++counters_.clock_resets;
    return accept(SampleVerdict::kAcceptedClockReset, seq, t_ns);  // a rebooted node restarts its sequence too
  }
  return reject(reason, seq);
}

bool SampleGate::explained_by_lost_samples(std::uint64_t seq, std::uint64_t t_ns) const {
  const std::uint64_t steps = seq - last_seq_;  // modulo 2^64, like the missing count
  if (!(period_ns_ > 0.0) || steps < 2 || steps >= params_.max_sequence_gap) return false;
  const double expected_ns = static_cast<double>(steps) * period_ns_;
  return std::abs(static_cast<double>(t_ns - last_ns_) - expected_ns) <= params_.outage_tolerance * expected_ns;
}

SampleVerdict SampleGate::accept(SampleVerdict verdict, std::uint64_t seq, std::uint64_t t_ns) {
  ++counters_.accepted;
  // The period, from consecutive samples only (a gap or a new time base says nothing about it); a slow average,
  // so one late sample barely moves it.
  if (have_last_ && verdict == SampleVerdict::kAccepted && seq - last_seq_ == 1 && t_ns > last_ns_) {
    const double dt = static_cast<double>(t_ns - last_ns_);
    period_ns_ = period_ns_ > 0.0 ? period_ns_ + (dt - period_ns_) / 16.0 : dt;
  }
  count_missing(seq, verdict == SampleVerdict::kAcceptedClockReset);
  have_last_ = true;
  last_seq_ = seq;
  last_ns_ = t_ns;
  candidate_count_ = 0;
  return verdict;
}

}  // namespace bsn::fusion
