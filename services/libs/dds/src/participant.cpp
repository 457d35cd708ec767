#include "bsn/dds/participant.hpp"

#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fnmatch.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/log/Log.hpp>
#include <fastdds/dds/topic/ContentFilteredTopic.hpp>
#include <fastdds/dds/topic/IContentFilter.hpp>
#include <fastdds/dds/topic/IContentFilterFactory.hpp>
#include <filesystem>
#include <mutex>
#include <sstream>
#include <stdexcept>

#include "bsn/dds/conversions.hpp"
#include "bsn/logging/log.hpp"
#include "participant_discovery.hpp"

namespace bsn::dds {

using namespace eprosima::fastdds::dds;

namespace {

constexpr std::uint32_t kUdpReceiveBufferBytes = 4u * 1024u * 1024u;

const char* rejected_reason_name(SampleRejectedStatusKind kind) {
  switch (kind) {
    case REJECTED_BY_INSTANCES_LIMIT:
      return "max_instances";
    case REJECTED_BY_SAMPLES_LIMIT:
      return "max_samples";
    case REJECTED_BY_SAMPLES_PER_INSTANCE_LIMIT:
      return "max_samples_per_instance";
    default:
      return "limit";
  }
}

// True if this incompatible-QoS event includes an ownership mismatch (the counts of `policies` only grow).
bool ownership_mismatch(const QosPolicyCountSeq& policies, std::uint32_t& seen) {
  const std::uint32_t count = policies[OWNERSHIP_QOS_POLICY_ID].count;
  const bool changed = count != seen;
  seen = count;
  return changed;
}

class WriterEvents final : public DataWriterListener {
 public:
  WriterEvents(std::shared_ptr<EndpointEvents> ev, bool exclusive) : events_(std::move(ev)), exclusive_(exclusive) {}
  void on_publication_matched(DataWriter*, const PublicationMatchedStatus& s) override {
    events_->matched.store(s.current_count);
  }
  void on_offered_incompatible_qos(DataWriter*, const OfferedIncompatibleQosStatus& s) override {
    // Every bsn reader of an estimate topic comes as a SHARED and an EXCLUSIVE twin, so one of the two never
    // matches this writer: no mismatch. A SHARED reader of another client gets nothing from an EXCLUSIVE writer:
    // said once.
    if (ownership_mismatch(s.policies, ownership_seen_)) {
      if (exclusive_ && !said_shared_reader_) {
        said_shared_reader_ = true;
        logging::log_info("topic ", events_->topic, ": this writer has EXCLUSIVE ownership (a primary or standby ",
                          "fusion), so readers with SHARED ownership (DDS's default) receive nothing from it; ",
                          "bsn's own readers match both kinds, other clients set EXCLUSIVE (docs/topics.md)");
      }
      return;
    }
    if (events_->mismatch_counter) ++*events_->mismatch_counter;
    logging::log_warn("topic ", events_->topic, ": a reader requests QoS this writer does not offer (",
                      qos_policy_name(s.last_policy_id), "); that reader receives nothing from us. bsn readers use ",
                      "BEST_EFFORT for streaming topics and match any writer.");
  }

