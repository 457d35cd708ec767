#include "bsn/calib/calibration_requests.hpp"

#include <algorithm>
#include <sstream>

namespace bsn::calib {

std::vector<std::string> split_node_list(const std::string& list) {
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

namespace {

std::string comma_list(const std::vector<std::string>& items) {
  std::string list;
  for (const std::string& item : items) list += (list.empty() ? "" : ", ") + item;
  return list;
}

RequestDecision decision(RequestDecision::Outcome outcome) {
  RequestDecision d;
  d.outcome = outcome;
  return d;
}

}  // namespace

RequestDecision CalibrationRequests::refuse(const std::string& id, const std::string& why) {
  if (const auto answered = answered_.find(id); answered != answered_.end()) answered->second = why;
  RequestDecision d = decision(RequestDecision::Outcome::refused);
  RequestProgress& p = d.progress.emplace();
  p.request_id = id;
  p.phase = RequestPhase::refused;
  p.message = why;
  return d;
}

RequestDecision CalibrationRequests::refuse_alignment(const std::string& id, const std::vector<std::string>& nodes,
                                                      const std::string& why) {
  RequestDecision d = refuse(id, why);
  for (const std::string& node : nodes) {
    if (node.empty() || node.size() > params_.max_node_id_length) continue;
    if (d.refused_alignment_nodes.size() == params_.max_refused_nodes) break;
    d.refused_alignment_nodes.push_back(node);
  }
  return d;
}

RequestDecision CalibrationRequests::request(const CalibrationRequest& request, std::uint64_t now) {
  const std::string& id = request.id;
  if (request.cancel) {
    if (runs_.count(id) == 0) return decision(RequestDecision::Outcome::cancel_not_running);
    RequestDecision d = decision(RequestDecision::Outcome::cancelled);
    d.finished = finish(id, now, "cancelled by the requester");
    return d;
  }
  if (id.empty()) return refuse(id, "the request has no request_id");
  if (const auto [answered, first] = answered_.try_emplace(id); !first) {
    // A refusal is said again: its requester sends again when no answer came, since the refusal can go out before
    // the service's writer has matched the requester's reader (discovery runs each way on its own).
    if (answered->second.empty()) return decision(RequestDecision::Outcome::repeat_ignored);
    RequestDecision d = refuse(id, answered->second);
    d.outcome = RequestDecision::Outcome::refusal_repeated;
    return d;
  }
  if (!request.kind) {
    return refuse(id, "unknown kind " + std::to_string(request.kind_value) +
                          " (known: 0 magnetometer, 1 gyro-bias, 2 accelerometer, 3 alignment)");
  }
  return *request.kind == CalibrationKind::alignment ? request_alignment(request, now) : request_sensor(request, now);
}

std::string CalibrationRequests::node_problem(const std::vector<std::string>& nodes) const {
  for (const std::string& node : nodes) {
    if (node.size() > params_.max_node_id_length)
      return "node id '" + node.substr(0, 20) + "...' is longer than " + std::to_string(params_.max_node_id_length) +
             " characters";
    if (const auto b = busy_.find(node); b != busy_.end())
      return "node '" + node + "' is being calibrated by request '" + b->second + "'; wait for its result";
  }
  return "";
}

RequestDecision CalibrationRequests::request_sensor(const CalibrationRequest& request, std::uint64_t now) {
  SessionParams params = request.session;
  params.kind = *request.kind;
  if (const std::string why = validate(params); !why.empty()) return refuse(request.id, why);
  std::vector<std::string> nodes;
  if (request.node_list == "*") {
    for (const auto& [node, at] : heard_)
      if (seconds_between(at, now) <= params_.active_node_window_s) nodes.push_back(node);
    std::sort(nodes.begin(), nodes.end());
    if (nodes.empty()) {
      return refuse(request.id, "node '*': no node has published on bsn/raw within the last " +
                                    std::to_string(params_.active_node_window_s) + " s");
    }
  } else {
    nodes = split_node_list(request.node_list);
    if (nodes.empty()) return refuse(request.id, "the request names no node (node_id is empty)");
  }
  if (const std::string why = node_problem(nodes); !why.empty()) return refuse(request.id, why);
  Run run;
  run.id = request.id;
  run.kind = params.kind;
  run.start_ns = now;
  for (const std::string& node : nodes) run.nodes.push_back({node, CalibrationSession(params, now), {}});
  std::string description = std::string(kind_name(params.kind)) + " of " + comma_list(nodes) + " (" +
                            (params.duration_s > 0 ? std::to_string(params.duration_s) + " s" : "no time limit") +
                            (params.sample_count > 0 ? ", " + std::to_string(params.sample_count) + " samples" : "") +
                            (params.until_good ? ", until good enough" : "") + ")";
  return start(std::move(run), nodes, std::move(description));
}

RequestDecision CalibrationRequests::request_alignment(const CalibrationRequest& request, std::uint64_t now) {
  const std::string& id = request.id;
  const std::vector<std::string> named =
      request.node_list == "*" ? std::vector<std::string>{} : split_node_list(request.node_list);
  if (!request.body_problem.empty()) return refuse_alignment(id, named, request.body_problem);
  for (const std::string& node : named) {
    if (node.size() > params_.max_node_id_length) return refuse_alignment(id, {}, node_problem({node}));
  }
  if (!request.nodes_problem.empty()) return refuse_alignment(id, named, request.nodes_problem);
  std::vector<std::string> ids;
  for (const AlignmentNode& n : request.alignment_nodes) ids.push_back(n.node);
  if (const std::string why = validate(request.alignment); !why.empty()) return refuse_alignment(id, ids, why);
  if (const std::string why = node_problem(ids); !why.empty()) return refuse_alignment(id, ids, why);
  Run run;
  run.id = id;
  run.kind = CalibrationKind::alignment;
  run.start_ns = now;
  run.alignment = std::make_unique<AlignmentSession>(request.alignment_nodes, request.alignment, now);
  std::ostringstream description;
  description << "alignment of " << comma_list(ids) << " (" << request.alignment.duration_s << " s, N-pose "
              << request.alignment.pose_s << " s" << (request.alignment.until_good ? ", until good enough" : "") << ")";
  return start(std::move(run), ids, description.str());
}

RequestDecision CalibrationRequests::start(Run run, const std::vector<std::string>& nodes, std::string description) {
  for (const std::string& node : nodes) busy_[node] = run.id;
  const std::uint64_t now = run.start_ns;
  Run& stored = runs_[run.id] = std::move(run);
  RequestDecision d = decision(RequestDecision::Outcome::started);
  d.description = std::move(description);
  d.progress = progress(stored, now);
  return d;
}

std::optional<FinishedRequest> CalibrationRequests::sample(const std::string& node, const SessionSample& sample,
                                                           std::uint64_t now) {
  heard_[node] = now;
  const auto b = busy_.find(node);
  if (b == busy_.end()) return std::nullopt;
  Run& run = runs_.at(b->second);
  if (run.alignment) {
    const auto& nodes = run.alignment->nodes();
    for (std::size_t i = 0; i < nodes.size(); ++i)
      if (nodes[i].node == node) run.alignment->add(i, sample, now);
  } else {
    for (NodeRun& n : run.nodes)
      if (n.node == node) n.session.add(sample, now);
  }
  if (!collection_over(run, now)) return std::nullopt;
  const std::string id = run.id;  // a copy: finish() erases the run
  return finish(id, now);
}

bool CalibrationRequests::collection_over(const Run& run, std::uint64_t now) {
  if (run.alignment) return run.alignment->collection_over(now);
  return std::all_of(run.nodes.begin(), run.nodes.end(),
                     [now](const NodeRun& n) { return n.session.collection_over(now); });
}

TickOutcome CalibrationRequests::tick(std::uint64_t now) {
  TickOutcome out;
  std::vector<std::string> over;
  for (auto& [id, run] : runs_) {
    if (seconds_between(run.last_progress_ns, now) >= params_.progress_period_s)
      out.progress.push_back(progress(run, now));
    if (collection_over(run, now)) over.push_back(id);
  }
  for (const std::string& id : over) out.finished.push_back(finish(id, now));
  return out;
}

std::vector<FinishedRequest> CalibrationRequests::abort_all(const std::string& reason, std::uint64_t now) {
  std::vector<std::string> ids;
  for (const auto& [id, run] : runs_) ids.push_back(id);
  std::vector<FinishedRequest> out;
  for (const std::string& id : ids) out.push_back(finish(id, now, reason));
  return out;
}

RequestProgress CalibrationRequests::progress(Run& run, std::uint64_t now) {
  run.last_progress_ns = now;
  if (run.alignment) return alignment_progress(run, now);
  RequestProgress p;
  p.request_id = run.id;
  bool started = false;
  p.fraction = 1.0;
  p.seconds_left = -1.0;
  const NodeRun* behind = nullptr;  // the node furthest from done sets the instruction of all (turned as one)
  for (NodeRun& n : run.nodes) {
    n.last_progress = n.session.progress(now);
    const SessionProgress& s = n.last_progress;
    started = started || s.started;
    if (behind == nullptr || s.fraction < p.fraction) behind = &n;
    p.fraction = std::min(p.fraction, s.fraction);
    p.seconds_left = std::max(p.seconds_left, s.seconds_left);
    p.nodes.push_back({n.node, s.samples, s.poses, s.octants, s.sphere_coverage, s.instruction});
  }
  p.phase = started ? RequestPhase::collecting : RequestPhase::waiting;
  p.elapsed_s = seconds_between(run.start_ns, now);
  if (behind != nullptr) p.instruction = behind->last_progress.instruction;
  return p;
}

RequestProgress CalibrationRequests::alignment_progress(Run& run, std::uint64_t now) {
  const AlignmentProgress a = run.alignment->progress(now);
  RequestProgress p;
  p.request_id = run.id;
  p.phase = a.phase == AlignmentPhase::waiting ? RequestPhase::waiting : RequestPhase::collecting;
  p.elapsed_s = a.elapsed_s;
  p.seconds_left = a.seconds_left;
  p.fraction = a.fraction;
  p.instruction = a.instruction;
  const auto& nodes = run.alignment->nodes();
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    NodeReport& r = p.nodes.emplace_back();
    r.node = nodes[i].node;
    r.samples = a.samples[i];
    r.instruction = a.node_instructions[i];
  }
  return p;
}

FinishedRequest CalibrationRequests::finish(const std::string& id, std::uint64_t now, const std::string& abort_reason) {
  FinishedRequest out;
  const auto it = runs_.find(id);
  if (it == runs_.end()) return out;
  Run run = std::move(it->second);
  runs_.erase(it);
  out.id = run.id;
  out.kind = run.kind;
  out.aborted = !abort_reason.empty();
  out.done.request_id = run.id;
  out.done.phase = RequestPhase::done;
  out.done.elapsed_s = seconds_between(run.start_ns, now);
  out.done.fraction = 1.0;
  if (run.alignment)
    finish_alignment(run, now, abort_reason, out);
  else
    finish_sensor(run, now, abort_reason, out);
  return out;
}

void CalibrationRequests::finish_sensor(Run& run, std::uint64_t now, const std::string& abort_reason,
                                        FinishedRequest& out) {
  std::size_t succeeded = 0;
  for (const NodeRun& n : run.nodes) {
    busy_.erase(n.node);
    SessionResult r;
    if (abort_reason.empty()) {
      r = n.session.finish();
    } else {
      r.kind = run.kind;
      r.samples = n.session.samples();
      r.message = abort_reason;
    }
    if (r.success) {
      ++succeeded;
    } else {
      if (r.message == "no sample arrived") {
        const double waited = seconds_between(run.start_ns, now);
        r.message = "no sample arrived within " + std::to_string(waited).substr(0, 4) + " s";
      }
      r.message = "node '" + n.node + "': " + r.message;
    }
    out.calibrations.push_back({n.node, std::move(r)});
    const SessionProgress& s = n.last_progress;
    out.done.nodes.push_back({n.node, n.session.samples(), s.poses, s.octants, s.sphere_coverage, s.instruction});
  }
  out.done.instruction =
      "done: " + std::to_string(succeeded) + " of " + std::to_string(run.nodes.size()) + " nodes calibrated";
}

void CalibrationRequests::finish_alignment(Run& run, std::uint64_t now, const std::string& abort_reason,
                                           FinishedRequest& out) {
  const auto& nodes = run.alignment->nodes();
  for (const auto& n : nodes) busy_.erase(n.node);
  AlignmentSessionResult& r = out.alignment_fit;
  if (abort_reason.empty()) {
    r = run.alignment->finish(now);
  } else {
    r.nodes.resize(nodes.size());
    for (auto& n : r.nodes) n.message = abort_reason;
  }
  std::size_t aligned = 0;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    NodeAlignment a = r.nodes[i];
    a.samples = run.alignment->samples(i);
    // A failure of the whole body (a silent node, no pose, another clock) says so; a segment's own names the node.
    std::string message = a.success                                      ? ""
                          : !r.problem.empty() && a.message == r.problem ? "the body's alignment failed: " + a.message
                                                                         : "node '" + nodes[i].node + "': " + a.message;
    if (a.success) ++aligned;
    NodeReport& report = out.done.nodes.emplace_back();
    report.node = nodes[i].node;
    report.samples = a.samples;
    report.instruction = a.success ? a.source : a.message;
    out.alignments.push_back({nodes[i].node, nodes[i].segment, std::move(a), std::move(message)});
  }
  out.done.instruction = "done: " + std::to_string(aligned) + " of " + std::to_string(nodes.size()) + " nodes aligned" +
                         (r.problem.empty() ? "" : " (" + r.problem + ")");
}

}  // namespace bsn::calib
