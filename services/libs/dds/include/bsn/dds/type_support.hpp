// The type support through which every bsn reader and writer gets its IDL types: fastddsgen's generated code with
// the failure paths that bytes from a foreign writer can reach closed.
//
// fastddsgen's code throws out of two places that run on a DDS thread, where an exception ends the process:
// - getKey() serialises the key into a buffer sized for a 255-character string, so a key string of 256 characters
//   or more (legal for an unbounded `string` in the IDL, and sent by e.g. Cyclone DDS) throws
//   NotEnoughMemoryException;
// - deserialize() catches NotEnoughMemoryException only: a bool byte other than 0 or 1 throws BadParamException.
// Guarded<PubSub> computes an oversized key's instance handle itself (the MD5 of its CDR key serialisation, as the
// DDS-RTPS specification says for keys longer than 16 bytes, so it agrees with other vendors) and turns any
// decoding failure into a `false` return plus a flag for the reader (Fast DDS 2.9 ignores deserialize's result
// and would hand out a half-decoded sample as valid).
//
// Every bsn key is an unbounded string, so every instance handle is an MD5, computed for each sample written and
// each sample received (about a twentieth of a sample's whole cost in the fusion service): Guarded<PubSub> keeps
// the handles of the keys it has seen, per thread, and computes an MD5 only for a key new to the thread.
#pragma once

#include <fastcdr/Cdr.h>
#include <fastcdr/FastBuffer.h>
#include <fastdds/rtps/common/InstanceHandle.h>
#include <fastdds/rtps/common/SerializedPayload.h>
#include <fastrtps/utils/md5.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace bsn::dds {

/// True if this thread's last Guarded<>::deserialize failed. A reader checks it right after take_next_sample()
/// (which deserialises on the caller's thread) and drops the sample as undecodable.
bool last_deserialize_failed();

namespace detail {
void set_last_deserialize_failed(bool failed);

/// The instance handles (MD5s) of the CDR key serialisations one thread has seen, for one type. Bounded: a writer
/// that invents keys costs MD5s, never memory.
class KeyHandleCache {
 public:
  static constexpr std::size_t kMaxKeys = 8192;
  static constexpr std::size_t kBufferBytes = 1024;  ///< longer key serialisations are not cached
  /// The MD5 of `key_bytes` into `handle`, computed only if this cache does not hold it.
  void handle_of(std::string_view key_bytes, eprosima::fastrtps::rtps::InstanceHandle_t* handle);
  char* buffer() { return buffer_.data(); }
  std::size_t size() const { return handles_.size(); }

 private:
  struct Hash {
    using is_transparent = void;
    std::size_t operator()(std::string_view s) const { return std::hash<std::string_view>{}(s); }
  };
  std::unordered_map<std::string, std::array<std::uint8_t, 16>, Hash, std::equal_to<>> handles_;
  std::array<char, kBufferBytes> buffer_{};
};
}  // namespace detail

/// fastddsgen's PubSub type support for one IDL type, hardened against any bytes (see the file comment).
template <class PubSub>
class Guarded final : public PubSub {
 public:
  using type = typename PubSub::type;

  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override {
    bool ok = false;
    try {
      ok = PubSub::deserialize(payload, data);
    } catch (...) {  // BadParamException, and anything else fastcdr or an allocation may throw
      ok = false;
    }
    // A failed decode leaves some fields from these bytes and some from the last sample: clear them all.
    if (!ok) *static_cast<type*>(data) = type();
    detail::set_last_deserialize_failed(!ok);
    return ok;
  }

  bool serialize(void* data, eprosima::fastrtps::rtps::SerializedPayload_t* payload) override {
    try {
      return PubSub::serialize(data, payload);
    } catch (...) {
      return false;  // a bsn writer refuses the sample (counted as a write failure) instead of ending the process
    }
  }

  bool getKey(void* data, eprosima::fastrtps::rtps::InstanceHandle_t* handle, bool force_md5 = false) override {
    if (this->m_isGetKeyDefined && (force_md5 || type::getKeyMaxCdrSerializedSize() > 16))
      return cached_md5_key(*static_cast<const type*>(data), handle);
    try {
      return PubSub::getKey(data, handle, force_md5);
    } catch (...) {
      return md5_key(*static_cast<const type*>(data), handle);
    }
  }

  /// md5_key through this thread's cache of the handles of keys already seen: the same handle, one MD5 per key.
  static bool cached_md5_key(const type& sample, eprosima::fastrtps::rtps::InstanceHandle_t* handle) {
    thread_local detail::KeyHandleCache cache;
    try {
      eprosima::fastcdr::FastBuffer buffer(cache.buffer(), detail::KeyHandleCache::kBufferBytes);
      eprosima::fastcdr::Cdr ser(buffer, eprosima::fastcdr::Cdr::BIG_ENDIANNESS);
      sample.serializeKey(ser);
      cache.handle_of({cache.buffer(), ser.getSerializedDataLength()}, handle);
      return true;
    } catch (...) {
      return md5_key(sample, handle);  // a key longer than the buffer
    }
  }

  /// The instance handle of `sample` as the specification defines it for a key longer than 16 bytes: the MD5 of
  /// the key's big-endian CDR serialisation. Used when the key is too long for fastddsgen's fixed key buffer.
  static bool md5_key(const type& sample, eprosima::fastrtps::rtps::InstanceHandle_t* handle) {
    try {
      eprosima::fastcdr::FastBuffer buffer;  // grows as needed
      eprosima::fastcdr::Cdr ser(buffer, eprosima::fastcdr::Cdr::BIG_ENDIANNESS);
      sample.serializeKey(ser);
      MD5 md5;
      md5.init();
      md5.update(buffer.getBuffer(), static_cast<unsigned int>(ser.getSerializedDataLength()));
      md5.finalize();
      for (std::size_t i = 0; i < 16; ++i) handle->value[i] = md5.digest[i];
      return true;
    } catch (...) {
      return false;
    }
  }
};

}  // namespace bsn::dds
