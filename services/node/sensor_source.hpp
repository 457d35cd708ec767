// The inputs of `bsn node`: one SensorSource per kind of device (serial, UDP, IIO, ...), made from the --source URI
// KIND:WHERE?key=value&... by the maker its kind names in the registry (sensor_source.cpp). A source reads bytes
// and hands each parsed reading or rejection to a ReadingSink (the node's publisher); the parsing itself is
// io/sensor_input.hpp's pure functions. Adding an input kind: a `<kind>_source.cpp` with its maker, and its line in
// the registry.
#pragma once

#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "bsn/io/sensor_input.hpp"

namespace bsn::services {

/// The --source URI: KIND:WHERE?key=value&key=value.
struct SourceUri {
  std::string kind, where;
  std::map<std::string, std::string> query;
};

/// nullopt when `uri` is not KIND:WHERE[?key=value&...] with a non-empty WHERE.
std::optional<SourceUri> parse_source_uri(const std::string& uri);

/// Where a source hands what it read.
class ReadingSink {
 public:
  virtual ~ReadingSink() = default;
  /// A parsed reading; its device time is in units of `device_time_scale_s` seconds.
  virtual void accept(const io::DeviceReading& reading, double device_time_scale_s) = 0;
  /// An input that was not a reading (counted; `sample_text` is kept for the log).
  virtual void reject(io::InputRejection rejection, std::string_view sample_text = {}) = 0;
  /// The device was reconnected and may have restarted its clock: a new time base at the next reading.
  virtual void reconnected() = 0;
  /// The line protocol's time unit, s (the axis map's time_scale_s; microseconds by default).
  virtual double line_time_scale() const = 0;
};

class SensorSource {
 public:
  virtual ~SensorSource() = default;
  /// Checks the URI and prepares the device, before any DDS entity exists (so a bad device is reported at once).
  /// nullopt: ready; else the exit code, the reason logged.
  virtual std::optional<int> open() = 0;
  /// Waits up to ~50 ms for input and hands what arrived to `sink`. nullopt: go on; else stop with this exit code.
  virtual std::optional<int> read_some(ReadingSink& sink) = 0;
  /// What the source reads, for the log (e.g. "serial /dev/ttyACM0 at 115200 baud").
  virtual std::string describe() const = 0;
};

/// One input kind of the registry.
struct SensorSourceKind {
  const char* name;   ///< the URI's KIND
  const char* usage;  ///< the URI's form, for --help and errors
  std::unique_ptr<SensorSource> (*make)(const SourceUri& uri);
};

/// Every input kind, in the order --help lists them.
std::span<const SensorSourceKind> sensor_source_kinds();
/// The usages of every kind: "serial:PATH[?baud=N], udp:PORT or iio:DEVICE[...]".
std::string sensor_source_usages();
/// The source of `uri`'s kind, nullptr for an unknown kind.
std::unique_ptr<SensorSource> make_sensor_source(const SourceUri& uri);

// Shared by the sources.
/// Parses one line of the bsn line protocol and hands the reading or the rejection to `sink`.
void handle_line(ReadingSink& sink, std::string_view line);
/// Waits up to 50 ms for `fd` to be readable (poll's result: > 0 readable or hung up, 0 timeout, < 0 error).
int wait_readable(int fd);

}  // namespace bsn::services
