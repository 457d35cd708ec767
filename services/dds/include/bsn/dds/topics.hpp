// Topic names and the QoS of each (design.md section 3). Writers and readers of bsn processes take their QoS
// from here so that they always match.
#pragma once

#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>

namespace bsn::dds {

inline constexpr const char* kRawTopic = "bsn/raw";
inline constexpr const char* kOrientationTopic = "bsn/orientation";
inline constexpr const char* kJointAnglesTopic = "bsn/joint_angles";
inline constexpr const char* kStatusTopic = "bsn/status";
inline constexpr const char* kCalibrationRequestTopic = "bsn/calibration/request";
inline constexpr const char* kCalibrationResultTopic = "bsn/calibration/result";
inline constexpr const char* kTruthOrientationTopic = "bsn/truth/orientation";

/// How a topic is delivered.
enum class TopicQos {
  kSensorData,          ///< BEST_EFFORT, VOLATILE, KEEP_LAST (raw samples)
  kEstimate,            ///< RELIABLE writer (every reader kind matches), VOLATILE, KEEP_LAST 1 per instance
  kEstimateBestEffort,  ///< BEST_EFFORT variant of kEstimate (lower overhead, lossy)
  kLatched,             ///< RELIABLE, TRANSIENT_LOCAL, KEEP_LAST 1: late joiners get the latest (status, results)
  kCommand,             ///< RELIABLE, VOLATILE, KEEP_LAST 16 (calibration requests)
};

eprosima::fastdds::dds::DataWriterQos writer_qos(TopicQos kind);

/// Reader QoS that matches the writer of `kind`. Readers keep a deeper history than writers so that a burst
/// of samples of one instance between two takes is not overwritten.
eprosima::fastdds::dds::DataReaderQos reader_qos(TopicQos kind);

/// Human-readable name of a QoS policy id, for incompatible-QoS reports.
const char* qos_policy_name(unsigned policy_id);

}  // namespace bsn::dds