 private:
  std::shared_ptr<EndpointEvents> events_;
  bool exclusive_;
  std::uint32_t ownership_seen_ = 0;
  bool said_shared_reader_ = false;
};

class ReaderEvents final : public DataReaderListener {
 public:
  /// `twin`: one of the SHARED and EXCLUSIVE pair of an estimate topic (`exclusive`: the latter).
  ReaderEvents(std::shared_ptr<EndpointEvents> ev, bool twin, bool exclusive)
      : events_(std::move(ev)), twin_(twin), exclusive_(exclusive) {}
  void on_data_available(DataReader* reader) override {
    std::lock_guard lock(events_->callback_mutex);
    if (events_->on_data) events_->on_data(reader);
  }
  void on_subscription_matched(DataReader*, const SubscriptionMatchedStatus& s) override {
    (exclusive_ ? events_->matched_exclusive : events_->matched).store(s.current_count);
  }
  void on_liveliness_changed(DataReader*, const LivelinessChangedStatus& s) override {
    (exclusive_ ? events_->alive_writers_exclusive : events_->alive_writers).store(s.alive_count);
    if (s.not_alive_count_change > 0) events_->writers_lost += static_cast<std::uint64_t>(s.not_alive_count_change);
  }
  // Losses are counted from the writers' sequence numbers (count_lost), which covers these statuses too: they are
  // only logged, once.
  void on_sample_rejected(DataReader*, const SampleRejectedStatus& s) override {
    if (events_->rejected_counter) *events_->rejected_counter += s.total_count_change;
    if (s.total_count == s.total_count_change)
      logging::log_warn("topic ", events_->topic, ": DDS dropped sample(s) at this reader's resource limit (",
                        rejected_reason_name(s.last_reason), "); counted on bsn/status as dds_lost_samples");
  }
  void on_sample_lost(DataReader*, const SampleLostStatus& s) override {
    if (s.total_count == s.total_count_change)
      logging::log_warn("topic ", events_->topic, ": DDS lost sample(s) on the way to this reader; counted on ",
                        "bsn/status as dds_lost_samples");
  }
  void on_requested_incompatible_qos(DataReader*, const RequestedIncompatibleQosStatus& s) override {
    // A writer of the other ownership kind matches this reader's twin.
    if (ownership_mismatch(s.policies, ownership_seen_) && twin_) return;
    if (events_->mismatch_counter) ++*events_->mismatch_counter;
    logging::log_warn("topic ", events_->topic, ": a writer offers QoS incompatible with this reader (",
                      qos_policy_name(s.last_policy_id), "); nothing from it will arrive. A BEST_EFFORT writer never ",
                      "matches a RELIABLE reader.");
  }

 private:
  std::shared_ptr<EndpointEvents> events_;
  bool twin_;
  bool exclusive_;
  std::uint32_t ownership_seen_ = 0;
};

// Fast DDS's own log lines (security handshake errors, XML parser errors, ...). Its default consumer prints them
// on stdout, which is the data stream of `bsn echo --format csv|json` and `bsn eval --json`: they go through bsn's
// log instead (stderr, with the process's role), escaped like every text from the network.
class MiddlewareLog final : public LogConsumer {
 public:
  void Consume(const Log::Entry& entry) override {
    const logging::LogLevel level = entry.kind == Log::Kind::Error     ? logging::LogLevel::kError
                                    : entry.kind == Log::Kind::Warning ? logging::LogLevel::kWarn
                                                                       : logging::LogLevel::kDebug;
    const char* category = entry.context.category != nullptr ? entry.context.category : "";
    std::string_view message = entry.message;
    while (!message.empty() && (message.back() == '\n' || message.back() == ' ')) message.remove_suffix(1);
    logging::log_line(
        level, "Fast DDS [" + logging::printable(category, 64) + "] " + logging::printable(message, kMaxMessageChars));
  }

