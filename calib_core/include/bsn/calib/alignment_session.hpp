// One live sensor-to-segment alignment of a body: the raw samples of all its nodes as they arrive, where the lab
// procedure stands (N-pose, then flexions) and what the subject should do now, and at the end align_body() on them.
// Unlike the per-node sensor calibrations it needs the nodes together: the N-pose is a time when every node is
// still at once, and a hinge's axis comes from the two segments' rates at the same instants (paired by the sensors'
// timestamps: the nodes of one body share one clock, as BSN hardware and `bsn sim --start-at` make them).
// Times are arguments (no clock), nothing is printed; the buffers grow with the samples (reserved in steps).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "bsn/calib/calibration_session.hpp"
#include "bsn/calib/segment_alignment.hpp"

namespace bsn::calib {

/// One node of the body to align.
struct AlignmentNode {
  std::string node;      ///< node id
  std::string segment;   ///< its segment
  std::string joint;     ///< the joint to its parent, e.g. "knee_l" (instructions name it), "" for a root
  int parent = -1;       ///< index (in the session's list, lower than this one) of the parent segment's node, -1: none
  int flexion_sign = 0;  ///< as AlignmentSegment::flexion_sign: -1 knee, +1 hip and ankle, 0 no vote
};

struct AlignmentSessionParams {
  /// Collect for this long from the start, s (wall clock). Default 30 s: 3 s pose, 3 flexions per leg of 2 s, and
  /// slack. The collection also ends earlier with until_good.
  double duration_s = 30.0;
  /// The N-pose: every node still at once for at least this long, s. Default 3 s (the lab procedure's).
  double pose_s = 3.0;
  /// End as soon as the N-pose is found and every joint with a flexion direction has moved min_moving_s.
  bool until_good = false;
  /// Good enough: each such joint moved (one of its two segments faster than the hinge fit's min_rate) this long,
  /// s. Default 3 s: about two flexions of hip, knee and ankle (their slow turning points do not count); the fit
  /// needs 2 s (HingeAxisParams::min_samples).
  double min_moving_s = 3.0;
  /// Still: |gyro| below this on every node, rad/s. Default 0.1 rad/s (6 deg/s): above a consumer gyro's bias
  /// (< 0.02 rad/s) and noise, below the sway of a person standing at ease (~0.02-0.05 rad/s).
  double still_rate_rad_s = 0.1;
  /// A node with no sample this long after the start fails the session, s. Default 5 s: discovery takes 1-2 s.
  double start_timeout_s = 5.0;
  /// A node silent this long after its last sample fails the session, s. Default 2 s.
  double silence_timeout_s = 2.0;
  /// The nodes' samples are paired by sensor time; two samples further apart than this are not paired, s.
  /// Default 0.02 s (two samples at 100 Hz): a node whose clock is off by more pairs with nothing.
  double max_pairing_gap_s = 0.02;
  /// Refused beyond these: 10 min of collection, and 10 min of 1 kHz samples per node.
  double max_duration_s = 600.0;
  std::size_t max_samples = 600'000;
  AlignmentParams fit;
};

/// "" when the parameters describe a collection that can end, else why not.
std::string validate(const AlignmentSessionParams& params);

/// "" when the nodes form a body that can be aligned, else why not (no node, an empty or repeated node id, a
/// parent index out of order).
std::string validate(const std::vector<AlignmentNode>& nodes);

enum class AlignmentPhase { waiting, pose, moves, good_enough };

struct AlignmentProgress {
  AlignmentPhase phase = AlignmentPhase::waiting;
  bool collection_over = false;
  double elapsed_s = 0.0;
  double seconds_left = 0.0;
  double fraction = 0.0;             ///< 0..1: the most advanced of the time and (with until_good) the procedure
  double still_s = 0.0;              ///< the current rest of all nodes at once (waiting, pose), s
  std::vector<std::size_t> samples;  ///< per node
  /// Per node: seconds of movement of the hinge joint to its parent (with a flexion direction), 0 for the others.
  std::vector<double> moving_s;
  std::string instruction;                     ///< what the subject should do now
  std::vector<std::string> node_instructions;  ///< per node, e.g. "moved 2.1 of 4 s"
};

/// The alignment of one node.
struct NodeAlignment {
  bool success = false;
  std::string message;  ///< why it failed, "" on success
  Quat sensor_to_segment = Quat::Identity();
  std::string source;               ///< "pose+hinge <parent>-<child>" or "pose+heading"
  double relative_residual = 0.0;   ///< of the hinge used (0 without)
  double axis_observability = 0.0;  ///< of the axis used in this node's sensor (0 without a hinge)
  std::size_t samples = 0;          ///< of this node, collected
};

struct AlignmentSessionResult {
  std::vector<NodeAlignment> nodes;             ///< in the session's order
  std::string problem;                          ///< why no node could be aligned ("" = at least one is)
  double pose_start_s = 0.0, pose_end_s = 0.0;  ///< the N-pose used, s after the first paired sample
  double moves_end_s = 0.0;        ///< the end of the flexions used (the next rest, or the last sample), same clock
  std::size_t paired_samples = 0;  ///< instants at which every node has a sample
};

class AlignmentSession {
 public:
  /// start_ns: the start on the arrival clock (monotonic, ns). Throws std::invalid_argument when validate() of the
  /// parameters or of the nodes is not empty.
  AlignmentSession(std::vector<AlignmentNode> nodes, const AlignmentSessionParams& params, std::uint64_t start_ns);

