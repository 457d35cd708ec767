// The calibration service (`bsn calibration`): requests on bsn/calibration/request, the requested nodes' samples
// from bsn/raw into one calib::CalibrationSession per node, progress on bsn/calibration/progress, results on
// bsn/calibration/result (RELIABLE + TRANSIENT_LOCAL, keyed by node and kind), successes into the store.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "alignment_nodes.hpp"
#include "bsn/calib/alignment_session.hpp"
#include "bsn/calib/calibration_session.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/fusion/body_model.hpp"
#include "bsn/fusion/imu_sample.hpp"
#include "calibration_store.hpp"
#include "calibration_wire.hpp"
#include "command.hpp"

namespace bsn::services {

class CalibrationService {
 public:
  struct Options {
    std::string store_dir;            ///< "" = default_calibration_store()
    double progress_period_s = 0.25;  ///< progress of each running request this often (>= 2 Hz for a person), s
    /// A request for node "*" takes every node heard on bsn/raw within this long, s.
    double active_node_window_s = 1.0;
  };

  /// Loads the store and republishes what it holds. Throws std::runtime_error if the store cannot be created.
  CalibrationService(dds::Participant& participant, Options options);
  /// Fails the requests still running ("the calibration service stopped") so that their clients know.
  ~CalibrationService();

  /// Call every ~20 ms: time limits, silent nodes, progress.
  void tick();

  /// Requests collecting now (for logs and tests).
  std::size_t running() const;

 private:
  struct NodeRun {
    std::string node;
    calib::CalibrationSession session;
    calib::SessionProgress last_progress;
  };
  struct Run {
    std::string id;
    calib::CalibrationKind kind;
    std::uint64_t start_ns = 0;
    std::uint64_t last_progress_ns = 0;
    std::vector<NodeRun> nodes;  ///< the sensor kinds: one session per node
    /// The alignment: one session for the body's nodes together (`nodes` stays empty).
    std::unique_ptr<calib::AlignmentSession> alignment;
  };

  void on_request(const bsn::CalibrationRequest& request);
  void on_alignment_request(const bsn::CalibrationRequest& request, std::uint64_t now_ns);
  /// Refuses an alignment request on the progress topic and fails each of `nodes` on the result topic.
  void refuse_alignment(const std::string& request_id, const std::vector<std::string>& nodes, const std::string& why);
  void finish_alignment(Run& run, std::uint64_t now_ns, const std::string& abort_reason);
  void publish_alignment_progress(Run& run, std::uint64_t now_ns);
  void on_raw(const bsn::RawSample& raw);
  void refuse(const std::string& request_id, const std::string& why);
  void publish_refusal(const std::string& request_id, const std::string& why);
  /// Ends `run` now: fits each node (or fails it with `abort_reason`), stores, publishes; erases it.
  void finish(const std::string& request_id, std::uint64_t now_ns, const std::string& abort_reason = "");
  void publish_progress(Run& run, std::uint64_t now_ns);
  void publish_done(const Run& run, std::size_t succeeded);
  void publish_stored();

  dds::Participant& participant_;
  Options options_;
  CalibrationStore store_;
  mutable std::mutex mutex_;
  std::map<std::string, Run> runs_;                    ///< by request id
  std::unordered_map<std::string, std::string> busy_;  ///< node -> the request collecting it
  /// Every request id ever accepted ("") or refused (why: said again on a repeat).
  std::map<std::string, std::string> answered_;
  std::unordered_map<std::string, std::uint64_t> heard_;                        ///< node -> last arrival on bsn/raw
  std::map<std::pair<std::string, int>, bsn::CalibrationResult> last_success_;  ///< (node, kind) -> stored result
  std::unique_ptr<dds::Writer<bsn::CalibrationResult>> result_writer_;
  std::unique_ptr<dds::Writer<bsn::CalibrationProgress>> progress_writer_;
  std::unique_ptr<dds::Reader<bsn::RawSample>> raw_reader_;
  std::unique_ptr<dds::Reader<bsn::CalibrationRequest>> request_reader_;
};

/// `bsn calibration`: its options and what runs it.
Command calibration_command();

}  // namespace bsn::services
