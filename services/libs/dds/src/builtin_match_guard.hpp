// The lock around Fast DDS 2.9.1's matching of DDS-Security builtin endpoints (builtin_match_guard.cpp).
#pragma once

#include <cstdint>

namespace bsn::dds {

/// How many times this process's Fast DDS matched a discovered participant's builtin security endpoints while
/// another participant's were being matched (each pair would have raced without the lock).
std::uint64_t builtin_match_overlaps();

}  // namespace bsn::dds
