// The calibration service's requests without DDS: which requests run, which node each one collects, which request
// ids were answered (and the refusals, said again on a repeat), which nodes were heard lately, and when a
// collection ends (its limit, a silent node, a cancel). Requests and samples come in as plain structs, decisions
// come out as the progress and results to publish; times are arguments (no clock), nothing is printed, no thread.
// The service moves them over DDS, logs them and keeps the store (`bsn calibration`).
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "bsn/calib/alignment_session.hpp"
#include "bsn/calib/calibration_session.hpp"

namespace bsn::calib {

/// A request's node list: ids separated by commas, blanks around them and repeats dropped, in their order.
std::vector<std::string> split_node_list(const std::string& list);

/// One request as it arrived.
struct CalibrationRequest {
  std::string id;       ///< chosen by the requester; answered once
  bool cancel = false;  ///< stop the collection of `id`
  /// nullopt: a kind outside the known ones (`kind_value` says which, in the refusal).
  std::optional<CalibrationKind> kind;
  int kind_value = 0;
  /// One node, several separated by commas, or "*": every node heard within active_node_window_s (the sensor
  /// kinds), every node of the body (the alignment; "" too).
  std::string node_list;
  SessionParams session;  ///< the sensor kinds' collection (its kind is taken from `kind`)
  AlignmentSessionParams alignment;
  // The alignment's nodes, from the request's body by the caller (a body model is not the calibration core's):
  std::string body_problem;                    ///< the body does not parse: refused with this
  std::string nodes_problem;                   ///< a named node is on no segment of the body: refused with this
  std::vector<AlignmentNode> alignment_nodes;  ///< the nodes to align, parents first
};

/// A request's phase on the progress topic.
enum class RequestPhase { waiting, collecting, done, refused };

struct NodeReport {
  std::string node;
  std::size_t samples = 0;
  std::size_t poses = 0;
  int octants = 0;
  double sphere_coverage = 0.0;
  std::string instruction;
};

/// What the progress topic says of one request.
struct RequestProgress {
  std::string request_id;
  RequestPhase phase = RequestPhase::waiting;
  double elapsed_s = 0.0;
  double seconds_left = 0.0;  ///< -1: the collection ends by sample count only
  double fraction = 0.0;
  std::string instruction;
  std::string message;  ///< refused: why
  std::vector<NodeReport> nodes;
};

/// One node's outcome of a sensor calibration; a failure's message names the node.
struct NodeCalibration {
  std::string node;
  SessionResult result;
};

/// One node's outcome of an alignment; a failure's message names the node, or says the body's alignment failed.
struct NodeAlignmentResult {
  std::string node;
  std::string segment;
  NodeAlignment alignment;  ///< its `samples` are the node's collected samples
  std::string message;
};

/// A request that ended: every node's result, then the progress that says it is done.
struct FinishedRequest {
  std::string id;
  CalibrationKind kind = CalibrationKind::magnetometer;
  bool aborted = false;                         ///< cancelled or stopped: nothing was fitted
  std::vector<NodeCalibration> calibrations;    ///< the sensor kinds, in the request's node order
  std::vector<NodeAlignmentResult> alignments;  ///< the alignment, parents first
  AlignmentSessionResult alignment_fit;         ///< the alignment's whole fit (pose and flexion times), unless aborted
  RequestProgress done;
};

/// The answer to a request.
struct RequestDecision {
  enum class Outcome {
    started,            ///< collecting now; `progress` is its first progress, `description` says what it collects
    refused,            ///< `progress` says why (phase refused)
    refusal_repeated,   ///< an id refused before: `progress` says the refusal again
    repeat_ignored,     ///< an id accepted before: answered once, this copy is ignored
    cancelled,          ///< `finished` holds the cancelled request's end
    cancel_not_running  ///< a cancel of an id not running: nothing to do
  };
  Outcome outcome = Outcome::refused;
  std::optional<RequestProgress> progress;
  /// A refused alignment: the nodes whose result topic says so too (at most a body's worth, each a valid id).
  std::vector<std::string> refused_alignment_nodes;
  std::string description;  ///< started: e.g. "gyro-bias of a, b (5 s, until good enough)"
  std::optional<FinishedRequest> finished;
};

/// What tick() found: the progress due, then the requests whose collection ended.
struct TickOutcome {
  std::vector<RequestProgress> progress;
  std::vector<FinishedRequest> finished;
};

class CalibrationRequests {
 public:
  struct Params {
    double progress_period_s = 0.25;  ///< progress of each running request this often (>= 2 Hz for a person), s
    /// A request for node "*" takes every node heard within this long, s.
    double active_node_window_s = 1.0;
    /// Longer node ids are refused: the wire's bound (bsn::RawSample.node_id).
    std::size_t max_node_id_length = 63;
    /// A refused alignment's result topic names at most this many nodes (a body's worth).
    std::size_t max_refused_nodes = 64;
  };

