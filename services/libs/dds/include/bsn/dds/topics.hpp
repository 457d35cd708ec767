// Every bsn topic, declared once (docs/design.md section 3): its name, its IDL type (through the type support that
// fastddsgen generates for it) and how it is delivered. Writers and readers take all three from here, so they
// always match; `bsn echo`, `bsn record`, `bsn export` and `bsn session` iterate kAllTopics. What else a new topic
// touches (security roles, a new type's formatting and fields) is listed in docs/development.md, "Adding a topic".
#pragma once

#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <string>
#include <tuple>

#include "bsn_idl/bsnPubSubTypes.h"
#include "bsn_idl/ros2PubSubTypes.h"

namespace bsn::dds {

/// How a topic is delivered.
enum class TopicQos {
  kSensorData,          ///< BEST_EFFORT, VOLATILE, KEEP_LAST (raw samples)
  kEstimate,            ///< RELIABLE writer (every reader kind matches), VOLATILE, KEEP_LAST 1 per instance
  kEstimateBestEffort,  ///< BEST_EFFORT variant of kEstimate (lower overhead, lossy)
  kLatched,             ///< RELIABLE, TRANSIENT_LOCAL, KEEP_LAST 1: late joiners get the latest (status, results)
  kCommand,             ///< RELIABLE, VOLATILE, KEEP_LAST 16 (calibration requests)
  kProgress,            ///< RELIABLE, VOLATILE, KEEP_LAST 4, liveliness leases 1 s (writer) and 1.5 s (reader):
                        ///< a reader learns within 1.5 s that the writer's process died (calibration progress)
  kRos2,                ///< RELIABLE, VOLATILE, KEEP_LAST 10: matches ROS 2's default (reliable, depth 10) and
                        ///< sensor-data (best effort, depth 5) subscriptions
};

/// A topic whose samples are `PubSub::type` (e.g. bsn::RawSample for bsn::RawSamplePubSubType).
template <class PubSub>
struct Topic {
  using Type = typename PubSub::type;
  const char* name;
  TopicQos qos;
};

inline constexpr Topic<bsn::RawSamplePubSubType> kRawTopic{"bsn/raw", TopicQos::kSensorData};
inline constexpr Topic<bsn::OrientationPubSubType> kOrientationTopic{"bsn/orientation", TopicQos::kEstimate};
inline constexpr Topic<bsn::JointAnglesPubSubType> kJointAnglesTopic{"bsn/joint_angles", TopicQos::kEstimate};
inline constexpr Topic<bsn::StatusPubSubType> kStatusTopic{"bsn/status", TopicQos::kLatched};
/// The simulator's true orientation of each sensor (sensor frame, no FLAG_SEGMENT_FRAME): what bsn/orientation
/// reads on the default mounting.
inline constexpr Topic<bsn::OrientationPubSubType> kTruthOrientationTopic{"bsn/truth/orientation", TopicQos::kEstimate};
/// The simulator's true ISB segment frame of each segment (FLAG_SEGMENT_FRAME): what bsn/orientation reads once the
/// segment is aligned. A consumer compares an estimate with the truth of the same frame (the estimate's flag).
inline constexpr Topic<bsn::OrientationPubSubType> kTruthSegmentOrientationTopic{"bsn/truth/segment_orientation",
                                                                                 TopicQos::kEstimate};
/// The simulator's true joint angles (ISB segment frames), keyed by joint: what bsn/joint_angles should read.
inline constexpr Topic<bsn::JointAnglesPubSubType> kTruthJointAnglesTopic{"bsn/truth/joint_angles",
                                                                          TopicQos::kEstimate};
inline constexpr Topic<bsn::CalibrationRequestPubSubType> kCalibrationRequestTopic{"bsn/calibration/request",
                                                                                   TopicQos::kCommand};
inline constexpr Topic<bsn::CalibrationResultPubSubType> kCalibrationResultTopic{"bsn/calibration/result",
                                                                                 TopicQos::kLatched};
inline constexpr Topic<bsn::CalibrationProgressPubSubType> kCalibrationProgressTopic{"bsn/calibration/progress",
                                                                                     TopicQos::kProgress};

inline constexpr std::tuple kAllTopics{kRawTopic,
                                       kOrientationTopic,
                                       kJointAnglesTopic,
                                       kStatusTopic,
                                       kTruthOrientationTopic,
                                       kTruthSegmentOrientationTopic,
                                       kTruthJointAnglesTopic,
                                       kCalibrationRequestTopic,
                                       kCalibrationResultTopic,
                                       kCalibrationProgressTopic};

// The ROS 2 mirror (bsn ros2-bridge): ROS 2 names and types, "rt/" + the ROS topic name as ROS 2's rmw spells them.
// Not in kAllTopics: they are no bsn types (bsn echo and bsn record read the bsn topics they mirror).
inline constexpr Topic<tf2_msgs::msg::dds_::TFMessage_PubSubType> kRos2TfTopic{"rt/tf", TopicQos::kRos2};
inline constexpr Topic<sensor_msgs::msg::dds_::JointState_PubSubType> kRos2JointStatesTopic{"rt/bsn/joint_states",
                                                                                            TopicQos::kRos2};
/// Per segment: rt/bsn/<segment>/imu (ROS 2: /bsn/<segment>/imu). `name` must outlive the Topic.
inline Topic<sensor_msgs::msg::dds_::Imu_PubSubType> ros2_imu_topic(const std::string& name) {
  return {name.c_str(), TopicQos::kRos2};
}
inline std::string ros2_imu_topic_name(const std::string& segment) { return "rt/bsn/" + segment + "/imu"; }

/// Calls `f(topic)` for every topic of kAllTopics, in order.
template <class F>
void for_each_topic(F&& f) {
  std::apply([&f](const auto&... topic) { (f(topic), ...); }, kAllTopics);
}

/// bsn's delivery of `kind` on top of `base` (the publisher's default, so an XML default profile's other
/// policies stay).
eprosima::fastdds::dds::DataWriterQos writer_qos(TopicQos kind, eprosima::fastdds::dds::DataWriterQos base);

/// Reader QoS that matches the writer of `kind`, on top of `base`. Readers keep a deeper history than writers so
/// that a burst of samples of one instance between two takes is not overwritten.
eprosima::fastdds::dds::DataReaderQos reader_qos(TopicQos kind, eprosima::fastdds::dds::DataReaderQos base);

/// The liveliness lease a kProgress writer offers, s.
inline constexpr double kProgressLivelinessLease_s = 1.0;

/// Human-readable name of a QoS policy id, for incompatible-QoS reports.
const char* qos_policy_name(unsigned policy_id);

}  // namespace bsn::dds
