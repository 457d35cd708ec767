// What `bsn demo` shows: per joint the latest estimate, its error against the simulator's truth of the same instant,
// and the range and error summary once the filters have settled; the alignment's progress. Fed by the demo's DDS
// readers (on_* under the view's mutex), drawn by render() and summed up by print_summary().
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "bsn/dds/participant.hpp"
#include "bsn/dds/sample_source.hpp"

namespace bsn::services {

/// Per joint: the latest estimate, the simulator's truth by sensor time (to pair each estimate with the truth of its
/// own instant), and the first angle's range and error against the truth once the filters have settled.
struct JointView {
  bsn::JointAngles latest;
  bool latest_finite = true;  ///< false: the latest sample held a NaN or Inf (shown flagged, no numbers)
  std::uint64_t count = 0;
  std::uint64_t non_finite = 0;  ///< samples with non-finite numbers
  std::size_t writers = 1;       ///< writers of this joint within the last second (more than 1: a conflict)
  std::map<std::uint64_t, std::array<double, 3>> truth;  ///< sensor time -> anatomical angles, the last ~2 s
  /// Estimates whose truth has not arrived yet (the simulator's and the fusion's samples race), sensor time ->
  /// anatomical angles and whether it counts in the summary: scored when the truth comes, the last ~2 s.
  std::map<std::uint64_t, std::pair<std::array<double, 3>, bool>> waiting;
  double error_sq_sum = 0.0, recent_error_deg = 0.0;
  double worst_error_sq_sum = 0.0;  ///< of the error column (the largest of the three angles' errors), counted ones
  bool has_recent_error = false;
  std::uint64_t errors = 0;
  /// The first angle's values in 0.5 deg bins over -180..180 deg: its range as percentiles, in bounded memory.
  std::array<std::uint32_t, 720> histogram{};
  std::uint64_t values = 0;
  /// The angle below which `share` of the values lie, deg.
  double percentile(double share) const {
    const auto wanted = static_cast<std::uint64_t>(share * static_cast<double>(values));
    std::uint64_t seen = 0;
    for (std::size_t b = 0; b < histogram.size(); ++b)
      if ((seen += histogram[b]) > wanted) return -180.0 + 0.5 * static_cast<double>(b) + 0.25;
    return 180.0;
  }
};

struct DemoView {
  std::mutex mutex;
  std::map<std::string, JointView> joints;
  dds::KeyWriters key_writers;
  bsn::Status status;
  bool have_status = false;
  std::uint64_t settled_after_ns = 0;  ///< sensor time from which estimates count in the ranges and errors
  /// With the live alignment: estimates count from this long after the first one (the walking's start), and only
  /// once both segments of the joint are aligned (FLAG_SEGMENT_FRAME).
  std::optional<double> walk_start_s;
  std::string alignment_id;  ///< the demo's alignment request
  std::string alignment_status = "waiting for the calibration service";
  std::map<std::string, bsn::CalibrationResult> alignment;  ///< its results, by node
};

/// A joint-angle estimate from the fusion: shown, and scored against the truth of its instant.
void on_estimate(DemoView& view, const bsn::JointAngles& j, const eprosima::fastdds::dds::SampleInfo& info);
/// The simulator's joint angles of one instant: the truth the estimates of that instant are scored against.
void on_truth(DemoView& view, const bsn::JointAngles& j);
/// The calibration service's progress on the demo's alignment request.
void on_alignment_progress(DemoView& view, const bsn::CalibrationProgress& p);
/// One node's alignment result of the demo's request.
void on_alignment_result(DemoView& view, const bsn::CalibrationResult& r);

/// The terminal page: the joints in `joint_order`, the alignment, the nodes' rates. `tty`: clear the screen first.
std::string render(DemoView& view, const std::vector<std::string>& joint_order, double elapsed_s, bool tty,
                   const std::string& view_url);

/// Prints the closing summary (samples per joint, each joint's range and error against the truth, the alignment) and
/// returns whether every joint produced angles and, with the alignment, whether every one of `node_count` nodes
/// aligned (`aligned`; true without an alignment).
struct DemoOutcome {
  bool every_joint = false;
  bool aligned = true;
};
DemoOutcome print_summary(DemoView& view, const std::vector<std::string>& joint_order, std::size_t node_count);

}  // namespace bsn::services
