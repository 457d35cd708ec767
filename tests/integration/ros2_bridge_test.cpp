// `bsn ros2-bridge` read the way a ROS 2 node reads it: plain Fast DDS readers on the rt/ topics with the ROS 2 type
// names, whose bytes this test decodes itself, field by field, after the ROS 2 message definitions (CDR, little
// endian, each field aligned to its size). The values must equal bsn's own orientation, raw and joint samples.
#include <gtest/gtest.h>

#include <array>
#include <cstring>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <map>
#include <mutex>
#include <numbers>
#include <set>
#include <string>
#include <vector>

#include "bsn/dds/participant.hpp"
#include "bsn/dds/topics.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;
using namespace eprosima::fastdds::dds;
using Bytes = std::vector<std::uint8_t>;

/// A type that is only a name: it hands out the serialised bytes as they came.
class RawBytesType : public TopicDataType {
 public:
  explicit RawBytesType(const std::string& name) {
    setName(name.c_str());
    m_typeSize = 1 << 16;
    m_isGetKeyDefined = false;
  }
  bool serialize(void* data, eprosima::fastrtps::rtps::SerializedPayload_t* payload) override {
    const auto* b = static_cast<Bytes*>(data);
    std::memcpy(payload->data, b->data(), b->size());
    payload->length = static_cast<std::uint32_t>(b->size());
    return true;
  }
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override {
    static_cast<Bytes*>(data)->assign(payload->data, payload->data + payload->length);
    return true;
  }
  std::function<std::uint32_t()> getSerializedSizeProvider(void* data) override {
    return [data] { return static_cast<std::uint32_t>(static_cast<Bytes*>(data)->size()); };
  }
  void* createData() override { return new Bytes(); }
  void deleteData(void* data) override { delete static_cast<Bytes*>(data); }
  bool getKey(void*, eprosima::fastrtps::rtps::InstanceHandle_t*, bool) override { return false; }
};

/// Plain CDR (XCDR1) little endian, as ROS 2 writes it: a 4-byte encapsulation header, then every primitive aligned
/// to its size from the start of the data.
class Cdr {
 public:
  explicit Cdr(const Bytes& b) : b_(b) {
    ok_ = b.size() >= 4 && b[0] == 0x00 && b[1] == 0x01;  // CDR_LE
  }
  bool ok() const { return ok_; }
  std::uint32_t u32() { return get<std::uint32_t>(); }
  std::int32_t i32() { return get<std::int32_t>(); }
  double f64() { return get<double>(); }
  std::string str() {
    const std::uint32_t n = u32();  // length with the terminating NUL
    if (!ok_ || n == 0 || 4 + pos_ + n > b_.size() || b_[4 + pos_ + n - 1] != 0) return fail();
    std::string s(reinterpret_cast<const char*>(&b_[4 + pos_]), n - 1);
    pos_ += n;
    return s;
  }
  std::array<double, 4> quat_xyzw() { return {f64(), f64(), f64(), f64()}; }
  std::array<double, 3> vec3() { return {f64(), f64(), f64()}; }
  /// All bytes read (the writer may pad the end to 4).
  bool at_end() const { return ok_ && 4 + pos_ <= b_.size() && b_.size() <= 4 + ((pos_ + 3) & ~std::size_t{3}); }

