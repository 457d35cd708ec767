// `bsn node --source URI --node ID`: a real sensor on bsn/raw, published like `bsn sim` (sensor timestamp,
// sequence number, channel bits). The sources (serial, UDP lines or NGIMU OSC, Linux IIO) are the registry of
// sensor_source.hpp; this is the axis map, the time base, the rejection counts and DDS around them.
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
