#include "fusion_pipeline.hpp"

#include <algorithm>
#include <cmath>

#include "bsn/dds/conversions.hpp"
#include "calibration_wire.hpp"

namespace bsn::services {

std::uint32_t to_wire_flags(const fusion::FilterFlags& f) {
  return (f.resting ? bsn::FLAG_RESTING : 0u) | (f.mag_rejected ? bsn::FLAG_MAG_REJECTED : 0u) |
         (f.initialising ? bsn::FLAG_INITIALISING : 0u) | (f.reinitialised ? bsn::FLAG_REINITIALISED : 0u);
}

FusionPipeline::FusionPipeline(fusion::BodyModel body, const fusion::BodyFusion::Calibrations& calibrations,
                               const fusion::BodyFusion::Params& params, std::uint64_t start_ns)
    : fusion_(std::move(body), calibrations, params, start_ns),
      calibration_id_(fusion_.body().segments.size()),
      // At least one each, so that orientation() and joint() name a sample even before the first estimate.
      orientation_msgs_(std::max<std::size_t>(1, fusion_.body().segments.size())),
      joint_msgs_(std::max<std::size_t>(1, fusion_.body().segments.size())) {
  const auto& segments = fusion_.body().segments;
  for (std::size_t i = 0; i < segments.size(); ++i) {
    orientation_msgs_[i].segment(segments[i].name);
    orientation_msgs_[i].node_id(segments[i].node);
    const std::optional<std::size_t> parent = fusion_.segment(i).parent;
    if (!parent) continue;
    bsn::JointAngles& j = joint_msgs_[i];
    j.joint(fusion::joint_name(segments[i]));
    j.parent(segments[*parent].name);
    j.child(segments[i].name);
    j.axes(segments[i].joint_axes.name());
    dds::fill_anatomical(fusion_.segment(i).convention, fusion::Vec3::Zero(), j);
  }
}

const fusion::SampleResult& FusionPipeline::process(const bsn::RawSample& raw, std::uint64_t arrival_ns,
                                                    const fusion::SourceId& writer) {
  return process({raw.node_id(), raw.seq(), dds::to_imu_sample(raw)}, arrival_ns, writer);
}

const fusion::SampleResult& FusionPipeline::process(const fusion::NodeSample& sample, std::uint64_t arrival_ns,
                                                    const fusion::SourceId& writer) {
  const fusion::SampleResult& r = fusion_.process(sample, arrival_ns, writer);
  if (r.outcome != fusion::SampleOutcome::kEstimated) return r;
  last_segment_ = r.segment;
  fill_orientation(r, sample.imu.timestamp_ns);
  if (r.joint) fill_joint(*r.joint, sample.imu.timestamp_ns);
  return r;
}

FusionPipeline::CalibrationApplied FusionPipeline::apply(const bsn::CalibrationResult& r) {
  CalibrationApplied out;
  if (!r.success()) {
    out.outcome = CalibrationOutcome::kFailedResult;  // changes nothing; the service republishes the one in effect
    return out;
  }
  const auto segment = fusion_.segment_of(r.node_id());
  if (!segment) return out;  // a node of another body
  out.segment = *segment;
  const bool alignment = r.kind() == bsn::CALIBRATION_SEGMENT_ALIGNMENT;
  const std::optional<calib::CalibrationKind> kind = from_wire(r.kind());
  out.kind = kind ? calib::kind_name(*kind) : nullptr;
  std::optional<fusion::Quat> rotation;
  calib::SensorCalibration update;
  if (alignment) {
    const auto& w = r.sensor_to_segment();
    const Eigen::Vector4d v(w[0], w[1], w[2], w[3]);
    if (!v.allFinite() || !(std::abs(v.norm() - 1.0) < 1e-3)) {
      out.outcome = CalibrationOutcome::kRefused;
      return out;
    }
    // An alignment fitted with the node on another segment (another body file) would turn it into the wrong frame.
    if (r.segment() != fusion_.body().segments[*segment].name) {
      out.outcome = CalibrationOutcome::kWrongSegment;
      return out;
    }
    rotation = fusion::Quat(v[0], v[1], v[2], v[3]).normalized();
  } else {
    calib::ChannelCalibration c;
    const auto& b = r.bias();
    const auto& h = r.transform();
    c.bias = calib::Vec3(b[0], b[1], b[2]);
    c.transform << h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8];
    if (r.kind() == bsn::CALIBRATION_GYRO_BIAS) c.transform.setIdentity();
    if (out.kind == nullptr || !c.bias.allFinite() || !c.transform.allFinite() ||
        !(std::abs(c.transform.determinant()) > 1e-12 * std::pow(c.transform.norm(), 3))) {
      out.outcome = CalibrationOutcome::kRefused;
      return out;
    }
    if (r.kind() == bsn::CALIBRATION_MAGNETOMETER) update.magnetometer = c;
    if (r.kind() == bsn::CALIBRATION_GYRO_BIAS) update.gyroscope = c;
    if (r.kind() == bsn::CALIBRATION_ACCELEROMETER) update.accelerometer = c;
  }
  std::string& applied = applied_calibration_[{*segment, static_cast<int>(r.kind())}];
  if (applied == r.request_id()) {
    out.outcome = CalibrationOutcome::kAlreadyApplied;  // the same calibration again (republished after a failure)
    return out;
  }
  if (rotation) {
    fusion_.update_alignment(r.node_id(), *rotation);
  } else {
    fusion_.update_calibration(r.node_id(), update);
  }
  applied = r.request_id();
  calibration_id_[*segment] = last_calibration_id_ = r.request_id();
  out.outcome = CalibrationOutcome::kApplied;
  return out;
}

