#include "demo_display.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "bsn/dds/conversions.hpp"
#include "bsn/logging/log.hpp"
#include "format.hpp"

namespace bsn::services {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

// Seconds after the first estimate that the filters get to converge (they start in motion: the body walks from
// the first sample) before the ranges and errors count.
constexpr double kSettleSeconds = 8.0;

/// Scores an estimate against the truth of its instant: the live error column (the largest of the three angles'
/// errors) and, if it counts, the summary (the first, flexion, angle's, as gait studies report it).
void score(JointView& v, const std::array<double, 3>& estimate, const std::array<double, 3>& truth, bool counts) {
  double worst = 0.0;
  for (std::size_t i = 0; i < 3; ++i) worst = std::max(worst, std::abs(estimate[i] - truth[i]) * kDeg);
  v.recent_error_deg = worst;
  v.has_recent_error = true;
  if (!counts) return;
  const double first = (estimate[0] - truth[0]) * kDeg;
  v.error_sq_sum += first * first;
  v.worst_error_sq_sum += worst * worst;
  ++v.errors;
}

/// Pairs an estimate with the truth of its instant now, or when the truth arrives. Every estimate is scored,
/// whichever of the two arrives first: scoring only those whose truth came first would keep the ones the fusion
/// computed late, a biased share.
void pair_with_truth(JointView& v, const bsn::JointAngles& j, bool counts) {
  if (const auto t = v.truth.find(j.timestamp_ns()); t != v.truth.end()) {
    score(v, j.anatomical(), t->second, counts);
    return;
  }
  v.waiting[j.timestamp_ns()] = {j.anatomical(), counts};
  while (v.waiting.size() > 256) v.waiting.erase(v.waiting.begin());
}

// The flags column: the sample's flags, the non-finite samples so far and a writers' conflict.
std::string joint_flags(const JointView& v) {
  std::string flags = format_flags(v.latest.flags());
  if (v.non_finite) flags += " non-finite=" + std::to_string(v.non_finite);
  if (v.writers > 1) flags += " WRITERS=" + std::to_string(v.writers);
  return flags;
}

}  // namespace

void on_estimate(DemoView& view, const bsn::JointAngles& j, const eprosima::fastdds::dds::SampleInfo& info) {
  std::lock_guard lock(view.mutex);
  auto& v = view.joints[j.joint()];
  v.writers = view.key_writers.note(j.joint(), info.sample_identity.writer_guid(), dds::monotonic_ns());
  v.latest = j;
  v.latest_finite = dds::finite_values(j);
  v.non_finite += v.latest_finite ? 0 : 1;
  ++v.count;
  // A sample with NaN or Inf is shown flagged and counted, never scored (and never cast to a histogram bin).
  if (!v.latest_finite || j.anatomy().empty() || (j.flags() & (bsn::FLAG_INITIALISING | bsn::FLAG_STALE))) return;
  if (view.settled_after_ns == 0)
    view.settled_after_ns =
        j.timestamp_ns() + static_cast<std::uint64_t>((view.walk_start_s ? *view.walk_start_s : kSettleSeconds) * 1e9);
  // The live column shows the error before the alignment too; the summary counts the settled (and aligned) part.
  const bool counts =
      j.timestamp_ns() >= view.settled_after_ns && (!view.walk_start_s || (j.flags() & bsn::FLAG_SEGMENT_FRAME));
  if (counts) {
    const double first = std::clamp(j.anatomical()[0] * kDeg, -180.0, 179.9);
    ++v.histogram[static_cast<std::size_t>((first + 180.0) * 2.0)];
    ++v.values;
  }
  pair_with_truth(v, j, counts);
}

void on_truth(DemoView& view, const bsn::JointAngles& j) {
  std::lock_guard lock(view.mutex);
  JointView& v = view.joints[j.joint()];
  if (const auto w = v.waiting.find(j.timestamp_ns()); w != v.waiting.end()) {
    score(v, w->second.first, j.anatomical(), w->second.second);
    v.waiting.erase(w);
  }
  v.truth[j.timestamp_ns()] = j.anatomical();
  while (v.truth.size() > 256) v.truth.erase(v.truth.begin());
}

void on_alignment_progress(DemoView& view, const bsn::CalibrationProgress& p) {
  std::lock_guard lock(view.mutex);
  if (p.request_id() != view.alignment_id || !view.alignment.empty()) return;
  view.alignment_status = logging::printable(
      p.phase() == bsn::CALIBRATION_PHASE_REFUSED ? "REFUSED: " + p.message() : p.instruction(), 160);
}

void on_alignment_result(DemoView& view, const bsn::CalibrationResult& r) {
  std::lock_guard lock(view.mutex);
  if (r.request_id() != view.alignment_id || r.kind() != bsn::CALIBRATION_SEGMENT_ALIGNMENT) return;
  view.alignment[r.node_id()] = r;
  std::size_t ok = 0;
  std::string failed;
  for (const auto& [node, result] : view.alignment) {
    if (result.success()) {
      ++ok;
    } else if (failed.empty()) {
      failed = ": " + logging::printable(result.message(), 120);
    }
  }
  view.alignment_status = std::to_string(ok) + " of " + std::to_string(view.alignment.size()) +
                          " nodes aligned (request " + view.alignment_id + ")" + failed;
}