 private:
  static constexpr std::size_t kMaxMessageChars = 1000;
};

void route_middleware_log() {
  static std::once_flag routed;
  std::call_once(routed, [] {
    Log::ClearConsumers();
    Log::RegisterConsumer(std::make_unique<MiddlewareLog>());
    // Fast DDS logs only its errors by default; its warnings (e.g. of the security handshake) on request.
    if (const char* level = std::getenv("BSN_DDS_LOG"); level && std::strcmp(level, "warning") == 0)
      Log::SetVerbosity(Log::Warning);
  });
}

// DDS-Security from an identity folder of deploy/security/make-pki.sh: PKI-DH authentication, access control
// by the signed governance and permissions, AES-GCM-GMAC encryption.
void add_security(DomainParticipantQos& qos, const std::string& dir) {
  auto file_uri = [&dir](const char* file) {
    const std::filesystem::path path = std::filesystem::absolute(std::filesystem::path(dir) / file);
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) {
      throw std::runtime_error("security folder " + dir + " has no " + file +
                               " (make one with deploy/security/make-pki.sh)");
    }
    return "file://" + path.string();
  };
  auto& properties = qos.properties().properties();
  auto set = [&properties](const char* key, std::string value) { properties.emplace_back(key, std::move(value)); };
  set("dds.sec.auth.plugin", "builtin.PKI-DH");
  set("dds.sec.auth.builtin.PKI-DH.identity_ca", file_uri("ca.pem"));
  set("dds.sec.auth.builtin.PKI-DH.identity_certificate", file_uri("cert.pem"));
  set("dds.sec.auth.builtin.PKI-DH.private_key", file_uri("key.pem"));
  set("dds.sec.access.plugin", "builtin.Access-Permissions");
  set("dds.sec.access.builtin.Access-Permissions.permissions_ca", file_uri("ca.pem"));
  set("dds.sec.access.builtin.Access-Permissions.governance", file_uri("governance.p7s"));
  set("dds.sec.access.builtin.Access-Permissions.permissions", file_uri("permissions.p7s"));
  set("dds.sec.crypto.plugin", "builtin.AES-GCM-GMAC");
}

// `security_dir`: the identity folder (BSN_SECURITY_DIR when the Participant was made), "" for none.
DomainParticipantQos participant_qos(const std::string& name, const std::string& security_dir) {
  route_middleware_log();
  // Start from the factory default so an XML profile (FASTRTPS_DEFAULT_PROFILES_FILE) still applies; the
  // factory reads the profiles lazily, so load them before asking for the default.
  // load_profiles() ignores a file that does not parse; loading it explicitly first reports that (and the
  // factory then skips the file it has already parsed).
  const char* profile = std::getenv("FASTRTPS_DEFAULT_PROFILES_FILE");
  if (profile && *profile &&
      DomainParticipantFactory::get_instance()->load_XML_profiles_file(profile) != ReturnCode_t::RETCODE_OK) {
    throw std::runtime_error(std::string("cannot load the Fast DDS profiles file ") + profile +
                             " (see the XMLPARSER errors above)");
  }
  DomainParticipantFactory::get_instance()->load_profiles();
  DomainParticipantQos qos = DomainParticipantFactory::get_instance()->get_default_participant_qos();
  qos.name(name);
  if (!security_dir.empty()) {
    add_security(qos, security_dir);
    // The participant's name travels in plaintext in discovery (SPDP is not encrypted, even with DDS-Security):
    // no node id or role in it.
    qos.name("bsn");
  } else {
    static std::once_flag said_open;
    std::call_once(said_open, [] {
      logging::log_info(
          "DDS-Security is off: any participant on this network can read and publish bsn topics "
          "(see README, deployment: --security DIR)");
    });
  }
  if (profile == nullptr || *profile == '\0') {
    // UDPv4 only, unless a profile says otherwise. Fast DDS 2.9.1 sends every BEST_EFFORT sample over both
    // shared memory and UDP (fixed in 2.9.2), and shared memory leaves files in /dev/shm when a process is
    // killed. On loopback UDP costs a few microseconds, far below a 10 ms sample period.
    qos.transport().use_builtin_transports = false;
    auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
    // Synchronised sensors arrive as one burst per tick; Linux's default 208 KiB socket buffer overflows at
    // ~150 samples per burst. The kernel caps this request at net.core.rmem_max (see README, deployment).
    udp->receiveBufferSize = kUdpReceiveBufferBytes;
    qos.transport().user_transports.push_back(udp);
  }
  return qos;
}

/// The likely reason an endpoint could not be created when DDS-Security is on.
std::string refused_by_permissions() {
  const char* security = std::getenv("BSN_SECURITY_DIR");
  if (!security || !*security) return "";
  return std::string(": the permissions of the identity in ") + security +
         " may not allow it (its role's topics: README, deployment)";
}

bool is_secured() {
  const char* security = std::getenv("BSN_SECURITY_DIR");
  return security && *security;
}

// Topics whose writers carry one node's samples: under DDS-Security each goes in its node's partition.
bool is_per_node(const std::string& topic) { return topic == kRawTopic.name; }

// The estimates a primary and its standby both write, arbitrated by ownership.
bool is_owned_estimate(const std::string& topic) {
  return topic == kOrientationTopic.name || topic == kJointAnglesTopic.name;
}

// EXCLUSIVE ownership with the lease of kOwnedEstimateLease_s, MANUAL_BY_TOPIC: each sample renews its writer's
// liveliness, and Writer::assert_liveliness between samples. Not AUTOMATIC: a Fast DDS 2.9.1 reader renews every
// AUTOMATIC writer it tracks whenever any one of them is heard from (LivelinessManager::assert_liveliness), so a
// killed primary's lease never lapsed while its standby kept writing, and ownership never passed.
void make_exclusive(OwnershipQosPolicy& ownership, LivelinessQosPolicy& liveliness) {
  ownership.kind = EXCLUSIVE_OWNERSHIP_QOS;
  liveliness.kind = MANUAL_BY_TOPIC_LIVELINESS_QOS;
  liveliness.lease_duration = eprosima::fastrtps::Duration_t(kOwnedEstimateLease_s);
}

}  // namespace

