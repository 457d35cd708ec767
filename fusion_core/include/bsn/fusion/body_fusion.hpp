// The per-sample pipeline of one body: calibration -> input gate -> filter -> joint angles, with the per-node
// counters bsn/status reports. No clocks and no logging: arrival times are arguments, and what a service logs
// (clock reset, node stale or fresh, a new unknown node) comes back as events.
#pragma once

#include <array>
#include <functional>
#include <span>
#include <string_view>
#include <unordered_map>

#include "bsn/calib/sensor_calibration.hpp"
#include "bsn/fusion/body_model.hpp"
#include "bsn/fusion/sample_gate.hpp"

namespace bsn::fusion {

/// The writer a sample came from, opaque to the core: a service fills in what its transport names a writer by (a
/// DDS writer GUID is 16 bytes). All zero is an unknown source (an offline pipeline): such samples skip the check.
struct SourceId {
  std::array<std::uint8_t, 16> bytes{};
  bool known() const { return bytes != std::array<std::uint8_t, 16>{}; }
  friend bool operator==(const SourceId&, const SourceId&) = default;
};

/// One raw sample as a node sent it: node id, the node's sequence number, uncalibrated values on the sensor clock.
struct NodeSample {
  std::string_view node;
  std::uint64_t seq = 0;
  ImuSample imu;
};

/// The joint from a segment's parent to the segment, at the segment's sample.
struct JointEstimate {
  std::size_t parent = 0, child = 0;  ///< segment indices
  Quat relative;               ///< q_parent* (x) q_child of the published frames (SampleResult::orientation), w >= 0
  Vec3 angles;                 ///< relative decomposed in the child's joint_axes, rad
  JointConvention convention;  ///< the anatomical convention of the joint (type kNone: no anatomical angles)
  Vec3 anatomical = Vec3::Zero();  ///< ISB angles of the two segment frames, rad, see anatomy.hpp
  bool aligned = false;            ///< both sensor-to-segment rotations are known (not the default mounting)
  bool stale = false;              ///< the parent's or the child's node is stale
  bool initialising = false;       ///< the parent's or the child's filter is initialising
  /// With `heading: kinematic` on the joint: the estimator after this sample (its offset_rad turned the child
  /// about the vertical before `relative`, `angles` and `anatomical` were computed; its observability says how
  /// well the hinge axis showed the offset lately). nullopt: the plain mode, the filters' headings as they are.
  std::optional<HingeHeadingEstimator::State> heading;
};

enum class SampleOutcome { kEstimated, kGateRejected, kFilterRejected, kUnknownNode };

struct SampleResult {
  SampleOutcome outcome = SampleOutcome::kUnknownNode;
  std::size_t segment = 0;                           ///< unless kUnknownNode
  SampleVerdict verdict = SampleVerdict::kAccepted;  ///< the gate's (why kGateRejected), unless kUnknownNode
  bool node_fresh = false;                           ///< event: the node was stale and sends again
  bool clock_reset = false;       ///< event: the node's clock moved to a new time base; its filter restarted
  bool new_unknown_node = false;  ///< event: first sample of an unknown node, which is now listed
  /// event: rejected as kConflictingSource from a writer other than the last one rejected so for this node
  bool new_conflicting_source = false;
  /// event: the node was stale and this sample's writer took it over from the previous one (whose id is in
  /// previous_source); its gate restarted the stream and its filter restarted
  bool source_handover = false;
  SourceId previous_source;
  // With kEstimated: the orientation (sensor-to-earth, or segment-to-earth when `aligned`), the filter's flags and
  // gyro bias (rad/s, sensor frame).
  Quat orientation = Quat::Identity();
  bool aligned = false;  ///< the segment's sensor-to-segment rotation is known: `orientation` is the segment frame
  FilterFlags flags;
  Vec3 gyro_bias = Vec3::Zero();
  std::optional<JointEstimate> joint;  ///< the joint to the parent, once the parent has an orientation
};

class BodyFusion {
 public:
  struct Params {
    /// A node with no sample for this long is reported stale, s. Default 0.3 s (30 samples at 100 Hz).
    double stale_timeout_s = 0.3;
    /// A node that never sent is reported stale this long after the start, s: time for discovery.
    double discovery_grace_s = 2.0;
    /// A joint pairs the child's new orientation with the parent's latest, which may be a few samples older (its
    /// sample has not arrived yet). The parent is turned on by its last bias-corrected gyro rate to the child's
    /// sample time when the two sensor times differ by at most this, s (a lag of one sample at 300 deg/s, a thigh
    /// in swing, is 3 deg at 100 Hz). A body's sensor clocks are taken to be one clock (as BSN hardware and
    /// `bsn sim --start-at` make them); a larger difference is not a lag but another clock, and the parent's latest
    /// is used as it is. Default 0.05 s (5 samples at 100 Hz); 0 turns it off.
    double max_joint_extrapolation_s = 0.05;
    SampleGate::Params gate;
  };
  /// Per node id: the calibration applied to every raw sample (u = H (raw - B)) before the gate and filter.
  using Calibrations = std::unordered_map<std::string, calib::SensorCalibration>;
  static constexpr std::size_t kMaxUnknownNodesListed = 16;

