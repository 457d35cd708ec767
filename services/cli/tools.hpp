// bsn's own tools, each in its own source next to its run function: `bsn echo` (print a topic live), `bsn demo`
// (simulated body + fusion in the terminal), `bsn eval` (score filters on recordings), `bsn calibrate` (offline
// calibration and Allan noise figures), `bsn tune` (identify filter parameters on recordings). Services (fusion, sim,
// ...) declare their command in their own header.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "command.hpp"

namespace bsn::services {

Command echo_command();
Command demo_command();
Command eval_command();
Command calibrate_command();
Command tune_command();

/// A recording file by its extension: .hdf5, .h5 (BROAD layout) or .csv.
bool is_recording_file(const std::filesystem::path& p);
/// Files named on the command line, and the recordings inside folders named there (sorted). Throws
/// std::runtime_error naming a missing path or a folder without recordings.
std::vector<std::filesystem::path> expand_recording_inputs(const std::vector<std::string>& inputs);

}  // namespace bsn::services
