// Serialises Fast DDS 2.9.1's matching of a discovered participant's DDS-Security builtin endpoints.
//
// When discovery first reports a participant, Fast DDS 2.9.1's SecurityManager matches the participant's stateless
// message writer and reader (the channel of the authentication handshake) with ours, and after authentication its
// volatile message secure endpoints (the key exchange). It builds each remote endpoint in one scratch proxy object per
// kind that the SecurityManager keeps as a member, fills it and hands it by reference to the local reader or writer,
// all without a lock. Discovery runs on two receive threads (the multicast and the unicast metatraffic port), and
// participants starting together announce themselves on both, so two participants are matched at once. The local
// reader first takes its own mutex, which the unicast thread holds while it computes a handshake message (milliseconds
// on an idle CPU, more under load), and only then reads the scratch object: meanwhile the other thread has refilled it
// with the next participant. The first participant's endpoint is then never matched: its handshake messages are
// dropped as coming from an unknown writer (or ours never go to it), and nothing matches it again, because the
// SecurityManager does so only when discovery first reports it, which its periodic announcements never do again. The
// handshake never completes, and nothing is logged. Fast DDS 2.9.2 builds each proxy in its own object.
//
// bsn's programs define these two member functions themselves: the library calls them through its procedure linkage
// table, so the dynamic linker binds its calls to the program's definitions, which take a lock and forward to the
// library's own (found with dlsym(RTLD_NEXT)). Each call that finds another in progress is counted and logged: that
// pair would have raced. BSN_DDS_MATCH_GUARD=off forwards without the lock (to observe the fault), still counting.
#include "builtin_match_guard.hpp"

#include <dlfcn.h>
#include <fastdds/rtps/builtin/data/ParticipantProxyData.h>
#include <fastrtps/config.h>

#include <atomic>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <sstream>
#include <string>

#include "bsn/logging/log.hpp"

namespace bsn::dds {
namespace {

using eprosima::fastrtps::rtps::GuidPrefix_t;
using eprosima::fastrtps::rtps::ParticipantProxyData;

// A non-virtual member function of the Itanium C++ ABI: `this` comes first.
using MatchFunction = void (*)(void* security_manager, const ParticipantProxyData& remote);

std::atomic<std::uint64_t> overlaps{0};

bool guard_enabled() {
  static const bool enabled = [] {
    const char* value = std::getenv("BSN_DDS_MATCH_GUARD");
    return value == nullptr || std::strcmp(value, "off") != 0;
  }();
  return enabled;
}

class Guard {
 public:
  Guard(const char* symbol, const char* what) : symbol_(symbol), what_(what) {}

  void call(void* security_manager, const ParticipantProxyData& remote) {
    MatchFunction original = library_function();
    if (original == nullptr) return;  // already reported: without it no handshake with anyone could start
    const GuidPrefix_t prefix = remote.m_guid.guidPrefix;
    GuidPrefix_t other;
    bool overlapping = false;
    {
      std::lock_guard lock(state_mutex_);
      if (in_progress_ > 0) {
        overlapping = true;
        other = current_;
      }
      ++in_progress_;
      current_ = prefix;
    }
    if (overlapping) {
      ++overlaps;
      std::ostringstream text;
      text << "Fast DDS matched the " << what_ << " of participant " << prefix << " while those of " << other
           << " were being matched"
           << (guard_enabled() ? "; serialised"
                               : " (BSN_DDS_MATCH_GUARD=off: not serialised, the handshake with one of them may "
                                 "never complete)");
      // Serialised, the pair is harmless: said for the record, not as a warning.
      logging::log(guard_enabled() ? logging::LogLevel::kInfo : logging::LogLevel::kWarn, text.str());
    }
    {
      std::unique_lock lock(call_mutex_, std::defer_lock);
      if (guard_enabled()) lock.lock();
      original(security_manager, remote);
    }
    std::lock_guard lock(state_mutex_);
    --in_progress_;
  }

 private:
  MatchFunction library_function() {
    std::call_once(resolved_, [this] {
      // RTLD_NEXT: the next definition after this program's, libfastrtps's own.
      void* address = dlsym(RTLD_NEXT, symbol_);
      if (address == nullptr) {
        logging::log_error("cannot find ", symbol_, " in the Fast DDS library (", FASTRTPS_VERSION_STR,
                           "): no DDS-Security handshake can start");
        return;
      }
      static_assert(sizeof(MatchFunction) == sizeof(void*));
      std::memcpy(&original_, &address, sizeof(address));
    });
    return original_;
  }

  const char* symbol_;
  const char* what_;
  std::once_flag resolved_;
  MatchFunction original_ = nullptr;
  std::mutex call_mutex_;   ///< held during the library's call
  std::mutex state_mutex_;  ///< guards the two fields below
  int in_progress_ = 0;
  GuidPrefix_t current_;
};

constexpr const char* kMatchBuiltinEndpoints =
    "_ZN8eprosima8fastrtps4rtps8security15SecurityManager23match_builtin_endpointsERKNS1_20ParticipantProxyDataE";
constexpr const char* kMatchKeyExchangeEndpoints =
    "_ZN8eprosima8fastrtps4rtps8security15SecurityManager36match_builtin_key_exchange_endpointsERKNS1_"
    "20ParticipantProxyDataE";

Guard& handshake_guard() {
  static Guard guard(kMatchBuiltinEndpoints, "handshake endpoints");
  return guard;
}

Guard& key_exchange_guard() {
  static Guard guard(kMatchKeyExchangeEndpoints, "key exchange endpoints");
  return guard;
}

}  // namespace

std::uint64_t builtin_match_overlaps() { return overlaps.load(); }

}  // namespace bsn::dds

// The definitions that take the library's place: declared under the mangled names of
// SecurityManager::match_builtin_endpoints and SecurityManager::match_builtin_key_exchange_endpoints (the class
// itself is private to Fast DDS). Two locks, not one: the key exchange endpoints are matched while the stateless
// message reader's mutex is held, which the other call waits for.
void bsn_match_builtin_endpoints(void* security_manager, const eprosima::fastrtps::rtps::ParticipantProxyData& remote) __asm__(
    "_ZN8eprosima8fastrtps4rtps8security15SecurityManager23match_builtin_endpointsERKNS1_20ParticipantProxyDataE");
void bsn_match_builtin_key_exchange_endpoints(void* security_manager, const eprosima::fastrtps::rtps::ParticipantProxyData& remote) __asm__(
    "_ZN8eprosima8fastrtps4rtps8security15SecurityManager36match_builtin_key_exchange_endpointsERKNS1_"
    "20ParticipantProxyDataE");

void bsn_match_builtin_endpoints(void* security_manager, const eprosima::fastrtps::rtps::ParticipantProxyData& remote) {
  bsn::dds::handshake_guard().call(security_manager, remote);
}

void bsn_match_builtin_key_exchange_endpoints(void* security_manager,
                                              const eprosima::fastrtps::rtps::ParticipantProxyData& remote) {
  bsn::dds::key_exchange_guard().call(security_manager, remote);
}