 private:
  template <class T>
  T get() {
    pos_ = (pos_ + sizeof(T) - 1) & ~(sizeof(T) - 1);
    T v{};
    if (!ok_ || 4 + pos_ + sizeof(T) > b_.size()) {
      ok_ = false;
      return v;
    }
    std::memcpy(&v, &b_[4 + pos_], sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  std::string fail() {
    ok_ = false;
    return "";
  }
  const Bytes& b_;
  std::size_t pos_ = 0;
  bool ok_ = false;
};

/// A best-effort reader (ROS 2's sensor-data profile) of `topic` with the type name `type`; take() polls it.
class RosReader {
 public:
  RosReader(DomainParticipant* p, const std::string& topic, const std::string& type) : participant_(p) {
    TypeSupport t(new RawBytesType(type));
    t.register_type(p);
    topic_ = p->create_topic(topic, type, TOPIC_QOS_DEFAULT);
    subscriber_ = p->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
    DataReaderQos q = DATAREADER_QOS_DEFAULT;
    q.reliability().kind = BEST_EFFORT_RELIABILITY_QOS;
    q.history().depth = 5;
    reader_ = subscriber_->create_datareader(topic_, q);
  }
  ~RosReader() {
    subscriber_->delete_datareader(reader_);
    participant_->delete_subscriber(subscriber_);
    participant_->delete_topic(topic_);
  }
  std::vector<Bytes> take() {
    std::vector<Bytes> out;
    Bytes b;
    SampleInfo info;
    while (reader_->take_next_sample(&b, &info) == ReturnCode_t::RETCODE_OK)
      if (info.valid_data) out.push_back(b);
    return out;
  }

 private:
  DomainParticipant* participant_;
  Topic* topic_ = nullptr;
  Subscriber* subscriber_ = nullptr;
  DataReader* reader_ = nullptr;
};

constexpr const char* kBody = R"(name: ros2_test
segments:
  - name: pelvis
    node: pelvis
  - name: thigh_l
    node: thigh_l
    parent: pelvis
    joint: hip_l
)";

bool same(const std::array<double, 4>& xyzw, const std::array<double, 4>& wxyz) {
  return xyzw[0] == wxyz[1] && xyzw[1] == wxyz[2] && xyzw[2] == wxyz[3] && xyzw[3] == wxyz[0];
}

TEST_F(ProcessTest, Ros2BridgeSamplesDecodeAsRos2MessagesWithBsnsValues) {
  const int domain = test_domain(68);
  write_file(dir() / "body.yaml", kBody);
  dds::Participant participant({domain, "ros2 test"});
  std::mutex mutex;
  std::map<std::string, std::vector<std::array<double, 4>>> orientations;          // segment -> quats
  std::map<std::string, std::vector<std::array<double, 3>>> gyros;                 // node -> rates
  std::map<std::string, std::vector<std::array<double, 4>>> joint_quats;           // joint -> quats
  std::map<std::string, std::map<std::uint64_t, bsn::JointAngles>> joint_samples;  // joint -> sensor time -> sample
  using SI = eprosima::fastdds::dds::SampleInfo;
  auto o_reader = participant.make_reader(dds::kOrientationTopic, [&](const bsn::Orientation& o, const SI&) {
    std::lock_guard lock(mutex);
    orientations[o.segment()].push_back(o.quat());
  });
  auto r_reader = participant.make_reader(dds::kRawTopic, [&](const bsn::RawSample& r, const SI&) {
    std::lock_guard lock(mutex);
    gyros[r.node_id()].push_back(r.gyr());
  });
  auto j_reader = participant.make_reader(dds::kJointAnglesTopic, [&](const bsn::JointAngles& j, const SI&) {
    std::lock_guard lock(mutex);
    joint_quats[j.joint()].push_back(j.quat());
    joint_samples[j.joint()][j.timestamp_ns()] = j;
  });
  RosReader imu(participant.native(), "rt/bsn/thigh_l/imu", "sensor_msgs::msg::dds_::Imu_");
  RosReader tf(participant.native(), "rt/tf", "tf2_msgs::msg::dds_::TFMessage_");
  RosReader joints(participant.native(), "rt/bsn/joint_states", "sensor_msgs::msg::dds_::JointState_");

  spawn("fusion", {"fusion", "--domain", std::to_string(domain), "--body", (dir() / "body.yaml").string()});
  for (const char* seg : {"pelvis", "thigh_l"}) spawn(seg, {"sim", "--domain", std::to_string(domain), "--node", seg});
  spawn("bridge", {"ros2-bridge", "--domain", std::to_string(domain)});

  std::vector<Bytes> imu_seen, tf_seen, joints_seen;
  ASSERT_TRUE(wait_until(
      [&] {
        for (auto& b : imu.take()) imu_seen.push_back(std::move(b));
        for (auto& b : tf.take()) tf_seen.push_back(std::move(b));
        for (auto& b : joints.take()) joints_seen.push_back(std::move(b));
        return imu_seen.size() >= 20 && tf_seen.size() >= 10 && joints_seen.size() >= 10;
      },
      30s))
      << imu_seen.size() << " Imu, " << tf_seen.size() << " TF, " << joints_seen.size() << " JointState\n"
      << tail(log_path("bridge"));
  std::this_thread::sleep_for(200ms);  // bsn's own samples of the last mirrored ones have surely arrived
  std::lock_guard lock(mutex);
  const auto now_s =
      std::chrono::duration_cast<std::chrono::seconds>(std::chrono::system_clock::now().time_since_epoch()).count();

  // sensor_msgs/Imu: header (stamp: int32 sec, uint32 nanosec; string frame_id), orientation (x, y, z, w),
  // float64[9] orientation_covariance, angular_velocity, float64[9], linear_acceleration, float64[9].
  // This test's own readers are best effort (as a ROS 2 sensor-data subscription), so on a loaded machine they may
  // miss a sample that the bridge mirrored: a value must be one of bsn's for most mirrored samples (a wrong mapping
  // matches none), not for every one.
  int imu_with_rates = 0, orientation_found = 0, rates_found = 0;
  for (const Bytes& b : imu_seen) {
    Cdr c(b);
    const std::int32_t sec = c.i32();
    const std::uint32_t nanosec = c.u32();
    EXPECT_EQ(c.str(), "bsn/thigh_l");
    const auto q = c.quat_xyzw();
    std::array<double, 9> cov_q{}, cov_w{}, cov_a{};
    for (double& v : cov_q) v = c.f64();
    const auto w = c.vec3();
    for (double& v : cov_w) v = c.f64();
    const auto a = c.vec3();
    for (double& v : cov_a) v = c.f64();
    ASSERT_TRUE(c.at_end()) << "Imu of " << b.size() << " bytes does not have the ROS 2 layout";
    EXPECT_LE(std::abs(sec - now_s), 10) << "stamp is ROS (UNIX) time";
    EXPECT_LT(nanosec, 1'000'000'000u);
    orientation_found += std::any_of(orientations["thigh_l"].begin(), orientations["thigh_l"].end(),
                                     [&](const auto& o) { return same(q, o); });
    for (double v : cov_q) EXPECT_EQ(v, 0.0) << "orientation covariance: all 0 = unknown";
    if (cov_w[0] == 0.0) {
      ++imu_with_rates;
      rates_found +=
          std::any_of(gyros["thigh_l"].begin(), gyros["thigh_l"].end(), [&](const auto& g) { return g == w; });
      EXPECT_GT(std::hypot(a[0], a[1], a[2]), 5.0) << "specific force includes gravity";
    } else {
      EXPECT_EQ(cov_w[0], -1.0) << "no rate: element 0 is -1";
    }
  }
  EXPECT_GT(imu_with_rates, 0) << "no Imu carried the raw sample's rates";
  EXPECT_GE(2 * orientation_found, static_cast<int>(imu_seen.size())) << "orientations equal to bsn/orientation's";
  EXPECT_GE(2 * rates_found, imu_with_rates) << "angular velocities equal to bsn/raw's";

  // tf2_msgs/TFMessage: sequence of TransformStamped (header, child_frame_id, translation xyz, rotation xyzw).
  bool saw_root = false, saw_joint = false;
  int tf_total = 0, tf_found = 0;
  for (const Bytes& b : tf_seen) {
    Cdr c(b);
    const std::uint32_t n = c.u32();
    for (std::uint32_t i = 0; i < n && c.ok(); ++i) {
      c.i32();
      c.u32();
      const std::string parent = c.str();
      const std::string child = c.str();
      const auto t = c.vec3();
      const auto q = c.quat_xyzw();
      ++tf_total;
      if (parent == "world" && (child == "bsn/pelvis" || child == "bsn/thigh_l")) {
        // thigh_l hangs from world only until its joint's first angles arrive.
        const std::string seg = child.substr(4);
        saw_root = saw_root || seg == "pelvis";
        tf_found +=
            std::any_of(orientations[seg].begin(), orientations[seg].end(), [&](const auto& o) { return same(q, o); });
      } else if (parent == "bsn/pelvis" && child == "bsn/thigh_l") {
        saw_joint = true;
        tf_found += std::any_of(joint_quats["hip_l"].begin(), joint_quats["hip_l"].end(),
                                [&](const auto& o) { return same(q, o); });
        EXPECT_EQ(t[2], -0.4);
      } else {
        ADD_FAILURE() << "unexpected frame " << parent << " -> " << child;
      }
    }
    ASSERT_TRUE(c.at_end()) << "TFMessage does not have the ROS 2 layout";
  }
  EXPECT_TRUE(saw_root && saw_joint);
  EXPECT_GE(2 * tf_found, tf_total) << "rotations equal to bsn's orientations and joint quaternions";

  // sensor_msgs/JointState: header, string[] name, float64[] position, velocity, effort. One message per joint
  // sample: stamped with its sensor time, named by the joint's anatomical angles, positions those angles (ISB signs,
  // rad) of the bsn/joint_angles sample of that time, within 0.01 degree.
  int joints_found = 0;
  for (const Bytes& b : joints_seen) {
    Cdr c(b);
    const std::int32_t sec = c.i32();
    const std::uint32_t nanosec = c.u32();
    EXPECT_EQ(c.str(), "");
    std::vector<std::string> names(c.u32());
    for (auto& n : names) n = c.str();
    std::vector<double> position(c.u32());
    for (auto& p : position) p = c.f64();
    EXPECT_EQ(c.u32(), 0u);  // velocity
    EXPECT_EQ(c.u32(), 0u);  // effort
    ASSERT_TRUE(c.at_end()) << "JointState does not have the ROS 2 layout";
    ASSERT_EQ(names.size(), 3u);
    ASSERT_EQ(position.size(), 3u);
    EXPECT_EQ(names[0], "hip_l_flexion_extension");
    EXPECT_EQ(names[1], "hip_l_adduction_abduction");
    EXPECT_EQ(names[2], "hip_l_internal_external_rotation");
    const std::uint64_t stamp_ns = static_cast<std::uint64_t>(sec) * 1'000'000'000ull + nanosec;
    const auto sample = joint_samples["hip_l"].find(stamp_ns);
    if (sample == joint_samples["hip_l"].end()) continue;  // a sample this best-effort reader missed
    ++joints_found;
    for (std::size_t i = 0; i < 3; ++i)
      EXPECT_NEAR(position[i], sample->second.anatomical()[i], 0.01 * std::numbers::pi / 180.0) << names[i];
  }
  EXPECT_GE(2 * joints_found, static_cast<int>(joints_seen.size()))
      << "JointState stamps are the sensor times of bsn/joint_angles samples";
}

}  // namespace
}  // namespace bsn::integration
