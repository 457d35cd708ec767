#include "fusion_service.hpp"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <set>
#include <string>

#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/config/subjects.hpp"
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

double seconds(std::uint64_t ns) { return std::chrono::duration<double>(std::chrono::nanoseconds(ns)).count(); }

}  // namespace

FusionService::FusionService(dds::Participant& participant, fusion::BodyModel body, Options options)
    : participant_(participant),
      options_(std::move(options)),
      pipeline_(std::move(body), options_.calibrations, options_, dds::monotonic_ns()),
      fusion_(pipeline_.fusion()),
      accepted_at_window_start_(fusion_.body().segments.size(), 0),
      rate_hz_(fusion_.body().segments.size(), 0.0),
      conflict_logged_ns_(fusion_.body().segments.size(), 0),
      not_permitted_(fusion_.body().segments.size(), 0),
      not_permitted_logged_ns_(fusion_.body().segments.size(), 0) {
  if (options_.process_id.empty())
    options_.process_id = default_process_id() + (options_.subject.empty() ? "" : "/" + options_.subject);
  // --best-effort switches both estimate topics from their own delivery to BEST_EFFORT.
  const auto estimate = [this](const auto& topic) {
    return options_.best_effort ? dds::TopicQos::kEstimateBestEffort : topic.qos;
  };
  // Each subject's estimates and status go in its partition; of a primary and its standby, DDS delivers the
  // estimates of the strongest live one.
  const dds::WriterScope scope{options_.subject, options_.ownership_strength};
  orientation_writer_ = participant_.make_writer(dds::kOrientationTopic, estimate(dds::kOrientationTopic), "", scope);
  joint_writer_ = participant_.make_writer(dds::kJointAnglesTopic, estimate(dds::kJointAnglesTopic), "", scope);
  status_writer_ = participant_.make_writer(dds::kStatusTopic, std::nullopt, "", scope);
  last_status_ns_ = rate_window_start_ns_ = dds::monotonic_ns();
  // Another fusion service publishing any of our segments doubles every orientation and joint angle under the
  // same keys: each notices the other's bsn/status (keyed by process id), warns and lists it in its own status.
  status_reader_ = participant_.make_reader(
      dds::kStatusTopic, [this](const bsn::Status& st, const eprosima::fastdds::dds::SampleInfo&) { on_status(st); },
      std::nullopt, {}, options_.subject);
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
  participant_.expect_peer(*raw_reader_, "writer of bsn/raw (a sensor node)");
  // Live calibrations (TRANSIENT_LOCAL: the ones published before this start arrive too and override the body
  // file's).
  calibration_reader_ = participant_.make_reader(
      dds::kCalibrationResultTopic,
      [this](const bsn::CalibrationResult& r, const eprosima::fastdds::dds::SampleInfo&) { on_calibration(r); });
}

void FusionService::on_calibration(const bsn::CalibrationResult& r) {
  using Outcome = FusionPipeline::CalibrationOutcome;
  std::lock_guard lock(mutex_);
  const FusionPipeline::CalibrationApplied a = pipeline_.apply(r);
  if (a.outcome == Outcome::kFailedResult || a.outcome == Outcome::kOtherBody || a.outcome == Outcome::kAlreadyApplied)
    return;
  const fusion::SegmentSpec& spec = fusion_.body().segments[a.segment];
  const bool alignment = r.kind() == bsn::CALIBRATION_SEGMENT_ALIGNMENT;
  if (a.outcome == Outcome::kRefused) {
    if (alignment) {
      logging::log_warn("alignment '", logging::printable(r.request_id()), "' for node '", spec.node,
                        "' refused: sensor_to_segment is not a finite unit quaternion");
    } else {
      logging::log_warn("calibration '", r.request_id(), "' for node '", r.node_id(),
                        "' refused: unknown kind, non-finite numbers or a singular transform");
    }
    return;
  }
  if (a.outcome == Outcome::kWrongSegment) {
    logging::log_warn("alignment '", logging::printable(r.request_id()), "' for node '", spec.node,
                      "' was fitted for segment '", logging::printable(r.segment()),
                      "', but this body has the node on '", spec.name, "'; not applied");
    return;
  }
  if (alignment) {
    logging::log_info("node '", spec.node, "' (", spec.name, "): alignment '", r.request_id(), "' (",
                      logging::printable(r.alignment_source()),
                      ") applied from its next sample on: bsn/orientation reports the segment frame");
  } else {
    logging::log_info("node '", spec.node, "' (", spec.name, "): ", a.kind, " calibration '", r.request_id(),
                      "' applied from its next sample on; its filter restarts");
  }
  status_due_ = true;
}

