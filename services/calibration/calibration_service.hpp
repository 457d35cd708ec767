// The calibration service (`bsn calibration`): requests on bsn/calibration/request and the requested nodes' samples
// from bsn/raw into calib::CalibrationRequests (which decides), its progress on bsn/calibration/progress, its results
// on bsn/calibration/result (RELIABLE + TRANSIENT_LOCAL, keyed by node and kind), successes into the store.
#pragma once

#include <cstdint>
#include <exception>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "alignment_nodes.hpp"
#include "bsn/calib/calibration_requests.hpp"
#include "bsn/dds/participant.hpp"
#include "calibration_store.hpp"
#include "calibration_wire.hpp"
#include "command.hpp"

namespace bsn::services {

class CalibrationService {
 public:
  struct Options {
    std::string store_dir;  ///< "" = default_calibration_store()
    calib::CalibrationRequests::Params requests;
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
  void on_request(const bsn::CalibrationRequest& request);
  void on_raw(const bsn::RawSample& raw);
  void publish(const calib::RequestProgress& progress);
  /// Writes a request's results, then its end on the progress topic, then stores the successes.
  void publish_finished(const calib::FinishedRequest& finished);
  void publish_calibrations(const calib::FinishedRequest& finished);
  void publish_alignments(const calib::FinishedRequest& finished);
  /// Writes a node's result; after a failure the node's last success of that kind again (the one in effect).
  void write_result(const bsn::CalibrationResult& result, calib::CalibrationKind kind);
  /// A good fit the store could not save: logged, and said on its result.
  void not_stored(const std::string& request_id, const std::string& node, calib::CalibrationKind kind,
                  const std::exception& e);
  void publish_stored();

  dds::Participant& participant_;
  Options options_;
  CalibrationStore store_;
  mutable std::mutex mutex_;
  calib::CalibrationRequests requests_;
  std::map<std::pair<std::string, int>, bsn::CalibrationResult> last_success_;  ///< (node, kind) -> stored result
  std::unique_ptr<dds::Writer<bsn::CalibrationResult>> result_writer_;
  std::unique_ptr<dds::Writer<bsn::CalibrationProgress>> progress_writer_;
  std::unique_ptr<dds::Reader<bsn::RawSample>> raw_reader_;
  std::unique_ptr<dds::Reader<bsn::CalibrationRequest>> request_reader_;
};

/// `bsn calibration`: its options and what runs it.
Command calibration_command();

}  // namespace bsn::services
