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
#include <shared_mutex>
#include <string>
#include <type_traits>
#include <vector>

#include "bsn/dds/topics.hpp"
#include "bsn/dds/type_support.hpp"

namespace bsn::dds {

/// Counts matches and incompatible-QoS events of one endpoint and logs them; for a reader it also holds the
/// data callback, which the Reader clears (under the mutex) when it is destroyed.
struct EndpointEvents {
  std::string topic;
  std::atomic<int> matched{0};
  std::atomic<int> matched_exclusive{0};  ///< reader of an estimate topic: writers its EXCLUSIVE twin matched
  std::atomic<std::uint64_t>* mismatch_counter = nullptr;
  std::atomic<int> alive_writers{0};                          ///< reader: matched writers whose liveliness holds
  std::atomic<int> alive_writers_exclusive{0};                ///< of the EXCLUSIVE twin
  std::atomic<std::uint64_t> writers_lost{0};                 ///< reader: times a matched writer lost its liveliness
  std::atomic<std::uint64_t>* undecodable_counter = nullptr;  ///< samples whose bytes did not decode (dropped)
  std::atomic<std::uint64_t>* lost_counter = nullptr;         ///< samples sent to this reader that never came
  std::atomic<std::uint64_t>* rejected_counter = nullptr;     ///< of those, the ones DDS reported rejected
  /// Per writer, the last DDS sequence number taken. Fast DDS 2.9.1 drops a sample beyond a reader's resource
  /// limit (max_instances) without a SAMPLE_REJECTED or SAMPLE_LOST status; a writer numbers its samples 1, 2, 3,
  /// ..., so a gap is a loss, whatever caused it (that limit, a full history, the network). Callback thread only.
  std::map<eprosima::fastrtps::rtps::GUID_t, std::int64_t> last_sequence;
  /// The writer of the last sample taken and its entry in last_sequence: a node's samples come in runs from one
  /// writer, so most samples need no look-up.
  eprosima::fastrtps::rtps::GUID_t last_writer;
  std::int64_t* last_writer_sequence = nullptr;
  /// EXCLUSIVE twin: per instance, the writer of the last sample taken. A writer's samples of an instance it did
  /// not own were dropped by DDS, not lost: the first sample after an ownership change counts no gap.
  std::map<eprosima::fastrtps::rtps::InstanceHandle_t, eprosima::fastrtps::rtps::GUID_t> owner_of_instance;
  /// EXCLUSIVE twin: per instance, the writer and sensor instant (timestamp_ns) of the last sample delivered.
  struct Delivered {
    eprosima::fastrtps::rtps::GUID_t writer;
    std::uint64_t instant_ns = 0;
  };
  std::map<eprosima::fastrtps::rtps::InstanceHandle_t, Delivered> delivered;
  std::uint64_t superseded = 0;  ///< samples of instants already delivered by the instance's previous owner
  std::mutex callback_mutex;
  std::function<void(eprosima::fastdds::dds::DataReader*)> on_data;
};

/// Counts an undecodable sample on a reader and logs the first one of each reader.
void count_undecodable(EndpointEvents& events);
/// False for a sample an EXCLUSIVE reader must not deliver: one of a sensor instant at or before the last one
/// delivered of its instance by another writer (a standby that lagged its primary when it took over, or the first
/// samples before the strongest writer's arrived), so that no instant comes twice or out of order across a handover.
bool new_instant_for_owner(EndpointEvents& events, const eprosima::fastdds::dds::SampleInfo& info,
                           const eprosima::fastdds::dds::DataReader* reader, std::uint64_t instant_ns);

/// Counts the samples between the last one taken from the same writer and this one as lost (`reader`: the one that
/// took it, for its ownership).
void count_lost(EndpointEvents& events, const eprosima::fastdds::dds::SampleInfo& info,
                const eprosima::fastdds::dds::DataReader* reader);

/// What ties an endpoint to its participant's re-creations (Participant::watch_peers): the participant makes again
/// only the endpoints whose handle still lives, and swaps a writer's DataWriter under the participant's guard.
struct EndpointHandle {
  /// A writer's current DataWriter; null while the participant is being made again (a write then fails).
  std::atomic<eprosima::fastdds::dds::DataWriter*> writer{nullptr};
  /// The participant's: held shared around each use of `writer`, exclusively to swap it.
  std::shared_mutex* guard = nullptr;
};

/// A typed writer. Valid while its Participant lives; it survives the participant's re-creation.
template <class T>
class Writer {
 public:
  Writer(std::shared_ptr<EndpointHandle> handle, std::shared_ptr<EndpointEvents> ev, bool is_volatile)
      : handle_(std::move(handle)), events_(std::move(ev)), volatile_(is_volatile) {}
  /// Returns false if DDS refused the sample (it is then lost and the caller should count it).
  bool write(const T& sample) {
    std::shared_lock lock(*handle_->guard);
    eprosima::fastdds::dds::DataWriter* w = handle_->writer.load(std::memory_order_relaxed);
    return w != nullptr && w->write(const_cast<T*>(&sample));
  }
  /// Readers currently matched.
  int matched() const { return events_->matched.load(); }
  /// True if a sample written now could reach no reader, ever: no reader is matched and the writer keeps nothing
  /// for later ones (VOLATILE; an XML profile may make it otherwise). Such a write may be skipped.
  bool unheard() const { return volatile_ && matched() == 0; }
  /// The writer's GUID: what readers see as the sample's writer (SampleInfo::sample_identity.writer_guid()). It
  /// changes when the participant is made again.
  eprosima::fastrtps::rtps::GUID_t guid() const {
    std::shared_lock lock(*handle_->guard);
    eprosima::fastdds::dds::DataWriter* w = handle_->writer.load(std::memory_order_relaxed);
    return w != nullptr ? w->guid() : eprosima::fastrtps::rtps::GUID_t::unknown();
  }
  /// An owned estimate writer (WriterScope::ownership_strength) is alive while it writes or asserts this at least
  /// once per kOwnedEstimateLease_s.
  void assert_liveliness() {
    std::shared_lock lock(*handle_->guard);
    if (eprosima::fastdds::dds::DataWriter* w = handle_->writer.load(std::memory_order_relaxed)) w->assert_liveliness();
  }
  const std::shared_ptr<EndpointEvents>& events() const { return events_; }