std::string render(DemoView& view, const std::vector<std::string>& joint_order, double elapsed_s, bool tty,
                   const std::string& view_url) {
  std::lock_guard lock(view.mutex);
  std::string out;
  char line[512];
  if (tty) out += "\033[H\033[2J";  // home + clear screen
  std::snprintf(line, sizeof line, "bsn demo  %.1f s  joint angles in degrees (Ctrl-C stops)\n", elapsed_s);
  out += line;
  if (!view_url.empty()) out += "live 3D view: " + view_url + "\n";
  std::snprintf(line, sizeof line, "%-10s %-38s %-38s %-38s %9s %7s  %-9s %s\n", "joint", "anatomical angle 1",
                "angle 2", "angle 3", "err truth", "samples", "mounting", "flags");
  out += line;
  for (const auto& name : joint_order) {
    auto it = view.joints.find(name);
    if (it == view.joints.end() || it->second.count == 0) {
      std::snprintf(line, sizeof line, "%-10s (waiting for data)\n", name.c_str());
    } else if (const auto& j = it->second.latest;
               it->second.latest_finite && !j.anatomy().empty() && j.anatomical_names().size() == 3) {
      // Named ISB angles; the error is the largest of the three against the simulator's truth at the same instant.
      std::string cells;
      for (std::size_t i = 0; i < 3; ++i) {
        char cell[64];
        std::snprintf(cell, sizeof cell, "%-29s %8.2f ", logging::printable(j.anatomical_names()[i], 28).c_str(),
                      j.anatomical()[i] * kDeg);
        cells += cell;
      }
      char error[16] = "-";
      if (it->second.has_recent_error) std::snprintf(error, sizeof error, "%.2f", it->second.recent_error_deg);
      const std::string flags = joint_flags(it->second);
      std::snprintf(line, sizeof line, "%-10s %s%9s %7llu  %-9s %s\n", name.c_str(), cells.c_str(), error,
                    static_cast<unsigned long long>(it->second.count),
                    (j.flags() & bsn::FLAG_SEGMENT_FRAME) ? "aligned" : "default", flags.c_str());
    } else {
      // Names from the network are escaped: a writer on the domain cannot drive this terminal.
      const std::string pc = logging::printable(j.parent(), 24) + " -> " + logging::printable(j.child(), 24);
      const std::string flags = joint_flags(it->second);
      if (it->second.latest_finite) {
        std::snprintf(line, sizeof line, "%-10s %-18s %4s %9.2f %9.2f %9.2f  %7llu  %s\n", name.c_str(), pc.c_str(),
                      logging::printable(j.axes(), 8).c_str(), j.angles()[0] * kDeg, j.angles()[1] * kDeg,
                      j.angles()[2] * kDeg, static_cast<unsigned long long>(it->second.count), flags.c_str());
      } else {
        std::snprintf(line, sizeof line, "%-10s %-18s %4s %29s  %7llu  %s\n", name.c_str(), pc.c_str(),
                      logging::printable(j.axes(), 8).c_str(), "NON-FINITE",
                      static_cast<unsigned long long>(it->second.count), flags.c_str());
      }
    }
    out += line;
  }
  if (view.walk_start_s) out += "alignment: " + view.alignment_status + "\n";
  if (view.have_status) {
    out += "nodes:";
    for (const auto& n : view.status.nodes()) {
      std::snprintf(line, sizeof line, " %s %.0fHz%s", logging::printable(n.node_id(), 64).c_str(), n.rate_hz(),
                    n.stale() ? "(STALE)" : "");
      out += line;
    }
    out += "\n";
  }
  return out;
}

DemoOutcome print_summary(DemoView& view, const std::vector<std::string>& joint_order, std::size_t node_count) {
  std::lock_guard lock(view.mutex);
  DemoOutcome outcome;
  std::uint64_t total = 0;
  std::size_t joints_seen = 0;
  for (const auto& name : joint_order) {
    if (auto it = view.joints.find(name); it != view.joints.end() && it->second.count > 0) {
      ++joints_seen;
      total += it->second.count;
    }
  }
  std::printf("bsn demo: %llu joint-angle samples from %zu of %zu joints\n", static_cast<unsigned long long>(total),
              joints_seen, joint_order.size());
  // Per joint with anatomical angles: the first angle's range (2nd to 98th percentile: a joint's sample pairs the
  // child's newest orientation with the parent's latest, which under load can be a few samples old, so single
  // extremes say more about the delivery than about the motion) and the error against the simulator's truth.
  for (const auto& name : joint_order) {
    const auto it = view.joints.find(name);
    if (it == view.joints.end() || it->second.errors == 0 || it->second.latest.anatomical_names().empty()) continue;
    const JointView& v = it->second;
    std::printf(
        "bsn demo: %s %s %.1f .. %.1f deg, error against the truth %.2f deg rms over %llu samples (error column, "
        "the largest of the three angles: %.2f deg rms)\n",
        name.c_str(), logging::printable(v.latest.anatomical_names()[0], 32).c_str(), v.percentile(0.02),
        v.percentile(0.98), std::sqrt(v.error_sq_sum / static_cast<double>(v.errors)),
        static_cast<unsigned long long>(v.errors), std::sqrt(v.worst_error_sq_sum / static_cast<double>(v.errors)));
  }
  if (view.walk_start_s) {
    std::printf("bsn demo: alignment: %s\n", view.alignment_status.c_str());
    for (const auto& [node, r] : view.alignment)
      std::printf("bsn demo:   %s: %s\n", logging::printable(node, 64).c_str(),
                  logging::printable(r.success() ? r.alignment_source() : r.message(), 200).c_str());
    outcome.aligned =
        view.alignment.size() == node_count &&
        std::all_of(view.alignment.begin(), view.alignment.end(), [](const auto& r) { return r.second.success(); });
  }
  outcome.every_joint = joints_seen == joint_order.size();
  return outcome;
}

}  // namespace bsn::services
