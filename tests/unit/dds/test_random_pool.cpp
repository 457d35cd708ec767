// The random pool in front of OpenSSL (DDS-Security's per-sample nonces): every byte handed out once, in every thread
// and across a fork, and requests above the pooled size still answered.
#define OPENSSL_SUPPRESS_DEPRECATED
#include <gtest/gtest.h>
#include <openssl/rand.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdint>
#include <cstring>
#include <set>
#include <thread>
#include <vector>

#include "bsn/dds/random_pool.hpp"

namespace bsn::dds {
namespace {

std::uint64_t draw_nonce_suffix() {
  std::uint64_t v = 0;
  EXPECT_EQ(RAND_bytes(reinterpret_cast<unsigned char*>(&v), sizeof v), 1);
  return v;
}

TEST(RandomPool, InstallsOnceAndBecomesOpenSslsMethod) {
  ASSERT_TRUE(install_random_pool());
  EXPECT_TRUE(install_random_pool()) << "a second call changes nothing and still reports the pool";
  EXPECT_TRUE(random_pool_installed());
  EXPECT_NE(RAND_get_rand_method(), RAND_OpenSSL());
}

// 8-byte suffixes as Fast DDS draws them, over several refills of the 4 KiB buffer: a pool that handed out a byte
// twice would repeat whole suffixes (two equal 64-bit draws from a sound generator: probability 2e4^2 / 2^65, 1e-11).
TEST(RandomPool, NeverRepeatsANonceSuffix) {
  ASSERT_TRUE(install_random_pool());
  std::set<std::uint64_t> seen;
  constexpr int kDraws = 20000;  // 160 000 bytes: 39 refills
  for (int i = 0; i < kDraws; ++i) seen.insert(draw_nonce_suffix());
  EXPECT_EQ(seen.size(), static_cast<std::size_t>(kDraws));
}

TEST(RandomPool, ThreadsDrawDifferentBytes) {
  ASSERT_TRUE(install_random_pool());
  constexpr int kPerThread = 2000;
  std::vector<std::uint64_t> a(kPerThread), b(kPerThread);
  std::thread ta([&] {
    for (auto& v : a) v = draw_nonce_suffix();
  });
  std::thread tb([&] {
    for (auto& v : b) v = draw_nonce_suffix();
  });
  ta.join();
  tb.join();
  std::set<std::uint64_t> all(a.begin(), a.end());
  all.insert(b.begin(), b.end());
  EXPECT_EQ(all.size(), static_cast<std::size_t>(2 * kPerThread));
}

// After a fork, parent and child hold the same copy of the pool: without the fork handler both would hand out the
// same next bytes, and two processes encrypting under one key would reuse nonces.
TEST(RandomPool, ForkedChildNeverDrawsTheParentsBytes) {
  ASSERT_TRUE(install_random_pool());
  draw_nonce_suffix();  // the buffer is filled and partly used
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    std::array<std::uint64_t, 16> drawn{};
    for (auto& v : drawn) {
      if (RAND_bytes(reinterpret_cast<unsigned char*>(&v), sizeof v) != 1) _exit(2);
    }
    const bool written = write(fds[1], drawn.data(), sizeof drawn) == static_cast<ssize_t>(sizeof drawn);
    _exit(written ? 0 : 3);
  }
  close(fds[1]);
  std::array<std::uint64_t, 16> parent{};
  for (auto& v : parent) v = draw_nonce_suffix();
  std::array<std::uint64_t, 16> from_child{};
  const ssize_t n = read(fds[0], from_child.data(), sizeof from_child);
  close(fds[0]);
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  ASSERT_EQ(WEXITSTATUS(status), 0);
  ASSERT_EQ(n, static_cast<ssize_t>(sizeof from_child));
  std::set<std::uint64_t> all(parent.begin(), parent.end());
  all.insert(from_child.begin(), from_child.end());
  EXPECT_EQ(all.size(), parent.size() + from_child.size());
}

TEST(RandomPool, LargerRequestsGoToOpenSslAndAreFilled) {
  ASSERT_TRUE(install_random_pool());
  std::array<unsigned char, 4 * kMaxPooledBytes> a{}, b{};
  ASSERT_EQ(RAND_bytes(a.data(), static_cast<int>(a.size())), 1);
  ASSERT_EQ(RAND_bytes(b.data(), static_cast<int>(b.size())), 1);
  EXPECT_NE(std::memcmp(a.data(), b.data(), a.size()), 0);
  // A request of exactly the pooled size and one of zero bytes are answered as OpenSSL answers them.
  std::array<unsigned char, kMaxPooledBytes> c{};
  EXPECT_EQ(RAND_bytes(c.data(), static_cast<int>(c.size())), 1);
  EXPECT_EQ(RAND_bytes(c.data(), 0), 1);
}

}  // namespace
}  // namespace bsn::dds
