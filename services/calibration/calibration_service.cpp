#include "calibration_service.hpp"

#include <chrono>
#include <cstdio>

#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/logging/log.hpp"

namespace bsn::services {
namespace {

calib::SessionSample to_session_sample(const bsn::RawSample& raw) {
  return session_sample(dds::to_imu_sample(raw), raw.seq());
}

/// The request as the core takes it; an alignment's body is parsed and its nodes found here (a body model is not
/// calib_core's).
calib::CalibrationRequest core_request(const bsn::CalibrationRequest& r) {
  calib::CalibrationRequest c;
  c.id = r.request_id();
  c.cancel = r.cancel();
  c.kind = from_wire(r.kind());
  c.kind_value = static_cast<int>(r.kind());
  c.node_list = r.node_id();
  c.session.duration_s = r.duration_s();
  c.session.sample_count = r.sample_count();
  c.session.until_good = r.until_good();
  if (r.field_magnitude() != 0.0) c.session.field_magnitude = r.field_magnitude();
  if (c.cancel || c.kind != calib::CalibrationKind::alignment) return c;
  c.alignment.duration_s = r.duration_s();
  if (r.pose_s() != 0.0) c.alignment.pose_s = r.pose_s();
  c.alignment.until_good = r.until_good();
  try {
    const fusion::BodyModel body =
        r.body().empty() ? fusion::default_lower_body() : config::parse_body_model(r.body(), "body");
    const std::vector<std::string> named =
        r.node_id() == "*" ? std::vector<std::string>{} : calib::split_node_list(r.node_id());
    c.alignment_nodes = alignment_nodes(body, named, c.nodes_problem);
  } catch (const config::ConfigError& e) {
    c.body_problem = std::string("the request's body does not parse: ") + e.what();
  }
  return c;
}

bsn::CalibrationPhase phase_to_wire(calib::RequestPhase phase) {
  switch (phase) {
    case calib::RequestPhase::waiting:
      return bsn::CALIBRATION_PHASE_WAITING;
    case calib::RequestPhase::collecting:
      return bsn::CALIBRATION_PHASE_COLLECTING;
    case calib::RequestPhase::done:
      return bsn::CALIBRATION_PHASE_DONE;
    case calib::RequestPhase::refused:
      return bsn::CALIBRATION_PHASE_REFUSED;
  }
  return bsn::CALIBRATION_PHASE_REFUSED;
}

bsn::CalibrationProgress progress_message(const calib::RequestProgress& p) {
  bsn::CalibrationProgress m;
  m.request_id(p.request_id);
  m.phase(phase_to_wire(p.phase));
  m.elapsed_s(p.elapsed_s);
  m.seconds_left(p.seconds_left);
  m.fraction(p.fraction);
  m.instruction(p.instruction);
  m.message(p.message);
  for (const calib::NodeReport& n : p.nodes) {
    bsn::CalibrationNodeProgress& np = m.nodes().emplace_back();
    np.node_id(n.node);
    np.samples(static_cast<std::uint32_t>(n.samples));
    np.poses(static_cast<std::uint32_t>(n.poses));
    np.octants(static_cast<std::uint32_t>(n.octants));
    np.sphere_coverage(n.sphere_coverage);
    np.instruction(n.instruction);
  }
  return m;
}

std::array<double, 3> arr(const calib::Vec3& v) { return {v.x(), v.y(), v.z()}; }
std::array<double, 9> arr(const calib::Mat3& m) {
  return {m(0, 0), m(0, 1), m(0, 2), m(1, 0), m(1, 1), m(1, 2), m(2, 0), m(2, 1), m(2, 2)};
}

bsn::CalibrationResult result_message(const std::string& node, const std::string& request_id,
                                      const calib::SessionResult& r) {
  bsn::CalibrationResult m;
  m.node_id(node);
  m.request_id(request_id);
  m.kind(to_wire(r.kind));
  m.success(r.success);
  m.sample_count(static_cast<std::uint32_t>(r.samples));
  m.transform(arr(calib::Mat3::Identity().eval()));
  if (r.kind == calib::CalibrationKind::gyro_bias) {
    m.bias(arr(r.gyro.bias));
    m.pose_count(0);
  } else {
    const calib::FitQuality& q = r.field.quality;
    m.bias(arr(r.field.calibration.bias));
    m.transform(arr(r.field.calibration.transform));
    m.field_magnitude(r.field.field_magnitude);
    m.field_vector(arr(r.field.field_vector));
    m.residual_rms(q.residual_rms);
    m.condition_number(q.transform_condition);
    m.pose_count(static_cast<std::uint32_t>(q.pose_count));
    m.sphere_coverage(q.sphere_coverage);
    m.octants_covered(static_cast<std::uint32_t>(q.octants_covered));
    m.pose_residual_rms(q.pose_residual_rms);
    m.warnings(q.warnings);
  }
  return m;
}

bsn::CalibrationResult alignment_message(const std::string& node, const std::string& request_id,
                                         const config::AlignmentRecord& a, bool success, const std::string& message) {
  bsn::CalibrationResult m;
  m.node_id(node);
  m.request_id(request_id);
  m.kind(bsn::CALIBRATION_SEGMENT_ALIGNMENT);
  m.success(success);
  m.transform(arr(calib::Mat3::Identity().eval()));
  m.segment(a.segment);
  const calib::Quat& q = a.sensor_to_segment;
  m.sensor_to_segment({q.w(), q.x(), q.y(), q.z()});
  m.alignment_source(a.source);
  m.hinge_residual(a.hinge_residual);
  m.axis_observability(a.axis_observability);
  m.sample_count(static_cast<std::uint32_t>(a.samples));
  m.message(message);
  return m;
}

}  // namespace

CalibrationService::CalibrationService(dds::Participant& participant, Options options)
    : participant_(participant),
      options_(std::move(options)),
      store_(options_.store_dir.empty() ? default_calibration_store() : options_.store_dir),
      requests_(options_.requests) {
  result_writer_ = participant_.make_writer(dds::kCalibrationResultTopic);
  progress_writer_ = participant_.make_writer(dds::kCalibrationProgressTopic);
  publish_stored();
  // Readers last: their callbacks may fire as soon as they exist.
  raw_reader_ =
      participant_.make_reader(dds::kRawTopic, [this](const bsn::RawSample& raw, const auto&) { on_raw(raw); });
  participant_.expect_peer(*raw_reader_, "writer of bsn/raw (a sensor node)");
  request_reader_ = participant_.make_reader(dds::kCalibrationRequestTopic,
                                             [this](const bsn::CalibrationRequest& r, const auto&) { on_request(r); });
}

CalibrationService::~CalibrationService() {
  // Stop the callbacks first, then tell the clients of requests still running.
  request_reader_.reset();
  raw_reader_.reset();
  std::lock_guard lock(mutex_);
  for (const calib::FinishedRequest& f : requests_.abort_all("the calibration service stopped", dds::monotonic_ns()))
    publish_finished(f);
}

std::size_t CalibrationService::running() const {
  std::lock_guard lock(mutex_);
  return requests_.running();
}

void CalibrationService::publish_stored() {
  std::vector<std::string> problems;
  const std::vector<StoredCalibration> stored = store_.load_all(problems);
  for (const std::string& p : problems) logging::log_warn(p, "; that calibration is skipped");
  for (const StoredCalibration& s : stored) {
    if (s.kind == calib::CalibrationKind::alignment) {
      const bsn::CalibrationResult m =
          alignment_message(s.node, s.document.request_id.empty() ? "stored" : s.document.request_id,
                            *s.document.alignment, true, "from the store: " + s.path);
      result_writer_->write(m);
      last_success_[{s.node, static_cast<int>(s.kind)}] = m;
      continue;
    }
    bsn::CalibrationResult m;
    m.node_id(s.node);
    m.request_id(s.document.request_id.empty() ? "stored" : s.document.request_id);
    m.kind(to_wire(s.kind));
    m.success(true);
    const calib::SensorCalibration& c = s.document.calibration;
    const calib::ChannelCalibration& ch = s.kind == calib::CalibrationKind::magnetometer    ? *c.magnetometer
                                          : s.kind == calib::CalibrationKind::accelerometer ? *c.accelerometer
                                                                                            : *c.gyroscope;
    m.bias(arr(ch.bias));
    m.transform(arr(ch.transform));
    if (s.kind == calib::CalibrationKind::magnetometer) {
      m.field_magnitude(s.document.magnetometer_field_magnitude);
      m.field_vector(arr(s.document.magnetometer_field_vector));
    } else if (s.kind == calib::CalibrationKind::accelerometer) {
      m.field_magnitude(s.document.accelerometer_field_magnitude);
    }
    m.message("from the store: " + s.path);
    result_writer_->write(m);
    last_success_[{s.node, static_cast<int>(s.kind)}] = m;
  }
  logging::log_info("calibration store ", store_.dir(), ": ", stored.size(), " calibrations published",
                    problems.empty() ? "" : ", ", problems.empty() ? "" : std::to_string(problems.size()),
                    problems.empty() ? "" : " files skipped");
}

void CalibrationService::publish(const calib::RequestProgress& progress) {
  progress_writer_->write(progress_message(progress));
}

void CalibrationService::write_result(const bsn::CalibrationResult& result, calib::CalibrationKind kind) {
  result_writer_->write(result);
  const std::pair<std::string, int> key{result.node_id(), static_cast<int>(kind)};
  if (result.success()) {
    last_success_[key] = result;
  } else if (const auto good = last_success_.find(key); good != last_success_.end()) {
    // The latched sample of (node, kind) is the calibration in effect for late joiners, not the failure.
    result_writer_->write(good->second);
  }
}

void CalibrationService::not_stored(const std::string& request_id, const std::string& node, calib::CalibrationKind kind,
                                    const std::exception& e) {
  // The fit is good and in effect; only its persistence failed: say so on the result too.
  logging::log_error("request '", request_id, "': node '", node, "': ", e.what());
  bsn::CalibrationResult& m = last_success_[{node, static_cast<int>(kind)}];
  m.message(std::string("not stored: ") + e.what());
  result_writer_->write(m);
}

void CalibrationService::on_request(const bsn::CalibrationRequest& request) {
  const calib::CalibrationRequest core = core_request(request);
  std::lock_guard lock(mutex_);
  const calib::RequestDecision d = requests_.request(core, dds::monotonic_ns());
  const std::string& id = core.id;
  using Outcome = calib::RequestDecision::Outcome;
  switch (d.outcome) {
    case Outcome::cancel_not_running:
      logging::log_info("cancel of request '", id, "', which is not running; ignored");
      return;
    case Outcome::cancelled:
      logging::log_info("request '", id, "' cancelled by its requester");
      publish_finished(*d.finished);
      return;
    case Outcome::repeat_ignored:
      logging::log_info("request '", id, "' arrived again; it is answered once, this copy is ignored");
      return;
    case Outcome::refusal_repeated:
      logging::log_info("request '", id, "' arrived again; its refusal is sent again");
      publish(*d.progress);
      return;
    case Outcome::refused:
      logging::log_warn("request '", id, "' refused: ", d.progress->message);
      publish(*d.progress);
      // An alignment's result topic says it too, per node named.
      for (const std::string& node : d.refused_alignment_nodes)
        write_result(alignment_message(node, id, {}, false, "refused: " + d.progress->message),
                     calib::CalibrationKind::alignment);
      return;
    case Outcome::started:
      logging::log_info("request '", id, "': ", d.description);
      publish(*d.progress);
      return;
  }
}

void CalibrationService::on_raw(const bsn::RawSample& raw) {
  std::lock_guard lock(mutex_);
  if (const auto finished = requests_.sample(raw.node_id(), to_session_sample(raw), dds::monotonic_ns()))
    publish_finished(*finished);
}

void CalibrationService::tick() {
  std::lock_guard lock(mutex_);
  const calib::TickOutcome t = requests_.tick(dds::monotonic_ns());
  for (const calib::RequestProgress& p : t.progress) publish(p);
  for (const calib::FinishedRequest& f : t.finished) publish_finished(f);
}

void CalibrationService::publish_finished(const calib::FinishedRequest& finished) {
  if (finished.kind == calib::CalibrationKind::alignment)
    publish_alignments(finished);
  else
    publish_calibrations(finished);
}

void CalibrationService::publish_calibrations(const calib::FinishedRequest& f) {
  std::vector<const calib::NodeCalibration*> to_store;
  for (const calib::NodeCalibration& n : f.calibrations) {
    if (!n.result.success) logging::log_warn("request '", f.id, "': ", n.result.message);
    bsn::CalibrationResult m = result_message(n.node, f.id, n.result);
    m.message(n.result.message);
    write_result(m, f.kind);
    if (n.result.success) to_store.push_back(&n);
  }
  publish(f.done);
  // Stored after every node's result is out: the store's fsync would delay each result by milliseconds.
  for (const calib::NodeCalibration* n : to_store) {
    try {
      const std::string path = store_.save(n->node, n->result, f.id);
      logging::log_info("request '", f.id, "': node '", n->node, "' calibrated (", n->result.samples, " samples, ",
                        n->result.field.quality.pose_count, " poses); stored in ", path);
    } catch (const std::exception& e) {
      not_stored(f.id, n->node, f.kind, e);
    }
  }
}

void CalibrationService::publish_alignments(const calib::FinishedRequest& f) {
  if (!f.aborted) {
    // What the fit had: a failed alignment is explained by these (a pose found late, flexions cut short).
    std::string samples;
    for (const calib::NodeAlignmentResult& n : f.alignments)
      samples += (samples.empty() ? "" : ", ") + n.node + " " + std::to_string(n.alignment.samples);
    const calib::AlignmentSessionResult& r = f.alignment_fit;
    char times[96];
    std::snprintf(times, sizeof times, "N-pose %.2f..%.2f s, flexions to %.2f s", r.pose_start_s, r.pose_end_s,
                  r.moves_end_s);
    logging::log_info("request '", f.id, "': samples ", samples, "; ", r.paired_samples, " instants with every node; ",
                      times, " after the first of them");
  }
  std::vector<std::pair<std::string, config::AlignmentRecord>> to_store;
  for (const calib::NodeAlignmentResult& n : f.alignments) {
    const calib::NodeAlignment& a = n.alignment;
    const config::AlignmentRecord record{n.segment,           a.sensor_to_segment,  a.source,
                                         a.relative_residual, a.axis_observability, a.samples};
    if (!a.success) logging::log_warn("request '", f.id, "': ", n.message);
    write_result(alignment_message(n.node, f.id, record, a.success, n.message), calib::CalibrationKind::alignment);
    if (a.success) to_store.emplace_back(n.node, record);
  }
  publish(f.done);
  for (const auto& [node, record] : to_store) {
    try {
      const std::string path = store_.save_alignment(node, record, f.id);
      logging::log_info("request '", f.id, "': node '", node, "' aligned to segment '", record.segment, "' (",
                        record.source, "); stored in ", path);
    } catch (const std::exception& e) {
      not_stored(f.id, node, calib::CalibrationKind::alignment, e);
    }
  }
}

namespace {

struct CalibrationCommandOptions {
  int domain = 0;
  CalibrationService::Options service;
};

int run_calibration(const CalibrationCommandOptions& opt) {
  DdsCommandFrame frame(opt.domain, "bsn calibration");
  std::optional<CalibrationService> service;
  try {
    service.emplace(frame.participant(), opt.service);
  } catch (const std::runtime_error& e) {
    logging::log_error(e.what());
    return 2;
  }
  logging::log_info("serving bsn/calibration/request in domain ", opt.domain);
  const int exit_code = frame.run_ticks(std::chrono::milliseconds(20), [&service] {
    service->tick();
    return std::optional<int>();
  });
  service.reset();
  logging::log_info("stopped");
  return exit_code;
}

}  // namespace

Command calibration_command() {
  return {"calibration", "Calibration service: fits sensor calibrations on request over DDS", [](CLI::App* cmd) {
            auto opt = std::make_shared<CalibrationCommandOptions>();
            cmd->add_option("--store", opt->service.store_dir,
                            "calibration store directory (default: $XDG_STATE_HOME/bsn/calibration or "
                            "~/.local/state/bsn/calibration)");
            cmd->add_option("--progress-period", opt->service.requests.progress_period_s,
                            "seconds between progress samples")
                ->check(CLI::Range(0.02, 0.5))
                ->capture_default_str();
            add_domain_option(cmd, opt->domain);
            return [opt] { return run_calibration(*opt); };
          }};
}

}  // namespace bsn::services