bool is_per_subject(const std::string& topic) { return is_owned_estimate(topic) || topic == kStatusTopic.name; }

bool Participant::writer_may_write_node(const eprosima::fastrtps::rtps::GUID_t& writer, const std::string& node) const {
  if (!discovery_) return true;
  std::lock_guard lock(discovery_->mutex);
  const auto it = discovery_->partitions.find(writer);
  if (it == discovery_->partitions.end()) return false;
  // A partition is a pattern in DDS; access control allowed this writer's only if its permissions match it.
  for (const std::string& partition : it->second)
    if (fnmatch(partition.c_str(), node.c_str(), 0) == 0) return true;
  return false;
}

// The content filters of a participant's admitting readers: one filter class per participant, named after its GUID
// so no other participant has a factory of that name and no writer filters for these readers on its side (a
// writer applies a reader's filter only when it has the reader's filter class itself). The filter expression is
// the admission's index.
struct Participant::AdmissionFilters final : IContentFilterFactory {
  struct Filter final : IContentFilter {
    PayloadAdmission admit;
    bool evaluate(const SerializedPayload& payload, const FilterSampleInfo&, const GUID_t&) const override {
      return admit(payload);
    }
  };
  std::string class_name;
  std::mutex mutex;
  std::vector<std::unique_ptr<Filter>> filters;

  ReturnCode_t create_content_filter(const char*, const char*, const TopicDataType*, const char* expression,
                                     const ParameterSeq&, IContentFilter*& instance) override {
    std::lock_guard lock(mutex);
    char* end = nullptr;
    const unsigned long index = std::strtoul(expression, &end, 10);
    if (end == expression || *end != '\0' || index >= filters.size()) return ReturnCode_t::RETCODE_BAD_PARAMETER;
    instance = filters[index].get();
    return ReturnCode_t::RETCODE_OK;
  }
  ReturnCode_t delete_content_filter(const char*, IContentFilter*) override { return ReturnCode_t::RETCODE_OK; }
};

std::size_t Participant::add_admission(PayloadAdmission admit) {
  std::lock_guard lock(mutex_);
  if (!admission_) admission_ = std::make_unique<AdmissionFilters>();
  std::lock_guard filters_lock(admission_->mutex);
  admission_->filters.push_back(std::make_unique<AdmissionFilters::Filter>());
  admission_->filters.back()->admit = std::move(admit);
  return admission_->filters.size() - 1;
}

TopicDescription* Participant::admitting_topic(eprosima::fastdds::dds::Topic* topic, std::size_t index) {
  std::lock_guard lock(mutex_);
  if (admission_->class_name.empty()) {  // the first admitting reader of this DDS participant
    std::ostringstream name;
    name << "bsn_admission_" << participant_->guid().guidPrefix;
    admission_->class_name = name.str();
    if (participant_->register_content_filter_factory(admission_->class_name.c_str(), admission_.get()) !=
        ReturnCode_t::RETCODE_OK)
      throw std::runtime_error("cannot register the admission filter of topic " + topic->get_name());
  }
  ContentFilteredTopic* filtered =
      participant_->create_contentfilteredtopic(topic->get_name() + "#admission" + std::to_string(index), topic,
                                                std::to_string(index), {}, admission_->class_name.c_str());
  if (!filtered) throw std::runtime_error("cannot create the admission filter of topic " + topic->get_name());
  return filtered;
}

int default_domain() {
  if (const char* env = std::getenv("BSN_DOMAIN")) {
    char* end = nullptr;
    errno = 0;
    const long v = std::strtol(env, &end, 10);
    if (end != env && *end == '\0' && errno == 0 && v >= 0 && v <= 232) return static_cast<int>(v);
    // No fallback: domain 0 may be another system's, which this process would then disturb.
    throw std::invalid_argument("BSN_DOMAIN='" + logging::printable(env) +
                                "' is not a DDS domain id in 0..232 (unset it, or fix it, or give --domain D)");
  }
  return 0;
}

