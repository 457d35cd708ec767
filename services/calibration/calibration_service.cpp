#include "calibration_service.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/logging/log.hpp"

namespace bsn::services {
namespace {

constexpr std::size_t kMaxNodeIdLength = 63;  // as bsn::RawSample.node_id
using calib::seconds_between;

std::vector<std::string> split_nodes(const std::string& list) {
  std::vector<std::string> out;
  std::stringstream in(list);
  std::string item;
  while (std::getline(in, item, ',')) {
    const auto b = item.find_first_not_of(" \t");
    const auto e = item.find_last_not_of(" \t");
    if (b == std::string::npos) continue;
    item = item.substr(b, e - b + 1);
    if (std::find(out.begin(), out.end(), item) == out.end()) out.push_back(item);
  }
  return out;
}

calib::SessionSample to_session_sample(const bsn::RawSample& raw) {
  return session_sample(dds::to_imu_sample(raw), raw.seq());
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
      store_(options_.store_dir.empty() ? default_calibration_store() : options_.store_dir) {
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
  std::vector<std::string> ids;
  for (const auto& [id, run] : runs_) ids.push_back(id);
  for (const std::string& id : ids) finish(id, dds::monotonic_ns(), "the calibration service stopped");
}

std::size_t CalibrationService::running() const {
  std::lock_guard lock(mutex_);
  return runs_.size();
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

void CalibrationService::refuse(const std::string& request_id, const std::string& why) {
  logging::log_warn("request '", request_id, "' refused: ", why);
  if (const auto answered = answered_.find(request_id); answered != answered_.end()) answered->second = why;
  publish_refusal(request_id, why);
}

void CalibrationService::publish_refusal(const std::string& request_id, const std::string& why) {
  bsn::CalibrationProgress p;
  p.request_id(request_id);
  p.phase(bsn::CALIBRATION_PHASE_REFUSED);
  p.fraction(0.0);
  p.seconds_left(0.0);
  p.message(why);
  progress_writer_->write(p);
}

void CalibrationService::on_request(const bsn::CalibrationRequest& request) {
  std::lock_guard lock(mutex_);
  const std::uint64_t now = dds::monotonic_ns();
  const std::string& id = request.request_id();
  if (request.cancel()) {
    if (runs_.count(id) == 0) {
      logging::log_info("cancel of request '", id, "', which is not running; ignored");
      return;
    }
    logging::log_info("request '", id, "' cancelled by its requester");
    finish(id, now, "cancelled by the requester");
    return;
  }
  if (id.empty()) {
    refuse(id, "the request has no request_id");
    return;
  }
  if (const auto [answered, first] = answered_.try_emplace(id); !first) {
    // A refusal is said again: its requester sends again when no answer came, since the refusal can go out before
    // this writer has matched the requester's progress reader (discovery runs each way on its own).
    if (!answered->second.empty()) {
      logging::log_info("request '", id, "' arrived again; its refusal is sent again");
      publish_refusal(id, answered->second);
      return;
    }
    logging::log_info("request '", id, "' arrived again; it is answered once, this copy is ignored");
    return;
  }
  const std::optional<calib::CalibrationKind> kind = from_wire(request.kind());
  if (!kind) {
    refuse(id, "unknown kind " + std::to_string(static_cast<int>(request.kind())) +
                   " (known: 0 magnetometer, 1 gyro bias, 2 accelerometer, 3 segment alignment)");
    return;
  }
  if (*kind == calib::CalibrationKind::alignment) {
    on_alignment_request(request, now);
    return;
  }
  calib::SessionParams params;
  params.kind = *kind;
  params.duration_s = request.duration_s();
  params.sample_count = request.sample_count();
  params.until_good = request.until_good();
  if (request.field_magnitude() != 0.0) params.field_magnitude = request.field_magnitude();
  if (const std::string why = calib::validate(params); !why.empty()) {
    refuse(id, why);
    return;
  }
  std::vector<std::string> nodes;
  if (request.node_id() == "*") {
    for (const auto& [node, at] : heard_)
      if (seconds_between(at, now) <= options_.active_node_window_s) nodes.push_back(node);
    std::sort(nodes.begin(), nodes.end());
    if (nodes.empty()) {
      refuse(id, "node '*': no node has published on bsn/raw within the last " +
                     std::to_string(options_.active_node_window_s) + " s");
      return;
    }
  } else {
    nodes = split_nodes(request.node_id());
    if (nodes.empty()) {
      refuse(id, "the request names no node (node_id is empty)");
      return;
    }
  }
  for (const std::string& node : nodes) {
    if (node.size() > kMaxNodeIdLength) {
      refuse(id, "node id '" + node.substr(0, 20) + "...' is longer than 63 characters");
      return;
    }
    if (const auto b = busy_.find(node); b != busy_.end()) {
      refuse(id, "node '" + node + "' is being calibrated by request '" + b->second + "'; wait for its result");
      return;
    }
  }
  Run run;
  run.id = id;
  run.kind = *kind;
  run.start_ns = now;
  run.last_progress_ns = 0;
  std::string list;
  for (const std::string& node : nodes) {
    run.nodes.push_back({node, calib::CalibrationSession(params, now), {}});
    busy_[node] = id;
    list += (list.empty() ? "" : ", ") + node;
  }
  logging::log_info("request '", id, "': ", calib::kind_name(*kind), " of ", list, " (",
                    params.duration_s > 0 ? std::to_string(params.duration_s) + " s" : std::string("no time limit"),
                    params.sample_count > 0 ? ", " + std::to_string(params.sample_count) + " samples" : std::string(),
                    params.until_good ? ", until good enough" : "", ")");
  auto& stored = runs_[id] = std::move(run);
  publish_progress(stored, now);
}

void CalibrationService::on_raw(const bsn::RawSample& raw) {
  std::lock_guard lock(mutex_);
  const std::uint64_t now = dds::monotonic_ns();
  heard_[raw.node_id()] = now;
  const auto b = busy_.find(raw.node_id());
  if (b == busy_.end()) return;
  const std::string request_id = b->second;  // a copy: finish() erases the entry
  Run& run = runs_.at(request_id);
  if (run.alignment) {
    const auto& nodes = run.alignment->nodes();
    for (std::size_t i = 0; i < nodes.size(); ++i)
      if (nodes[i].node == raw.node_id()) run.alignment->add(i, to_session_sample(raw), now);
    if (run.alignment->collection_over(now)) finish(request_id, now);
    return;
  }
  bool all_over = true;
  for (NodeRun& n : run.nodes) {
    if (n.node == raw.node_id()) n.session.add(to_session_sample(raw), now);
    all_over = all_over && n.session.collection_over(now);
  }
  // The last sample of a sample_count collection: fit at once, from this thread, for the lowest latency.
  if (all_over) finish(request_id, now);
}

void CalibrationService::tick() {
  std::lock_guard lock(mutex_);
  const std::uint64_t now = dds::monotonic_ns();
  std::vector<std::string> over;
  for (auto& [id, run] : runs_) {
    if (seconds_between(run.last_progress_ns, now) >= options_.progress_period_s) publish_progress(run, now);
    const bool all_over = run.alignment ? run.alignment->collection_over(now)
                                        : std::all_of(run.nodes.begin(), run.nodes.end(), [now](const NodeRun& n) {
                                            return n.session.collection_over(now);
                                          });
    if (all_over) over.push_back(id);
  }
  for (const std::string& id : over) finish(id, now);
}

void CalibrationService::publish_progress(Run& run, std::uint64_t now) {
  if (run.alignment) {
    publish_alignment_progress(run, now);
    return;
  }
  bsn::CalibrationProgress p;
  p.request_id(run.id);
  bool started = false;
  double fraction = 1.0;
  double seconds_left = -1.0;
  const NodeRun* behind = nullptr;  // the node furthest from done sets the instruction of all (turned as one)
  for (NodeRun& n : run.nodes) {
    n.last_progress = n.session.progress(now);
    const calib::SessionProgress& s = n.last_progress;
    started = started || s.started;
    if (behind == nullptr || s.fraction < fraction) behind = &n;
    fraction = std::min(fraction, s.fraction);
    seconds_left = std::max(seconds_left, s.seconds_left);
    bsn::CalibrationNodeProgress& np = p.nodes().emplace_back();
    np.node_id(n.node);
    np.samples(static_cast<std::uint32_t>(s.samples));
    np.poses(static_cast<std::uint32_t>(s.poses));
    np.octants(static_cast<std::uint32_t>(s.octants));
    np.sphere_coverage(s.sphere_coverage);
    np.instruction(s.instruction);
  }
  p.phase(started ? bsn::CALIBRATION_PHASE_COLLECTING : bsn::CALIBRATION_PHASE_WAITING);
  p.elapsed_s(seconds_between(run.start_ns, now));
  p.seconds_left(seconds_left);
  p.fraction(fraction);
  if (behind != nullptr) p.instruction(behind->last_progress.instruction);
  progress_writer_->write(p);
  run.last_progress_ns = now;
}

void CalibrationService::publish_done(const Run& run, std::size_t succeeded) {
  bsn::CalibrationProgress p;
  p.request_id(run.id);
  p.phase(bsn::CALIBRATION_PHASE_DONE);
  p.elapsed_s(seconds_between(run.start_ns, dds::monotonic_ns()));
  p.seconds_left(0.0);
  p.fraction(1.0);
  p.instruction("done: " + std::to_string(succeeded) + " of " + std::to_string(run.nodes.size()) + " nodes calibrated");
  for (const NodeRun& n : run.nodes) {
    bsn::CalibrationNodeProgress& np = p.nodes().emplace_back();
    np.node_id(n.node);
    np.samples(static_cast<std::uint32_t>(n.session.samples()));
    np.poses(static_cast<std::uint32_t>(n.last_progress.poses));
    np.octants(static_cast<std::uint32_t>(n.last_progress.octants));
    np.sphere_coverage(n.last_progress.sphere_coverage);
    np.instruction(n.last_progress.instruction);
  }
  progress_writer_->write(p);
}

void CalibrationService::finish(const std::string& request_id, std::uint64_t now, const std::string& abort_reason) {
  const auto it = runs_.find(request_id);
  if (it == runs_.end()) return;
  Run run = std::move(it->second);
  runs_.erase(it);
  if (run.alignment) {
    finish_alignment(run, now, abort_reason);
    return;
  }
  std::vector<std::pair<const NodeRun*, calib::SessionResult>> to_store;
  for (const NodeRun& n : run.nodes) {
    busy_.erase(n.node);
    calib::SessionResult r;
    if (abort_reason.empty()) {
      r = n.session.finish();
    } else {
      r.kind = run.kind;
      r.samples = n.session.samples();
      r.message = abort_reason;
    }
    if (!r.success) {
      const double waited = seconds_between(run.start_ns, now);
      if (r.message == "no sample arrived")
        r.message = "no sample arrived within " + std::to_string(waited).substr(0, 4) + " s";
      r.message = "node '" + n.node + "': " + r.message;
      logging::log_warn("request '", run.id, "': ", r.message);
    }
    bsn::CalibrationResult m = result_message(n.node, run.id, r);
    m.message(r.message);
    result_writer_->write(m);
    const std::pair<std::string, int> key{n.node, static_cast<int>(run.kind)};
    if (r.success) {
      last_success_[key] = m;
      to_store.emplace_back(&n, std::move(r));
    } else if (const auto good = last_success_.find(key); good != last_success_.end()) {
      // The latched sample of (node, kind) is the calibration in effect for late joiners, not the failure.
      result_writer_->write(good->second);
    }
  }
  publish_done(run, to_store.size());
  // Stored after every node's result is out: the store's fsync would delay each result by milliseconds.
  for (auto& [n, r] : to_store) {
    try {
      const std::string path = store_.save(n->node, r, run.id);
      logging::log_info("request '", run.id, "': node '", n->node, "' calibrated (", r.samples, " samples, ",
                        r.field.quality.pose_count, " poses); stored in ", path);
    } catch (const std::exception& e) {
      // The fit is good and in effect; only its persistence failed: say so on the result too.
      logging::log_error("request '", run.id, "': node '", n->node, "': ", e.what());
      bsn::CalibrationResult& m = last_success_[{n->node, static_cast<int>(run.kind)}];
      m.message(std::string("not stored: ") + e.what());
      result_writer_->write(m);
    }
  }
}

void CalibrationService::refuse_alignment(const std::string& request_id, const std::vector<std::string>& nodes,
                                          const std::string& why) {
  refuse(request_id, why);
  // The result topic says it too, per node named (at most a body's worth: the refusal is on progress anyway).
  std::size_t written = 0;
  for (const std::string& node : nodes) {
    if (node.empty() || node.size() > kMaxNodeIdLength || ++written > 64) continue;
    result_writer_->write(alignment_message(node, request_id, {}, false, "refused: " + why));
    if (const auto good = last_success_.find({node, static_cast<int>(calib::CalibrationKind::alignment)});
        good != last_success_.end())
      result_writer_->write(good->second);
  }
}

void CalibrationService::on_alignment_request(const bsn::CalibrationRequest& request, std::uint64_t now) {
  const std::string& id = request.request_id();
  const std::vector<std::string> named = request.node_id() == "*" || request.node_id().empty()
                                             ? std::vector<std::string>{}
                                             : split_nodes(request.node_id());
  fusion::BodyModel body;
  try {
    body = request.body().empty() ? fusion::default_lower_body() : config::parse_body_model(request.body(), "body");
  } catch (const config::ConfigError& e) {
    refuse_alignment(id, named, std::string("the request's body does not parse: ") + e.what());
    return;
  }
  for (const std::string& node : named) {
    if (node.size() > kMaxNodeIdLength) {
      refuse_alignment(id, {}, "node id '" + node.substr(0, 20) + "...' is longer than 63 characters");
      return;
    }
  }
  std::string problem;
  std::vector<calib::AlignmentNode> nodes = alignment_nodes(body, named, problem);
  if (!problem.empty()) {
    refuse_alignment(id, named, problem);
    return;
  }
  calib::AlignmentSessionParams params;
  params.duration_s = request.duration_s();
  if (request.pose_s() != 0.0) params.pose_s = request.pose_s();
  params.until_good = request.until_good();
  std::vector<std::string> ids;
  for (const auto& n : nodes) ids.push_back(n.node);
  if (const std::string why = calib::validate(params); !why.empty()) {
    refuse_alignment(id, ids, why);
    return;
  }
  for (const std::string& node : ids) {
    if (const auto b = busy_.find(node); b != busy_.end()) {
      refuse_alignment(id, ids,
                       "node '" + node + "' is being calibrated by request '" + b->second + "'; wait for its result");
      return;
    }
  }
  Run run;
  run.id = id;
  run.kind = calib::CalibrationKind::alignment;
  run.start_ns = now;
  run.alignment = std::make_unique<calib::AlignmentSession>(std::move(nodes), params, now);
  std::string list;
  for (const std::string& node : ids) {
    busy_[node] = id;
    list += (list.empty() ? "" : ", ") + node;
  }
  logging::log_info("request '", id, "': alignment of ", list, " (", params.duration_s, " s, N-pose ", params.pose_s,
                    " s", params.until_good ? ", until good enough" : "", ")");
  auto& stored = runs_[id] = std::move(run);
  publish_progress(stored, now);
}

void CalibrationService::publish_alignment_progress(Run& run, std::uint64_t now) {
  const calib::AlignmentProgress a = run.alignment->progress(now);
  bsn::CalibrationProgress p;
  p.request_id(run.id);
  p.phase(a.phase == calib::AlignmentPhase::waiting ? bsn::CALIBRATION_PHASE_WAITING
                                                    : bsn::CALIBRATION_PHASE_COLLECTING);
  p.elapsed_s(a.elapsed_s);
  p.seconds_left(a.seconds_left);
  p.fraction(a.fraction);
  p.instruction(a.instruction);
  const auto& nodes = run.alignment->nodes();
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    bsn::CalibrationNodeProgress& np = p.nodes().emplace_back();
    np.node_id(nodes[i].node);
    np.samples(static_cast<std::uint32_t>(a.samples[i]));
    np.instruction(a.node_instructions[i]);
  }
  progress_writer_->write(p);
  run.last_progress_ns = now;
}

void CalibrationService::finish_alignment(Run& run, std::uint64_t now, const std::string& abort_reason) {
  const auto& nodes = run.alignment->nodes();
  for (const auto& n : nodes) busy_.erase(n.node);
  calib::AlignmentSessionResult r;
  if (abort_reason.empty()) {
    r = run.alignment->finish(now);
  } else {
    r.nodes.resize(nodes.size());
    for (auto& n : r.nodes) n.message = abort_reason;
  }
  if (abort_reason.empty()) {
    // What the fit had: a failed alignment is explained by these (a pose found late, flexions cut short).
    std::string samples;
    for (std::size_t i = 0; i < nodes.size(); ++i)
      samples += (i == 0 ? "" : ", ") + nodes[i].node + " " + std::to_string(run.alignment->samples(i));
    char times[96];
    std::snprintf(times, sizeof times, "N-pose %.2f..%.2f s, flexions to %.2f s", r.pose_start_s, r.pose_end_s,
                  r.moves_end_s);
    logging::log_info("request '", run.id, "': samples ", samples, "; ", r.paired_samples,
                      " instants with every node; ", times, " after the first of them");
  }
  std::vector<std::pair<std::string, config::AlignmentRecord>> to_store;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const calib::NodeAlignment& a = r.nodes[i];
    config::AlignmentRecord record{nodes[i].segment,    a.sensor_to_segment,  a.source,
                                   a.relative_residual, a.axis_observability, run.alignment->samples(i)};
    // A failure of the whole body (a silent node, no pose, another clock) says so; a segment's own names the node.
    const std::string message = a.success ? ""
                                : !r.problem.empty() && a.message == r.problem
                                    ? "the body's alignment failed: " + a.message
                                    : "node '" + nodes[i].node + "': " + a.message;
    if (!a.success) logging::log_warn("request '", run.id, "': ", message);
    const bsn::CalibrationResult m = alignment_message(nodes[i].node, run.id, record, a.success, message);
    result_writer_->write(m);
    const std::pair<std::string, int> key{nodes[i].node, static_cast<int>(calib::CalibrationKind::alignment)};
    if (a.success) {
      last_success_[key] = m;
      to_store.emplace_back(nodes[i].node, record);
    } else if (const auto good = last_success_.find(key); good != last_success_.end()) {
      result_writer_->write(good->second);
    }
  }
  bsn::CalibrationProgress p;
  p.request_id(run.id);
  p.phase(bsn::CALIBRATION_PHASE_DONE);
  p.elapsed_s(seconds_between(run.start_ns, now));
  p.fraction(1.0);
  p.instruction("done: " + std::to_string(to_store.size()) + " of " + std::to_string(nodes.size()) + " nodes aligned" +
                (r.problem.empty() ? "" : " (" + r.problem + ")"));
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    bsn::CalibrationNodeProgress& np = p.nodes().emplace_back();
    np.node_id(nodes[i].node);
    np.samples(static_cast<std::uint32_t>(run.alignment->samples(i)));
    np.instruction(r.nodes[i].success ? r.nodes[i].source : r.nodes[i].message);
  }
  progress_writer_->write(p);
  for (const auto& [node, record] : to_store) {
    try {
      const std::string path = store_.save_alignment(node, record, run.id);
      logging::log_info("request '", run.id, "': node '", node, "' aligned to segment '", record.segment, "' (",
                        record.source, "); stored in ", path);
    } catch (const std::exception& e) {
      logging::log_error("request '", run.id, "': node '", node, "': ", e.what());
      bsn::CalibrationResult& m = last_success_[{node, static_cast<int>(calib::CalibrationKind::alignment)}];
      m.message(std::string("not stored: ") + e.what());
      result_writer_->write(m);
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
            cmd->add_option("--progress-period", opt->service.progress_period_s, "seconds between progress samples")
                ->check(CLI::Range(0.02, 0.5))
                ->capture_default_str();
            add_domain_option(cmd, opt->domain);
            return [opt] { return run_calibration(*opt); };
          }};
}

}  // namespace bsn::services
