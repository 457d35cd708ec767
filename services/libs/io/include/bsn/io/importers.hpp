// Importers: the multi-sensor recordings labs already hold, each read by a small reader behind one interface into
// per-node Recordings (raw samples with their timestamps, in bsn's units and the sensor's own frame, and a reference
// orientation where the format has one). `bsn process` and `bsn eval --body` read their input through these.
// Formats, units and frames: docs/importers.md.
#pragma once

#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "bsn/io/recording.hpp"
#include "bsn/io/units.hpp"

namespace bsn::io {

struct ImportOptions {
  UnitOptions units;          ///< overrides of the units a format assumes (--unit QUANTITY=UNIT)
  std::string imu = "rigid";  ///< DIODEM: which of its two IMUs per segment, rigid or nonrigid
};

/// One node's recording, named as the format names it (a file's stem, a DIODEM segment prefix).
struct ImportedNode {
  std::string name;
  Recording rec;
};

class RecordingImporter {
 public:
  virtual ~RecordingImporter() = default;
  /// The --format name.
  virtual std::string name() const = 0;
  /// Reads the input at `path` (a file, or a folder where the format defines one). Malformed content throws
  /// FormatError naming file:line; an unreadable file IoError.
  virtual std::vector<ImportedNode> read(const std::string& path, const ImportOptions& options) const = 0;
  /// Reads one file's text; `source` names it in errors and gives the node's name. Formats that are not text throw.
  virtual std::vector<ImportedNode> parse(std::string_view text, const std::string& source,
                                          const ImportOptions& options) const = 0;
};

/// Every importer: bsn-csv, broad-hdf5, diodem, xsens-dot.
const std::vector<const RecordingImporter*>& recording_importers();

/// The importer named `name`; throws std::invalid_argument listing the names.
const RecordingImporter& recording_importer(const std::string& name);

/// The input's format, for --format auto: a DIODEM trial folder or file (`*_imu_rigid.csv`, `*_omc.csv`), an
/// Xsens DOT export (a header with SampleTimeFine), a BROAD HDF5 (.h5, .hdf5), else bsn's CSV.
std::string detect_format(const std::string& path);

/// Reads an input: a file (one node, or a DIODEM trial), a DIODEM trial folder, or a folder of per-node files (each
/// in its own format under "auto", else all in `format`; files of other extensions are left out). Nodes come sorted
/// by name; two of one name are a FormatError. With `wanted`, a node (or a folder's file, by its stem) it refuses is
/// not read, and listed in `left_out` if given.
std::vector<ImportedNode> import_recordings(const std::string& path, const std::string& format,
                                            const ImportOptions& options,
                                            const std::function<bool(const std::string&)>& wanted = {},
                                            std::vector<std::string>* left_out = nullptr);

}  // namespace bsn::io
