#include "fusion_service.hpp"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>

#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/dds/sample_source.hpp"
#include "bsn/logging/log.hpp"

namespace bsn::services {

namespace {

std::string default_process_id() {
  char host[256] = {};
  gethostname(host, sizeof host - 1);
  return std::string("fusion@") + host + ":" + std::to_string(getpid());
}

std::uint32_t to_wire_flags(const fusion::FilterFlags& f) {
  return (f.resting ? bsn::FLAG_RESTING : 0u) | (f.mag_rejected ? bsn::FLAG_MAG_REJECTED : 0u) |
         (f.initialising ? bsn::FLAG_INITIALISING : 0u) | (f.reinitialised ? bsn::FLAG_REINITIALISED : 0u);
}

double seconds(std::uint64_t ns) { return std::chrono::duration<double>(std::chrono::nanoseconds(ns)).count(); }

}  // namespace

FusionService::FusionService(dds::Participant& participant, fusion::BodyModel body, Options options)
    : participant_(participant),
      options_(std::move(options)),
      fusion_(std::move(body), options_.calibrations, options_, dds::monotonic_ns()),
      accepted_at_window_start_(fusion_.body().segments.size(), 0),
      rate_hz_(fusion_.body().segments.size(), 0.0),
      calibration_id_(fusion_.body().segments.size()),
      conflict_logged_ns_(fusion_.body().segments.size(), 0),
      not_permitted_(fusion_.body().segments.size(), 0),
      not_permitted_logged_ns_(fusion_.body().segments.size(), 0) {
  if (options_.process_id.empty()) options_.process_id = default_process_id();
  // --best-effort switches both estimate topics from their own delivery to BEST_EFFORT.
  const auto estimate = [this](const auto& topic) {
    return options_.best_effort ? dds::TopicQos::kEstimateBestEffort : topic.qos;
  };
  orientation_writer_ = participant_.make_writer(dds::kOrientationTopic, estimate(dds::kOrientationTopic));
  joint_writer_ = participant_.make_writer(dds::kJointAnglesTopic, estimate(dds::kJointAnglesTopic));
  status_writer_ = participant_.make_writer(dds::kStatusTopic);
  last_status_ns_ = rate_window_start_ns_ = dds::monotonic_ns();
  // Another fusion service publishing any of our segments doubles every orientation and joint angle under the
  // same keys: each notices the other's bsn/status (keyed by process id), warns and lists it in its own status.
  status_reader_ = participant_.make_reader(
      dds::kStatusTopic, [this](const bsn::Status& st, const eprosima::fastdds::dds::SampleInfo&) { on_status(st); });
  // The raw reader goes last: its callback may fire as soon as it exists.
  // Each sample's writer goes with it: a node's samples are taken from one writer at a time.
  // Samples of nodes on no segment are counted and dropped before they enter the reader's history, so however many
  // ids a writer invents, none takes one of the reader's instances (max_instances) from a node of the body, and
  // each is counted when it arrives, not when (or if) its writer's next admitted sample shows a gap.
  raw_reader_ = participant_.make_reader(
      dds::kRawTopic,
      [this](const bsn::RawSample& raw, const eprosima::fastdds::dds::SampleInfo& info) {
        // Secured, each node's samples come only from writers in its partition: an identity with the permission
        // for other nodes cannot take this one over, even after its own writer went stale.
        const auto& writer = info.sample_identity.writer_guid();
        if (participant_.secured() && !participant_.writer_may_write_node(writer, raw.node_id())) {
          on_not_permitted(raw, writer);
          return;
        }
        on_raw(raw, dds::source_id(writer));
      },
      std::nullopt, [this](const bsn::RawSample& raw) { return admit_raw(raw); });
  // Live calibrations (TRANSIENT_LOCAL: the ones published before this start arrive too and override the body
  // file's).
  calibration_reader_ = participant_.make_reader(
      dds::kCalibrationResultTopic,
      [this](const bsn::CalibrationResult& r, const eprosima::fastdds::dds::SampleInfo&) { on_calibration(r); });
}

void FusionService::on_calibration(const bsn::CalibrationResult& r) {
  if (!r.success()) return;  // a failed calibration changes nothing; the service republishes the one in effect
  if (r.kind() == bsn::CALIBRATION_SEGMENT_ALIGNMENT) {
    on_alignment(r);
    return;
  }
  const char* channel = r.kind() == bsn::CALIBRATION_MAGNETOMETER    ? "magnetometer"
                        : r.kind() == bsn::CALIBRATION_GYRO_BIAS     ? "gyroscope"
                        : r.kind() == bsn::CALIBRATION_ACCELEROMETER ? "accelerometer"
                                                                     : nullptr;
  calib::ChannelCalibration c;
  const auto& b = r.bias();
  const auto& h = r.transform();
  c.bias = calib::Vec3(b[0], b[1], b[2]);
  c.transform << h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8];
  if (r.kind() == bsn::CALIBRATION_GYRO_BIAS) c.transform.setIdentity();
  std::lock_guard lock(mutex_);
  const auto segment = fusion_.segment_of(r.node_id());
  if (!segment) return;  // a node of another body
  if (channel == nullptr || !c.bias.allFinite() || !c.transform.allFinite() ||
      !(std::abs(c.transform.determinant()) > 1e-12 * std::pow(c.transform.norm(), 3))) {
    logging::log_warn("calibration '", r.request_id(), "' for node '", r.node_id(),
                      "' refused: unknown kind, non-finite numbers or a singular transform");
    return;
  }
  std::string& applied = applied_calibration_[{*segment, static_cast<int>(r.kind())}];
  if (applied == r.request_id()) return;  // the same calibration again (republished after a failure)
  calib::SensorCalibration update;
  if (r.kind() == bsn::CALIBRATION_MAGNETOMETER) update.magnetometer = c;
  if (r.kind() == bsn::CALIBRATION_GYRO_BIAS) update.gyroscope = c;
  if (r.kind() == bsn::CALIBRATION_ACCELEROMETER) update.accelerometer = c;
  fusion_.update_calibration(r.node_id(), update);
  applied = r.request_id();
  calibration_id_[*segment] = last_calibration_id_ = r.request_id();
  const fusion::SegmentSpec& spec = fusion_.body().segments[*segment];
  logging::log_info("node '", spec.node, "' (", spec.name, "): ", channel, " calibration '", r.request_id(),
                    "' applied from its next sample on; its filter restarts");
  status_due_ = true;
}

