#include "bsn/logging/log.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <mutex>

namespace bsn::logging {
namespace {

struct LogConfig {
  std::mutex mutex;
  std::string role = "bsn";
  LogLevel min_level = LogLevel::kInfo;
};

LogConfig& config() {
  static LogConfig c;
  return c;
}

const char* level_name(LogLevel l) {
  switch (l) {
    case LogLevel::kDebug:
      return "debug";
    case LogLevel::kInfo:
      return "info";
    case LogLevel::kWarn:
      return "warning";
    case LogLevel::kError:
      return "error";
  }
  return "";
}

}  // namespace

void set_log_identity(std::string role, LogLevel min_level) {
  std::lock_guard lock(config().mutex);
  config().role = std::move(role);
  config().min_level = min_level;
}

void log_line(LogLevel level, std::string_view message) {
  LogConfig& c = config();
  std::lock_guard lock(c.mutex);
  if (level < c.min_level) return;
  const auto now = std::chrono::system_clock::now();
  const std::time_t secs = std::chrono::system_clock::to_time_t(now);
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000;
  std::tm tm{};
  gmtime_r(&secs, &tm);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%H:%M:%S", &tm);
  std::fprintf(stderr, "%s.%03lld [%s] %s: %.*s\n", stamp, static_cast<long long>(ms), c.role.c_str(),
               level_name(level), static_cast<int>(message.size()), message.data());
}

std::string printable(std::string_view text, std::size_t max_chars) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  const std::size_t n = std::min(text.size(), max_chars);
  out.reserve(n + 16);
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c >= 0x20 && c < 0x7f && c != '\\') {
      out += static_cast<char>(c);
    } else {
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 0xf];
    }
  }
  if (text.size() > n) out += "...(" + std::to_string(text.size() - n) + " more)";
  return out;
}

}  // namespace bsn::logging
