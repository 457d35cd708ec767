#pragma once

#include <string>

namespace bsn::services {

struct DemoOptions {
  double duration_s = 0.0;  ///< stop after this long, s (0 = until Ctrl-C)
  std::string body_path;    ///< "" = default 7-segment lower body
  double rate_hz = 100.0;   ///< sample rate of the simulated nodes
  int domain = 0;
};

/// Starts one `bsn sim` per segment and one `bsn fusion`, shows the joint angles live, and stops them all.
int run_demo(const DemoOptions& options);

}  // namespace bsn::services