void FusionService::on_alignment(const bsn::CalibrationResult& r) {
  const auto& w = r.sensor_to_segment();
  const Eigen::Vector4d v(w[0], w[1], w[2], w[3]);
  std::lock_guard lock(mutex_);
  const auto segment = fusion_.segment_of(r.node_id());
  if (!segment) return;  // a node of another body
  const fusion::SegmentSpec& spec = fusion_.body().segments[*segment];
  if (!v.allFinite() || !(std::abs(v.norm() - 1.0) < 1e-3)) {
    logging::log_warn("alignment '", logging::printable(r.request_id()), "' for node '", spec.node,
                      "' refused: sensor_to_segment is not a finite unit quaternion");
    return;
  }
  // An alignment fitted with the node on another segment (another body file) would turn it into the wrong frame.
  if (r.segment() != spec.name) {
    logging::log_warn("alignment '", logging::printable(r.request_id()), "' for node '", spec.node,
                      "' was fitted for segment '", logging::printable(r.segment()),
                      "', but this body has the node on '", spec.name, "'; not applied");
    return;
  }
  std::string& applied = applied_calibration_[{*segment, static_cast<int>(r.kind())}];
  if (applied == r.request_id()) return;
  fusion_.update_alignment(r.node_id(), fusion::Quat(v[0], v[1], v[2], v[3]).normalized());
  applied = r.request_id();
  calibration_id_[*segment] = last_calibration_id_ = r.request_id();
  logging::log_info("node '", spec.node, "' (", spec.name, "): alignment '", r.request_id(), "' (",
                    logging::printable(r.alignment_source()),
                    ") applied from its next sample on: bsn/orientation reports the segment frame");
  status_due_ = true;
}

bool FusionService::admit_raw(const bsn::RawSample& raw) {
  if (fusion_.segment_of(raw.node_id())) return true;  // the body model does not change: no lock needed
  std::lock_guard lock(mutex_);
  const fusion::SampleResult& r = fusion_.process({raw.node_id(), raw.seq(), dds::to_imu_sample(raw)},
                                                  dds::monotonic_ns(), fusion::SourceId{});  // counted there
  if (r.new_unknown_node)
    logging::log_warn("samples from node '", logging::printable(raw.node_id()),
                      "', which is on no segment of the body model; ignored");
  return false;
}

