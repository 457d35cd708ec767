// One DDS participant per bsn process, with typed writers and readers for the bsn topics. Every endpoint
// reports incompatible QoS at match time, because a mismatch otherwise means silence.
#pragma once

#include <atomic>
#include <cstdint>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "bsn/dds/topics.hpp"

namespace bsn::dds {

/// Counts matches and incompatible-QoS events of one endpoint and logs them; for a reader it also holds the
/// data callback, which the Reader clears (under the mutex) when it is destroyed.
struct EndpointEvents {
  std::string topic;
  std::atomic<int> matched{0};
  std::atomic<std::uint64_t>* mismatch_counter = nullptr;
  std::atomic<int> alive_writers{0};           ///< reader: matched writers whose liveliness holds
  std::atomic<std::uint64_t> writers_lost{0};  ///< reader: times a matched writer lost its liveliness
  std::mutex callback_mutex;
  std::function<void(eprosima::fastdds::dds::DataReader*)> on_data;
};

/// A typed writer. Valid while its Participant lives.
template <class T>
class Writer {
 public:
  Writer(eprosima::fastdds::dds::DataWriter* w, std::shared_ptr<EndpointEvents> ev)
      : writer_(w), events_(std::move(ev)) {}
  /// Returns false if DDS refused the sample (it is then lost and the caller should count it).
  bool write(const T& sample) { return writer_->write(const_cast<T*>(&sample)); }
  /// Readers currently matched.
  int matched() const { return events_->matched.load(); }

 private:
  eprosima::fastdds::dds::DataWriter* writer_;
  std::shared_ptr<EndpointEvents> events_;
};

/// A typed reader whose callback runs on a DDS thread for every valid sample. Once the Reader is destroyed
/// the callback is never called again, so it may capture objects that die with the Reader's owner.
template <class T>
class Reader {
 public:
  explicit Reader(std::shared_ptr<EndpointEvents> ev) : events_(std::move(ev)) {}
  ~Reader() {
    std::lock_guard lock(events_->callback_mutex);
    events_->on_data = nullptr;
  }
  Reader(const Reader&) = delete;
  Reader& operator=(const Reader&) = delete;
  int matched() const { return events_->matched.load(); }
  /// Matched writers whose liveliness holds, and how often one lost it (its process died or hangs).
  int alive_writers() const { return events_->alive_writers.load(); }
  std::uint64_t writers_lost() const { return events_->writers_lost.load(); }

 private:
  std::shared_ptr<EndpointEvents> events_;
};

class Participant {
 public:
  struct Options {
    int domain = 0;            ///< DDS domain id (0..232); every test uses its own
    std::string name = "bsn";  ///< participant name shown by DDS tools
  };

  /// Throws std::runtime_error if the participant cannot be created.
  explicit Participant(const Options& options);
  ~Participant();
  Participant(const Participant&) = delete;
  Participant& operator=(const Participant&) = delete;

  /// A writer on `topic`, delivered as the topic says or as `delivery`. A data_writer profile named after the
  /// topic in the XML profiles file replaces bsn's delivery settings for it.
  template <class PubSub>
  std::unique_ptr<Writer<typename PubSub::type>> make_writer(const Topic<PubSub>& topic,
                                                             std::optional<TopicQos> delivery = {}) {
    auto events = std::make_shared<EndpointEvents>();
    auto* w = create_writer(dds_topic<PubSub>(topic.name), delivery.value_or(topic.qos), events);
    return std::make_unique<Writer<typename PubSub::type>>(w, events);
  }

  /// A reader on `topic` (delivery and XML profile as for writers) that calls `on_sample` for every valid sample.
  template <class PubSub>
  std::unique_ptr<Reader<typename PubSub::type>> make_reader(
      const Topic<PubSub>& topic,
      std::function<void(const typename PubSub::type&, const eprosima::fastdds::dds::SampleInfo&)> on_sample,
      std::optional<TopicQos> delivery = {}) {
    auto events = std::make_shared<EndpointEvents>();
    events->on_data = [cb = std::move(on_sample)](eprosima::fastdds::dds::DataReader* reader) {
      typename PubSub::type sample;
      eprosima::fastdds::dds::SampleInfo info;
      while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
        if (info.valid_data) cb(sample, info);
      }
    };
    create_reader(dds_topic<PubSub>(topic.name), delivery.value_or(topic.qos), events);
    return std::make_unique<Reader<typename PubSub::type>>(events);
  }

  /// Incompatible-QoS events seen by any endpoint of this participant.
  std::uint64_t qos_mismatches() const { return qos_mismatches_.load(); }

  eprosima::fastdds::dds::DomainParticipant* native() { return participant_; }

 private:
  template <class PubSub>
  eprosima::fastdds::dds::Topic* dds_topic(const std::string& name) {
    eprosima::fastdds::dds::TypeSupport type(new PubSub());
    return find_or_create_topic(name, type);
  }

  eprosima::fastdds::dds::Topic* find_or_create_topic(const std::string& name,
                                                      eprosima::fastdds::dds::TypeSupport type);
  eprosima::fastdds::dds::DataWriter* create_writer(eprosima::fastdds::dds::Topic* topic, TopicQos delivery,
                                                    std::shared_ptr<EndpointEvents> events);
  void create_reader(eprosima::fastdds::dds::Topic* topic, TopicQos delivery, std::shared_ptr<EndpointEvents> events);

  eprosima::fastdds::dds::DomainParticipant* participant_ = nullptr;
  eprosima::fastdds::dds::Publisher* publisher_ = nullptr;
  eprosima::fastdds::dds::Subscriber* subscriber_ = nullptr;
  std::mutex mutex_;
  std::map<std::string, eprosima::fastdds::dds::Topic*> topics_;
  std::vector<std::unique_ptr<eprosima::fastdds::dds::DataWriterListener>> writer_listeners_;
  std::vector<std::unique_ptr<eprosima::fastdds::dds::DataReaderListener>> reader_listeners_;
  std::vector<eprosima::fastdds::dds::DataReader*> readers_;
  std::atomic<std::uint64_t> qos_mismatches_{0};
};

/// Domain id from the environment variable BSN_DOMAIN, else 0.
int default_domain();

}  // namespace bsn::dds
