// A participant's endpoints made again from their recipes, and the watch on the peers each one expects: a secured
// participant whose handshake never completes says so and starts over (docs/deployment.md).
#include <algorithm>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <stdexcept>

#include "bsn/dds/participant.hpp"
#include "bsn/logging/log.hpp"
#include "builtin_match_guard.hpp"
#include "participant_discovery.hpp"

namespace bsn::dds {

using namespace eprosima::fastdds::dds;

std::shared_ptr<EndpointHandle> Participant::add_writer(const std::string& topic, TopicQos delivery,
                                                        std::shared_ptr<EndpointEvents> events, const std::string& node,
                                                        const WriterScope& scope) {
  std::lock_guard lock(endpoints_mutex_);
  auto handle = std::make_shared<EndpointHandle>();
  handle->guard = &writer_guard_;
  WriterRecipe recipe{handle, std::move(events), topic, delivery, node, scope};
  handle->writer = create_writer(recipe);
  writer_recipes_.push_back(std::move(recipe));
  return handle;
}

std::shared_ptr<EndpointHandle> Participant::add_reader(const std::string& topic, std::optional<std::size_t> admission,
                                                        TopicQos delivery, std::shared_ptr<EndpointEvents> events,
                                                        const std::optional<std::string>& subject) {
  std::lock_guard lock(endpoints_mutex_);
  auto handle = std::make_shared<EndpointHandle>();
  handle->guard = &writer_guard_;
  ReaderRecipe recipe{handle, std::move(events), topic, admission, delivery, subject};
  create_reader(recipe);
  reader_recipes_.push_back(std::move(recipe));
  return handle;
}

bool Participant::writer_is_volatile(const EndpointHandle& handle) {
  return handle.writer.load()->get_qos().durability().kind == VOLATILE_DURABILITY_QOS;
}

void Participant::expect(const std::shared_ptr<EndpointEvents>& events, const std::string& peer) {
  if (!secured_) return;
  std::lock_guard lock(endpoints_mutex_);
  auto it = std::find_if(expectations_.begin(), expectations_.end(), [&](const auto& e) { return e.peer == peer; });
  if (it == expectations_.end()) it = expectations_.insert(expectations_.end(), Expectation{peer, {}, monotonic_ns()});
  it->endpoints.push_back(events);
}

bool Participant::watch_peers() {
  if (!secured_) return false;
  std::unique_lock lock(endpoints_mutex_);
  const std::uint64_t now = monotonic_ns();
  if (peer_bound_ns_ == 0) peer_bound_ns_ = static_cast<std::uint64_t>(kPeerBound_s * 1e9);
  const Expectation* unmet = nullptr;
  bool all_met = true;
  for (Expectation& e : expectations_) {
    bool matched = false, live = false;
    for (const auto& weak : e.endpoints) {
      if (const auto ev = weak.lock()) {
        live = true;
        matched = matched || ev->matched.load() > 0 || ev->matched_exclusive.load() > 0;
      }
    }
    if (!live || matched) {
      e.unmatched_since_ns = now;
      continue;
    }
    all_met = false;
    if (now - e.unmatched_since_ns >= peer_bound_ns_ && unmet == nullptr) unmet = &e;
  }
  if (all_met) peer_bound_ns_ = static_cast<std::uint64_t>(kPeerBound_s * 1e9);
  if (unmet == nullptr) return false;
  // On a loaded machine with many participants the handshakes take seconds each; while some still finish, a new
  // participant would only start them all again (every process at once, a storm that never settles).
  if (discovery_->progressing(peer_bound_ns_ / 4)) return false;
  const std::uint64_t rejoin = ++rejoins_;
  logging::log_error("no ", unmet->peer, " matched in ", peer_bound_ns_ / 1'000'000'000ull, " s (",
                     discovery_->unfinished_handshakes(peer_bound_ns_ / 2), "; ", builtin_match_overlaps(),
                     " concurrent match(es) of security endpoints): none runs, or a DDS-Security handshake never "
                     "completed (a Fast DDS 2.9.1 fault). Making a ",
                     "new participant (", rejoin, "; counted on bsn/status as participant_rejoins)");
  recreate();
  peer_bound_ns_ = std::min(2 * peer_bound_ns_, static_cast<std::uint64_t>(kMaxPeerBound_s * 1e9));
  for (Expectation& e : expectations_) e.unmatched_since_ns = monotonic_ns();
  return true;
}

void Participant::recreate() {
  std::lock_guard lock(endpoints_mutex_);
  {
    // No write uses a DataWriter of the old participant once this block ends.
    std::unique_lock guard(writer_guard_);
    for (const WriterRecipe& r : writer_recipes_)
      if (const auto h = r.handle.lock()) h->writer = nullptr;
  }
  std::ostringstream was;
  was << participant_->guid().guidPrefix;
  close();
  discovery_->clear();
  auto forget = [](EndpointEvents& ev) {
    ev.matched = 0;
    ev.matched_exclusive = 0;
    ev.alive_writers = 0;
    ev.alive_writers_exclusive = 0;
    std::lock_guard callback_lock(ev.callback_mutex);
    // The remote writers keep their sequence numbers; what they wrote while unmatched was never this reader's.
    ev.last_sequence.clear();
    ev.last_writer_sequence = nullptr;
    ev.owner_of_instance.clear();
  };
  open();
  std::erase_if(writer_recipes_, [](const WriterRecipe& r) { return r.handle.expired(); });
  std::erase_if(reader_recipes_, [](const ReaderRecipe& r) { return r.handle.expired(); });
  std::vector<DataWriter*> writers;
  for (const WriterRecipe& r : writer_recipes_) {
    forget(*r.events);
    writers.push_back(create_writer(r));
  }
  for (const ReaderRecipe& r : reader_recipes_) {
    forget(*r.events);
    create_reader(r);
  }
  {
    std::unique_lock guard(writer_guard_);
    for (std::size_t i = 0; i < writer_recipes_.size(); ++i)
      if (const auto h = writer_recipes_[i].handle.lock()) h->writer = writers[i];
  }
  std::ostringstream is;
  is << participant_->guid().guidPrefix;
  logging::log_info("the new DDS participant is ", is.str(), " (was ", was.str(), "), with ", writer_recipes_.size(),
                    " writer(s) and ", reader_recipes_.size(), " reader(s)");
}

}  // namespace bsn::dds
