// A Fast DDS XML profile (FASTRTPS_DEFAULT_PROFILES_FILE) named after a topic replaces bsn's QoS of that topic in
// a real `bsn` process, and only of that topic. The QoS the process announces is read from DDS discovery, and
// what it does is observed: a late joiner gets history only from a TRANSIENT_LOCAL writer; a RELIABLE raw
// reader does not match bsn's BEST_EFFORT writers, and both ends report it.
#include <fastdds/rtps/reader/ReaderDiscoveryInfo.h>
#include <fastdds/rtps/writer/WriterDiscoveryInfo.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <map>
#include <mutex>
#include <string>
#include <thread>

#include "bsn/dds/conversions.hpp"
#include "bsn/dds/participant.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;
using namespace eprosima::fastdds::dds;

struct AnnouncedQos {
  DurabilityQosPolicyKind durability;
  ReliabilityQosPolicyKind reliability;
};

/// The QoS that remote writers and readers announce, by topic.
class Discovery final : public DomainParticipantListener {
 public:
  void on_publisher_discovery(DomainParticipant*, eprosima::fastrtps::rtps::WriterDiscoveryInfo&& w) override {
    if (w.status != eprosima::fastrtps::rtps::WriterDiscoveryInfo::DISCOVERED_WRITER) return;
    std::lock_guard lock(mutex_);
    writers_[w.info.topicName().to_string()] = {w.info.m_qos.m_durability.kind, w.info.m_qos.m_reliability.kind};
  }
  void on_subscriber_discovery(DomainParticipant*, eprosima::fastrtps::rtps::ReaderDiscoveryInfo&& r) override {
    if (r.status != eprosima::fastrtps::rtps::ReaderDiscoveryInfo::DISCOVERED_READER) return;
    std::lock_guard lock(mutex_);
    readers_[r.info.topicName().to_string()] = {r.info.m_qos.m_durability.kind, r.info.m_qos.m_reliability.kind};
  }
  std::optional<AnnouncedQos> writer(const std::string& topic) { return find(writers_, topic); }
  std::optional<AnnouncedQos> reader(const std::string& topic) { return find(readers_, topic); }

 private:
  std::optional<AnnouncedQos> find(const std::map<std::string, AnnouncedQos>& m, const std::string& topic) {
    std::lock_guard lock(mutex_);
    const auto it = m.find(topic);
    return it == m.end() ? std::nullopt : std::optional(it->second);
  }
  std::mutex mutex_;
  std::map<std::string, AnnouncedQos> writers_, readers_;
};

/// How old each bsn/truth/orientation sample is when it arrives (on this host's CLOCK_MONOTONIC, like the sim's).
class SampleAges final : public DataReaderListener {
 public:
  void on_data_available(DataReader* reader) override {
    bsn::Orientation o;
    SampleInfo info;
    while (reader->take_next_sample(&o, &info) == ReturnCode_t::RETCODE_OK) {
      std::lock_guard lock(mutex_);
      if (info.valid_data) ages_ns_.push_back(dds::monotonic_ns() - o.timestamp_ns());
    }
  }
  long older_than(std::chrono::nanoseconds age) {
    std::lock_guard lock(mutex_);
    return std::count_if(ages_ns_.begin(), ages_ns_.end(),
                         [&](std::uint64_t a) { return a > std::uint64_t(age.count()); });
  }

 private:
  std::mutex mutex_;
  std::vector<std::uint64_t> ages_ns_;
};

// UDP only, so the child leaves nothing in /dev/shm; the profile's transports are used as they are.
constexpr const char* kUdpOnly = R"(
  <transport_descriptors>
    <transport_descriptor><transport_id>udp</transport_id><type>UDPv4</type></transport_descriptor>
  </transport_descriptors>
  <participant profile_name="udp_only" is_default_profile="true">
    <rtps><userTransports><transport_id>udp</transport_id></userTransports>
          <useBuiltinTransports>false</useBuiltinTransports></rtps>
  </participant>)";

std::string profiles(const std::string& endpoints) {
  return std::string(R"(<?xml version="1.0" encoding="UTF-8"?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">)") +
         kUdpOnly + endpoints + "\n</profiles>\n";
}

class QosProfile : public ProcessTest {
 protected:
  /// Starts `bsn <args>` with FASTRTPS_DEFAULT_PROFILES_FILE = a file holding `xml`; this process keeps no profile.
  void spawn_with_profiles(const std::string& name, const std::string& xml, const std::vector<std::string>& args) {
    const std::string path = (dir() / (name + ".xml")).string();
    write_file(path, xml);
    setenv("FASTRTPS_DEFAULT_PROFILES_FILE", path.c_str(), 1);
    spawn(name, args);
    unsetenv("FASTRTPS_DEFAULT_PROFILES_FILE");
  }
};

