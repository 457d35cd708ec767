#include "bsn/io/sensor_input.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <numbers>

namespace bsn::io {

const char* input_rejection_name(InputRejection r) {
  switch (r) {
    case InputRejection::kNone:
      return "none";
    case InputRejection::kIgnored:
      return "ignored";
    case InputRejection::kLineTooLong:
      return "line_too_long";
    case InputRejection::kNotANumber:
      return "not_a_number";
    case InputRejection::kColumnCount:
      return "column_count";
    case InputRejection::kNonFinite:
      return "non_finite";
    case InputRejection::kTruncated:
      return "truncated";
    case InputRejection::kOversized:
      return "oversized";
    case InputRejection::kNotOsc:
      return "not_osc";
    case InputRejection::kWrongAddress:
      return "wrong_address";
    case InputRejection::kWrongTypeTags:
      return "wrong_type_tags";
    case InputRejection::kShortRead:
      return "short_read";
    case InputRejection::kCount:
      break;
  }
  return "unknown";
}

namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

// A whole field as a double: no trailing characters. from_chars does not accept a leading '+'.
bool parse_number(std::string_view field, double& out) {
  if (!field.empty() && field.front() == '+') field.remove_prefix(1);
  if (field.empty()) return false;
  const auto [end, ec] = std::from_chars(field.data(), field.data() + field.size(), out);
  return ec == std::errc() && end == field.data() + field.size();
}

}  // namespace

ParseResult parse_sensor_line(std::string_view line) {
  ParseResult r;
  if (line.size() > kMaxLineLength) {
    r.rejection = InputRejection::kLineTooLong;
    return r;
  }
  line = trim(line);
  if (line.empty() || line.front() == '#') {
    r.rejection = InputRejection::kIgnored;
    return r;
  }
  std::array<std::string_view, 11> fields;
  std::size_t n = 0;
  while (true) {
    const std::size_t comma = line.find(',');
    if (n == fields.size()) {
      r.rejection = InputRejection::kColumnCount;
      return r;
    }
    fields[n++] = trim(line.substr(0, comma));
    if (comma == std::string_view::npos) break;
    line.remove_prefix(comma + 1);
  }
  if (n != 7 && n != 10) {
    r.rejection = InputRejection::kColumnCount;
    return r;
  }
  std::array<double, 10> v{};
  const bool mag_empty = n == 10 && fields[7].empty() && fields[8].empty() && fields[9].empty();
  for (std::size_t i = 0; i < n; ++i) {
    if (i >= 7 && mag_empty) continue;
    if (!parse_number(fields[i], v[i])) {
      r.rejection = InputRejection::kNotANumber;
      return r;
    }
    if (!std::isfinite(v[i])) {
      r.rejection = InputRejection::kNonFinite;
      return r;
    }
  }
  DeviceReading& d = r.reading;
  d.device_time = v[0];
  d.acc = {v[1], v[2], v[3]};
  d.gyr = {v[4], v[5], v[6]};
  d.has_acc = d.has_gyr = true;
  d.has_mag = n == 10 && !mag_empty;
  if (d.has_mag) d.mag = {v[7], v[8], v[9]};
  return r;
}

// ---------------------------------------------------------------------------------------------------------------
// OSC 1.0: strings are NUL-terminated and padded to 4 bytes; numbers are big-endian; a bundle is "#bundle\0", an
// NTP time tag (uint64: seconds since 1900 in the high half, fraction in the low), then int32 size + element.