bsn::NodeStatus FusionPipeline::node_status(std::size_t i) const {
  const fusion::SegmentSpec& spec = fusion_.body().segments[i];
  const fusion::BodyFusion::Segment& state = fusion_.segment(i);
  const auto& c = state.gate.counters();
  bsn::NodeStatus n;
  n.node_id(spec.node);
  n.segment(spec.name);
  n.received(c.received);
  n.accepted(c.accepted);
  n.missing(c.missing);
  for (std::size_t r = 0; r <= fusion::kRejectionReasonCount; ++r) {  // the gate's reasons, then the filter's
    bsn::ReasonCount& rc = n.rejected().emplace_back();
    rc.reason(r < fusion::kRejectionReasonCount ? std::string(fusion::rejection_reason_name(r)) : "filter_rejected");
    rc.count(r < fusion::kRejectionReasonCount ? c.rejected[r] : state.filter_rejected);
  }
  n.clock_resets(c.clock_resets);
  n.stale(state.stale);
  n.last_calibration_id(calibration_id_[i]);
  n.source_handovers(state.source_handovers);
  return n;
}

void FusionPipeline::fill_orientation(const fusion::SampleResult& r, std::uint64_t timestamp_ns) {
  bsn::Orientation& o = orientation_msgs_[r.segment];
  o.timestamp_ns(timestamp_ns);
  dds::fill_orientation(r.orientation, o);
  o.gyro_bias({r.gyro_bias.x(), r.gyro_bias.y(), r.gyro_bias.z()});
  o.flags(to_wire_flags(r.flags) | (r.aligned ? bsn::FLAG_SEGMENT_FRAME : 0u));
}

void FusionPipeline::fill_joint(const fusion::JointEstimate& joint, std::uint64_t timestamp_ns) {
  // The texts were set from the body; a segment's joint is always to its parent, with its convention.
  bsn::JointAngles& j = joint_msgs_[joint.child];
  j.timestamp_ns(timestamp_ns);
  j.quat(dds::to_wxyz(joint.relative));
  j.angles({joint.angles.x(), joint.angles.y(), joint.angles.z()});
  j.flags((joint.stale ? bsn::FLAG_STALE : 0u) | (joint.initialising ? bsn::FLAG_INITIALISING : 0u) |
          (joint.aligned ? bsn::FLAG_SEGMENT_FRAME : 0u) | (joint.heading ? bsn::FLAG_HEADING_KINEMATIC : 0u));
  j.anatomical({joint.anatomical.x(), joint.anatomical.y(), joint.anatomical.z()});
  j.heading_offset(joint.heading ? joint.heading->offset_rad : 0.0);
  j.heading_observability(joint.heading ? joint.heading->observability : 0.0);
}

}  // namespace bsn::services
