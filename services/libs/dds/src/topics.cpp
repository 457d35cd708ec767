#include "bsn/dds/topics.hpp"

#include <fastdds/dds/core/policy/QosPolicies.hpp>
#include <utility>

namespace bsn::dds {

using namespace eprosima::fastdds::dds;

namespace {

// Every bsn topic is keyed (one instance per node, segment, joint or process). The Fast DDS default resource
// limits (max_instances 10, max_samples 5000) silently drop the 11th instance, so a body of more than 10 nodes
// loses segments. LENGTH_UNLIMITED does not work either in Fast DDS 2.9.1: a KEEP_LAST history is sized
// depth * max_instances, which goes negative, and then nothing is delivered, without any error.
constexpr int kMaxInstances = 4096;

void set_limits(eprosima::fastdds::dds::ResourceLimitsQosPolicy& r, int depth) {
  r.max_instances = kMaxInstances;
  r.max_samples_per_instance = depth;
  r.max_samples = kMaxInstances * depth;  // consistent: max_samples >= max_instances * max_samples_per_instance
}

// Payload buffers sized to the samples that arrive, kept for reuse. Fast DDS's default
// (PREALLOCATED_WITH_REALLOC) preallocates each buffer at the type's largest serialised size, which for a type
// with unbounded sequences is the generator's guess of 100 elements each: 2.9 MB per bsn/status buffer. Each
// buffer's pages are touched only as samples land in it, so a long-running reader's RSS crept up for minutes
// (bsn record: +0.12 MB/s after levelling at 156 MB) towards the hundreds of MB reserved.
constexpr auto kPayloadMemory = eprosima::fastrtps::rtps::DYNAMIC_REUSABLE_MEMORY_MODE;

struct Delivery {
  ReliabilityQosPolicyKind reliability;
  DurabilityQosPolicyKind durability;
  int writer_depth;
  int reader_depth;
};

Delivery delivery(TopicQos kind) {
  switch (kind) {
    case TopicQos::kSensorData:
      return {BEST_EFFORT_RELIABILITY_QOS, VOLATILE_DURABILITY_QOS, 8, 64};
    case TopicQos::kEstimate:
      return {RELIABLE_RELIABILITY_QOS, VOLATILE_DURABILITY_QOS, 1, 64};
    case TopicQos::kEstimateBestEffort:
      return {BEST_EFFORT_RELIABILITY_QOS, VOLATILE_DURABILITY_QOS, 1, 64};
    case TopicQos::kLatched:
      return {RELIABLE_RELIABILITY_QOS, TRANSIENT_LOCAL_DURABILITY_QOS, 1, 8};
    case TopicQos::kCommand:
      return {RELIABLE_RELIABILITY_QOS, VOLATILE_DURABILITY_QOS, 16, 16};
    case TopicQos::kProgress:
      return {RELIABLE_RELIABILITY_QOS, VOLATILE_DURABILITY_QOS, 4, 16};
    case TopicQos::kRos2:
      return {RELIABLE_RELIABILITY_QOS, VOLATILE_DURABILITY_QOS, 10, 64};
  }
  return {BEST_EFFORT_RELIABILITY_QOS, VOLATILE_DURABILITY_QOS, 1, 1};
}

}  // namespace

DataWriterQos writer_qos(TopicQos kind, DataWriterQos q) {
  const Delivery d = delivery(kind);
  q.reliability().kind = d.reliability;
  q.durability().kind = d.durability;
  q.history().kind = KEEP_LAST_HISTORY_QOS;
  q.history().depth = d.writer_depth;
  set_limits(q.resource_limits(), d.writer_depth);
  q.endpoint().history_memory_policy = kPayloadMemory;
  // Data is written from the caller's thread: lowest latency, and no extra thread per writer.
  q.publish_mode().kind = SYNCHRONOUS_PUBLISH_MODE;
  if (kind == TopicQos::kProgress) {
    // Asserted by the participant (AUTOMATIC) every quarter lease: a killed process stops asserting it.
    q.liveliness().kind = AUTOMATIC_LIVELINESS_QOS;
    q.liveliness().lease_duration = eprosima::fastrtps::Duration_t(kProgressLivelinessLease_s);
    q.liveliness().announcement_period = eprosima::fastrtps::Duration_t(kProgressLivelinessLease_s / 4.0);
  }
  return q;
}

DataReaderQos reader_qos(TopicQos kind, DataReaderQos q) {
  const Delivery d = delivery(kind);
  // A best-effort reader matches writers of either kind; only latched and command topics need reliability.
  const bool reliable = kind == TopicQos::kLatched || kind == TopicQos::kCommand || kind == TopicQos::kProgress;
  q.reliability().kind = reliable ? RELIABLE_RELIABILITY_QOS : BEST_EFFORT_RELIABILITY_QOS;
  q.durability().kind = d.durability;
  q.history().kind = KEEP_LAST_HISTORY_QOS;
  q.history().depth = d.reader_depth;
  set_limits(q.resource_limits(), d.reader_depth);
  q.endpoint().history_memory_policy = kPayloadMemory;
  if (kind == TopicQos::kProgress) {
    // Fast DDS tracks a writer's liveliness with the reader's requested lease (infinite by default: never lost),
    // so the reader asks for one: 1.5 x the writer's (it must be >= the offered 1 s to match).
    q.liveliness().kind = AUTOMATIC_LIVELINESS_QOS;
    q.liveliness().lease_duration = eprosima::fastrtps::Duration_t(1.5 * kProgressLivelinessLease_s);
  }
  return q;
}

const char* qos_policy_name(unsigned id) {
  // The policies whose mismatch stops two endpoints from matching.
  static constexpr std::pair<QosPolicyId_t, const char*> kNames[] = {
      {DURABILITY_QOS_POLICY_ID, "DURABILITY"},
      {DEADLINE_QOS_POLICY_ID, "DEADLINE"},
      {LATENCYBUDGET_QOS_POLICY_ID, "LATENCY_BUDGET"},
      {OWNERSHIP_QOS_POLICY_ID, "OWNERSHIP"},
      {LIVELINESS_QOS_POLICY_ID, "LIVELINESS"},
      {RELIABILITY_QOS_POLICY_ID, "RELIABILITY"},
      {DESTINATIONORDER_QOS_POLICY_ID, "DESTINATION_ORDER"},
      {PRESENTATION_QOS_POLICY_ID, "PRESENTATION"},
      {DATAREPRESENTATION_QOS_POLICY_ID, "DATA_REPRESENTATION"}};
  for (const auto& [policy, name] : kNames)
    if (policy == id) return name;
  return "policy";
}

}  // namespace bsn::dds