 private:
  std::shared_ptr<EndpointHandle> handle_;
  std::shared_ptr<EndpointEvents> events_;
  bool volatile_;
};

/// A typed reader whose callback runs on a DDS thread for every valid sample. Once the Reader is destroyed
/// the callback is never called again, so it may capture objects that die with the Reader's owner.
template <class T>
class Reader {
 public:
  Reader(std::shared_ptr<EndpointHandle> handle, std::shared_ptr<EndpointEvents> ev)
      : handle_(std::move(handle)), events_(std::move(ev)) {}
  ~Reader() {
    std::lock_guard lock(events_->callback_mutex);
    events_->on_data = nullptr;
  }
  Reader(const Reader&) = delete;
  Reader& operator=(const Reader&) = delete;
  int matched() const { return events_->matched.load() + events_->matched_exclusive.load(); }
  /// Matched writers whose liveliness holds, and how often one lost it (its process died or hangs).
  int alive_writers() const { return events_->alive_writers.load() + events_->alive_writers_exclusive.load(); }
  std::uint64_t writers_lost() const { return events_->writers_lost.load(); }
  const std::shared_ptr<EndpointEvents>& events() const { return events_; }

 private:
  std::shared_ptr<EndpointHandle> handle_;
  std::shared_ptr<EndpointEvents> events_;
};

/// The liveliness lease of estimates written with EXCLUSIVE ownership, s: the lease bsn's readers request (DDS
/// tracks a writer's liveliness with the reader's lease) and the writers offer, MANUAL_BY_TOPIC (each sample, or
/// Writer::assert_liveliness, renews it). A standby takes an instance over within about this long after its
/// owner's process died (docs/topics.md, ownership).
inline constexpr double kOwnedEstimateLease_s = 0.05;

/// Where a writer publishes and who owns the instances it writes.
struct WriterScope {
  /// DDS partition of a subject's estimates and status (bsn/orientation, bsn/joint_angles, bsn/status); unset:
  /// the participant's subject. Other topics ignore it.
  std::optional<std::string> subject;
  /// Estimate topics (bsn/orientation, bsn/joint_angles): EXCLUSIVE ownership with this strength and a liveliness
  /// lease of kOwnedEstimateLease_s, so that a reader takes each instance from the strongest live writer (a
  /// primary and its hot standby); its owner asserts the writer's liveliness between samples. Unset: SHARED, as
  /// every other writer.
  std::optional<std::uint32_t> ownership_strength;
};

/// True for the topics written per subject, in the subject's DDS partition.
bool is_per_subject(const std::string& topic);

class Participant {
 public:
  struct Options {
    int domain = 0;            ///< DDS domain id (0..232); every test uses its own
    std::string name = "bsn";  ///< participant name shown by DDS tools
    /// The subject whose estimates and status this participant's endpoints write and read: the DDS partition of
    /// that name (docs/design.md section 3). "" is the default partition, which a single-body fusion uses.
    std::string subject = "";
  };

