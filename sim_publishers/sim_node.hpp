// `bsn sim`: one simulated sensor node. Publishes raw samples on bsn/raw and its exact orientation on
// bsn/truth/orientation, at a fixed rate on the host's monotonic clock.
#pragma once

#include <cstdint>
#include <string>

namespace bsn::sim {

struct SimNodeOptions {
  std::string node;         ///< node_id on bsn/raw
  std::string segment;      ///< segment name on bsn/truth/orientation ("" = node id)
  double rate_hz = 100.0;   ///< sample rate, Hz
  std::uint64_t seed = 0;   ///< motion and noise seed; 0 = derived from the node id
  double duration_s = 0.0;  ///< stop after this long, s (0 = until SIGINT/SIGTERM)
  bool ideal = false;       ///< no sensor noise
  int domain = 0;
};

/// Runs until the duration ends or a signal arrives. Returns the process exit code.
int run_sim_node(const SimNodeOptions& options);

}  // namespace bsn::sim
