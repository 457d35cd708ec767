// `bsn record`: every bsn topic (or the ones named) into one HDF5 session file, one group per topic and key, with
// the sample's own fields, the serialised sample and its arrival time; flushed every half second, so a crash
// loses at most that much and leaves a file that opens.
#pragma once

#include <string>
#include <vector>

#include "command.hpp"

namespace bsn::services {

struct RecordOptions {
  std::string out;                  ///< session file (.h5)
  std::vector<std::string> topics;  ///< empty = every topic
  double duration_s = 0.0;          ///< 0 = until SIGINT/SIGTERM
  bool overwrite = false;
  std::string body_path;        ///< body model whose text (and calibrations) go into the metadata
  double flush_period_s = 0.5;  ///< time between writes to disk, s (at most 1 s)
  int domain = 0;
  std::string subject;  ///< the subject (DDS partition) of the estimates and status recorded
};

/// Returns the process exit code: 0, 1 on a write failure (disk full: the message says so), 2 on a usage error.
int run_record(const RecordOptions& options);

/// Names of every bsn topic, in declaration order.
std::vector<std::string> all_topic_names();

Command record_command();

}  // namespace bsn::services
