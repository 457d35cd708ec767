// A per-thread pool in front of OpenSSL's random generator, for DDS-Security's per-sample nonces.
//
// Why: Fast DDS's AES-GCM transform draws an 8-byte nonce suffix with RAND_bytes for every sample it encrypts.
// OpenSSL 3.0 answers each call through its provider layer: OSSL_PARAM look-ups by string and four getpid() system
// calls (its fork check). Measured here: 5-9 us per call, more than the AES-GCM of the sample itself (about 2 us),
// so on a machine with slow system calls it was the largest part of DDS-Security's latency cost (README,
// DDS-Security). OpenSSL 3.2+ detects forks without getpid(); Debian 12 ships 3.0.
//
// What it does: RAND_bytes and RAND_priv_bytes requests of at most kMaxPooledBytes are served from a 4 KiB buffer per
// thread, refilled in one call to OpenSSL's own generator (its public DRBG, as every RAND_bytes call is by default);
// bytes are wiped from the buffer as they are handed out, so none is ever given twice. Larger requests (keys,
// handshakes) go to OpenSSL's generator directly. A fork discards the forking thread's buffer in the child, so
// parent and child never share bytes. Only processes with DDS-Security on install it (participant_qos).
#pragma once

#include <cstddef>

namespace bsn::dds {

/// Requests up to this size are pooled: the AES-GCM nonce suffix is 8 bytes, a session-key salt 32.
inline constexpr std::size_t kMaxPooledBytes = 64;

/// Installs the pool as OpenSSL's random method, once per process; later calls do nothing. Returns false, and leaves
/// OpenSSL as it was, if OpenSSL refuses the method.
bool install_random_pool();

/// Whether install_random_pool succeeded in this process.
bool random_pool_installed();

}  // namespace bsn::dds
