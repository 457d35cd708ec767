// `bsn export`: a session file into the formats labs use. `sto`: OpenSim OpenSense orientation files; `csv`: one
// file per topic with units in the header; `broad`: one BROAD-layout HDF5 file per node, with the simulator's
// truth as the reference where it was recorded, so `bsn eval` scores a live session.
#pragma once

#include <string>

#include "command.hpp"

namespace bsn::services {

struct ExportOptions {
  std::string session;
  std::string format;  ///< sto, csv or broad
  std::string out_dir;
  std::string frame = "opensim";  ///< sto: opensim (Y up) or enu (as recorded, Z up)
};

int run_export(const ExportOptions& options);

Command export_command();

}  // namespace bsn::services
