#include "ros2_bridge.hpp"

#include <chrono>
#include <cmath>
#include <set>

#include "bsn/logging/log.hpp"

namespace bsn::services {
namespace {

builtin_interfaces::msg::dds_::Time_ now_stamp() {
  // ROS time is the UNIX time (rviz2 and tf2 compare stamps with their own clock); bsn's sensor time is not.
  const auto ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
  builtin_interfaces::msg::dds_::Time_ t;
  t.sec(static_cast<std::int32_t>(ns / 1'000'000'000));
  t.nanosec(static_cast<std::uint32_t>(ns % 1'000'000'000));
  return t;
}

geometry_msgs::msg::dds_::Quaternion_ ros_quat(const std::array<double, 4>& wxyz) {
  geometry_msgs::msg::dds_::Quaternion_ q;
  q.x(wxyz[1]);
  q.y(wxyz[2]);
  q.z(wxyz[3]);
  q.w(wxyz[0]);
  return q;
}

geometry_msgs::msg::dds_::Vector3_ vec(double x, double y, double z) {
  geometry_msgs::msg::dds_::Vector3_ v;
  v.x(x);
  v.y(y);
  v.z(z);
  return v;
}

bool finite(const std::array<double, 4>& q) {
  return std::isfinite(q[0]) && std::isfinite(q[1]) && std::isfinite(q[2]) && std::isfinite(q[3]);
}

}  // namespace

std::string ros2_name(const std::string& name) {
  std::string out;
  for (const char c : name.substr(0, 64)) out += std::isalnum(static_cast<unsigned char>(c)) || c == '_' ? c : '_';
  if (out.empty() || std::isdigit(static_cast<unsigned char>(out[0]))) out = "s" + out;
  return out;
}

std::array<std::pair<std::string, double>, 3> ros2_joint_positions(const bsn::JointAngles& j) {
  std::array<std::pair<std::string, double>, 3> out;
  const bool named = !j.anatomy().empty() && j.anatomical_names().size() == 3;
  for (std::size_t i = 0; i < 3; ++i) {
    if (named) {
      out[i] = {ros2_name(j.joint() + "_" + j.anatomical_names()[i]), j.anatomical()[i]};
    } else {
      const char axis = i < j.axes().size() ? j.axes()[i] : '_';
      out[i] = {ros2_name(j.joint() + "_angle_" + std::to_string(i + 1) + "_" + std::string(1, axis)), j.angles()[i]};
    }
  }
  return out;
}

Ros2Bridge::Ros2Bridge(dds::Participant& participant) : participant_(participant) {
  tf_writer_ = participant_.make_writer(dds::kRos2TfTopic);
  joint_state_writer_ = participant_.make_writer(dds::kRos2JointStatesTopic);
  using eprosima::fastdds::dds::SampleInfo;
  raw_reader_ =
      participant_.make_reader(dds::kRawTopic, [this](const bsn::RawSample& r, const SampleInfo&) { on_raw(r); });
  orientation_reader_ = participant_.make_reader(
      dds::kOrientationTopic, [this](const bsn::Orientation& o, const SampleInfo&) { on_orientation(o); });
  joint_reader_ = participant_.make_reader(dds::kJointAnglesTopic,
                                           [this](const bsn::JointAngles& j, const SampleInfo&) { on_joint(j); });
}

void Ros2Bridge::on_raw(const bsn::RawSample& r) {
  std::lock_guard lock(mutex_);
  auto it = raw_.find(r.node_id());
  if (it == raw_.end()) {
    if (raw_.size() >= kMaxSegments) return;
    it = raw_.emplace(r.node_id(), std::vector<Raw>(kRawHistory)).first;
  }
  it->second[r.seq() % kRawHistory] = {r.timestamp_ns(), r.acc(), r.gyr(), r.channels()};
}

void Ros2Bridge::on_orientation(const bsn::Orientation& o) {
  if (!finite(o.quat())) return;
  // Written outside the lock: a DDS call under a lock that a DDS callback also takes can deadlock with Fast DDS's
  // own locks (the callback thread holds its reader's).
  sensor_msgs::msg::dds_::Imu_ imu;
  dds::Writer<sensor_msgs::msg::dds_::Imu_>* writer = nullptr;
  {
    std::lock_guard lock(mutex_);
    auto it = segments_.find(o.segment());
    if (it == segments_.end()) {
      if (segments_.size() >= kMaxSegments) return;
      it = segments_.emplace(o.segment(), Segment{}).first;  // its writer comes at the next tick (main thread)
    }
    Segment& s = it->second;
    s.quat = o.quat();
    s.fresh = true;
    if (!s.imu) return;
    writer = s.imu.get();
    imu.header().stamp(now_stamp());
    imu.header().frame_id(ros2_frame(o.segment()));
    imu.orientation(ros_quat(o.quat()));
    // orientation_covariance all 0: "unknown" (sensor_msgs/Imu). Rates and accelerations of the same raw sample;
    // without it, element 0 of their covariance is -1: "not in this message".
    imu.angular_velocity_covariance()[0] = -1.0;
    imu.linear_acceleration_covariance()[0] = -1.0;
    if (auto r = raw_.find(o.node_id()); r != raw_.end()) {
      for (const Raw& raw : r->second) {
        if (raw.timestamp_ns != o.timestamp_ns() || raw.timestamp_ns == 0) continue;
        if (raw.channels & bsn::CHANNEL_GYR) {
          imu.angular_velocity(vec(raw.gyr[0], raw.gyr[1], raw.gyr[2]));
          imu.angular_velocity_covariance()[0] = 0.0;
        }
        if (raw.channels & bsn::CHANNEL_ACC) {
          imu.linear_acceleration(vec(raw.acc[0], raw.acc[1], raw.acc[2]));
          imu.linear_acceleration_covariance()[0] = 0.0;
        }
        break;
      }
    }
  }
  if (!writer->write(imu)) ++write_failures_;
}

void Ros2Bridge::on_joint(const bsn::JointAngles& j) {
  const auto& a = j.angles();
  const auto& n = j.anatomical();
  if (!finite(j.quat()) || !std::isfinite(a[0]) || !std::isfinite(a[1]) || !std::isfinite(a[2]) ||
      !std::isfinite(n[0]) || !std::isfinite(n[1]) || !std::isfinite(n[2]))
    return;
  const auto positions = ros2_joint_positions(j);
  std::lock_guard lock(mutex_);
  if (joints_.size() >= kMaxSegments && !joints_.count(j.joint())) return;
  Joint& joint = joints_[j.joint()];
  joint = {j.parent(), j.child(), j.axes(), j.quat(), a, {}, {}, j.timestamp_ns(), true};
  for (std::size_t i = 0; i < 3; ++i) {
    joint.names[i] = positions[i].first;
    joint.positions[i] = positions[i].second;
  }
  joints_fresh_ = true;
}

void Ros2Bridge::tick() {
  // New segments' writers are made outside the lock (DDS calls under it can deadlock with a DDS callback).
  std::vector<std::string> new_segments;
  {
    std::lock_guard lock(mutex_);
    for (const auto& [name, s] : segments_)
      if (!s.imu) new_segments.push_back(name);
  }
  for (const std::string& name : new_segments) {
    Segment made;
    made.topic_name = dds::ros2_imu_topic_name(ros2_name(name));
    made.imu = participant_.make_writer(dds::ros2_imu_topic(made.topic_name));
    std::lock_guard lock(mutex_);
    Segment& s = segments_[name];
    s.topic_name = std::move(made.topic_name);  // the writer's topic keeps its own copy of the name
    s.imu = std::move(made.imu);
  }
  tf2_msgs::msg::dds_::TFMessage_ tf;
  std::vector<sensor_msgs::msg::dds_::JointState_> joint_states;
  {
    std::lock_guard lock(mutex_);
    const auto stamp = now_stamp();
    bool any_fresh = joints_fresh_;
    for (const auto& [name, s] : segments_) any_fresh = any_fresh || s.fresh;
    if (!any_fresh) return;

    // TF: a segment that is some joint's child hangs from its parent by the joint's rotation; the others from world.
    std::set<std::string> children;
    for (const auto& [name, j] : joints_) {
      children.insert(j.child);
      geometry_msgs::msg::dds_::TransformStamped_ t;
      t.header().stamp(stamp);
      t.header().frame_id(ros2_frame(j.parent));
      t.child_frame_id(ros2_frame(j.child));
      t.transform().translation(vec(0, 0, -kRos2LinkLength_m));  // the parent's far end, along its -z
      t.transform().rotation(ros_quat(j.quat));                  // q_parent^* q_child: child frame to parent frame
      tf.transforms().push_back(std::move(t));
    }
    for (auto& [name, s] : segments_) {
      s.fresh = false;
      if (!s.quat || children.count(name)) continue;
      geometry_msgs::msg::dds_::TransformStamped_ t;
      t.header().stamp(stamp);
      t.header().frame_id("world");  // ENU, as REP-103 has it
      t.child_frame_id(ros2_frame(name));
      t.transform().translation(vec(0, 0, 1.0));  // a root 1 m above the floor
      t.transform().rotation(ros_quat(*s.quat));
      tf.transforms().push_back(std::move(t));
    }
    if (joints_fresh_) {
      joints_fresh_ = false;
      // One JointState per joint sample, stamped with its sensor time: the joints of a body are sampled at their
      // own instants, and one stamp for all would be wrong for all but one.
      for (auto& [name, j] : joints_) {
        if (!j.fresh) continue;
        j.fresh = false;
        sensor_msgs::msg::dds_::JointState_ msg;
        builtin_interfaces::msg::dds_::Time_ t;
        t.sec(static_cast<std::int32_t>(j.timestamp_ns / 1'000'000'000ull));
        t.nanosec(static_cast<std::uint32_t>(j.timestamp_ns % 1'000'000'000ull));
        msg.header().stamp(t);
        for (std::size_t i = 0; i < 3; ++i) {
          msg.name().push_back(j.names[i]);
          msg.position().push_back(j.positions[i]);
        }
        joint_states.push_back(std::move(msg));
      }
    }
  }
  if (!tf.transforms().empty() && !tf_writer_->write(tf)) ++write_failures_;
  for (const auto& msg : joint_states)
    if (!joint_state_writer_->write(msg)) ++write_failures_;
}

namespace {

int run_ros2_bridge(int domain, const std::string& subject) {
  logging::set_log_identity("ros2-bridge");
  // The mirror's rt/ topics keep their ROS 2 names (default partition) whichever subject it reads.
  DdsCommandFrame frame(domain, "bsn ros2-bridge", subject);
  Ros2Bridge bridge(frame.participant());
  std::printf("bsn ros2-bridge: mirroring domain %d to ROS 2 (rt/tf, rt/bsn/joint_states, rt/bsn/<segment>/imu)\n",
              domain);
  std::fflush(stdout);
  return frame.run_ticks(std::chrono::milliseconds(20), [&]() -> std::optional<int> {
    bridge.tick();
    return std::nullopt;
  });
}

}  // namespace

Command ros2_bridge_command() {
  return {"ros2-bridge", "Mirror orientations and joint angles to ROS 2 (Imu, TF, JointState)", [](CLI::App* cmd) {
            auto domain = std::make_shared<int>(0);
            auto subject = std::make_shared<std::string>();
            add_domain_option(cmd, *domain);
            add_subject_option(cmd, *subject);
            return [domain, subject] { return run_ros2_bridge(*domain, *subject); };
          }};
}

}  // namespace bsn::services
