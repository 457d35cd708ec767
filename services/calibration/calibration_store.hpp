// The calibration store of `bsn calibration`: one file per node and kind, DIR/<node>.<kind>.calib.yaml, in the
// format `bsn calibrate` writes (so a stored file can be named in a body model as it is). A new result replaces
// the file atomically (temporary file, fsync, rename) and the one it replaces is kept as <file>.previous.
#pragma once

#include <string>
#include <vector>

#include "bsn/calib/calibration_session.hpp"
#include "bsn/config/calibration_file.hpp"

namespace bsn::services {

/// The default store: $XDG_STATE_HOME/bsn/calibration, else $HOME/.local/state/bsn/calibration.
std::string default_calibration_store();

struct StoredCalibration {
  std::string path;
  std::string node;
  calib::CalibrationKind kind;
  config::CalibrationDocument document;
};

class CalibrationStore {
 public:
  /// Creates the directory if needed. Throws std::runtime_error when it cannot.
  explicit CalibrationStore(std::string dir);

  const std::string& dir() const { return dir_; }

  /// Writes a successful result; returns the file's path. Throws std::runtime_error on an I/O failure (then
  /// the previous file is still in place and no temporary file is left).
  std::string save(const std::string& node, const calib::SessionResult& result, const std::string& request_id);
  /// Writes a node's alignment (kind alignment) the same way; returns the file's path. Throws as save().
  std::string save_alignment(const std::string& node, const config::AlignmentRecord& alignment,
                             const std::string& request_id);

  /// Every readable stored calibration (one entry per channel a file holds). A file that does not parse, or
  /// whose node disagrees with its name, is skipped and its "FILE:LINE: problem" added to `problems`. Leftover
  /// temporary files of an interrupted write are removed.
  std::vector<StoredCalibration> load_all(std::vector<std::string>& problems) const;

  /// DIR/<node>.<kind>.calib.yaml (node characters outside [A-Za-z0-9_-] written as %XX).
  std::string path_of(const std::string& node, calib::CalibrationKind kind) const;

 private:
  /// Replaces `path` by `text` atomically, keeping the old file as <path>.previous.
  std::string replace_file(const std::string& path, const std::string& text);

  std::string dir_;
};

}  // namespace bsn::services
