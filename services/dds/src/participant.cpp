#include "bsn/dds/participant.hpp"

#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <filesystem>
#include <mutex>
#include <stdexcept>

#include "bsn/logging/log.hpp"

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

class WriterEvents final : public DataWriterListener {
 public:
  explicit WriterEvents(std::shared_ptr<EndpointEvents> ev) : events_(std::move(ev)) {}
  void on_publication_matched(DataWriter*, const PublicationMatchedStatus& s) override {
    events_->matched.store(s.current_count);
  }
  void on_offered_incompatible_qos(DataWriter*, const OfferedIncompatibleQosStatus& s) override {
    if (events_->mismatch_counter) ++*events_->mismatch_counter;
    logging::log_warn("topic ", events_->topic, ": a reader requests QoS this writer does not offer (",
                      qos_policy_name(s.last_policy_id), "); that reader receives nothing from us. bsn readers use ",
                      "BEST_EFFORT for streaming topics and match any writer.");
  }

 private:
  std::shared_ptr<EndpointEvents> events_;
};

class ReaderEvents final : public DataReaderListener {
 public:
  explicit ReaderEvents(std::shared_ptr<EndpointEvents> ev) : events_(std::move(ev)) {}
  void on_data_available(DataReader* reader) override {
    std::lock_guard lock(events_->callback_mutex);
    if (events_->on_data) events_->on_data(reader);
  }
  void on_subscription_matched(DataReader*, const SubscriptionMatchedStatus& s) override {
    events_->matched.store(s.current_count);
  }
  void on_liveliness_changed(DataReader*, const LivelinessChangedStatus& s) override {
    events_->alive_writers.store(s.alive_count);
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
    if (events_->mismatch_counter) ++*events_->mismatch_counter;
    logging::log_warn("topic ", events_->topic, ": a writer offers QoS incompatible with this reader (",
                      qos_policy_name(s.last_policy_id), "); nothing from it will arrive. A BEST_EFFORT writer never ",
                      "matches a RELIABLE reader.");
  }

 private:
  std::shared_ptr<EndpointEvents> events_;
};

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

DomainParticipantQos participant_qos(const std::string& name) {
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
  const char* security = std::getenv("BSN_SECURITY_DIR");
  if (security && *security) {
    add_security(qos, security);
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

}  // namespace

void count_undecodable(EndpointEvents& events) {
  if (!events.undecodable_counter) return;
  if ((*events.undecodable_counter)++ == 0)
    logging::log_warn("topic ", events.topic, ": a sample that does not decode as this topic's type was dropped ",
                      "(a writer with another definition of the type?); counted on bsn/status as undecodable_samples");
}

void count_lost(EndpointEvents& events, const SampleInfo& info) {
  const std::int64_t seq = info.sample_identity.sequence_number().to64long();
  auto [it, first] = events.last_sequence.try_emplace(info.sample_identity.writer_guid(), seq);
  if (first) return;  // samples before a reader matches are not its losses
  if (seq > it->second + 1) {
    const auto lost = static_cast<std::uint64_t>(seq - it->second - 1);
    if (events.lost_counter && (*events.lost_counter += lost) == lost)
      logging::log_warn("topic ", events.topic, ": ", lost, " sample(s) of a writer never arrived (a DDS resource ",
                        "limit, a full history or the network); counted on bsn/status as dds_lost_samples");
  }
  it->second = std::max(it->second, seq);
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

Participant::Participant(const Options& options) {
  if (options.domain < 0 || options.domain > 232) {
    throw std::runtime_error("DDS domain id " + std::to_string(options.domain) + " is outside 0..232");
  }
  participant_ = DomainParticipantFactory::get_instance()->create_participant(static_cast<DomainId_t>(options.domain),
                                                                              participant_qos(options.name));
  if (!participant_)
    throw std::runtime_error("cannot create a DDS participant in domain " + std::to_string(options.domain));
  // The participant's defaults, not PUBLISHER_QOS_DEFAULT: an XML default profile applies to them.
  publisher_ = participant_->create_publisher(participant_->get_default_publisher_qos());
  subscriber_ = participant_->create_subscriber(participant_->get_default_subscriber_qos());
  if (!publisher_ || !subscriber_) throw std::runtime_error("cannot create a DDS publisher or subscriber");
}

Participant::~Participant() {
  if (!participant_) return;
  // Stop callbacks before the listeners they call are destroyed.
  for (DataReader* r : readers_) r->set_listener(nullptr);
  participant_->delete_contained_entities();
  DomainParticipantFactory::get_instance()->delete_participant(participant_);
}

eprosima::fastdds::dds::Topic* Participant::find_or_create_topic(const std::string& name, TypeSupport type) {
  std::lock_guard lock(mutex_);
  if (auto it = topics_.find(name); it != topics_.end()) return it->second;
  if (participant_->find_type(type.get_type_name()) == nullptr) type.register_type(participant_);
  eprosima::fastdds::dds::Topic* t = participant_->create_topic(name, type.get_type_name(), TOPIC_QOS_DEFAULT);
  if (!t) throw std::runtime_error("cannot create DDS topic " + name);
  topics_[name] = t;
  return t;
}

// Writers and readers start from their publisher's or subscriber's default QoS (the XML default profile, if
// any) with bsn's delivery of the topic on top; a profile named after the topic replaces both.
DataWriter* Participant::create_writer(eprosima::fastdds::dds::Topic* topic, TopicQos delivery,
                                       std::shared_ptr<EndpointEvents> events) {
  DataWriterQos qos = publisher_->get_default_datawriter_qos();
  if (publisher_->get_datawriter_qos_from_profile(topic->get_name(), qos) != ReturnCode_t::RETCODE_OK)
    qos = writer_qos(delivery, publisher_->get_default_datawriter_qos());
  events->topic = topic->get_name();
  events->mismatch_counter = &qos_mismatches_;
  auto listener = std::make_unique<WriterEvents>(events);
  DataWriter* w = publisher_->create_datawriter(topic, qos, listener.get(), StatusMask::all());
  if (!w) throw std::runtime_error("cannot create a DDS writer on " + topic->get_name() + refused_by_permissions());
  std::lock_guard lock(mutex_);
  writer_listeners_.push_back(std::move(listener));
  return w;
}

void Participant::create_reader(eprosima::fastdds::dds::Topic* topic, TopicQos delivery,
                                std::shared_ptr<EndpointEvents> events) {
  DataReaderQos qos = subscriber_->get_default_datareader_qos();
  if (subscriber_->get_datareader_qos_from_profile(topic->get_name(), qos) != ReturnCode_t::RETCODE_OK)
    qos = reader_qos(delivery, subscriber_->get_default_datareader_qos());
  events->topic = topic->get_name();
  events->mismatch_counter = &qos_mismatches_;
  events->undecodable_counter = &undecodable_samples_;
  events->lost_counter = &lost_samples_;
  events->rejected_counter = &rejected_samples_;
  auto listener = std::make_unique<ReaderEvents>(events);
  DataReader* r = subscriber_->create_datareader(topic, qos, listener.get(), StatusMask::all());
  if (!r) throw std::runtime_error("cannot create a DDS reader on " + topic->get_name() + refused_by_permissions());
  std::lock_guard lock(mutex_);
  reader_listeners_.push_back(std::move(listener));
  readers_.push_back(r);
}

}  // namespace bsn::dds