Participant::Participant(const Options& options) : options_(options) {
  if (options.domain < 0 || options.domain > 232) {
    throw std::runtime_error("DDS domain id " + std::to_string(options.domain) + " is outside 0..232");
  }
  secured_ = is_secured();
  subject_ = options.subject;
  if (secured_) {
    discovery_ = std::make_unique<Discovery>();
    discovery_->security_dir = std::getenv("BSN_SECURITY_DIR");
  }
  open();
}

Participant::~Participant() { close(); }

void Participant::open() {
  participant_ = DomainParticipantFactory::get_instance()->create_participant(
      static_cast<DomainId_t>(options_.domain),
      participant_qos(options_.name, discovery_ ? discovery_->security_dir : ""), discovery_.get(), StatusMask::none());
  if (!participant_)
    throw std::runtime_error("cannot create a DDS participant in domain " + std::to_string(options_.domain));
  // The participant's defaults, not PUBLISHER_QOS_DEFAULT: an XML default profile applies to them.
  publisher_ = participant_->create_publisher(participant_->get_default_publisher_qos());
  subscriber_ = participant_->create_subscriber(participant_->get_default_subscriber_qos());
  if (!publisher_ || !subscriber_) throw std::runtime_error("cannot create a DDS publisher or subscriber");
}

void Participant::close() {
  if (!participant_) return;
  // Stop callbacks before the listeners they call are destroyed.
  for (DataReader* r : readers_) r->set_listener(nullptr);
  participant_->set_listener(nullptr);
  participant_->delete_contained_entities();
  DomainParticipantFactory::get_instance()->delete_participant(participant_);
  participant_ = nullptr;
  publisher_ = nullptr;
  subscriber_ = nullptr;
  std::lock_guard lock(mutex_);
  topics_.clear();
  partition_publishers_.clear();
  partition_subscribers_.clear();
  any_partition_subscriber_ = nullptr;
  readers_.clear();
  writer_listeners_.clear();
  reader_listeners_.clear();
  if (admission_) admission_->class_name.clear();
}

eprosima::fastdds::dds::Topic* Participant::find_or_create_topic(const std::string& name, TypeSupport type) {
  std::lock_guard lock(mutex_);
  if (auto it = topics_.find(name); it != topics_.end()) return it->second;
  types_.try_emplace(name, type);
  if (participant_->find_type(type.get_type_name()) == nullptr) type.register_type(participant_);
  eprosima::fastdds::dds::Topic* t = participant_->create_topic(name, type.get_type_name(), TOPIC_QOS_DEFAULT);
  if (!t) throw std::runtime_error("cannot create DDS topic " + name);
  topics_[name] = t;
  return t;
}

eprosima::fastdds::dds::Topic* Participant::topic_named(const std::string& name) {
  TypeSupport type;
  {
    std::lock_guard lock(mutex_);
    type = types_.at(name);
  }
  return find_or_create_topic(name, type);
}

Subscriber* Participant::subscriber_in(const std::string& partition) {
  if (auto it = partition_subscribers_.find(partition); it != partition_subscribers_.end()) return it->second;
  SubscriberQos qos = participant_->get_default_subscriber_qos();
  qos.partition().push_back(partition.c_str());
  Subscriber* s = participant_->create_subscriber(qos);
  if (!s) throw std::runtime_error("cannot create a DDS subscriber in partition " + partition);
  partition_subscribers_[partition] = s;
  return s;
}

Publisher* Participant::publisher_in(const std::string& partition) {
  if (auto it = partition_publishers_.find(partition); it != partition_publishers_.end()) return it->second;
  PublisherQos qos = participant_->get_default_publisher_qos();
  qos.partition().push_back(partition.c_str());
  Publisher* p = participant_->create_publisher(qos);
  if (!p) throw std::runtime_error("cannot create a DDS publisher in partition " + partition);
  partition_publishers_[partition] = p;
  return p;
}

