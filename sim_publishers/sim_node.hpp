// `bsn sim`: one simulated sensor node. Publishes raw samples on bsn/raw, its exact orientation on
// bsn/truth/orientation and, for a segment with a parent, the joint's true anatomical angles on
// bsn/truth/joint_angles, at a fixed rate on the host's monotonic clock. With a scenario file it publishes one
// segment of the scenario (real time or `speed` times faster), or writes every segment to BROAD-layout HDF5.
#pragma once

#include <cstdint>
#include <string>

#include "command.hpp"

namespace bsn::sim {

struct SimNodeOptions {
  std::string node;         ///< node_id on bsn/raw
  std::string segment;      ///< segment name on bsn/truth/orientation ("" = node id)
  double rate_hz = 100.0;   ///< sample rate, Hz
  std::uint64_t seed = 0;   ///< motion and noise seed; 0 = derived from the node id
  double duration_s = 0.0;  ///< stop after this long, s (0 = until SIGINT/SIGTERM)
  bool ideal = false;       ///< no sensor noise (with a scenario: every sensor error off)
  int domain = 0;
  std::string scenario;     ///< scenario YAML file ("" = the simple per-node motion above)
  double speed = 1.0;       ///< scenario mode: publish this many times faster than real time
  std::string out_dir;      ///< scenario mode: write DIR/<segment>.hdf5 instead of publishing
  bool rate_given = false;  ///< --rate was on the command line (not allowed with a scenario)
  /// Scenario time 0 at this Unix time, s (0 = at the node's start): nodes given the same instant move as one
  /// body; a node started later joins at the scenario time of its start.
  double start_at_unix_s = 0.0;
};

/// Runs until the duration ends or a signal arrives. Returns the process exit code.
int run_sim_node(const SimNodeOptions& options);

/// `bsn sim`: its options and run_sim_node.
services::Command sim_command();

}  // namespace bsn::sim
