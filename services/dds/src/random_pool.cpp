#include "bsn/dds/random_pool.hpp"

// RAND_METHOD is deprecated in OpenSSL 3.0 in favour of providers, but a provider-level DRBG would keep the per-call
// parameter look-ups and fork checks that this pool exists to avoid.
#define OPENSSL_SUPPRESS_DEPRECATED
#include <openssl/crypto.h>
#include <openssl/rand.h>
#include <pthread.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstring>
#include <mutex>

namespace bsn::dds {
namespace {

const RAND_METHOD* openssl_method = nullptr;  // OpenSSL's own method, which refills the pools
RAND_METHOD pooled_method{};
std::atomic<bool> installed{false};

struct ThreadPool {
  std::array<unsigned char, 4096> bytes{};
  std::size_t left = 0;  ///< unused bytes at the end of `bytes`
  ~ThreadPool() { OPENSSL_cleanse(bytes.data(), bytes.size()); }
};

thread_local ThreadPool pool;

int pooled_bytes(unsigned char* out, int count) {
  if (count < 0) return 0;
  auto n = static_cast<std::size_t>(count);
  if (n > kMaxPooledBytes) return openssl_method->bytes(out, count);
  while (n > 0) {
    if (pool.left == 0) {
      if (openssl_method->bytes(pool.bytes.data(), static_cast<int>(pool.bytes.size())) != 1) return 0;
      pool.left = pool.bytes.size();
    }
    const std::size_t take = std::min(n, pool.left);
    unsigned char* from = pool.bytes.data() + (pool.bytes.size() - pool.left);
    std::memcpy(out, from, take);
    OPENSSL_cleanse(from, take);
    pool.left -= take;
    out += take;
    n -= take;
  }
  return 1;
}

// In a forked child only the forking thread exists; its copy of the pool is the parent's: drop it.
void drop_pool_in_child() {
  OPENSSL_cleanse(pool.bytes.data(), pool.bytes.size());
  pool.left = 0;
}

}  // namespace

bool install_random_pool() {
  static std::once_flag once;
  std::call_once(once, [] {
    openssl_method = RAND_OpenSSL();
    if (openssl_method == nullptr || openssl_method->bytes == nullptr) return;
    pooled_method = *openssl_method;
    pooled_method.bytes = pooled_bytes;
    pooled_method.pseudorand = pooled_bytes;
    if (pthread_atfork(nullptr, nullptr, drop_pool_in_child) != 0) return;
    installed.store(RAND_set_rand_method(&pooled_method) == 1);
  });
  return installed.load();
}

bool random_pool_installed() { return installed.load(); }

}  // namespace bsn::dds
