// The fusion service: raw samples in, one filter per body segment, orientations, joint angles and status out.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "bsn/calib/sensor_calibration.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/fusion/body_model.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/sample_gate.hpp"

namespace bsn::services {

class FusionService {
 public:
  struct Options {
    /// A node with no sample for this long is reported stale, s. Default 0.3 s (30 samples at 100 Hz).
    double stale_timeout_s = 0.3;
    /// bsn/status is published this often, and at once whenever a node turns stale or fresh, s.
    double status_period_s = 1.0;
    /// Publish orientations and joint angles BEST_EFFORT instead of RELIABLE.
    bool best_effort = false;
    fusion::SampleGate::Params gate;
    std::string process_id;  ///< key on bsn/status; default "fusion@<host>:<pid>"
    /// Per node id: sensor calibrations applied to every raw sample (u = H (raw - B)) before the gate and filter.
    std::unordered_map<std::string, calib::SensorCalibration> calibrations;
  };

  FusionService(dds::Participant& participant, fusion::BodyModel body, Options options);

  /// Call periodically (every few tens of ms) from the main thread: staleness and status.
  void tick();

  /// Processes one raw sample (called from the DDS thread; public for tests without DDS).
  void on_raw(const bsn::RawSample& raw);

 private:
  struct SegmentRuntime {
    fusion::SegmentSpec spec;
    std::unique_ptr<fusion::OrientationFilter> filter;
    fusion::SampleGate gate;
    calib::SensorCalibration calibration;  ///< empty = raw samples used as they come
    std::uint64_t filter_rejected = 0;
    bool has_orientation = false;
    fusion::Quat q = fusion::Quat::Identity();
    std::uint32_t flags = 0;
    std::chrono::steady_clock::time_point last_arrival{};
    bool ever_received = false;
    bool stale = false;
    std::uint64_t accepted_at_last_status = 0;
    std::vector<std::size_t> children;  ///< segments whose parent this is
    std::optional<std::size_t> parent;
  };

  void publish_orientation(SegmentRuntime& seg, std::uint64_t timestamp_ns);
  void publish_joint(const SegmentRuntime& parent, const SegmentRuntime& child, std::uint64_t timestamp_ns);
  void publish_status(std::chrono::steady_clock::time_point now);

  dds::Participant& participant_;
  fusion::BodyModel body_;
  Options options_;
  std::mutex mutex_;
  std::vector<SegmentRuntime> segments_;
  std::unordered_map<std::string, std::size_t> by_node_;
  std::uint64_t unknown_node_samples_ = 0;
  std::vector<std::string> unknown_nodes_;
  std::uint64_t write_failures_ = 0;
  std::chrono::steady_clock::time_point last_status_{};
  std::chrono::steady_clock::time_point started_{};
  std::unique_ptr<dds::Writer<bsn::Orientation>> orientation_writer_;
  std::unique_ptr<dds::Writer<bsn::JointAngles>> joint_writer_;
  std::unique_ptr<dds::Writer<bsn::Status>> status_writer_;
  std::unique_ptr<dds::Reader<bsn::RawSample>> raw_reader_;
  bsn::Orientation orientation_msg_;
  bsn::JointAngles joint_msg_;
};

}  // namespace bsn::services