void FusionService::on_not_permitted(const bsn::RawSample& raw, const eprosima::fastrtps::rtps::GUID_t& writer) {
  std::lock_guard lock(mutex_);
  const auto segment = fusion_.segment_of(raw.node_id());
  if (!segment) return;  // admit_raw let only the body's nodes in
  ++not_permitted_[*segment];
  const std::uint64_t now = dds::monotonic_ns();
  std::uint64_t& logged = not_permitted_logged_ns_[*segment];
  if (logged != 0 && now - logged < kConflictLogPeriodNs) return;
  logged = now;
  const fusion::SegmentSpec& spec = fusion_.body().segments[*segment];
  logging::log_warn("node '", spec.node, "' (", spec.name, "): samples from writer ", dds::writer_name(writer),
                    ", which its permissions do not allow to write this node ", "(its DDS partition is not '",
                    spec.node, "'), rejected as not_permitted");
  status_due_ = true;
}

void FusionService::on_raw(const bsn::RawSample& raw, const fusion::SourceId& writer) {
  // Lock order: publish_mutex_, then mutex_. DDS writes happen after mutex_ is released (see the header).
  std::lock_guard publishing(publish_mutex_);
  bool joint = false;
  {
    std::lock_guard lock(mutex_);
    const std::uint64_t now = dds::monotonic_ns();
    const fusion::SampleResult& r = fusion_.process({raw.node_id(), raw.seq(), dds::to_imu_sample(raw)}, now, writer);
    if (r.outcome == fusion::SampleOutcome::kUnknownNode) {
      if (r.new_unknown_node)
        logging::log_warn("samples from node '", logging::printable(raw.node_id()),
                          "', which is on no segment of the body model; ignored");
      return;
    }
    log_source_events(r, now);
    const fusion::SegmentSpec& spec = fusion_.body().segments[r.segment];
    if (r.node_fresh) {
      logging::log_info("node '", spec.node, "' (", spec.name, ") is sending again");
      status_due_ = true;
    }
    if (r.clock_reset)
      logging::log_warn("node '", spec.node, "': its clock moved to a new time base; restarting its filter");
    if (r.outcome != fusion::SampleOutcome::kEstimated) return;  // counted by BodyFusion, reported on bsn/status
    fill_orientation(r, raw.timestamp_ns());
    if (r.joint) fill_joint(*r.joint, raw.timestamp_ns());
    joint = r.joint.has_value();
  }
  if (!orientation_writer_->write(orientation_msg_)) ++write_failures_;
  if (joint && !joint_writer_->write(joint_msg_)) ++write_failures_;
}

void FusionService::log_source_events(const fusion::SampleResult& r, std::uint64_t now) {
  const fusion::SegmentSpec& spec = fusion_.body().segments[r.segment];
  const fusion::BodyFusion::Segment& seg = fusion_.segment(r.segment);
  if (r.source_handover) {
    logging::log_warn("node '", spec.node, "' (", spec.name, "): its writer ", dds::writer_name(r.previous_source),
                      " went stale and writer ", dds::writer_name(*seg.source), " took the node over (handover ",
                      seg.source_handovers, "; counted as source_handovers on bsn/status); its filter restarts");
    status_due_ = true;
  }
  if (!r.new_conflicting_source) return;
  // A rogue that keeps making new writers must not flood the log: one line per segment per period; every sample
  // is still counted, and bsn/status names the last conflicting writer.
  std::uint64_t& logged = conflict_logged_ns_[r.segment];
  if (logged != 0 && now - logged < kConflictLogPeriodNs) return;
  logged = now;
  logging::log_warn("node '", spec.node, "' (", spec.name, "): samples from a second writer, ",
                    dds::writer_name(*seg.conflicting_source), ", rejected as conflicting_source: the node's samples ",
                    "come from writer ", dds::writer_name(*seg.source), " until it goes stale. Another process ",
                    "publishes this node id (a second sensor process with the same --node, or a rogue one).");
  status_due_ = true;
}

void FusionService::on_status(const bsn::Status& other) {
  if (other.process_id() == options_.process_id) return;
  std::string shared;
  for (const bsn::NodeStatus& n : other.nodes()) {
    if (!fusion_.body().find_segment(n.segment())) continue;
    if (!shared.empty()) shared += ", ";
    shared += logging::printable(n.segment());
  }
  if (shared.empty()) return;
  std::lock_guard lock(mutex_);
  const std::string id = other.process_id().substr(0, kMaxListedIdChars);
  if (std::find(other_fusions_.begin(), other_fusions_.end(), id) != other_fusions_.end()) return;
  if (other_fusions_.size() >= kMaxOtherFusionsListed) return;
  other_fusions_.push_back(id);
  logging::log_warn("another fusion service, '", logging::printable(other.process_id()), "', publishes segments ",
                    shared, " on this domain: every orientation and joint angle of them is published twice with ",
                    "the same keys. Run one fusion service per body (or give each its own domain).");
  status_due_ = true;
}