  explicit CalibrationRequests(const Params& params) : params_(params) {}

  /// Answers a request that arrived at now_ns: starts it, refuses it, cancels the run it names, or ignores a
  /// repeat.
  RequestDecision request(const CalibrationRequest& request, std::uint64_t now_ns);

  /// A raw sample of `node` that arrived at now_ns: the node counts as heard; the request collecting it takes the
  /// sample. Returns that request's end when this sample ended its collection (a sample count reached: fitted at
  /// once, for the lowest latency).
  std::optional<FinishedRequest> sample(const std::string& node, const SessionSample& sample, std::uint64_t now_ns);

  /// Call every ~20 ms: the progress due and the collections over (time limits, silent nodes, good enough).
  TickOutcome tick(std::uint64_t now_ns);

  /// Ends every running request with `reason` (the service stops): their ends, nothing fitted.
  std::vector<FinishedRequest> abort_all(const std::string& reason, std::uint64_t now_ns);

  /// Requests collecting now.
  std::size_t running() const { return runs_.size(); }

 private:
  struct NodeRun {
    std::string node;
    CalibrationSession session;
    SessionProgress last_progress;
  };
  struct Run {
    std::string id;
    CalibrationKind kind = CalibrationKind::magnetometer;
    std::uint64_t start_ns = 0;
    std::uint64_t last_progress_ns = 0;
    std::vector<NodeRun> nodes;  ///< the sensor kinds: one session per node
    /// The alignment: one session for the body's nodes together (`nodes` stays empty).
    std::unique_ptr<AlignmentSession> alignment;
  };

  RequestDecision refuse(const std::string& id, const std::string& why);
  RequestDecision refuse_alignment(const std::string& id, const std::vector<std::string>& nodes,
                                   const std::string& why);
  RequestDecision request_sensor(const CalibrationRequest& request, std::uint64_t now_ns);
  RequestDecision request_alignment(const CalibrationRequest& request, std::uint64_t now_ns);
  /// Why one of `nodes` cannot be collected (too long an id, another request collecting it), "" if none.
  std::string node_problem(const std::vector<std::string>& nodes) const;
  RequestDecision start(Run run, const std::vector<std::string>& nodes, std::string description);
  RequestProgress progress(Run& run, std::uint64_t now_ns);
  RequestProgress alignment_progress(Run& run, std::uint64_t now_ns);
  static bool collection_over(const Run& run, std::uint64_t now_ns);
  /// Ends the request `id`: fits each node (or fails it with `abort_reason`) and frees its nodes.
  FinishedRequest finish(const std::string& id, std::uint64_t now_ns, const std::string& abort_reason = "");
  void finish_sensor(Run& run, std::uint64_t now_ns, const std::string& abort_reason, FinishedRequest& out);
  void finish_alignment(Run& run, std::uint64_t now_ns, const std::string& abort_reason, FinishedRequest& out);

  Params params_;
  std::map<std::string, Run> runs_;                    ///< by request id
  std::unordered_map<std::string, std::string> busy_;  ///< node -> the request collecting it
  /// Every request id ever accepted ("") or refused (why: said again on a repeat).
  std::map<std::string, std::string> answered_;
  std::unordered_map<std::string, std::uint64_t> heard_;  ///< node -> last arrival
};

}  // namespace bsn::calib
