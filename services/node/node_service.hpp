// `bsn node --source URI --node ID`: a real sensor on bsn/raw, published like `bsn sim` (sensor timestamp,
// sequence number, channel bits). Sources:
//   serial:PATH[?baud=N]   the bsn line protocol from a microcontroller; reconnects when the device comes back
//   udp:PORT               the same lines in UDP datagrams, or x-io NGIMU OSC /sensors messages
//   iio:DEVICE[?sysfs=DIR&dev=FILE]   the Linux IIO buffered interface (scan elements and scales from sysfs)
// The parsing is io/sensor_input.hpp (pure functions); this is the I/O around it, the axis map and DDS.
#pragma once

#include <string>

#include "bsn/io/sensor_input.hpp"
#include "command.hpp"

namespace bsn::services {

/// The source's defaults (line protocol: SI units and microseconds; NGIMU: deg/s, g, uT) overridden by the YAML
/// axis map file (format in README, "Connecting a real sensor"). Throws config::ConfigError("FILE:LINE: ...").
io::AxisMap load_axis_map(const std::string& path, io::AxisMap defaults);

struct NodeOptions {
  std::string source;
  std::string node;
  std::string map_path;  ///< "" = the source's defaults
  double status_period_s = 1.0;
  int domain = 0;
};

int run_node(const NodeOptions& options);

Command node_command();

}  // namespace bsn::services