void FusionService::fill_orientation(const fusion::SampleResult& r, std::uint64_t timestamp_ns) {
  const fusion::SegmentSpec& spec = fusion_.body().segments[r.segment];
  bsn::Orientation& o = orientation_msg_;
  o.segment(spec.name);
  o.node_id(spec.node);
  o.timestamp_ns(timestamp_ns);
  dds::fill_orientation(r.orientation, o);
  o.gyro_bias({r.gyro_bias.x(), r.gyro_bias.y(), r.gyro_bias.z()});
  o.flags(to_wire_flags(r.flags) | (r.aligned ? bsn::FLAG_SEGMENT_FRAME : 0u));
}

void FusionService::fill_joint(const fusion::JointEstimate& joint, std::uint64_t timestamp_ns) {
  const fusion::SegmentSpec& child = fusion_.body().segments[joint.child];
  bsn::JointAngles& j = joint_msg_;
  j.joint(fusion::joint_name(child));
  j.parent(fusion_.body().segments[joint.parent].name);
  j.child(child.name);
  j.timestamp_ns(timestamp_ns);
  j.quat(dds::to_wxyz(joint.relative));
  j.axes(child.joint_axes.name());
  j.angles({joint.angles.x(), joint.angles.y(), joint.angles.z()});
  j.flags((joint.stale ? bsn::FLAG_STALE : 0u) | (joint.initialising ? bsn::FLAG_INITIALISING : 0u) |
          (joint.aligned ? bsn::FLAG_SEGMENT_FRAME : 0u) | (joint.heading ? bsn::FLAG_HEADING_KINEMATIC : 0u));
  dds::fill_anatomical(joint.convention, joint.anatomical, j);
  j.heading_offset(joint.heading ? joint.heading->offset_rad : 0.0);
  j.heading_observability(joint.heading ? joint.heading->observability : 0.0);
}

void FusionService::tick() {
  std::optional<bsn::Status> status;
  {
    std::lock_guard lock(mutex_);
    const std::uint64_t now = dds::monotonic_ns();
    const auto turned_stale = fusion_.check_stale(now);
    for (const std::size_t i : turned_stale) {
      const fusion::SegmentSpec& spec = fusion_.body().segments[i];
      if (fusion_.segment(i).last_arrival_ns) logging::log_warn("node '", spec.node, "' (", spec.name, ") is stale");
    }
    if (!turned_stale.empty() || status_due_ || seconds(now - last_status_ns_) >= options_.status_period_s) {
      status_due_ = false;
      status = make_status(now);
    }
  }
  if (status) status_writer_->write(*status);
}

