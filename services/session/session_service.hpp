// `bsn session FILE`: a lab session by one command. The session file (YAML) names the body, the node sources
// (simulated, or real sensors through `bsn node`), where calibrations live, the alignment, what to record and the
// trials, the exports and whether to open the view. The session starts the calibration service, fusion, the nodes
// it owns, the view; guides the alignment procedure (the service's instructions); records each trial with its
// event markers (Enter in the terminal); exports it; and stops every process it started.
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

#include "command.hpp"

namespace bsn::services {

struct SessionError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// A session file, its paths made absolute: the files it reads (body, scenario, maps) relative to the session file,
/// the folders it writes (calibrations, record.out) relative to the working folder.
struct SessionSpec {
  std::string name;
  std::string body_path;  ///< body model file
  std::string store_dir;  ///< the calibration service's store ("calibrations:")
  std::string scenario;   ///< simulated nodes: every segment of the body publishes its segment of this scenario
  struct RealNode {
    std::string node, source, map;  ///< `bsn node --node ID --source URI [--map FILE]`
  };
  std::vector<RealNode> nodes;  ///< real sensors
  bool align = true;
  double pose_s = 3.0;               ///< the N-pose's length
  double align_duration_s = 30.0;    ///< the alignment's longest collection (it ends once good)
  std::string out_dir;               ///< trials/<trial>.h5, trials/<trial>/ (exports), trials/<trial>.events.csv
  double record_s = 30.0;            ///< per trial
  std::vector<std::string> topics;   ///< recorded topics (empty: every topic)
  std::vector<std::string> trials;   ///< names, recorded one after the other
  std::vector<std::string> exports;  ///< formats of bsn export: sto, csv, broad
  bool view = false;
  int view_port = 8080;
};

/// Reads and checks a session file; throws SessionError "FILE:LINE: problem".
SessionSpec load_session(const std::string& path);

/// `bsn session`.
Command session_command();

}  // namespace bsn::services
