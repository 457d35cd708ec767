// A complete Fast DDS subscriber of bsn's joint angles, as a user writes one from the README: the types come from
// `fastddsgen -replace -d gen idl/bsn.idl` and nothing else of bsn is used. The README quotes this file and a test
// builds and runs it against a real bsn fusion.
//
// Build it on its own (Fast DDS 2.9, Debian's libfastrtps-dev):
//   mkdir -p gen && fastddsgen -replace -d gen idl/bsn.idl
//   g++ -std=c++17 -Igen tests/integration/fastdds_subscriber.cpp gen/bsn.cxx gen/bsnPubSubTypes.cxx
//       -lfastrtps -lfastcdr -o joint_angle_subscriber     (one line)
// Run: ./joint_angle_subscriber [DOMAIN (0)] [COUNT (10)] [TIMEOUT_S (30)]
// Prints one line per joint-angle sample; exits 0 after COUNT samples, 1 if they did not come within TIMEOUT_S.
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <thread>

#include "bsn.h"
#include "bsnPubSubTypes.h"

using namespace eprosima::fastdds::dds;

class JointAngleListener : public DataReaderListener {
 public:
  void on_data_available(DataReader* reader) override {
    bsn::JointAngles sample;
    SampleInfo info;
    while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      constexpr double kDeg = 180.0 / 3.14159265358979323846;
      std::printf("%s (%s -> %s) %s: %.1f %.1f %.1f deg\n", sample.joint().c_str(), sample.parent().c_str(),
                  sample.child().c_str(), sample.axes().c_str(), sample.angles()[0] * kDeg, sample.angles()[1] * kDeg,
                  sample.angles()[2] * kDeg);
      std::fflush(stdout);
      ++received;
    }
  }
  std::atomic<int> received{0};
};

int main(int argc, char** argv) {
  const int domain = argc > 1 ? std::atoi(argv[1]) : 0;
  const int count = argc > 2 ? std::atoi(argv[2]) : 10;
  const int timeout_s = argc > 3 ? std::atoi(argv[3]) : 30;

  DomainParticipant* participant =
      DomainParticipantFactory::get_instance()->create_participant(domain, PARTICIPANT_QOS_DEFAULT);
  if (participant == nullptr) return 2;
  // The type name is bsn::JointAngles, as bsn registers it, so the topic matches.
  TypeSupport type(new bsn::JointAnglesPubSubType());
  type.register_type(participant);
  Topic* topic = participant->create_topic("bsn/joint_angles", type.get_type_name(), TOPIC_QOS_DEFAULT);
  Subscriber* subscriber = participant->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
  // BEST_EFFORT matches any writer: a RELIABLE reader never matches a BEST_EFFORT writer, and nothing says why.
  DataReaderQos qos = DATAREADER_QOS_DEFAULT;
  qos.reliability().kind = BEST_EFFORT_RELIABILITY_QOS;
  JointAngleListener listener;
  DataReader* reader = subscriber->create_datareader(topic, qos, &listener);
  if (topic == nullptr || reader == nullptr) return 2;

  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(timeout_s);
  while (listener.received < count && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  const bool got_all = listener.received >= count;
  // Endpoints first, then the participant (Fast DDS refuses to delete a participant that still has entities).
  subscriber->delete_datareader(reader);
  participant->delete_subscriber(subscriber);
  participant->delete_topic(topic);
  DomainParticipantFactory::get_instance()->delete_participant(participant);
  if (!got_all)
    std::fprintf(stderr, "received %d of %d joint-angle samples within %d s\n", listener.received.load(), count,
                 timeout_s);
  return got_all ? 0 : 1;
}
