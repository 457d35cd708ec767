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

/// `text` safe to print on a terminal: every byte outside printable ASCII (control characters such as ESC, and
/// all bytes >= 0x80, which include C1 controls in UTF-8) and the backslash as \xNN, cut after `max_chars` input
/// characters with "...(N more)". Every string that comes from the network (node ids, segment names, process ids)
/// goes through this before it reaches a log or a terminal, so it cannot move the cursor or forge a line.
std::string printable(std::string_view text, std::size_t max_chars = 64);

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