// Writers and readers start from their publisher's or subscriber's default QoS (the XML default profile, if
// any) with bsn's delivery of the topic on top; a profile named after the topic replaces both.
DataWriter* Participant::create_writer(const WriterRecipe& recipe) {
  eprosima::fastdds::dds::Topic* topic = topic_named(recipe.topic);
  const TopicQos& delivery = recipe.delivery;
  const std::string& node = recipe.node;
  const WriterScope& scope = recipe.scope;
  const std::shared_ptr<EndpointEvents>& events = recipe.events;
  Publisher* publisher = publisher_;
  const std::string subject = scope.subject.value_or(subject_);
  if (secured_ && is_per_node(topic->get_name())) {
    if (node.empty()) throw std::runtime_error("a secured writer on " + topic->get_name() + " needs its node id");
    std::lock_guard lock(mutex_);
    publisher = publisher_in(node);
  } else if (!subject.empty() && is_per_subject(topic->get_name())) {
    std::lock_guard lock(mutex_);
    publisher = publisher_in(subject);
  }
  DataWriterQos qos = publisher->get_default_datawriter_qos();
  if (publisher->get_datawriter_qos_from_profile(topic->get_name(), qos) != ReturnCode_t::RETCODE_OK)
    qos = writer_qos(delivery, publisher->get_default_datawriter_qos());
  const bool exclusive = scope.ownership_strength && is_owned_estimate(topic->get_name());
  if (exclusive) {
    make_exclusive(qos.ownership(), qos.liveliness());
    qos.ownership_strength().value = *scope.ownership_strength;
  }
  events->topic = topic->get_name();
  events->mismatch_counter = &qos_mismatches_;
  auto listener = std::make_unique<WriterEvents>(events, exclusive);
  DataWriter* w = publisher->create_datawriter(topic, qos, listener.get(), StatusMask::all());
  if (!w) {
    throw std::runtime_error("cannot create a DDS writer on " + topic->get_name() +
                             (publisher != publisher_ ? " for node " + node : "") + refused_by_permissions());
  }
  std::lock_guard lock(mutex_);
  writer_listeners_.push_back(std::move(listener));
  return w;
}

void Participant::create_reader(const ReaderRecipe& recipe) {
  eprosima::fastdds::dds::Topic* source = topic_named(recipe.topic);
  TopicDescription* topic = recipe.admission ? admitting_topic(source, *recipe.admission) : source;
  const std::string& name = recipe.topic;
  const TopicQos& delivery = recipe.delivery;
  const std::optional<std::string>& subject = recipe.subject;
  const std::shared_ptr<EndpointEvents>& events = recipe.events;
  Subscriber* subscriber = subscriber_;
  const std::string partition = subject.value_or(subject_);
  if (secured_ && is_per_node(name)) {
    // Secured writers of bsn/raw are each in their node's partition: read them all ("*" also matches the default).
    std::lock_guard lock(mutex_);
    if (!any_partition_subscriber_) {
      SubscriberQos sq = participant_->get_default_subscriber_qos();
      sq.partition().push_back("*");
      any_partition_subscriber_ = participant_->create_subscriber(sq);
      if (!any_partition_subscriber_) throw std::runtime_error("cannot create a DDS subscriber of every partition");
    }
    subscriber = any_partition_subscriber_;
  } else if (!partition.empty() && is_per_subject(name)) {
    std::lock_guard lock(mutex_);
    subscriber = subscriber_in(partition);
  }
  events->topic = name;
  events->mismatch_counter = &qos_mismatches_;
  events->undecodable_counter = &undecodable_samples_;
  events->lost_counter = &lost_samples_;
  events->rejected_counter = &rejected_samples_;
  const bool twin = is_owned_estimate(name);
  create_one_reader(subscriber, topic, name, delivery, events, false);
  if (twin) create_one_reader(subscriber, topic, name, delivery, events, true);
}

void Participant::create_one_reader(Subscriber* subscriber, TopicDescription* topic, const std::string& name,
                                    TopicQos delivery, std::shared_ptr<EndpointEvents> events, bool exclusive) {
  DataReaderQos qos = subscriber->get_default_datareader_qos();
  if (subscriber->get_datareader_qos_from_profile(name, qos) != ReturnCode_t::RETCODE_OK)
    qos = reader_qos(delivery, subscriber->get_default_datareader_qos());
  if (exclusive) make_exclusive(qos.ownership(), qos.liveliness());
  auto listener = std::make_unique<ReaderEvents>(events, is_owned_estimate(name), exclusive);
  DataReader* r = subscriber->create_datareader(topic, qos, listener.get(), StatusMask::all());
  if (!r) throw std::runtime_error("cannot create a DDS reader on " + name + refused_by_permissions());
  std::lock_guard lock(mutex_);
  reader_listeners_.push_back(std::move(listener));
  readers_.push_back(r);
}

}  // namespace bsn::dds