  /// One segment's pipeline and what bsn/status reports of its node.
  struct Segment {
    std::unique_ptr<OrientationFilter> filter;
    SampleGate gate;  ///< counts received, accepted, missing, clock resets, rejected by reason
    calib::SensorCalibration calibration;
    std::optional<std::size_t> parent;
    std::uint64_t filter_rejected = 0;  ///< passed the gate, not used by the filter
    std::optional<Quat> q;              ///< the last published orientation (sensor frame, or segment frame if aligned)
    std::optional<Quat> q_segment;      ///< the last segment (ISB) frame orientation, default mounting if not aligned
    Quat sensor_to_segment = default_sensor_to_segment();
    bool aligned = false;              ///< sensor_to_segment is known (body file or alignment), not the default
    FilterFlags flags;                 ///< of the last orientation
    Quat q_sensor = Quat::Identity();  ///< the last sensor-frame orientation (valid with q)
    Vec3 rate = Vec3::Zero();          ///< the last bias-corrected gyro rate, rad/s, sensor frame (valid with q)
    std::uint64_t timestamp_ns = 0;    ///< sensor time of the last orientation (valid with q)
    std::optional<std::uint64_t> last_arrival_ns;  ///< of the last sample from the node's source
    bool stale = false;  ///< silent for the stale timeout (or, never heard of, the discovery grace)
    /// The writer the node's samples are taken from: the first one heard, until the node goes stale; then the
    /// next writer heard takes over (a handover). Samples from any other writer are rejected as kConflictingSource
    /// and do not keep the node fresh. Unset until the first sample with a known source.
    std::optional<SourceId> source;
    std::optional<SourceId> conflicting_source;  ///< the last other writer rejected as kConflictingSource
    std::uint64_t source_handovers = 0;          ///< times another writer took the node over after it went stale
    /// With `heading: kinematic`: the hinge heading estimator of the joint to the parent (axes in segment frames).
    std::optional<HingeHeadingEstimator> kinematic_heading;
  };

  /// start_ns: the start on the arrival clock (monotonic, ns), from which the discovery grace runs.
  /// Throws std::invalid_argument for a filter spec or gate parameters that make_filter or SampleGate refuse.
  BodyFusion(BodyModel body, const Calibrations& calibrations, const Params& params, std::uint64_t start_ns);

  /// Runs one sample, from the writer `source`, through its segment's pipeline; the result is valid until the next
  /// call. A sample whose source is not the node's (see Segment::source) is counted by the gate as
  /// kConflictingSource and goes no further.
  const SampleResult& process(const NodeSample& sample, std::uint64_t arrival_ns, const SourceId& source = {});
  /// A live calibration: replaces the channels that `update` holds in the calibration of `node`'s segment (the
  /// others stay), from its next sample on, and restarts its filter, whose state (orientation, the disturbance
  /// detector's magnetic reference, the gyro bias estimate) was built on the old calibration. Returns the
  /// segment, nullopt for a node on no segment.
  std::optional<std::size_t> update_calibration(std::string_view node, const calib::SensorCalibration& update);
  /// A new sensor-to-segment rotation of `node`'s segment (an alignment), from its next sample on; the filter keeps
  /// running (the sensor's orientation does not change). Returns the segment, nullopt for a node on no segment.
  std::optional<std::size_t> update_alignment(std::string_view node, const Quat& sensor_to_segment);
  /// The segment of a node, nullopt for a node on no segment.
  std::optional<std::size_t> segment_of(std::string_view node) const;
  /// Marks the nodes silent at now_ns stale; returns the segments that turned stale with this call.
  std::span<const std::size_t> check_stale(std::uint64_t now_ns);

  const BodyModel& body() const { return body_; }
  const Segment& segment(std::size_t index) const { return segments_.at(index); }
  std::uint64_t unknown_node_samples() const { return unknown_node_samples_; }
  /// The first kMaxUnknownNodesListed unknown node ids, in order of their first sample.
  const std::vector<std::string>& unknown_nodes() const { return unknown_nodes_; }

 private:
  /// The joint of segment `index` (seg, with its parent's latest estimate) at seg's sample time.
  JointEstimate joint_estimate(std::size_t index, Segment& seg, const Segment& parent);

  BodyModel body_;
  std::uint64_t stale_timeout_ns_, discovery_end_ns_, max_joint_extrapolation_ns_;
  std::vector<Segment> segments_;
  // Node id -> segment index, looked up with the sample's string_view: one hash per sample, no allocation.
  struct NodeHash {
    using is_transparent = void;
    std::size_t operator()(std::string_view node) const { return std::hash<std::string_view>{}(node); }
  };
  std::unordered_map<std::string, std::size_t, NodeHash, std::equal_to<>> segment_of_node_;
  std::uint64_t unknown_node_samples_ = 0;
  std::vector<std::string> unknown_nodes_;
  SampleResult result_;
  std::vector<std::size_t> turned_stale_;
};

}  // namespace bsn::fusion
