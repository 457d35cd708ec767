#include "bsn/dds/shutdown.hpp"

#include <atomic>
#include <csignal>
#include <thread>

namespace bsn::dds {
namespace {

// A signal handler may only touch a lock-free atomic; this is the one process-wide flag of a bsn process.
std::atomic<bool> g_shutdown{false};
static_assert(std::atomic<bool>::is_always_lock_free);

extern "C" void on_signal(int) { g_shutdown.store(true); }

}  // namespace

void install_shutdown_handlers() {
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  // A closed stdout (e.g. `bsn echo | head`) must end the process through the normal path, not kill it.
  std::signal(SIGPIPE, SIG_IGN);
}

bool shutdown_requested() { return g_shutdown.load(); }

void request_shutdown() { g_shutdown.store(true); }

bool sleep_unless_shutdown(std::chrono::nanoseconds d) {
  const auto end = std::chrono::steady_clock::now() + d;
  while (!shutdown_requested()) {
    const auto now = std::chrono::steady_clock::now();
    if (now >= end) return true;
    std::this_thread::sleep_for(std::min<std::chrono::nanoseconds>(end - now, std::chrono::milliseconds(20)));
  }
  return false;
}

}  // namespace bsn::dds
