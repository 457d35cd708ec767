// `bsn ros2-bridge`: bsn's estimates mirrored to ROS 2 tools, wire-compatible with ROS 2 (Humble and later) and
// with the names ROS 2's rmw uses (idl/ros2.idl, dds::kRos2TfTopic, ...):
// - per segment sensor_msgs/msg/Imu on rt/bsn/<segment>/imu: orientation from bsn/orientation, angular velocity and
//   linear acceleration from the raw sample it came from (bsn/raw, same node and timestamp);
// - tf2_msgs/msg/TFMessage on rt/tf: the skeleton, world -> root segment (its orientation), parent -> child (the
//   joint's relative quaternion from bsn/joint_angles), nominal link lengths;
// - sensor_msgs/msg/JointState on rt/bsn/joint_states: per joint sample, the joint's three named anatomical angles
//   (ISB signs, "<joint>_<angle name>", e.g. knee_l_flexion_extension), stamped with the sample's sensor time.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "bsn/dds/participant.hpp"
#include "command.hpp"

namespace bsn::services {

/// The ROS 2 name of a bsn segment or joint: characters other than letters, digits and '_' become '_', and a
/// leading digit gets an 's' before it (ROS 2 topic and frame name rules). At most 64 characters.
std::string ros2_name(const std::string& name);

/// The three JointState names and positions (rad) of a joint sample: "<joint>_<anatomical name>" with the named
/// anatomical angles (ISB signs), or "<joint>_angle_<n>_<axis>" with the axis-sequence angles for a joint of no
/// anatomy.
std::array<std::pair<std::string, double>, 3> ros2_joint_positions(const bsn::JointAngles& j);

/// Nominal length of a link in the TF skeleton, m (bsn's body model has no segment lengths).
inline constexpr double kRos2LinkLength_m = 0.4;
/// The TF frame of a segment.
inline std::string ros2_frame(const std::string& segment) { return "bsn/" + ros2_name(segment); }

class Ros2Bridge {
 public:
  explicit Ros2Bridge(dds::Participant& participant);
  /// Main thread, every few ms: creates the writers of new segments, publishes TF and joint states.
  void tick();
  std::uint64_t write_failures() const { return write_failures_.load(); }

  static constexpr std::size_t kMaxSegments = 256;  ///< segments and joints mirrored; further ones are ignored
  static constexpr std::size_t kRawHistory = 16;    ///< raw samples kept per node to find an estimate's own

 private:
  struct Raw {
    std::uint64_t timestamp_ns = 0;
    std::array<double, 3> acc{}, gyr{};
    std::uint32_t channels = 0;
  };
  struct Segment {
    std::string topic_name;  ///< rt/bsn/<segment>/imu (the Topic points into it)
    std::unique_ptr<dds::Writer<sensor_msgs::msg::dds_::Imu_>> imu;
    std::optional<std::array<double, 4>> quat;
    bool fresh = false;
  };
  struct Joint {
    std::string parent, child, axes;
    std::array<double, 4> quat{};
    std::array<double, 3> angles{};
    std::array<std::string, 3> names;   ///< ROS joint names of `positions`
    std::array<double, 3> positions{};  ///< the anatomical angles, rad (a joint of no anatomy: the axis sequence's)
    std::uint64_t timestamp_ns = 0;     ///< sensor time of the sample
    bool fresh = false;
  };
  void on_raw(const bsn::RawSample& raw);
  void on_orientation(const bsn::Orientation& o);
  void on_joint(const bsn::JointAngles& j);

  dds::Participant& participant_;
  std::mutex mutex_;
  std::map<std::string, std::vector<Raw>> raw_;  ///< per node, ring of kRawHistory
  std::map<std::string, Segment> segments_;
  std::map<std::string, Joint> joints_;
  bool joints_fresh_ = false;
  std::atomic<std::uint64_t> write_failures_{0};  // counted by the DDS callbacks and the tick
  std::unique_ptr<dds::Writer<tf2_msgs::msg::dds_::TFMessage_>> tf_writer_;
  std::unique_ptr<dds::Writer<sensor_msgs::msg::dds_::JointState_>> joint_state_writer_;
  std::unique_ptr<dds::Reader<bsn::RawSample>> raw_reader_;
  std::unique_ptr<dds::Reader<bsn::Orientation>> orientation_reader_;
  std::unique_ptr<dds::Reader<bsn::JointAngles>> joint_reader_;
};

/// `bsn ros2-bridge`.
Command ros2_bridge_command();

}  // namespace bsn::services