bool FusionService::admit_raw(const bsn::RawSample& raw) {
  if (fusion_.segment_of(raw.node_id())) return true;  // the body model does not change: no lock needed
  if (options_.served_elsewhere && options_.served_elsewhere->contains(raw.node_id())) return false;
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
    const fusion::SampleResult& r = pipeline_.process(raw, now, writer);
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
    joint = r.joint.has_value();
  }
  // publish_mutex_ keeps the pipeline's messages whole until written (the next raw sample waits for it).
  // A sample no reader could ever receive is not written: a write costs about as much as the rest of the sample's
  // path (serialisation, history, acknowledgement bookkeeping) even with no one to send it to.
  if (!orientation_writer_->unheard() && !orientation_writer_->write(pipeline_.orientation())) ++write_failures_;
  if (joint && !joint_writer_->unheard() && !joint_writer_->write(pipeline_.joint())) ++write_failures_;
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
  // With exclusive ownership a second fusion of the same segments is the point (primary and standby): DDS
  // delivers one of them.
  if (options_.ownership_strength) return;
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
  if (options_.ownership_strength) {
    // Owned estimates stay alive between samples (a body at rest on silent sensors), each tick < the lease.
    orientation_writer_->assert_liveliness();
    joint_writer_->assert_liveliness();
  }
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
    const fusion::BodyFusion::Segment& state = fusion_.segment(i);
    bsn::NodeStatus n = pipeline_.node_status(i);
    if (window_complete) {
      rate_hz_[i] = static_cast<double>(n.accepted() - accepted_at_window_start_[i]) / window;
      accepted_at_window_start_[i] = n.accepted();
    }
    n.rate_hz(rate_hz_[i]);
    if (participant_.secured()) {
      bsn::ReasonCount& rc = n.rejected().emplace_back();
      rc.reason("not_permitted");
      rc.count(not_permitted_[i]);
    }
    n.last_sample_age_s(state.last_arrival_ns ? seconds(now - *state.last_arrival_ns) : -1.0);
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
  st.last_calibration_id(pipeline_.last_calibration_id());
  st.undecodable_samples(participant_.undecodable_samples());
  st.dds_rejected_samples(participant_.rejected_samples());
  st.dds_lost_samples(participant_.lost_samples());
  st.other_fusion_processes(other_fusions_);
  st.participant_rejoins(participant_.rejoins());
  last_status_ns_ = now;
  return st;
}