  /// Adds a sample of node `index` that arrived at now_ns; ignored once the collection is over.
  void add(std::size_t index, const SessionSample& sample, std::uint64_t now_ns);

  /// True once duration_s has passed, the procedure was done (with until_good, at the last progress()), a node
  /// never sent or fell silent (a failure), or a buffer is full.
  bool collection_over(std::uint64_t now_ns) const;

  /// Where the procedure stands at now_ns (pairs the samples so far: ~1 ms per 10 000 samples).
  AlignmentProgress progress(std::uint64_t now_ns);

  /// Aligns what was collected (call once the collection is over, or to end it early).
  AlignmentSessionResult finish(std::uint64_t now_ns) const;

  const std::vector<AlignmentNode>& nodes() const { return nodes_; }
  const AlignmentSessionParams& params() const { return params_; }
  std::size_t samples(std::size_t index) const { return buffers_.at(index).timestamps.size(); }

 private:
  struct Buffer {
    std::vector<std::uint64_t> timestamps;  ///< sensor clock, increasing
    std::vector<Vec3> acc, gyr, mag;        ///< NaN where the sample lacks the channel
    std::optional<std::uint64_t> last_arrival_ns;
    std::optional<std::uint64_t> last_seq;
    std::size_t non_finite = 0;
  };
  /// The nodes' samples at common instants: the first node's sample times at which every node has a sample within
  /// max_pairing_gap_s (nearest in time). rows[k][i] indexes node i's buffer.
  struct Paired {
    std::vector<std::vector<std::size_t>> rows;
    double rate_hz = 0.0;
  };
  Paired pair() const;
  /// The first run of at least pose_s where every node is still, as [first, last) rows; {0, 0} if none. `longest`
  /// (rows) gets the longest run seen and `trailing` the run at the end.
  std::pair<std::size_t, std::size_t> find_pose(const Paired& p, std::size_t& longest, std::size_t& trailing) const;
  /// The first row from `from` on that starts a rest of every node of at least `rows` rows; p.rows.size() if none.
  std::size_t next_rest(const Paired& p, std::size_t from, std::size_t rows) const;
  bool still(const Paired& p, std::size_t row) const;
  /// Why the collection failed for a silent node, "" if none did.
  std::string silence_failure(std::uint64_t now_ns) const;

  std::vector<AlignmentNode> nodes_;
  AlignmentSessionParams params_;
  std::uint64_t start_ns_;
  std::vector<Buffer> buffers_;
  bool good_enough_ = false;
  bool full_ = false;
};

}  // namespace bsn::calib
