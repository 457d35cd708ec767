// `bsn process`: a recorded session, or a folder of per-node recordings, through the body pipeline of `bsn fusion`
// (FusionPipeline: calibration, gate, filters, joint angles) without DDS, as fast as the CPU allows, into a session
// file of the layout `bsn record` writes (bsn/orientation, bsn/joint_angles, bsn/status), which `bsn export` reads.
#pragma once

#include <string>
#include <vector>

#include "command.hpp"

namespace bsn::services {

/// How the recordings are read: the importers' options (--format, --unit, --imu).
struct ImportSelection {
  std::string format = "auto";     ///< the recordings' format (bsn/io/importers.hpp); auto: by each file
  std::vector<std::string> units;  ///< QUANTITY=UNIT overriding a format's units (--unit)
  std::string imu = "rigid";       ///< DIODEM: rigid or nonrigid
  bool is_default() const { return format == "auto" && units.empty() && imu == "rigid"; }
};

struct ProcessOptions {
  std::string input;  ///< a session file, a recording file, or a folder of per-node recordings (or a DIODEM trial)
  ImportSelection import;
  std::string body_path;  ///< "" = the session's recorded body model (a folder needs one)
  std::string out;        ///< session file to write
  bool overwrite = false;
  std::vector<std::string> filters;            ///< NAME[:k=v,...] for every segment (the last one given wins)
  std::vector<std::string> calibration_files;  ///< calibration files (`bsn calibrate`), applied from the first sample
  /// first-sample: the session's last successful calibration result per node and kind applied before its first
  /// sample; as-recorded: each at the instant it arrived during the recording (as the live fusion applied it).
  std::string calibrations = "first-sample";
  /// arrival: the samples in the order they arrived at the recorder (the live fusion's order); time: by sensor
  /// time, a parent before its child at one instant. Default: arrival for a session, time for a folder.
  std::string order;
  bool quiet = false;     ///< no progress bar
  bool copy_raw = false;  ///< write the input's raw samples as bsn/raw too (a complete session: replay, alignment)
};

/// Returns the exit code: 0, 1 (a read or write failure) or 2 (a usage error: a bad option, body or input).
int run_process(const ProcessOptions& options);

/// `bsn eval --body`: the recordings' reference orientation per segment (BROAD opt_quat, or a session's
/// bsn/truth/orientation) against the body pipeline's estimates: per segment the BROAD error angles, per joint the
/// RMS of the relative orientation's error and of the named anatomical angles, without and with a per-segment
/// constant alignment (fitted over `align_window`).
struct BodyEvalOptions {
  std::string input;  ///< as ProcessOptions::input
  std::string body_path;
  ImportSelection import;
  std::vector<std::string> filters;
  std::string align_window = "all";  ///< all, none, or A:B (seconds from the first sample)
  bool json = false;
  std::string plot_path;  ///< SVG of each joint's error over time ("" = none)
};
int run_body_eval(const BodyEvalOptions& options);

/// --format, --unit and --imu (the importers' options) on a command.
void add_import_options(CLI::App* cmd, ImportSelection& import);

Command process_command();

}  // namespace bsn::services
