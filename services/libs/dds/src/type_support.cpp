#include "bsn/dds/type_support.hpp"

namespace bsn::dds {
namespace {
// Per thread: Fast DDS deserialises a taken sample on the thread that calls take_next_sample().
thread_local bool g_last_deserialize_failed = false;
}  // namespace

bool last_deserialize_failed() { return g_last_deserialize_failed; }

namespace detail {
void set_last_deserialize_failed(bool failed) { g_last_deserialize_failed = failed; }

void KeyHandleCache::handle_of(std::string_view key_bytes, eprosima::fastrtps::rtps::InstanceHandle_t* handle) {
  auto it = handles_.find(key_bytes);
  if (it == handles_.end()) {
    if (handles_.size() >= kMaxKeys) handles_.clear();
    MD5 md5;
    md5.init();
    md5.update(key_bytes.data(), static_cast<unsigned int>(key_bytes.size()));
    md5.finalize();
    std::array<std::uint8_t, 16> digest{};
    for (std::size_t i = 0; i < 16; ++i) digest[i] = md5.digest[i];
    it = handles_.emplace(std::string(key_bytes), digest).first;
  }
  for (std::size_t i = 0; i < 16; ++i) handle->value[i] = it->second[i];
}
}  // namespace detail

}  // namespace bsn::dds
