// The two JSON leaves bsn's machine-readable outputs (`bsn eval --json`, `bsn calibrate --json`) are built of.
#pragma once

#include <cmath>
#include <cstdio>
#include <string>
#include <string_view>

namespace bsn::io {

/// A JSON string literal: quotes and backslashes escaped, control characters as \u00XX. With `ascii_only`, every
/// byte outside printable ASCII is escaped too (as \u00XX): for bytes from the network, which need not be UTF-8,
/// the result is then valid JSON whatever they hold.
inline std::string json_string(std::string_view s, bool ascii_only = false) {
  std::string out = "\"";
  for (const char ch : s) {
    const auto c = static_cast<unsigned char>(ch);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += ch;
    } else if (c < 0x20 || (ascii_only && c >= 0x7f)) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", c);
      out += buf;
    } else {
      out += ch;
    }
  }
  return out + "\"";
}

/// A JSON number with `digits` significant digits; null for NaN and infinities, which JSON cannot hold.
inline std::string json_number(double v, int digits = 6) {
  if (!std::isfinite(v)) return "null";
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

}  // namespace bsn::io