  /// Throws std::runtime_error if the participant cannot be created.
  explicit Participant(const Options& options);
  ~Participant();
  Participant(const Participant&) = delete;
  Participant& operator=(const Participant&) = delete;

  /// A writer on `topic`, delivered as the topic says or as `delivery`. A data_writer profile named after the
  /// topic in the XML profiles file replaces bsn's delivery settings for it.
  /// `node`: the node whose samples a bsn/raw writer carries. Under DDS-Security the writer goes in the DDS
  /// partition of that name, which the identity's permissions must allow (make-pki.sh NAME:sensor:NODES), and fusion
  /// takes a node's samples only from writers in its partition. Ignored on an open network and for other topics.
  /// `scope`: the subject partition and the ownership of its estimates (WriterScope).
  template <class PubSub>
  std::unique_ptr<Writer<typename PubSub::type>> make_writer(const Topic<PubSub>& topic,
                                                             std::optional<TopicQos> delivery = {},
                                                             const std::string& node = "",
                                                             const WriterScope& scope = {}) {
    std::lock_guard lock(endpoints_mutex_);  // not while the participant is made again
    auto events = std::make_shared<EndpointEvents>();
    dds_topic<PubSub>(topic.name);
    auto handle = add_writer(topic.name, delivery.value_or(topic.qos), events, node, scope);
    return std::make_unique<Writer<typename PubSub::type>>(handle, events, writer_is_volatile(*handle));
  }

  /// Decides whether a sample may enter a reader. Fast DDS asks it on its receive thread for every sample before
  /// the sample enters the reader's history (a content filter of this participant's own class), so a refused
  /// sample takes none of the reader's instances (max_instances, 4096 by default) and never reaches on_sample;
  /// the decider counts what it refuses. Samples whose bytes do not decode are let through to be counted as
  /// undecodable.
  template <class T>
  using Admission = std::function<bool(const T&)>;

  /// A reader on `topic` (delivery and XML profile as for writers) that calls `on_sample` for every valid sample
  /// that `admit` (if given) lets in. A per-subject topic is read in `subject`'s partition (unset: the
  /// participant's subject). An estimate topic (bsn/orientation, bsn/joint_angles) gets a second, EXCLUSIVE
  /// reader beside the SHARED one (DDS matches a writer only with a reader of its own ownership kind): every writer
  /// is read by one of the two, and of a primary and its standby only the live owner's samples arrive.
  template <class PubSub>
  std::unique_ptr<Reader<typename PubSub::type>> make_reader(
      const Topic<PubSub>& topic,
      std::function<void(const typename PubSub::type&, const eprosima::fastdds::dds::SampleInfo&)> on_sample,
      std::optional<TopicQos> delivery = {}, Admission<typename PubSub::type> admit = {},
      const std::optional<std::string>& subject = {}) {
    std::lock_guard lock(endpoints_mutex_);  // not while the participant is made again
    auto events = std::make_shared<EndpointEvents>();
    // One sample object for the reader's life (on_data runs under the callback mutex): its strings and sequences
    // keep their storage from one sample to the next.
    events->on_data = [cb = std::move(on_sample), events_ptr = events.get(),
                       sample = typename PubSub::type()](eprosima::fastdds::dds::DataReader* reader) mutable {
      eprosima::fastdds::dds::SampleInfo info;
      while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
        count_lost(*events_ptr, info, reader);
        if (!info.valid_data) continue;
        if (last_deserialize_failed()) {  // bytes no bsn type can hold (a foreign or broken writer): dropped
          count_undecodable(*events_ptr);
          continue;
        }
        using Sample = typename PubSub::type;
        if constexpr (std::is_same_v<Sample, bsn::Orientation> || std::is_same_v<Sample, bsn::JointAngles>) {
          if (!new_instant_for_owner(*events_ptr, info, reader, sample.timestamp_ns())) continue;
        }
        cb(sample, info);
      }
    };
    dds_topic<PubSub>(topic.name);
    std::optional<std::size_t> admission;
    if (admit) {
      admission = add_admission([admit = std::move(admit)](const eprosima::fastrtps::rtps::SerializedPayload_t& bytes) {
        thread_local typename PubSub::type sample;
        thread_local Guarded<PubSub> type;
        auto* payload = const_cast<eprosima::fastrtps::rtps::SerializedPayload_t*>(&bytes);
        if (!type.deserialize(payload, &sample) || last_deserialize_failed()) return true;
        return admit(sample);
      });
    }
    auto handle = add_reader(topic.name, admission, delivery.value_or(topic.qos), events, subject);
    return std::make_unique<Reader<typename PubSub::type>>(handle, events);
  }

