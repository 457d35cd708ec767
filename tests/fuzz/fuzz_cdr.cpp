// CDR decoding of every IDL type exactly as a bsn reader decodes what any writer on the domain sends: the first
// byte picks the type, the rest is the serialized payload (encapsulation header included).
// Invariants: nothing escapes Guarded<>'s deserialize (no exception, no crash); a failed decode raises the reader's
// flag and leaves a default sample; a decoded sample has an instance handle (whatever its key's length) and
// serialises again.
#include <fastdds/rtps/common/SerializedPayload.h>

#include <cstring>

#include "bsn/dds/type_support.hpp"
#include "bsn_idl/bsnPubSubTypes.h"
#include "fuzz_check.hpp"

namespace {

using eprosima::fastrtps::rtps::InstanceHandle_t;
using eprosima::fastrtps::rtps::SerializedPayload_t;

template <class PubSub>
void decode(const std::uint8_t* data, std::size_t size) {
  bsn::dds::Guarded<PubSub> type;
  SerializedPayload_t payload(static_cast<std::uint32_t>(size + 1));  // never a null buffer, as in a real reader
  if (size > 0) std::memcpy(payload.data, data, size);
  payload.length = static_cast<std::uint32_t>(size);
  typename PubSub::type sample;
  const bool ok = type.deserialize(&payload, &sample);
  BSN_FUZZ_CHECK(ok == !bsn::dds::last_deserialize_failed(), "the reader's flag disagrees with deserialize()");
  if (!ok) {
    BSN_FUZZ_CHECK(sample == typename PubSub::type(), "a failed decode left fields of the bytes in the sample");
    return;
  }
  InstanceHandle_t handle;
  BSN_FUZZ_CHECK(type.getKey(&sample, &handle, false), "a decoded sample has no instance handle");
  SerializedPayload_t out(type.getSerializedSizeProvider(&sample)());
  BSN_FUZZ_CHECK(type.serialize(&sample, &out), "a decoded sample does not serialise again");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::uint8_t which = data[0] % 6;
  ++data;
  --size;
  switch (which) {
    case 0:
      decode<bsn::RawSamplePubSubType>(data, size);
      break;
    case 1:
      decode<bsn::OrientationPubSubType>(data, size);
      break;
    case 2:
      decode<bsn::JointAnglesPubSubType>(data, size);
      break;
    case 3:
      decode<bsn::StatusPubSubType>(data, size);
      break;
    case 4:
      decode<bsn::CalibrationRequestPubSubType>(data, size);
      break;
    default:
      decode<bsn::CalibrationResultPubSubType>(data, size);
      break;
  }
  return 0;
}
