// `bsn export`: a session file into the formats labs use. `sto`: OpenSim OpenSense orientation files; `csv`: one
// file per topic with units in the header; `broad`: one BROAD-layout HDF5 file per node, with the simulator's
// truth as the reference where it was recorded, so `bsn eval` scores a live session.
#pragma once

#include <string>
#include <vector>

#include "command.hpp"

namespace bsn::services {

struct ExportOptions {
  std::string session;
  std::string format;  ///< sto, csv or broad
  std::string out_dir;
  std::string frame = "opensim";  ///< sto: opensim (Y up) or enu (as recorded, Z up)
  /// sto: "segment" (every sample in its segment's ISB frame, the alignment applied to every sample, those before
  /// it too) or "sensor" (every sample in its sensor's frame, the alignment written beside it). Never mixed.
  std::string frames = "segment";
  double from_s = 0.0;                     ///< sto: the first row kept, s from the session's first complete row
  double to_s = 1e300;                     ///< sto: the last row kept, s
  double calibration_at_s = -1.0;          ///< sto: the row of calibration.sto, s (< 0: the first row kept)
  std::vector<std::string> opensim_names;  ///< sto: SEGMENT=BODY overrides of the OpenSim body names
};

int run_export(const ExportOptions& options);

Command export_command();

}  // namespace bsn::services