namespace {

// Longest duration an option takes: a day (a longer one overflows nothing, but means a typo).
constexpr double kMaxSeconds = 86400.0;

struct FusionCommandOptions {
  std::vector<std::string> body_paths;  ///< empty = the default 7-segment lower body
  std::vector<std::string> subjects;    ///< --subject: serve only these (empty: every subject listed)
  int share = 0;                        ///< --share: serve the subjects of this share (0: every share)
  bool print_body = false;
  int domain = 0;
  std::optional<std::uint32_t> ownership_strength;
  bool primary = false;
  bool standby = false;
  FusionService::Options service;
};

// The strengths of --primary and --standby: a reader takes each instance from the strongest live writer.
constexpr std::uint32_t kPrimaryStrength = 100;
constexpr std::uint32_t kStandbyStrength = 50;

/// One subject this process serves.
struct ServedSubject {
  std::string subject;
  std::string body_path;  ///< "" for the default body
  fusion::BodyModel body;
  fusion::BodyFusion::Calibrations calibrations;
};

/// The subjects of the body files that this process serves (its share), and the nodes of every other subject
/// listed. Throws config::ConfigError.
std::vector<ServedSubject> served_subjects(const FusionCommandOptions& opt, std::set<std::string>& other_nodes) {
  std::vector<config::SubjectEntry> entries;
  if (opt.body_paths.empty()) entries.push_back({"", "", 0});
  for (const std::string& path : opt.body_paths)
    for (config::SubjectEntry& e : config::load_subject_entries(path)) entries.push_back(std::move(e));
  for (std::size_t i = 0; i < entries.size(); ++i) {
    if (entries.size() > 1 && entries[i].subject.empty())
      throw config::ConfigError(entries[i].body_path + ": serving several bodies, each needs its subject: give " +
                                "the body file a top-level 'subject: NAME' (or list it in a team file)");
    for (std::size_t j = 0; j < i; ++j)
      if (entries[j].subject == entries[i].subject)
        throw config::ConfigError(entries[i].body_path + ": subject '" + entries[i].subject + "' is also " +
                                  entries[j].body_path + "'s");
  }
  for (const std::string& wanted : opt.subjects)
    if (std::none_of(entries.begin(), entries.end(), [&](const auto& e) { return e.subject == wanted; }))
      throw config::ConfigError("--subject " + wanted + ": no body file given lists this subject");
  std::vector<ServedSubject> served;
  std::map<std::string, std::string> node_subject;  // every node listed, to find one on two subjects
  for (const config::SubjectEntry& e : entries) {
    ServedSubject s{e.subject, e.body_path, {}, {}};
    s.body = e.body_path.empty() ? fusion::default_lower_body() : config::load_body_model(e.body_path);
    const bool mine = (opt.subjects.empty() ||
                       std::find(opt.subjects.begin(), opt.subjects.end(), e.subject) != opt.subjects.end()) &&
                      (opt.share == 0 || e.share == opt.share);
    for (const fusion::SegmentSpec& seg : s.body.segments) {
      const auto [it, fresh] = node_subject.emplace(seg.node, e.subject);
      if (!fresh)
        throw config::ConfigError(e.body_path + ": node '" + seg.node + "' is on subject '" + e.subject +
                                  "' and on subject '" + it->second + "': a node id is one sensor");
      if (!mine) other_nodes.insert(seg.node);
    }
    if (!mine) continue;
    s.calibrations = config::load_body_calibrations(e.body_path);
    config::apply_body_alignments(e.body_path, s.body);
    served.push_back(std::move(s));
  }
  if (served.empty()) throw config::ConfigError("no subject of the body files given is in this process's share");
  return served;
}

int run_fusion(const FusionCommandOptions& opt) {
  std::vector<ServedSubject> served;
  auto other_nodes = std::make_shared<std::set<std::string>>();
  try {
    served = served_subjects(opt, *other_nodes);
  } catch (const config::ConfigError& e) {
    std::fprintf(stderr, "bsn fusion: error: %s\n", e.what());
    return 2;
  }
  if (opt.print_body) {
    for (const ServedSubject& s : served) {
      if (served.size() > 1) std::printf("# subject %s\n", s.subject.c_str());
      std::fputs(config::body_model_to_yaml(s.body).c_str(), stdout);
    }
    return 0;
  }
  std::optional<std::uint32_t> strength = opt.ownership_strength;
  if (opt.primary) strength = kPrimaryStrength;
  if (opt.standby) strength = kStandbyStrength;
  DdsCommandFrame frame(opt.domain, "bsn fusion");
  std::vector<std::unique_ptr<FusionService>> services;
  std::vector<std::set<std::string>> nodes_of(served.size());  // before the bodies move into their services
  for (std::size_t i = 0; i < served.size(); ++i)
    for (const fusion::SegmentSpec& seg : served[i].body.segments) nodes_of[i].insert(seg.node);
  for (std::size_t i = 0; i < served.size(); ++i) {
    ServedSubject& s = served[i];
    FusionService::Options service_options = opt.service;
    service_options.calibrations = std::move(s.calibrations);
    service_options.subject = s.subject;
    service_options.ownership_strength = strength;
    // A subject's nodes are also refused by the other subjects' services of this process.
    auto elsewhere = std::make_shared<std::set<std::string>>(*other_nodes);
    for (std::size_t j = 0; j < served.size(); ++j)
      if (j != i) elsewhere->insert(nodes_of[j].begin(), nodes_of[j].end());
    service_options.served_elsewhere = std::move(elsewhere);
    if (!opt.service.process_id.empty() && served.size() > 1)
      service_options.process_id = opt.service.process_id + "/" + s.subject;
    const std::size_t segments = s.body.segments.size();
    const std::string name = s.body.name.empty() ? s.body_path : s.body.name;
    services.push_back(std::make_unique<FusionService>(frame.participant(), std::move(s.body), service_options));
    logging::log_info("fusing ", segments, " segments of '", name, "'",
                      s.subject.empty() ? std::string() : " (subject '" + s.subject + "')", " in domain ", opt.domain,
                      strength ? ", exclusive ownership strength " + std::to_string(*strength) : std::string());
  }
  const int exit_code = frame.run_ticks(std::chrono::milliseconds(20), [&services] {
    for (const auto& service : services) service->tick();
    return std::optional<int>();
  });
  logging::log_info("stopped");
  return exit_code;
}

}  // namespace

Command fusion_command() {
  return {"fusion", "Fusion service: one filter per body segment", [](CLI::App* cmd) {
            auto opt = std::make_shared<FusionCommandOptions>();
            cmd->add_option("--body", opt->body_paths,
                            "YAML body model, or a team file listing subjects (repeatable: one process serves "
                            "several subjects; default: the 7-segment lower body)");
            cmd->add_option("--subject", opt->subjects,
                            "serve only this subject of the body files (repeatable): this process's share");
            cmd->add_option("--share", opt->share, "serve the subjects the team file gives this share")
                ->check(CLI::Range(1, 1000));
            auto* strength =
                cmd->add_option("--ownership-strength", opt->ownership_strength,
                                "publish estimates with EXCLUSIVE ownership of this strength: subscribers take "
                                "each segment from the strongest live fusion (primary and standby)")
                    ->check(CLI::Range(std::uint32_t{1}, std::uint32_t{1000000}));
            auto* primary = cmd->add_flag("--primary", opt->primary, "--ownership-strength 100")->excludes(strength);
            cmd->add_flag("--standby", opt->standby,
                          "hot standby: --ownership-strength 50; fuses all along and takes over when the "
                          "primary's liveliness lapses")
                ->excludes(strength)
                ->excludes(primary);
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
