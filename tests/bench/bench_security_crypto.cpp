// What DDS-Security costs per sample on this machine, one OpenSSL operation at a time, made the way Fast DDS 2.9.1's
// builtin.AES-GCM-GMAC plugin makes them (its AESGCMGMAC_Transform): the README's DDS-Security section explains
// the secured latency with these figures.
//   - writer, per sample: an 8-byte nonce suffix (RAND_bytes), then AES-128-GCM of the serialised sample;
//   - reader, per sample: the session key derived again from the master key (HMAC-SHA256 through EVP_PKEY, which the
//     plugin does for every sample it decodes, not once per session), then AES-128-GCM decryption.
// Run: ./build/tests/bench/bsn_bench_security_crypto --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>
#include <openssl/evp.h>
#include <openssl/rand.h>

#include <array>
#include <cstdint>
#include <cstring>

namespace {

// 200 bytes: about one bsn/orientation sample (a secured one leaves as a 288-byte RTPS message, seen with strace).
constexpr std::size_t kSampleBytes = 200;

void BM_NoncePerEncryptedSample(benchmark::State& state) {
  std::uint64_t suffix = 0;
  for (auto _ : state) {
    RAND_bytes(reinterpret_cast<unsigned char*>(&suffix), sizeof suffix);
    benchmark::DoNotOptimize(suffix);
  }
}
BENCHMARK(BM_NoncePerEncryptedSample);

void BM_SessionKeyPerDecodedSample(benchmark::State& state) {
  const std::array<unsigned char, 32> master_key{1, 2, 3};
  std::array<unsigned char, 10 + 32 + 4> source{};  // "SessionKey" | master salt | session id
  std::memcpy(source.data(), "SessionKey", 10);
  std::array<unsigned char, 32> session_key{};
  for (auto _ : state) {
    EVP_PKEY* key = EVP_PKEY_new_mac_key(EVP_PKEY_HMAC, nullptr, master_key.data(), 16);
    EVP_MD_CTX* ctx = EVP_MD_CTX_new();
    EVP_DigestSignInit(ctx, nullptr, EVP_sha256(), nullptr, key);
    EVP_DigestSignUpdate(ctx, source.data(), source.size() - 16);
    std::size_t length = session_key.size();
    EVP_DigestSignFinal(ctx, session_key.data(), &length);
    EVP_PKEY_free(key);
    EVP_MD_CTX_free(ctx);
    benchmark::DoNotOptimize(session_key);
  }
}
BENCHMARK(BM_SessionKeyPerDecodedSample);

void aes_gcm(benchmark::State& state, bool encrypt) {
  const std::array<unsigned char, 16> key{7};
  const std::array<unsigned char, 12> iv{9};
  std::array<unsigned char, kSampleBytes> in{}, out{};
  std::array<unsigned char, 16> tag{};
  for (auto _ : state) {
    EVP_CIPHER_CTX* ctx = EVP_CIPHER_CTX_new();
    int n = 0, last = 0;
    if (encrypt) {
      EVP_EncryptInit(ctx, EVP_aes_128_gcm(), key.data(), iv.data());
      EVP_EncryptUpdate(ctx, out.data(), &n, in.data(), static_cast<int>(in.size()));
      EVP_EncryptFinal(ctx, out.data() + n, &last);
      EVP_CIPHER_CTX_ctrl(ctx, EVP_CTRL_GCM_GET_TAG, static_cast<int>(tag.size()), tag.data());
    } else {
      EVP_DecryptInit(ctx, EVP_aes_128_gcm(), key.data(), iv.data());
      EVP_DecryptUpdate(ctx, out.data(), &n, in.data(), static_cast<int>(in.size()));
      EVP_CIPHER_CTX_ctrl(ctx, EVP_CTRL_GCM_SET_TAG, static_cast<int>(tag.size()), tag.data());
      EVP_DecryptFinal(ctx, out.data() + n, &last);  // the tag does not match: only the cost is of interest
    }
    EVP_CIPHER_CTX_free(ctx);
    benchmark::DoNotOptimize(out);
  }
}

void BM_AesGcmEncryptSample(benchmark::State& state) { aes_gcm(state, true); }
BENCHMARK(BM_AesGcmEncryptSample);

void BM_AesGcmDecryptSample(benchmark::State& state) { aes_gcm(state, false); }
BENCHMARK(BM_AesGcmDecryptSample);

}  // namespace

BENCHMARK_MAIN();
