#include "bsn/fusion/body_fusion.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace bsn::fusion {
namespace {

// u = H (raw - B) on every calibrated channel that the sample carries.
void apply_calibration(const calib::SensorCalibration& c, ImuSample& s) {
  if (c.accelerometer && s.has_acc) s.acc = calib::apply(*c.accelerometer, s.acc);
  if (c.gyroscope && s.has_gyr) s.gyr = calib::apply(*c.gyroscope, s.gyr);
  if (c.magnetometer && s.has_mag) s.mag = calib::apply(*c.magnetometer, s.mag);
}

}  // namespace

BodyFusion::BodyFusion(BodyModel body, const Calibrations& calibrations, const Params& params, std::uint64_t start_ns)
    : body_(std::move(body)),
      stale_timeout_ns_(seconds_to_ns(std::max(0.0, params.stale_timeout_s))),
      discovery_end_ns_(start_ns + seconds_to_ns(std::max(0.0, params.discovery_grace_s))),
      max_joint_extrapolation_ns_(seconds_to_ns(std::isfinite(params.max_joint_extrapolation_s)
                                                    ? std::clamp(params.max_joint_extrapolation_s, 0.0, 1.0)
                                                    : 0.0)),
      segments_(body_.segments.size()) {
  turned_stale_.reserve(segments_.size());
  for (std::size_t i = 0; i < segments_.size(); ++i) {
    const SegmentSpec& spec = body_.segments[i];
    segments_[i].filter = make_filter(spec.filter);
    segments_[i].gate = SampleGate(params.gate);
    if (const auto c = calibrations.find(spec.node); c != calibrations.end()) segments_[i].calibration = c->second;
    segments_[i].parent = body_.find_segment(spec.parent);
    if (spec.kinematic_heading && segments_[i].parent)
      segments_[i].kinematic_heading.emplace(*kinematic_heading_params(spec));
    if (spec.sensor_to_segment) {
      segments_[i].sensor_to_segment = spec.sensor_to_segment->normalized();
      segments_[i].aligned = true;
    }
    segment_of_node_.emplace(spec.node, i);
  }
}

const SampleResult& BodyFusion::process(const NodeSample& in, std::uint64_t arrival_ns, const SourceId& source) {
  SampleResult& r = result_ = SampleResult{};
  const auto index = segment_of_node_.find(in.node);
  if (index == segment_of_node_.end()) {
    ++unknown_node_samples_;
    r.new_unknown_node = unknown_nodes_.size() < kMaxUnknownNodesListed &&
                         std::find(unknown_nodes_.begin(), unknown_nodes_.end(), in.node) == unknown_nodes_.end();
    if (r.new_unknown_node) unknown_nodes_.emplace_back(in.node);
    return r;
  }
  r.segment = index->second;
  Segment& seg = segments_[r.segment];
  if (source.known()) {
    if (!seg.source) {
      seg.source = source;  // the first writer heard owns the node
    } else if (*seg.source != source) {
      // Stale by the flag (check_stale) or by this arrival, whichever comes first: the owner has been silent.
      const bool owner_silent =
          seg.stale || (seg.last_arrival_ns && arrival_ns > *seg.last_arrival_ns + stale_timeout_ns_);
      if (!owner_silent) {
        // Two writers of one node interleave two unrelated streams; the owner's keeps the filter. The rejected
        // sample leaves the gate's stream and the node's freshness alone.
        seg.gate.refuse(SampleVerdict::kConflictingSource);
        r.outcome = SampleOutcome::kGateRejected;
        r.verdict = SampleVerdict::kConflictingSource;
        r.new_conflicting_source = seg.conflicting_source != source;
        seg.conflicting_source = source;
        return r;
      }
      // The owner went stale: this writer takes the node over. Its sequence numbers and clock are its own, so the
      // gate starts a new stream and the filter restarts.
      r.source_handover = true;
      r.previous_source = *seg.source;
      seg.source = source;
      ++seg.source_handovers;
      seg.gate.restart_stream();
      seg.filter->reset();
    }
  }
  seg.last_arrival_ns = arrival_ns;
  r.node_fresh = std::exchange(seg.stale, false);

  ImuSample s = in.imu;
  apply_calibration(seg.calibration, s);
  r.verdict = seg.gate.check(in.seq, s);
  r.clock_reset = r.verdict == SampleVerdict::kAcceptedClockReset;
  if (r.clock_reset) {
    seg.filter->reset();
  } else if (r.verdict != SampleVerdict::kAccepted) {
    r.outcome = SampleOutcome::kGateRejected;  // counted by the gate
    return r;
  }
  if (seg.filter->update(s) == UpdateResult::kRejected) {
    ++seg.filter_rejected;
    r.outcome = SampleOutcome::kFilterRejected;
    return r;
  }
  r.outcome = SampleOutcome::kEstimated;
  const Quat q_sensor = seg.filter->orientation();
  seg.q_segment = segment_orientation(q_sensor, seg.sensor_to_segment);
  r.aligned = seg.aligned;
  r.orientation = *(seg.q = seg.aligned ? *seg.q_segment : q_sensor);
  r.flags = seg.flags = seg.filter->flags();
  r.gyro_bias = seg.filter->gyro_bias();
  seg.q_sensor = q_sensor;
  seg.rate = s.has_gyr ? Vec3(s.gyr - r.gyro_bias) : Vec3::Zero();
  seg.timestamp_ns = s.timestamp_ns;
  if (const Segment* parent = seg.parent ? &segments_[*seg.parent] : nullptr; parent && parent->q) {
    r.joint = joint_estimate(r.segment, seg, *parent);
  }
  return r;
}

