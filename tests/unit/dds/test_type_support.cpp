// Guarded<PubSub>: what fastddsgen's type support throws on (a key too long for its buffer, a bool byte that is
// neither 0 nor 1) and what it half-decodes (a truncated payload) become a handle, or a refused sample with the
// reader's flag raised and nothing of the bytes left in it.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "bsn/dds/type_support.hpp"
#include "bsn_idl/bsnPubSubTypes.h"

namespace bsn::dds {
namespace {

using eprosima::fastrtps::rtps::InstanceHandle_t;
using eprosima::fastrtps::rtps::SerializedPayload_t;

template <class PubSub>
SerializedPayload_t serialized(Guarded<PubSub>& type, typename PubSub::type sample) {
  SerializedPayload_t payload(type.getSerializedSizeProvider(&sample)());
  EXPECT_TRUE(type.serialize(&sample, &payload));
  return payload;
}

TEST(GuardedTypeSupport, AKeyLongerThanTheGeneratedBufferGetsTheSpecificationsHandle) {
  Guarded<bsn::RawSamplePubSubType> type;
  bsn::RawSample sample;
  // A short key: the generated code's handle (MD5, the key's maximum size exceeds 16 bytes) and ours agree.
  sample.node_id("thigh_l");
  InstanceHandle_t generated, ours;
  ASSERT_TRUE(type.getKey(&sample, &generated));
  ASSERT_TRUE(Guarded<bsn::RawSamplePubSubType>::md5_key(sample, &ours));
  EXPECT_EQ(generated, ours);
  // 256 and 300 characters: the generated code throws; ours gives distinct handles.
  sample.node_id(std::string(256, 'x'));
  InstanceHandle_t h256, h300;
  EXPECT_THROW(type.bsn::RawSamplePubSubType::getKey(&sample, &h256), std::exception);
  ASSERT_TRUE(type.getKey(&sample, &h256));
  sample.node_id(std::string(300, 'x'));
  ASSERT_TRUE(type.getKey(&sample, &h300));
  EXPECT_NE(h256, h300);
  EXPECT_NE(h256, generated);
}

// The handles come from a per-thread cache after a key's first sample: each must still be the generated code's own
// (which other Fast DDS participants compute), whether the key is new, seen before or seen before the cache was
// emptied at its bound.
template <class PubSub, class SetKey>
void expect_cached_handles_are_the_generated_ones(SetKey set_key) {
  Guarded<PubSub> type;
  typename PubSub::type sample;
  const std::size_t keys = detail::KeyHandleCache::kMaxKeys + 100;
  std::vector<InstanceHandle_t> first(keys);
  for (int pass = 0; pass < 2; ++pass) {
    for (std::size_t i = 0; i < keys; ++i) {
      set_key(sample, "k" + std::to_string(i) + std::string(i % 40, 'x'));
      InstanceHandle_t generated, cached;
      ASSERT_TRUE(type.PubSub::getKey(&sample, &generated));
      ASSERT_TRUE(type.getKey(&sample, &cached));
      ASSERT_EQ(cached, generated) << "key " << i << ", pass " << pass;
      if (pass == 0) first[i] = cached;
      ASSERT_EQ(cached, first[i]);
    }
  }
  // Distinct keys, distinct handles.
  EXPECT_NE(first[0], first[1]);
}

TEST(GuardedTypeSupport, CachedInstanceHandlesAreTheGeneratedCodesForEveryKeyedTopic) {
  expect_cached_handles_are_the_generated_ones<bsn::RawSamplePubSubType>(
      [](bsn::RawSample& s, const std::string& k) { s.node_id(k); });
  expect_cached_handles_are_the_generated_ones<bsn::OrientationPubSubType>(
      [](bsn::Orientation& s, const std::string& k) {
        s.segment(k);
        s.node_id("not part of the key");
      });
  expect_cached_handles_are_the_generated_ones<bsn::JointAnglesPubSubType>(
      [](bsn::JointAngles& s, const std::string& k) { s.joint(k); });
  expect_cached_handles_are_the_generated_ones<bsn::StatusPubSubType>(
      [](bsn::Status& s, const std::string& k) { s.process_id(k); });
}

TEST(GuardedTypeSupport, ABoolThatIsNeitherZeroNorOneIsRefusedNotThrown) {
  Guarded<bsn::CalibrationResultPubSubType> type;
  bsn::CalibrationResult result;
  result.node_id("a");
  result.success(true);
  result.message("fit");
  SerializedPayload_t payload = serialized(type, result);
  // After the 4-byte header: node_id "a" (length 4 + 2 bytes), request_id "" (aligned to 8, 4 + 1 bytes), kind
  // (aligned to 16, 4 bytes); the bool is the byte at 20.
  const std::size_t at = 4 + 20;
  ASSERT_EQ(payload.data[at], 1);
  payload.data[at] = 2;
  bsn::CalibrationResult decoded;
  decoded.message("stale content");
  EXPECT_THROW(type.bsn::CalibrationResultPubSubType::deserialize(&payload, &decoded), std::exception);
  EXPECT_FALSE(type.deserialize(&payload, &decoded));
  EXPECT_TRUE(last_deserialize_failed());
  EXPECT_EQ(decoded, bsn::CalibrationResult());
}

TEST(GuardedTypeSupport, ATruncatedPayloadIsRefusedAndLeavesNothingOfItsBytes) {
  Guarded<bsn::RawSamplePubSubType> type;
  bsn::RawSample sample;
  sample.node_id("pelvis");
  sample.seq(42);
  SerializedPayload_t payload = serialized(type, sample);
  payload.length = 24;  // header, node_id, and part of the timestamp
  bsn::RawSample decoded;
  EXPECT_FALSE(type.deserialize(&payload, &decoded));
  EXPECT_TRUE(last_deserialize_failed());
  EXPECT_EQ(decoded, bsn::RawSample());
  // The next good one clears the flag.
  payload.length = serialized(type, sample).length;
  EXPECT_TRUE(type.deserialize(&payload, &decoded));
  EXPECT_FALSE(last_deserialize_failed());
  EXPECT_EQ(decoded.node_id(), "pelvis");
  EXPECT_EQ(decoded.seq(), 42u);
}

/// A seed of the CDR fuzz corpus as a reader receives it: the first byte picks the type (fuzz_cdr.cpp), the rest
/// is the payload.
SerializedPayload_t corpus_payload(const std::string& name) {
  std::ifstream in(std::string(BSN_FUZZ_CORPUS_DIR) + "/cdr/" + name, std::ios::binary);
  const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_GT(bytes.size(), 1u) << name;
  SerializedPayload_t payload(static_cast<std::uint32_t>(bytes.size()));
  if (bytes.size() > 1) std::memcpy(payload.data, bytes.data() + 1, bytes.size() - 1);
  payload.length = static_cast<std::uint32_t>(bytes.size() > 1 ? bytes.size() - 1 : 0);
  return payload;
}

TEST(GuardedTypeSupport, TheAlignmentFieldsRoundTripAndTheCorpusSeedsDecodeToThem) {
  Guarded<bsn::CalibrationResultPubSubType> type;
  bsn::CalibrationResult r;
  r.node_id("shank_l");
  r.kind(bsn::CALIBRATION_SEGMENT_ALIGNMENT);
  r.segment("shank_l");
  r.sensor_to_segment({0.5, 0.5, -0.5, 0.5});
  r.alignment_source("pose+hinge thigh_l-shank_l");
  r.axis_observability(0.052);
  SerializedPayload_t payload = serialized(type, r);
  bsn::CalibrationResult decoded;
  ASSERT_TRUE(type.deserialize(&payload, &decoded));
  EXPECT_EQ(decoded, r);

  // The seeds hold what the appended fields carry (so the fuzzer starts from payloads that reach them).
  SerializedPayload_t result_seed = corpus_payload("result_alignment");
  ASSERT_TRUE(type.deserialize(&result_seed, &decoded));
  EXPECT_EQ(decoded.kind(), bsn::CALIBRATION_SEGMENT_ALIGNMENT);
  EXPECT_EQ(decoded.segment(), "shank_l");
  EXPECT_EQ(decoded.sensor_to_segment(), (std::array<double, 4>{0.5, 0.5, -0.5, 0.5}));
  EXPECT_EQ(decoded.alignment_source(), "pose+hinge thigh_l-shank_l");
  EXPECT_DOUBLE_EQ(decoded.axis_observability(), 0.052);
  Guarded<bsn::CalibrationRequestPubSubType> request_type;
  bsn::CalibrationRequest request;
  SerializedPayload_t request_seed = corpus_payload("request_alignment");
  ASSERT_TRUE(request_type.deserialize(&request_seed, &request));
  EXPECT_EQ(request.kind(), bsn::CALIBRATION_SEGMENT_ALIGNMENT);
  EXPECT_EQ(request.node_id(), "*");
  EXPECT_NE(request.body().find("joint: knee_l"), std::string::npos);
  EXPECT_DOUBLE_EQ(request.pose_s(), 3.0);
}

}  // namespace
}  // namespace bsn::dds
