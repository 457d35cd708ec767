#pragma once

#include <string>

namespace bsn::services {

struct EchoOptions {
  std::string topic;
  long count = 0;          ///< stop after this many samples (0 = never)
  double rate_hz = 0.0;    ///< print at most this many samples per second (0 = all)
  double timeout_s = 0.0;  ///< exit 1 if not `count` samples within this time (0 = wait forever)
  int domain = 0;
};

/// Names of the topics `bsn echo` knows.
std::string echo_topic_list();

int run_echo(const EchoOptions& options);

}  // namespace bsn::services
