// Minimal logging to stderr: one line per message, time-stamped, with the process role as prefix.
#pragma once

#include <sstream>
#include <string>
#include <string_view>

namespace bsn::logging {

enum class LogLevel { kDebug, kInfo, kWarn, kError };

/// Sets the role printed on every line ("fusion", "sim thigh_l", ...) and the lowest level printed.
void set_log_identity(std::string role, LogLevel min_level = LogLevel::kInfo);

void log_line(LogLevel level, std::string_view message);

template <class... Args>
void log(LogLevel level, const Args&... args) {
  std::ostringstream s;
  (s << ... << args);
  log_line(level, s.str());
}

template <class... Args>
void log_info(const Args&... args) {
  log(LogLevel::kInfo, args...);
}
template <class... Args>
void log_warn(const Args&... args) {
  log(LogLevel::kWarn, args...);
}
template <class... Args>
void log_error(const Args&... args) {
  log(LogLevel::kError, args...);
}

}  // namespace bsn::logging
