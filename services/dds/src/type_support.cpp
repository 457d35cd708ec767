#include "bsn/dds/type_support.hpp"

namespace bsn::dds {
namespace {
// Per thread: Fast DDS deserialises a taken sample on the thread that calls take_next_sample().
thread_local bool g_last_deserialize_failed = false;
}  // namespace

bool last_deserialize_failed() { return g_last_deserialize_failed; }

namespace detail {
void set_last_deserialize_failed(bool failed) { g_last_deserialize_failed = failed; }
}  // namespace detail

}  // namespace bsn::dds