  /// Under DDS-Security, says that `endpoint` (a Writer or Reader of this participant) needs a peer, named by
  /// `peer` ("a fusion reading bsn/raw"). Endpoints given the same `peer` are one expectation, met while any of them
  /// is matched. On an open network it does nothing.
  template <class Endpoint>
  void expect_peer(const Endpoint& endpoint, const std::string& peer) {
    expect(endpoint.events(), peer);
  }

  /// Fast DDS 2.9.1 sometimes never completes the DDS-Security handshake of two participants and never tries
  /// again while both live (docs/deployment.md, DDS-Security). Under DDS-Security, if an expectation (expect_peer)
  /// has had no match for kPeerBound_s (doubling after each try, up to kMaxPeerBound_s), this logs an error naming
  /// the peer and the handshakes still unfinished, counts it (rejoins()) and makes the participant again (unless some
  /// handshake finished within the last quarter of the bound: they are slow, not stuck), with a new
  /// GUID and every endpoint whose Writer or Reader still lives: a fresh handshake with everyone. Call it from one
  /// thread, periodically (DdsCommandFrame::run_ticks does); not from a DDS callback. True if it made it again.
  bool watch_peers();
  /// Times watch_peers made the participant again (bsn/status participant_rejoins).
  std::uint64_t rejoins() const { return rejoins_.load(); }

  /// Incompatible-QoS events seen by any endpoint of this participant.
  std::uint64_t qos_mismatches() const { return qos_mismatches_.load(); }
  /// Samples any reader of this participant received but could not decode (malformed bytes), dropped.
  std::uint64_t undecodable_samples() const { return undecodable_samples_.load(); }
  /// Samples writers sent to this participant's readers that never arrived: gaps in each writer's DDS sequence
  /// numbers (a reader's resource limit such as max_instances, a full history, the network).
  std::uint64_t lost_samples() const { return lost_samples_.load(); }
  /// Of lost_samples(), those DDS itself reported rejected at a reader's resource limit (SAMPLE_REJECTED; Fast DDS
  /// 2.9.1 does not report the max_instances case).
  std::uint64_t rejected_samples() const { return rejected_samples_.load(); }

  /// The current DDS participant: another one after watch_peers made it again.
  eprosima::fastdds::dds::DomainParticipant* native() { return participant_; }

  /// True if the participant runs with DDS-Security (BSN_SECURITY_DIR).
  bool secured() const { return secured_; }
  /// Under DDS-Security: true if the bsn/raw writer `writer` was discovered in a DDS partition that names `node`
  /// (access control let it match only if its identity may write that partition). Partitions are taken as first
  /// discovered: a later change of a matched writer's partitions is not checked again by Fast DDS 2.9.1.
  bool writer_may_write_node(const eprosima::fastrtps::rtps::GUID_t& writer, const std::string& node) const;

 private:
  template <class PubSub>
  eprosima::fastdds::dds::Topic* dds_topic(const std::string& name) {
    eprosima::fastdds::dds::TypeSupport type(new Guarded<PubSub>());
    return find_or_create_topic(name, type);
  }

  /// The DDS participant with its default publisher and subscriber.
  void open();
  /// Deletes the DDS participant and every entity in it.
  void close();
  eprosima::fastdds::dds::Topic* find_or_create_topic(const std::string& name,
                                                      eprosima::fastdds::dds::TypeSupport type);
  /// The topic of that name on the current participant; its type was given the first time (dds_topic).
  eprosima::fastdds::dds::Topic* topic_named(const std::string& name);
  using PayloadAdmission = std::function<bool(const eprosima::fastrtps::rtps::SerializedPayload_t&)>;
  /// The index of a new admission (AdmissionFilters in participant.cpp).
  std::size_t add_admission(PayloadAdmission admit);
  /// A content-filtered view of `topic` whose filter is admission `index`.
  eprosima::fastdds::dds::TopicDescription* admitting_topic(eprosima::fastdds::dds::Topic* topic, std::size_t index);
  /// What a writer or reader is made of, kept to make it again on a new participant.
  struct WriterRecipe {
    std::weak_ptr<EndpointHandle> handle;
    std::shared_ptr<EndpointEvents> events;
    std::string topic;
    TopicQos delivery;
    std::string node;
    WriterScope scope;
  };
  struct ReaderRecipe {
    std::weak_ptr<EndpointHandle> handle;
    std::shared_ptr<EndpointEvents> events;
    std::string topic;
    std::optional<std::size_t> admission;
    TopicQos delivery;
    std::optional<std::string> subject;
  };
  std::shared_ptr<EndpointHandle> add_writer(const std::string& topic, TopicQos delivery,
                                             std::shared_ptr<EndpointEvents> events, const std::string& node,
                                             const WriterScope& scope);
  std::shared_ptr<EndpointHandle> add_reader(const std::string& topic, std::optional<std::size_t> admission,
                                             TopicQos delivery, std::shared_ptr<EndpointEvents> events,
                                             const std::optional<std::string>& subject);
  static bool writer_is_volatile(const EndpointHandle& handle);
  eprosima::fastdds::dds::DataWriter* create_writer(const WriterRecipe& recipe);
  void create_reader(const ReaderRecipe& recipe);
  eprosima::fastdds::dds::Publisher* publisher_in(const std::string& partition);    ///< under mutex_
  eprosima::fastdds::dds::Subscriber* subscriber_in(const std::string& partition);  ///< under mutex_
  void create_one_reader(eprosima::fastdds::dds::Subscriber* subscriber,
                         eprosima::fastdds::dds::TopicDescription* topic, const std::string& name, TopicQos delivery,
                         std::shared_ptr<EndpointEvents> events, bool exclusive);
  void expect(const std::shared_ptr<EndpointEvents>& events, const std::string& peer);
  /// Makes the participant again with every live endpoint (watch_peers).
  void recreate();