JointEstimate BodyFusion::joint_estimate(std::size_t index, Segment& seg, const Segment& parent) {
  const SegmentSpec& spec = body_.segments[index];
  // The parent at the child's sample time: its latest orientation turned on by its rate over the lag (one clock).
  Quat parent_q = *parent.q, parent_q_segment = *parent.q_segment;
  // Signed (the parent may also be ahead); the modular difference is exact for any lag within the bound.
  const auto lag_ns = static_cast<std::int64_t>(seg.timestamp_ns - parent.timestamp_ns);
  const auto max_ns = static_cast<std::int64_t>(max_joint_extrapolation_ns_);
  if (lag_ns != 0 && lag_ns >= -max_ns && lag_ns <= max_ns) {
    const double dt = 1e-9 * static_cast<double>(lag_ns);
    const Quat turned = (parent.q_sensor * exp_rotation_vector(parent.rate * dt)).normalized();
    parent_q_segment = segment_orientation(turned, parent.sensor_to_segment);
    parent_q = parent.aligned ? parent_q_segment : turned;
  }
  Quat child_q = *seg.q, child_q_segment = *seg.q_segment;
  std::optional<HingeHeadingEstimator::State> heading;
  if (seg.kinematic_heading) {
    // A restarted filter starts a new heading: the offset learnt against the old one no longer holds.
    if (seg.flags.reinitialised || parent.flags.reinitialised) seg.kinematic_heading->reset();
    heading = seg.kinematic_heading->update(parent_q_segment, child_q_segment, seg.timestamp_ns);
    // A rotation about the earth's vertical: the same for the sensor and the segment frame.
    child_q = seg.kinematic_heading->correct(child_q);
    child_q_segment = seg.kinematic_heading->correct(child_q_segment);
  }
  const Quat relative = canonical(relative_orientation(parent_q, child_q));
  const JointConvention convention = joint_convention(spec);
  return JointEstimate{*seg.parent,
                       index,
                       relative,
                       decompose(relative, spec.joint_axes),
                       convention,
                       anatomical_angles(relative_orientation(parent_q_segment, child_q_segment), convention),
                       parent.aligned && seg.aligned,
                       parent.stale || seg.stale,
                       parent.flags.initialising || seg.flags.initialising,
                       heading};
}

std::optional<std::size_t> BodyFusion::update_calibration(std::string_view node,
                                                          const calib::SensorCalibration& update) {
  const auto index = segment_of_node_.find(node);
  if (index == segment_of_node_.end()) return std::nullopt;
  Segment& seg = segments_[index->second];
  if (update.accelerometer) seg.calibration.accelerometer = update.accelerometer;
  if (update.gyroscope) seg.calibration.gyroscope = update.gyroscope;
  if (update.magnetometer) seg.calibration.magnetometer = update.magnetometer;
  seg.filter->reset();
  return index->second;
}

std::optional<std::size_t> BodyFusion::update_alignment(std::string_view node, const Quat& sensor_to_segment) {
  const auto index = segment_of_node_.find(node);
  if (index == segment_of_node_.end()) return std::nullopt;
  Segment& seg = segments_[index->second];
  seg.sensor_to_segment = sensor_to_segment.normalized();
  seg.aligned = true;
  // The hinge axes are given in segment frames: an offset learnt in the old frames no longer holds, for this
  // segment's joint to its parent and for its children's joints.
  if (seg.kinematic_heading) seg.kinematic_heading->reset();
  for (Segment& other : segments_)
    if (other.parent == index->second && other.kinematic_heading) other.kinematic_heading->reset();
  // The frames change: a child's joint must not pair its new frame with this segment's last one in the old frame.
  seg.q.reset();
  seg.q_segment.reset();
  return index->second;
}

std::optional<std::size_t> BodyFusion::segment_of(std::string_view node) const {
  const auto index = segment_of_node_.find(node);
  return index == segment_of_node_.end() ? std::nullopt : std::optional<std::size_t>(index->second);
}

std::span<const std::size_t> BodyFusion::check_stale(std::uint64_t now_ns) {
  turned_stale_.clear();
  for (std::size_t i = 0; i < segments_.size(); ++i) {
    Segment& seg = segments_[i];
    // A node that never sent gets a grace period for discovery before it counts as stale.
    const bool silent =
        seg.last_arrival_ns ? now_ns > *seg.last_arrival_ns + stale_timeout_ns_ : now_ns > discovery_end_ns_;
    if (silent && !seg.stale) turned_stale_.push_back(i);
    seg.stale = seg.stale || silent;
  }
  return turned_stale_;
}

}  // namespace bsn::fusion