bsn::Status FusionService::make_status(std::uint64_t now) {
  const double window = seconds(now - rate_window_start_ns_);
  const bool window_complete = window >= options_.status_period_s;
  if (window_complete) {
    rate_window_s_ = window;
    rate_window_start_ns_ = now;
  }
  bsn::Status st;
  st.process_id(options_.process_id);
  st.wall_time_ns(static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count()));
  st.period_s(rate_window_s_);
  std::vector<bsn::NodeStatus> nodes;
  for (std::size_t i = 0; i < fusion_.body().segments.size(); ++i) {
    const fusion::SegmentSpec& spec = fusion_.body().segments[i];
    const fusion::BodyFusion::Segment& state = fusion_.segment(i);
    const auto& c = state.gate.counters();
    bsn::NodeStatus n;
    n.node_id(spec.node);
    n.segment(spec.name);
    if (window_complete) {
      rate_hz_[i] = static_cast<double>(c.accepted - accepted_at_window_start_[i]) / window;
      accepted_at_window_start_[i] = c.accepted;
    }
    n.rate_hz(rate_hz_[i]);
    n.received(c.received);
    n.accepted(c.accepted);
    n.missing(c.missing);
    for (std::size_t r = 0; r <= fusion::kRejectionReasonCount; ++r) {  // the gate's reasons, then the filter's
      bsn::ReasonCount& rc = n.rejected().emplace_back();
      rc.reason(r < fusion::kRejectionReasonCount ? std::string(fusion::rejection_reason_name(r)) : "filter_rejected");
      rc.count(r < fusion::kRejectionReasonCount ? c.rejected[r] : state.filter_rejected);
    }
    if (participant_.secured()) {
      bsn::ReasonCount& rc = n.rejected().emplace_back();
      rc.reason("not_permitted");
      rc.count(not_permitted_[i]);
    }
    n.clock_resets(c.clock_resets);
    n.stale(state.stale);
    n.last_sample_age_s(state.last_arrival_ns ? seconds(now - *state.last_arrival_ns) : -1.0);
    n.last_calibration_id(calibration_id_[i]);
    n.source_writer(state.source ? dds::writer_name(*state.source) : "");
    n.conflicting_writer(state.conflicting_source ? dds::writer_name(*state.conflicting_source) : "");
    n.source_handovers(state.source_handovers);
    nodes.push_back(std::move(n));
  }
  st.nodes(std::move(nodes));
  st.unknown_node_samples(fusion_.unknown_node_samples());
  // Unknown ids come from the network: listed at most kMaxListedIdChars long, so a status sample stays small.
  std::vector<std::string> unknown;
  for (const std::string& id : fusion_.unknown_nodes()) unknown.push_back(id.substr(0, kMaxListedIdChars));
  st.unknown_nodes(std::move(unknown));
  st.qos_mismatches(participant_.qos_mismatches());
  st.write_failures(write_failures_);
  st.last_calibration_id(last_calibration_id_);
  st.undecodable_samples(participant_.undecodable_samples());
  st.dds_rejected_samples(participant_.rejected_samples());
  st.dds_lost_samples(participant_.lost_samples());
  st.other_fusion_processes(other_fusions_);
  last_status_ns_ = now;
  return st;
}

namespace {

// Longest duration an option takes: a day (a longer one overflows nothing, but means a typo).
constexpr double kMaxSeconds = 86400.0;

struct FusionCommandOptions {
  std::string body_path;  ///< "" = the default 7-segment lower body
  bool print_body = false;
  int domain = 0;
  FusionService::Options service;
};

int run_fusion(const FusionCommandOptions& opt) {
  fusion::BodyModel body;
  FusionService::Options service_options = opt.service;
  try {
    body = opt.body_path.empty() ? fusion::default_lower_body() : config::load_body_model(opt.body_path);
    service_options.calibrations = config::load_body_calibrations(opt.body_path);
    config::apply_body_alignments(opt.body_path, body);
  } catch (const config::ConfigError& e) {
    std::fprintf(stderr, "bsn fusion: error: %s\n", e.what());
    return 2;
  }
  if (opt.print_body) {
    std::fputs(config::body_model_to_yaml(body).c_str(), stdout);
    return 0;
  }
  DdsCommandFrame frame(opt.domain, "bsn fusion");
  FusionService service(frame.participant(), body, service_options);
  logging::log_info("fusing ", body.segments.size(), " segments of '", body.name.empty() ? opt.body_path : body.name,
                    "' in domain ", opt.domain);
  const int exit_code = frame.run_ticks(std::chrono::milliseconds(20), [&service] {
    service.tick();
    return std::optional<int>();
  });
  logging::log_info("stopped");
  return exit_code;
}

}  // namespace

Command fusion_command() {
  return {"fusion", "Fusion service: one filter per body segment", [](CLI::App* cmd) {
            auto opt = std::make_shared<FusionCommandOptions>();
            cmd->add_option("--body", opt->body_path, "YAML body model (default: 7-segment lower body)");
            cmd->add_flag("--print-body", opt->print_body, "print the body model in effect as YAML and exit");
            cmd->add_option("--stale-timeout", opt->service.stale_timeout_s,
                            "seconds without samples before a node is stale")
                ->capture_default_str()
                ->check(positive_number(kMaxSeconds));
            cmd->add_option("--status-period", opt->service.status_period_s, "seconds between bsn/status samples")
                ->capture_default_str()
                ->check(positive_number(kMaxSeconds));
            cmd->add_flag("--best-effort", opt->service.best_effort,
                          "publish orientations and joint angles BEST_EFFORT instead of RELIABLE");
            cmd->add_option("--max-time-jump", opt->service.gate.max_forward_jump_s,
                            "a sensor timestamp more than S seconds ahead is rejected as a jump")
                ->capture_default_str()
                ->check(positive_number(kMaxSeconds));
            add_domain_option(cmd, opt->domain);
            return [opt] { return run_fusion(*opt); };
          }};
}

}  // namespace bsn::services