  Options options_;
  eprosima::fastdds::dds::DomainParticipant* participant_ = nullptr;
  eprosima::fastdds::dds::Publisher* publisher_ = nullptr;
  eprosima::fastdds::dds::Subscriber* subscriber_ = nullptr;
  std::mutex mutex_;
  std::map<std::string, eprosima::fastdds::dds::Topic*> topics_;
  std::map<std::string, eprosima::fastdds::dds::TypeSupport> types_;  ///< per topic name, to make the topic again
  std::vector<std::unique_ptr<eprosima::fastdds::dds::DataWriterListener>> writer_listeners_;
  std::vector<std::unique_ptr<eprosima::fastdds::dds::DataReaderListener>> reader_listeners_;
  std::vector<eprosima::fastdds::dds::DataReader*> readers_;
  bool secured_ = false;
  std::string subject_;  ///< Options::subject
  std::map<std::string, eprosima::fastdds::dds::Publisher*> partition_publishers_;
  std::map<std::string, eprosima::fastdds::dds::Subscriber*> partition_subscribers_;
  eprosima::fastdds::dds::Subscriber* any_partition_subscriber_ = nullptr;  ///< secured bsn/raw readers
  struct Discovery;
  std::unique_ptr<Discovery> discovery_;  ///< discovered bsn/raw writers' partitions, handshakes (secured only)
  struct AdmissionFilters;
  std::unique_ptr<AdmissionFilters> admission_;  ///< the filter class of this participant's admitting readers
  /// Held from make_writer/make_reader to the end of a re-creation: the recipes do not change meanwhile.
  std::recursive_mutex endpoints_mutex_;
  std::vector<WriterRecipe> writer_recipes_;
  std::vector<ReaderRecipe> reader_recipes_;
  std::shared_mutex writer_guard_;  ///< EndpointHandle::guard of every writer
  /// An expectation of expect_peer: its endpoints, and since when none of them has been matched.
  struct Expectation {
    std::string peer;
    std::vector<std::weak_ptr<EndpointEvents>> endpoints;
    std::uint64_t unmatched_since_ns = 0;
  };
  std::vector<Expectation> expectations_;  ///< under endpoints_mutex_
  std::uint64_t peer_bound_ns_ = 0;        ///< the current bound; 0 until the first watch
  std::atomic<std::uint64_t> rejoins_{0};
  std::atomic<std::uint64_t> qos_mismatches_{0};
  std::atomic<std::uint64_t> undecodable_samples_{0};
  std::atomic<std::uint64_t> lost_samples_{0};
  std::atomic<std::uint64_t> rejected_samples_{0};
};

/// How long an expected peer may stay unmatched under DDS-Security before the participant is made again, s, and the
/// longest such wait after tries (each doubles it). A secured handshake takes about 10 ms per pair on one host and
/// seconds on a loaded 2-core machine with a dozen participants; 10 s is past every one that completed in tests.
inline constexpr double kPeerBound_s = 10.0;
inline constexpr double kMaxPeerBound_s = 60.0;

/// Domain id from the environment variable BSN_DOMAIN, else 0. Throws std::invalid_argument naming the value when
/// BSN_DOMAIN is set but not a domain id in 0..232 (never a fallback to 0: that may be another system's domain).
int default_domain();

}  // namespace bsn::dds