namespace {

std::uint32_t be32(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | std::uint32_t{p[3]};
}

// The OSC string at `pos` (padded length in `padded`), or nullopt if it runs past the end.
std::optional<std::string_view> osc_string(std::span<const std::uint8_t> data, std::size_t pos, std::size_t& padded) {
  if (pos >= data.size()) return std::nullopt;
  const auto* begin = reinterpret_cast<const char*>(data.data() + pos);
  const void* nul = std::memchr(begin, '\0', data.size() - pos);
  if (nul == nullptr) return std::nullopt;
  const std::size_t len = static_cast<std::size_t>(static_cast<const char*>(nul) - begin);
  padded = (len + 4) & ~std::size_t{3};
  if (pos + padded > data.size()) return std::nullopt;
  return std::string_view(begin, len);
}

ParseResult parse_osc_message(std::span<const std::uint8_t> msg) {
  ParseResult r;
  std::size_t padded = 0;
  const auto address = osc_string(msg, 0, padded);
  if (!address || address->empty() || address->front() != '/') {
    r.rejection = address ? InputRejection::kNotOsc : InputRejection::kTruncated;
    return r;
  }
  if (*address != "/sensors") {
    r.rejection = InputRejection::kWrongAddress;
    return r;
  }
  std::size_t pos = padded;
  const auto tags = osc_string(msg, pos, padded);
  if (!tags) {
    r.rejection = InputRejection::kTruncated;
    return r;
  }
  if (*tags != ",ffffffffff") {
    r.rejection = InputRejection::kWrongTypeTags;
    return r;
  }
  pos += padded;
  if (msg.size() - pos < 40) {
    r.rejection = InputRejection::kTruncated;
    return r;
  }
  std::array<double, 10> v{};
  for (std::size_t i = 0; i < 10; ++i) {
    const std::uint32_t bits = be32(msg.data() + pos + 4 * i);
    float f;
    std::memcpy(&f, &bits, sizeof f);
    if (!std::isfinite(f)) {
      r.rejection = InputRejection::kNonFinite;
      return r;
    }
    v[i] = f;
  }
  // The NGIMU's documented units: deg/s, g, uT; bsn's: rad/s, m/s^2, uT.
  constexpr double kDeg = std::numbers::pi / 180.0;
  constexpr double kStandardGravity = 9.80665;
  DeviceReading& d = r.reading;
  d.gyr = {v[0] * kDeg, v[1] * kDeg, v[2] * kDeg};
  d.acc = {v[3] * kStandardGravity, v[4] * kStandardGravity, v[5] * kStandardGravity};
  d.mag = {v[6], v[7], v[8]};
  d.has_acc = d.has_gyr = d.has_mag = true;
  return r;
}

}  // namespace

ParseResult parse_osc_sensors(std::span<const std::uint8_t> datagram) {
  ParseResult r;
  if (datagram.size() > kMaxDatagram) {
    r.rejection = InputRejection::kOversized;
    return r;
  }
  if (datagram.size() < 4) {
    r.rejection = datagram.empty() ? InputRejection::kNotOsc : InputRejection::kTruncated;
    return r;
  }
  if (datagram.size() % 4 != 0) {  // every OSC packet is a multiple of 4 bytes
    r.rejection = InputRejection::kTruncated;
    return r;
  }
  static constexpr std::uint8_t kBundle[8] = {'#', 'b', 'u', 'n', 'd', 'l', 'e', 0};
  if (datagram.size() >= 8 && std::memcmp(datagram.data(), kBundle, 8) == 0) {
    if (datagram.size() < 20) {
      r.rejection = InputRejection::kTruncated;
      return r;
    }
    const std::uint32_t secs = be32(datagram.data() + 8);
    const std::uint32_t frac = be32(datagram.data() + 12);
    // The first element that is a /sensors message; a bundle may also hold others (quaternion, battery, ...).
    std::size_t pos = 16;
    InputRejection first_problem = InputRejection::kWrongAddress;
    while (pos + 4 <= datagram.size()) {
      const std::uint32_t size = be32(datagram.data() + pos);
      pos += 4;
      if (size == 0 || size % 4 != 0 || size > datagram.size() - pos) {
        r.rejection = InputRejection::kTruncated;
        return r;
      }
      ParseResult element = parse_osc_message(datagram.subspan(pos, size));
      if (element.ok()) {
        // NTP time: seconds since 1900 plus a binary fraction; a tag of exactly 1 means "immediately" (no time).
        if (!(secs == 0 && frac == 1)) {
          element.reading.device_time = static_cast<double>(secs) + static_cast<double>(frac) / 4294967296.0;
        }
        return element;
      }
      if (element.rejection != InputRejection::kWrongAddress) first_problem = element.rejection;
      pos += size;
    }
    r.rejection = first_problem;
    return r;
  }
  return parse_osc_message(datagram);
}

// ---------------------------------------------------------------------------------------------------------------

std::optional<IioChannelType> parse_iio_channel_type(std::string_view text, std::string* error) {
  auto fail = [&](const char* what) -> std::optional<IioChannelType> {
    if (error) *error = std::string(what) + " in '" + std::string(text) + "'";
    return std::nullopt;
  };
  text = trim(text);
  while (!text.empty() && text.back() == '\n') text.remove_suffix(1);
  IioChannelType t;
  if (text.rfind("be:", 0) == 0) {
    t.big_endian = true;
  } else if (text.rfind("le:", 0) != 0) {
    return fail("endianness is neither 'be:' nor 'le:'");
  }
  text.remove_prefix(3);
  if (text.empty() || (text.front() != 's' && text.front() != 'u')) return fail("sign is neither 's' nor 'u'");
  t.is_signed = text.front() == 's';
  text.remove_prefix(1);
  auto number = [&text](int& out) {
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), out);
    if (ec != std::errc()) return false;
    text.remove_prefix(static_cast<std::size_t>(end - text.data()));
    return true;
  };
  if (!number(t.bits) || text.empty() || text.front() != '/') return fail("no BITS/STORAGE");
  text.remove_prefix(1);
  if (!number(t.storage_bits)) return fail("no storage bits");
  if (!text.empty() && text.front() == 'X') {
    text.remove_prefix(1);
    if (!number(t.repeat) || t.repeat < 1) return fail("bad repeat count");
  }
  if (text.rfind(">>", 0) != 0) return fail("no '>>SHIFT'");
  text.remove_prefix(2);
  if (!number(t.shift) || !text.empty()) return fail("bad shift");
  if (t.storage_bits != 8 && t.storage_bits != 16 && t.storage_bits != 32 && t.storage_bits != 64) {
    return fail("storage bits must be 8, 16, 32 or 64");
  }
  if (t.bits < 1 || t.bits > t.storage_bits || t.shift < 0 || t.shift + t.bits > t.storage_bits) {
    return fail("bits and shift do not fit the storage");
  }
  return t;
}

