// The fusion service without its transport: bsn types in (raw samples, calibration results), BodyFusion, bsn types
// out (orientations, joint angles). `bsn fusion` feeds it from DDS and `bsn process` from a file: one code path, so
// the same samples and calibrations in the same order give the same numbers. No DDS entities, no clocks, no logging:
// what a service logs comes back as outcomes.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "bsn/fusion/body_fusion.hpp"
#include "bsn_idl/bsn.h"

namespace bsn::services {

class FusionPipeline {
 public:
  /// Throws std::invalid_argument as BodyFusion does (a filter spec or gate parameters it refuses).
  FusionPipeline(fusion::BodyModel body, const fusion::BodyFusion::Calibrations& calibrations,
                 const fusion::BodyFusion::Params& params, std::uint64_t start_ns);

  /// One raw sample through BodyFusion. When the result is kEstimated, orientation() is its bsn/orientation
  /// sample and, when it has a joint, joint() its bsn/joint_angles sample (valid until the next call).
  const fusion::SampleResult& process(const bsn::RawSample& raw, std::uint64_t arrival_ns,
                                      const fusion::SourceId& writer = {});
  /// The same for a sample already in the fusion's form (dds::to_imu_sample of the raw sample; `bsn process` reads
  /// its input into that form).
  const fusion::SampleResult& process(const fusion::NodeSample& sample, std::uint64_t arrival_ns,
                                      const fusion::SourceId& writer = {});
  const bsn::Orientation& orientation() const { return orientation_msgs_[last_segment_]; }
  const bsn::JointAngles& joint() const { return joint_msgs_[last_segment_]; }

  enum class CalibrationOutcome {
    kApplied,         ///< applied from the node's next sample on
    kFailedResult,    ///< a failed calibration: nothing changes
    kOtherBody,       ///< for a node on no segment of this body
    kAlreadyApplied,  ///< this request id is in effect already (a republished result)
    kRefused,         ///< unknown kind, non-finite numbers, a singular transform or a non-unit rotation
    kWrongSegment,    ///< an alignment fitted for the node on another segment
  };
  struct CalibrationApplied {
    CalibrationOutcome outcome = CalibrationOutcome::kOtherBody;
    std::size_t segment = 0;     ///< unless kFailedResult or kOtherBody
    const char* kind = nullptr;  ///< calib::kind_name of the result's kind ("gyro-bias", ...); null if unknown
  };
  /// A calibration result as the calibration service publishes it (bsn/calibration/result): the channel's
  /// calibration replaces the segment's (its filter restarts), an alignment the sensor-to-segment rotation.
  CalibrationApplied apply(const bsn::CalibrationResult& result);

  fusion::BodyFusion& fusion() { return fusion_; }
  const fusion::BodyFusion& fusion() const { return fusion_; }
  const fusion::BodyModel& body() const { return fusion_.body(); }
  /// The request id of the calibration last applied to a segment ("" if none), and to any node.
  const std::string& calibration_id(std::size_t segment) const { return calibration_id_.at(segment); }
  const std::string& last_calibration_id() const { return last_calibration_id_; }
  /// A segment's node on bsn/status as far as the pipeline knows it: ids, the gate's and the filter's counters,
  /// staleness, the calibration in effect and the writer handovers (rate, age and writer names are the service's).
  bsn::NodeStatus node_status(std::size_t segment) const;

 private:
  void fill_orientation(const fusion::SampleResult& r, std::uint64_t timestamp_ns);
  void fill_joint(const fusion::JointEstimate& joint, std::uint64_t timestamp_ns);

  fusion::BodyFusion fusion_;
  std::vector<std::string> calibration_id_;
  std::map<std::pair<std::size_t, int>, std::string> applied_calibration_;  ///< per (segment, kind): request id
  std::string last_calibration_id_;
  // One output sample per segment (its joint: the joint to its parent), its texts (names from the body, the joint's
  // axes and anatomy) set once here: a sample only sets numbers, so it neither allocates nor copies a string.
  std::vector<bsn::Orientation> orientation_msgs_;
  std::vector<bsn::JointAngles> joint_msgs_;
  std::size_t last_segment_ = 0;  ///< of the last estimate
};

/// The wire flags of a filter's flags (bsn::FLAG_RESTING, ...).
std::uint32_t to_wire_flags(const fusion::FilterFlags& flags);

}  // namespace bsn::services
