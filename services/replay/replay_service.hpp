// `bsn replay`: raw samples from session files (`bsn record`), BROAD-layout HDF5 trials, `bsn eval` CSV files or
// folders of them, published on bsn/raw with the recorded timing. Sensor timestamps are rebased to this host's
// monotonic clock keeping every interval (so filters see exactly the recorded dt), sequence numbers are kept.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "command.hpp"
#include "session_streams.hpp"

namespace bsn::services {

/// The raw samples of one node, as columns.
struct ReplayTrack : RawColumns {
  std::string node;
};

/// Reads every raw track of `path`: a session file (one track per node of bsn/raw), a BROAD-layout HDF5 or CSV
/// file (one track named after the file), or a folder of those. Throws io::IoError naming the file and dataset.
std::vector<ReplayTrack> load_replay_tracks(const std::string& path);

struct ReplayOptions {
  std::vector<std::string> inputs;
  double speed = 1.0;  ///< times real time; 0 = as fast as possible
  bool loop = false;
  std::vector<std::string> node_map;  ///< "A=B": publish node A as B
  int readers = 1;                    ///< wait until this many bsn/raw readers have matched before starting
  double wait_s = 10.0;               ///< for at most this long
  int domain = 0;
};

int run_replay(const ReplayOptions& options);

Command replay_command();

}  // namespace bsn::services