TEST_F(QosProfile, WriterProfileReplacesTheQosOfItsTopicOnly) {
  const int domain = test_domain(24);
  Discovery discovery;
  SampleAges ages;
  dds::Participant participant({domain, "qos profile test"});
  participant.native()->set_listener(&discovery, StatusMask::none());

  // bsn/truth/orientation is VOLATILE with a history of 1 in bsn; the profile keeps the last 50 for late joiners.
  constexpr int kProfileDepth = 50;
  spawn_with_profiles("sim", profiles(R"(
  <data_writer profile_name="bsn/truth/orientation">
    <topic><historyQos><kind>KEEP_LAST</kind><depth>50</depth></historyQos></topic>
    <qos><durability><kind>TRANSIENT_LOCAL</kind></durability><reliability><kind>RELIABLE</kind></reliability></qos>
  </data_writer>)"),
                      {"sim", "--node", "n1", "--rate", "100", "--domain", std::to_string(domain)});

  ASSERT_TRUE(wait_until([&] { return discovery.writer("bsn/truth/orientation") && discovery.writer("bsn/raw"); }, 15s))
      << "the sim's writers were not discovered";
  const AnnouncedQos truth = *discovery.writer("bsn/truth/orientation");
  EXPECT_EQ(truth.durability, TRANSIENT_LOCAL_DURABILITY_QOS);
  EXPECT_EQ(truth.reliability, RELIABLE_RELIABILITY_QOS);
  const AnnouncedQos raw = *discovery.writer("bsn/raw");  // no profile: bsn's sensor-data QoS
  EXPECT_EQ(raw.durability, VOLATILE_DURABILITY_QOS);
  EXPECT_EQ(raw.reliability, BEST_EFFORT_RELIABILITY_QOS);

  // After 1 s at 100 Hz the writer has published twice what its history holds. Then a late joiner that keeps
  // everything it gets (bsn's own latched readers keep 8 per instance).
  std::this_thread::sleep_for(1s);
  TypeSupport type(new bsn::OrientationPubSubType());
  type.register_type(participant.native());
  Topic* topic =
      participant.native()->create_topic(dds::kTruthOrientationTopic.name, type.get_type_name(), TOPIC_QOS_DEFAULT);
  DataReaderQos qos = DATAREADER_QOS_DEFAULT;
  qos.reliability().kind = RELIABLE_RELIABILITY_QOS;
  qos.durability().kind = TRANSIENT_LOCAL_DURABILITY_QOS;
  qos.history().depth = 1000;
  participant.native()->create_subscriber(SUBSCRIBER_QOS_DEFAULT)->create_datareader(topic, qos, &ages);

  // A live sample arrives within a millisecond or so of its time stamp; the writer's history reaches the late
  // reader at once, the oldest of it 49 periods old. Count what is older than 5 periods (50 ms): none with bsn's
  // VOLATILE writer (it would not even match this reader), none with a history of 1, about 44 with the profile's
  // 50, and never more than 50.
  EXPECT_TRUE(wait_until([&] { return ages.older_than(50ms) >= 30; }, 10s))
      << ages.older_than(50ms) << " samples from the history";
  std::this_thread::sleep_for(500ms);  // anything more from the history would have come by now
  EXPECT_LE(ages.older_than(50ms), kProfileDepth);
  EXPECT_EQ(participant.qos_mismatches(), 0u);
}

TEST_F(QosProfile, ReaderProfileIsHonouredAndTheMismatchIsReported) {
  const int domain = test_domain(25);
  Discovery discovery;
  dds::Participant participant({domain, "qos profile test"});
  participant.native()->set_listener(&discovery, StatusMask::none());
  auto raw_writer = participant.make_writer(dds::kRawTopic);  // bsn's BEST_EFFORT
  std::mutex mutex;
  std::uint64_t reported_mismatches = 0;
  auto status_reader = participant.make_reader(dds::kStatusTopic, [&](const bsn::Status& s, const SampleInfo&) {
    std::lock_guard lock(mutex);
    reported_mismatches = std::max<std::uint64_t>(reported_mismatches, s.qos_mismatches());
  });

  spawn_with_profiles("fusion", profiles(R"(
  <data_reader profile_name="bsn/raw">
    <qos><reliability><kind>RELIABLE</kind></reliability></qos>
  </data_reader>)"),
                      {"fusion", "--status-period", "0.2", "--domain", std::to_string(domain)});

  ASSERT_TRUE(wait_until([&] { return discovery.reader("bsn/raw") && discovery.writer("bsn/status"); }, 15s))
      << "the fusion service's endpoints were not discovered";
  EXPECT_EQ(discovery.reader("bsn/raw")->reliability, RELIABLE_RELIABILITY_QOS);
  EXPECT_EQ(discovery.writer("bsn/status")->durability, TRANSIENT_LOCAL_DURABILITY_QOS);  // bsn's, no profile

  // A BEST_EFFORT writer never matches a RELIABLE reader: our writer and the fusion service both say so.
  EXPECT_TRUE(wait_until([&] { return participant.qos_mismatches() > 0; }, 10s))
      << "our BEST_EFFORT raw writer reported no incompatible QoS";
  EXPECT_TRUE(wait_until(
      [&] {
        std::lock_guard lock(mutex);
        return reported_mismatches > 0;
      },
      10s))
      << "bsn/status of the fusion service reported no QoS mismatch";
  EXPECT_EQ(raw_writer->matched(), 0);
  ASSERT_TRUE(exited_cleanly(stop("fusion")));
  EXPECT_NE(read_file(log_path("fusion")).find("RELIABILITY"), std::string::npos)
      << "the fusion service did not name the incompatible policy";
}

}  // namespace
}  // namespace bsn::integration