void finish_iio_layout(IioScanLayout& layout) {
  std::size_t pos = 0, largest = 1;
  for (auto& c : layout.channels) {
    const std::size_t bytes = static_cast<std::size_t>(c.type.storage_bits / 8);
    const std::size_t size = bytes * static_cast<std::size_t>(c.type.repeat);
    // Each element is aligned to its storage size (the kernel's iio_compute_scan_bytes rule).
    if (pos % bytes != 0) pos += bytes - pos % bytes;
    c.offset = pos;
    pos += size;
    largest = std::max(largest, bytes);
  }
  if (pos % largest != 0) pos += largest - pos % largest;
  layout.scan_bytes = pos;
}

ParseResult parse_iio_scan(std::span<const std::uint8_t> scan, const IioScanLayout& layout) {
  ParseResult r;
  if (scan.size() < layout.scan_bytes || layout.scan_bytes == 0) {
    r.rejection = InputRejection::kShortRead;
    return r;
  }
  std::array<double, 10> v{};
  std::array<bool, 10> seen{};
  for (const auto& c : layout.channels) {
    if (c.target < 0 || c.target > 9) continue;
    const int bytes = c.type.storage_bits / 8;
    std::uint64_t raw = 0;
    for (int i = 0; i < bytes; ++i) {
      const std::uint8_t b = scan[c.offset + static_cast<std::size_t>(i)];
      const int at = c.type.big_endian ? bytes - 1 - i : i;
      raw |= std::uint64_t{b} << (8 * at);
    }
    raw >>= c.type.shift;
    const std::uint64_t mask = c.type.bits == 64 ? ~std::uint64_t{0} : ((std::uint64_t{1} << c.type.bits) - 1);
    raw &= mask;
    double value;
    if (c.type.is_signed && c.type.bits < 64 && (raw >> (c.type.bits - 1)) != 0) {
      value = static_cast<double>(static_cast<std::int64_t>(raw | ~mask));  // sign-extend
    } else if (c.type.is_signed) {
      value = static_cast<double>(static_cast<std::int64_t>(raw));
    } else {
      value = static_cast<double>(raw);
    }
    v[static_cast<std::size_t>(c.target)] = (value + c.value_offset) * c.scale;
    seen[static_cast<std::size_t>(c.target)] = true;
  }
  DeviceReading& d = r.reading;
  d.has_acc = seen[0] && seen[1] && seen[2];
  d.has_gyr = seen[3] && seen[4] && seen[5];
  d.has_mag = seen[6] && seen[7] && seen[8];
  d.acc = {v[0], v[1], v[2]};
  d.gyr = {v[3], v[4], v[5]};
  d.mag = {v[6], v[7], v[8]};
  if (seen[9]) d.device_time = v[9];
  return r;
}

fusion::ImuSample apply_axis_map(const DeviceReading& reading, const AxisMap& map) {
  auto mapped = [](const std::array<double, 3>& in, const ChannelMap& m) {
    fusion::Vec3 out;
    for (std::size_t i = 0; i < 3; ++i) {
      const auto from = static_cast<std::size_t>(std::clamp(m.source[i], 0, 2));  // load_axis_map allows 0..2 only
      out[static_cast<Eigen::Index>(i)] = m.sign[i] * in[from] * m.scale;
    }
    return out;
  };
  fusion::ImuSample s;
  s.has_acc = reading.has_acc && map.acc.enabled;
  s.has_gyr = reading.has_gyr && map.gyr.enabled;
  s.has_mag = reading.has_mag && map.mag.enabled;
  s.acc = s.has_acc ? mapped(reading.acc, map.acc) : fusion::Vec3::Zero();
  s.gyr = s.has_gyr ? mapped(reading.gyr, map.gyr) : fusion::Vec3::Zero();
  s.mag = s.has_mag ? mapped(reading.mag, map.mag) : fusion::Vec3::Zero();
  return s;
}

}  // namespace bsn::io
