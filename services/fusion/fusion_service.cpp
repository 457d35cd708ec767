#include "fusion_service.hpp"

#include <unistd.h>

#include <algorithm>

#include "bsn/dds/conversions.hpp"
#include "bsn/dds/log.hpp"

namespace bsn::services {

using Clock = std::chrono::steady_clock;

namespace {

constexpr std::size_t kMaxUnknownNodesListed = 16;
constexpr auto kDiscoveryGrace = std::chrono::seconds(2);

std::string default_process_id() {
  char host[256] = {};
  gethostname(host, sizeof host - 1);
  return std::string("fusion@") + host + ":" + std::to_string(getpid());
}

std::uint32_t to_wire_flags(const fusion::FilterFlags& f) {
  return (f.resting ? bsn::FLAG_RESTING : 0u) | (f.mag_rejected ? bsn::FLAG_MAG_REJECTED : 0u) |
         (f.initialising ? bsn::FLAG_INITIALISING : 0u) | (f.reinitialised ? bsn::FLAG_REINITIALISED : 0u);
}

}  // namespace

FusionService::FusionService(dds::Participant& participant, fusion::BodyModel body, Options options)
    : participant_(participant), body_(std::move(body)), options_(std::move(options)) {
  if (options_.process_id.empty()) options_.process_id = default_process_id();
  segments_.reserve(body_.segments.size());
  for (std::size_t i = 0; i < body_.segments.size(); ++i) {
    const auto& spec = body_.segments[i];
    SegmentRuntime& seg = segments_.emplace_back();
    seg.spec = spec;
    seg.filter = fusion::make_filter(spec.filter);
    seg.gate = fusion::SampleGate(options_.gate);
    if (const auto c = options_.calibrations.find(spec.node); c != options_.calibrations.end())
      seg.calibration = c->second;
    by_node_[spec.node] = i;
  }
  for (std::size_t i = 0; i < segments_.size(); ++i) {
    if (auto p = body_.find_segment(segments_[i].spec.parent)) {
      segments_[i].parent = *p;
      segments_[*p].children.push_back(i);
    }
  }
  // --best-effort switches both estimate topics from their own delivery to BEST_EFFORT.
  const auto estimate = [this](const auto& topic) {
    return options_.best_effort ? dds::TopicQos::kEstimateBestEffort : topic.qos;
  };
  orientation_writer_ = participant_.make_writer(dds::kOrientationTopic, estimate(dds::kOrientationTopic));
  joint_writer_ = participant_.make_writer(dds::kJointAnglesTopic, estimate(dds::kJointAnglesTopic));
  status_writer_ = participant_.make_writer(dds::kStatusTopic);
  last_status_ = started_ = Clock::now();
  // The reader goes last: its callback may fire as soon as it exists.
  raw_reader_ = participant_.make_reader(
      dds::kRawTopic, [this](const bsn::RawSample& raw, const eprosima::fastdds::dds::SampleInfo&) { on_raw(raw); });
}

namespace {

// u = H (raw - B) on every calibrated channel that the sample carries.
void apply_calibration(const calib::SensorCalibration& c, fusion::ImuSample& s) {
  if (c.accelerometer && s.has_acc) s.acc = calib::apply(*c.accelerometer, s.acc);
  if (c.gyroscope && s.has_gyr) s.gyr = calib::apply(*c.gyroscope, s.gyr);
  if (c.magnetometer && s.has_mag) s.mag = calib::apply(*c.magnetometer, s.mag);
}

}  // namespace

void FusionService::on_raw(const bsn::RawSample& raw) {
  std::lock_guard lock(mutex_);
  const auto it = by_node_.find(raw.node_id());
  if (it == by_node_.end()) {
    ++unknown_node_samples_;
    if (unknown_nodes_.size() < kMaxUnknownNodesListed &&
        std::find(unknown_nodes_.begin(), unknown_nodes_.end(), raw.node_id()) == unknown_nodes_.end()) {
      unknown_nodes_.push_back(raw.node_id());
      dds::log_warn("samples from node '", raw.node_id(), "', which is on no segment of the body model; ignored");
    }
    return;
  }
  SegmentRuntime& seg = segments_[it->second];
  const auto now = Clock::now();
  seg.last_arrival = now;
  seg.ever_received = true;
  if (seg.stale) {
    seg.stale = false;
    dds::log_info("node '", seg.spec.node, "' (", seg.spec.name, ") is sending again");
    publish_status(now);
  }

  fusion::ImuSample sample = dds::to_imu_sample(raw);
  apply_calibration(seg.calibration, sample);
  const fusion::SampleVerdict verdict = seg.gate.check(raw.seq(), sample);
  if (verdict == fusion::SampleVerdict::kAcceptedClockReset) {
    dds::log_warn("node '", seg.spec.node, "': its clock moved to a new time base; restarting its filter");
    seg.filter->reset();
  } else if (verdict != fusion::SampleVerdict::kAccepted) {
    return;  // counted by the gate, reported on bsn/status
  }
  if (seg.filter->update(sample) == fusion::UpdateResult::kRejected) {
    ++seg.filter_rejected;
    return;
  }
  seg.q = seg.filter->orientation();
  seg.flags = to_wire_flags(seg.filter->flags());
  seg.has_orientation = true;
  publish_orientation(seg, sample.timestamp_ns);
  if (seg.parent) {
    const SegmentRuntime& parent = segments_[*seg.parent];
    if (parent.has_orientation) publish_joint(parent, seg, sample.timestamp_ns);
  }
}

void FusionService::publish_orientation(SegmentRuntime& seg, std::uint64_t timestamp_ns) {
  bsn::Orientation& o = orientation_msg_;
  o.segment(seg.spec.name);
  o.node_id(seg.spec.node);
  o.timestamp_ns(timestamp_ns);
  dds::fill_orientation(seg.q, o);
  const fusion::Vec3 b = seg.filter->gyro_bias();
  o.gyro_bias({b.x(), b.y(), b.z()});
  o.flags(seg.flags);
  if (!orientation_writer_->write(o)) ++write_failures_;
}

void FusionService::publish_joint(const SegmentRuntime& parent, const SegmentRuntime& child,
                                  std::uint64_t timestamp_ns) {
  bsn::JointAngles& j = joint_msg_;
  const fusion::Quat rel = fusion::canonical(fusion::relative_orientation(parent.q, child.q));
  const fusion::Vec3 a = fusion::decompose(rel, child.spec.joint_axes);
  j.joint(fusion::joint_name(child.spec));
  j.parent(parent.spec.name);
  j.child(child.spec.name);
  j.timestamp_ns(timestamp_ns);
  j.quat(dds::to_wxyz(rel));
  j.axes(child.spec.joint_axes.name());
  j.angles({a.x(), a.y(), a.z()});
  j.flags((parent.stale || child.stale ? bsn::FLAG_STALE : 0u) |
          ((parent.flags | child.flags) & bsn::FLAG_INITIALISING));
  if (!joint_writer_->write(j)) ++write_failures_;
}

void FusionService::tick() {
  std::lock_guard lock(mutex_);
  const auto now = Clock::now();
  const auto stale_after = std::chrono::duration<double>(options_.stale_timeout_s);
  bool changed = false;
  for (auto& seg : segments_) {
    // A node that never sent gets a grace period for discovery before it counts as stale.
    const bool silent = seg.ever_received ? now - seg.last_arrival > stale_after : now - started_ > kDiscoveryGrace;
    if (silent && !seg.stale) {
      seg.stale = true;
      changed = true;
      if (seg.ever_received) dds::log_warn("node '", seg.spec.node, "' (", seg.spec.name, ") is stale");
    }
  }
  if (changed || now - last_status_ >= std::chrono::duration<double>(options_.status_period_s)) publish_status(now);
}

void FusionService::publish_status(Clock::time_point now) {
  const double period = std::chrono::duration<double>(now - last_status_).count();
  bsn::Status st;
  st.process_id(options_.process_id);
  st.wall_time_ns(static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count()));
  st.period_s(period);
  std::vector<bsn::NodeStatus> nodes;
  for (auto& seg : segments_) {
    const auto& c = seg.gate.counters();
    bsn::NodeStatus n;
    n.node_id(seg.spec.node);
    n.segment(seg.spec.name);
    n.rate_hz(period > 0.0 ? static_cast<double>(c.accepted - seg.accepted_at_last_status) / period : 0.0);
    seg.accepted_at_last_status = c.accepted;
    n.received(c.received);
    n.accepted(c.accepted);
    n.missing(c.missing);
    std::vector<bsn::ReasonCount> rejected;
    for (std::size_t r = 0; r < fusion::kRejectionReasonCount; ++r) {
      bsn::ReasonCount rc;
      rc.reason(std::string(fusion::rejection_reason_name(r)));
      rc.count(c.rejected[r]);
      rejected.push_back(rc);
    }
    bsn::ReasonCount fr;
    fr.reason("filter_rejected");
    fr.count(seg.filter_rejected);
    rejected.push_back(fr);
    n.rejected(rejected);
    n.clock_resets(c.clock_resets);
    n.stale(seg.stale);
    n.last_sample_age_s(seg.ever_received ? std::chrono::duration<double>(now - seg.last_arrival).count() : -1.0);
    nodes.push_back(std::move(n));
  }
  st.nodes(std::move(nodes));
  st.unknown_node_samples(unknown_node_samples_);
  st.unknown_nodes(unknown_nodes_);
  st.qos_mismatches(participant_.qos_mismatches());
  st.write_failures(write_failures_);
  status_writer_->write(st);
  last_status_ = now;
}

}  // namespace bsn::services
