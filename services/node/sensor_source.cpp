#include "sensor_source.hpp"

#include <poll.h>

#include <array>

namespace bsn::services {

// Each kind's maker is defined in its own <kind>_source.cpp.
std::unique_ptr<SensorSource> make_serial_source(const SourceUri& uri);
std::unique_ptr<SensorSource> make_udp_source(const SourceUri& uri);
std::unique_ptr<SensorSource> make_iio_source(const SourceUri& uri);

namespace {

// The registry of input kinds: one line per kind.
constexpr std::array kKinds = {
    SensorSourceKind{"serial", "serial:PATH[?baud=N]", &make_serial_source},
    SensorSourceKind{"udp", "udp:PORT", &make_udp_source},
    SensorSourceKind{"iio", "iio:DEVICE[?sysfs=DIR&dev=FILE]", &make_iio_source},
};

}  // namespace

std::span<const SensorSourceKind> sensor_source_kinds() { return kKinds; }

std::string sensor_source_usages() {
  std::string out;
  for (std::size_t i = 0; i < kKinds.size(); ++i)
    out += std::string(i == 0 ? "" : i + 1 == kKinds.size() ? " or " : ", ") + kKinds[i].usage;
  return out;
}

std::unique_ptr<SensorSource> make_sensor_source(const SourceUri& uri) {
  for (const SensorSourceKind& k : kKinds)
    if (uri.kind == k.name) return k.make(uri);
  return nullptr;
}

std::optional<SourceUri> parse_source_uri(const std::string& uri) {
  const auto colon = uri.find(':');
  if (colon == std::string::npos) return std::nullopt;
  SourceUri u;
  u.kind = uri.substr(0, colon);
  std::string rest = uri.substr(colon + 1);
  const auto q = rest.find('?');
  if (q != std::string::npos) {
    std::string query = rest.substr(q + 1);
    rest = rest.substr(0, q);
    std::size_t pos = 0;
    while (pos <= query.size()) {
      const auto amp = query.find('&', pos);
      const std::string kv = query.substr(pos, amp == std::string::npos ? std::string::npos : amp - pos);
      const auto eq = kv.find('=');
      if (eq == std::string::npos) return std::nullopt;
      u.query[kv.substr(0, eq)] = kv.substr(eq + 1);
      if (amp == std::string::npos) break;
      pos = amp + 1;
    }
  }
  u.where = rest;
  if (u.where.empty()) return std::nullopt;
  return u;
}

void handle_line(ReadingSink& sink, std::string_view line) {
  const io::ParseResult r = io::parse_sensor_line(line);
  if (r.ok()) {
    sink.accept(r.reading, sink.line_time_scale());
  } else {
    sink.reject(r.rejection, line);
  }
}

int wait_readable(int fd) {
  pollfd p{fd, POLLIN, 0};
  return ::poll(&p, 1, 50);
}

}  // namespace bsn::services
