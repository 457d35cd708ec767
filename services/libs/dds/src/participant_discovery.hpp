// The participant's listener (participant.cpp and participant_rejoin.cpp share it): the partitions of each
// discovered bsn/raw writer, and the handshakes of the discovered participants.
#pragma once

#include <cstdint>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <map>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include "bsn/dds/conversions.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/dds/topics.hpp"

namespace bsn::dds {

using namespace eprosima::fastdds::dds;

// Remembers the partitions each discovered bsn/raw writer had when it was first discovered (before Fast DDS pairs
// it with a reader: PDP::addWriterProxyData calls the listener first), and which discovered participants have not
// finished their authentication handshake with this one: the evidence watch_peers names.
struct Participant::Discovery final : DomainParticipantListener {
  using GuidPrefix = eprosima::fastrtps::rtps::GuidPrefix_t;
  mutable std::mutex mutex;
  std::map<eprosima::fastrtps::rtps::GUID_t, std::vector<std::string>> partitions;
  struct Handshake {
    std::uint64_t discovered_ns = 0;
    bool authorised = false;
  };
  std::map<GuidPrefix, Handshake> handshakes;
  std::uint64_t refused = 0;             ///< participants whose authentication failed
  std::uint64_t last_authorised_ns = 0;  ///< when the last handshake finished
  /// The identity folder, kept for the participant's re-creation (the environment may have changed since).
  std::string security_dir;

  void on_participant_discovery(DomainParticipant*,
                                eprosima::fastrtps::rtps::ParticipantDiscoveryInfo&& info) override {
    using Info = eprosima::fastrtps::rtps::ParticipantDiscoveryInfo;
    std::lock_guard lock(mutex);
    const GuidPrefix& prefix = info.info.m_guid.guidPrefix;
    if (info.status == Info::DISCOVERED_PARTICIPANT)
      handshakes.try_emplace(prefix, Handshake{monotonic_ns(), false});
    else if (info.status == Info::REMOVED_PARTICIPANT || info.status == Info::DROPPED_PARTICIPANT)
      handshakes.erase(prefix);
  }
  void onParticipantAuthentication(DomainParticipant*,
                                   eprosima::fastrtps::rtps::ParticipantAuthenticationInfo&& info) override {
    using Info = eprosima::fastrtps::rtps::ParticipantAuthenticationInfo;
    std::lock_guard lock(mutex);
    if (info.status == Info::AUTHORIZED_PARTICIPANT) {
      handshakes.try_emplace(info.guid.guidPrefix, Handshake{monotonic_ns(), false}).first->second.authorised = true;
      last_authorised_ns = monotonic_ns();
    } else {
      ++refused;
      handshakes.erase(info.guid.guidPrefix);
    }
  }
  void on_publisher_discovery(DomainParticipant*, eprosima::fastrtps::rtps::WriterDiscoveryInfo&& info) override {
    using Info = eprosima::fastrtps::rtps::WriterDiscoveryInfo;
    if (info.info.topicName().to_string() != kRawTopic.name) return;  // per-node partitions: bsn/raw only
    std::lock_guard lock(mutex);
    if (info.status == Info::DISCOVERED_WRITER)
      partitions.try_emplace(info.info.guid(), info.info.m_qos.m_partition.getNames());
    else if (info.status == Info::REMOVED_WRITER)
      partitions.erase(info.info.guid());
  }
  /// "N discovered participant(s) without a finished handshake (GUID prefixes ...), M refused".
  std::string unfinished_handshakes(std::uint64_t older_than_ns) const {
    std::lock_guard lock(mutex);
    const std::uint64_t now = monotonic_ns();
    std::ostringstream out;
    std::size_t n = 0, authorised = 0;
    for (const auto& [prefix, h] : handshakes) {
      if (h.authorised) {
        ++authorised;
        continue;
      }
      if (now - h.discovered_ns < older_than_ns) continue;
      out << (n++ == 0 ? " " : ", ") << prefix;
    }
    std::ostringstream text;
    text << authorised << " participant(s) authenticated, " << n << " discovered " << older_than_ns / 1'000'000'000ull
         << "+ s ago without a finished handshake" << (n > 0 ? ":" : "") << out.str();
    if (refused > 0) text << ", " << refused << " refused";
    return text.str();
  }
  /// True if a handshake finished within the last `window_ns`: the handshakes progress, only slowly.
  bool progressing(std::uint64_t window_ns) const {
    std::lock_guard lock(mutex);
    return last_authorised_ns != 0 && monotonic_ns() - last_authorised_ns < window_ns;
  }
  void clear() {
    std::lock_guard lock(mutex);
    partitions.clear();
    handshakes.clear();
  }
};

}  // namespace bsn::dds
