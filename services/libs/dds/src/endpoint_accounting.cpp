// What a reader counts of the samples it takes: undecodable ones, losses per writer, an owner's repeated instants.
#include <algorithm>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>

#include "bsn/dds/participant.hpp"
#include "bsn/logging/log.hpp"

namespace bsn::dds {

using namespace eprosima::fastdds::dds;

void count_undecodable(EndpointEvents& events) {
  if (!events.undecodable_counter) return;
  if ((*events.undecodable_counter)++ == 0)
    logging::log_warn("topic ", events.topic, ": a sample that does not decode as this topic's type was dropped ",
                      "(a writer with another definition of the type?); counted on bsn/status as undecodable_samples");
}

bool new_instant_for_owner(EndpointEvents& events, const SampleInfo& info, const DataReader* reader,
                           std::uint64_t instant_ns) {
  if (reader->get_qos().ownership().kind != EXCLUSIVE_OWNERSHIP_QOS) return true;
  const eprosima::fastrtps::rtps::GUID_t& writer = info.sample_identity.writer_guid();
  auto [it, fresh] = events.delivered.try_emplace(info.instance_handle, EndpointEvents::Delivered{writer, instant_ns});
  if (fresh) return true;
  if (it->second.writer != writer && instant_ns <= it->second.instant_ns) {
    if (events.superseded++ == 0)
      logging::log_info("topic ", events.topic, ": a new owner's sample of an instant its previous owner already ",
                        "delivered was dropped (a standby taking over behind its primary); no instant comes twice");
    return false;
  }
  it->second = {writer, instant_ns};
  return true;
}

void count_lost(EndpointEvents& events, const SampleInfo& info, const DataReader* reader) {
  const std::int64_t seq = info.sample_identity.sequence_number().to64long();
  const auto& writer = info.sample_identity.writer_guid();
  bool first = false;
  if (events.last_writer_sequence == nullptr || events.last_writer != writer) {
    auto [it, inserted] = events.last_sequence.try_emplace(writer, seq);
    events.last_writer = writer;
    events.last_writer_sequence = &it->second;  // std::map entries stay where they are
    first = inserted;
  }
  std::int64_t& last = *events.last_writer_sequence;
  if (reader->get_qos().ownership().kind == EXCLUSIVE_OWNERSHIP_QOS) {
    auto [owner, fresh] = events.owner_of_instance.try_emplace(info.instance_handle, writer);
    if (!fresh && owner->second != writer) {  // ownership passed: what it wrote meanwhile went to the owner's
      owner->second = writer;
      last = seq;
      return;
    }
  }
  if (first) return;  // samples before a reader matches are not its losses
  if (seq > last + 1) {
    const auto lost = static_cast<std::uint64_t>(seq - last - 1);
    if (events.lost_counter && (*events.lost_counter += lost) == lost)
      logging::log_warn("topic ", events.topic, ": ", lost, " sample(s) of a writer never arrived (a DDS resource ",
                        "limit, a full history or the network); counted on bsn/status as dds_lost_samples");
  }
  last = std::max(last, seq);
}

}  // namespace bsn::dds
