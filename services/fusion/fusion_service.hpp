// The fusion service (`bsn fusion`): raw samples in over DDS, BodyFusion, orientations, joint angles and status out.
#pragma once

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "bsn/dds/participant.hpp"
#include "bsn/fusion/body_fusion.hpp"
#include "command.hpp"
#include "fusion_pipeline.hpp"

namespace bsn::services {

class FusionService {
 public:
  /// The core's parameters (stale timeout, discovery grace, gate) and the service's own.
  struct Options : fusion::BodyFusion::Params {
    /// bsn/status is published this often, and at once whenever a node turns stale or fresh, s.
    double status_period_s = 1.0;
    /// Publish orientations and joint angles BEST_EFFORT instead of RELIABLE.
    bool best_effort = false;
    std::string process_id;  ///< key on bsn/status; default "fusion@<host>:<pid>" (+ "/<subject>")
    fusion::BodyFusion::Calibrations calibrations;
    /// The subject: estimates and status go in its DDS partition ("" : the default partition).
    std::string subject;
    /// Estimates with EXCLUSIVE ownership of this strength (a primary and its hot standby; dds::WriterScope).
    std::optional<std::uint32_t> ownership_strength;
    /// Nodes of other subjects (of this process or of another one's share): their samples are refused before they
    /// enter this service's raw reader and not counted as unknown.
    std::shared_ptr<const std::set<std::string>> served_elsewhere;
  };

  FusionService(dds::Participant& participant, fusion::BodyModel body, Options options);

  /// Call periodically (every few tens of ms) from the main thread: staleness and status.
  void tick();

  const std::string& subject() const { return options_.subject; }

 private:
  void on_raw(const bsn::RawSample& raw, const fusion::SourceId& writer);  ///< called from the DDS thread
  /// Before a raw sample enters the reader (DDS receive thread): false, and counted, for a node on no segment.
  bool admit_raw(const bsn::RawSample& raw);
  /// A sample of a body node from a writer the permissions do not allow to write it: counted, never fused.
  void on_not_permitted(const bsn::RawSample& raw, const eprosima::fastrtps::rtps::GUID_t& writer);
  void log_source_events(const fusion::SampleResult& r, std::uint64_t now_ns);
  void on_calibration(const bsn::CalibrationResult& result);  ///< called from the DDS thread
  void on_status(const bsn::Status& status);      ///< another process's status (DDS thread): a second fusion?
  bsn::Status make_status(std::uint64_t now_ns);  ///< with mutex_ held; restarts the rate window when due

  dds::Participant& participant_;
  Options options_;
  // No DDS write happens with mutex_ held: a write may deliver to this participant's own readers, whose locks the
  // DDS threads hold while their callbacks wait for mutex_ (our status to our status reader while on_status of
  // another fusion waits: a deadlock seen once in CI). Every status goes out from tick(), within one tick of its
  // cause (status_due_). publish_mutex_ keeps the pipeline's messages whole until written.
  std::mutex publish_mutex_;
  std::mutex mutex_;
  FusionPipeline pipeline_;  ///< BodyFusion and the messages it fills: the same code as `bsn process`
  fusion::BodyFusion& fusion_;
  // Rates are counted over windows of at least one status period, so that an early status (a node turning
  // stale or fresh) does not divide a burst by a few milliseconds.
  std::vector<std::uint64_t> accepted_at_window_start_;  ///< per segment
  std::vector<double> rate_hz_;                          ///< per segment, over the last full window
  std::uint64_t rate_window_start_ns_ = 0;
  double rate_window_s_ = 0.0;  ///< length of the last full window
  std::atomic<std::uint64_t> write_failures_ = 0;
  std::uint64_t last_status_ns_ = 0;
  std::unique_ptr<dds::Writer<bsn::Orientation>> orientation_writer_;
  std::unique_ptr<dds::Writer<bsn::JointAngles>> joint_writer_;
  std::unique_ptr<dds::Writer<bsn::Status>> status_writer_;
  static constexpr std::size_t kMaxListedIdChars = 64;  ///< ids from the network listed on bsn/status
  static constexpr std::size_t kMaxOtherFusionsListed = 16;
  std::vector<std::string> other_fusions_;  ///< process ids of other fusion services publishing our segments
  bool status_due_ = false;                 ///< publish bsn/status at the next tick (something new to report)
  std::unique_ptr<dds::Reader<bsn::Status>> status_reader_;
  std::unique_ptr<dds::Reader<bsn::RawSample>> raw_reader_;
  std::unique_ptr<dds::Reader<bsn::CalibrationResult>> calibration_reader_;
  /// Per segment, when a conflicting writer was last logged (0: never): at most one line per kConflictLogPeriodNs.
  std::vector<std::uint64_t> conflict_logged_ns_;
  /// Per segment, samples of the node from a writer whose DDS partition does not name it (secured only): another
  /// identity's writer, refused (reported as rejected "not_permitted"), and when that was last logged.
  std::vector<std::uint64_t> not_permitted_;
  std::vector<std::uint64_t> not_permitted_logged_ns_;
  static constexpr std::uint64_t kConflictLogPeriodNs = 10'000'000'000;
};

/// `bsn fusion`: its options and what runs it.
Command fusion_command();

}  // namespace bsn::services
