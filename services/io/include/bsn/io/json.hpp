// The two JSON leaves bsn's machine-readable outputs (`bsn eval --json`, `bsn calibrate --json`) are built of.
#pragma once

#include <cmath>
#include <cstdio>
#include <string>

namespace bsn::io {

/// A JSON string literal: quotes and backslashes escaped, control characters as \u00XX.
inline std::string json_string(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", c);
      out += buf;
    } else {
      out += c;
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
