// Recordings on disk: BROAD-layout HDF5 (read and write) and CSV (read). I/O only; the cores never see files.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <iosfwd>
#include <stdexcept>
#include <string>
#include <vector>

#include "bsn/fusion/imu_sample.hpp"
#include "bsn/io/units.hpp"

namespace bsn::io {

using RowsX3 = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
using RowsX4 = Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor>;

/// A read or write failure; the message names the file and what is wrong.
class IoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Malformed content in an input file (a bad cell, a missing column, a time going back): the user's input is wrong,
/// not the machine (the commands exit 2). The message names the file and line.
class FormatError : public IoError {
 public:
  using IoError::IoError;
};

/// One sensor's recording in the BROAD layout (../shared/data/broad/README.md), in the project's units.
struct Recording {
  double sampling_rate_hz = 0.0;  ///< nominal rate, Hz
  RowsX3 gyr;                     ///< rad/s, sensor frame, N x 3
  RowsX3 acc;                     ///< m/s^2, sensor frame, N x 3
  RowsX3 mag;                     ///< uT, sensor frame, N x 3; a row of NaN = no magnetometer sample
  RowsX4 opt_quat;                ///< reference (w, x, y, z) sensor-to-earth ENU, N x 4 or empty; NaN = no reference
  RowsX3 opt_pos;                 ///< marker position, m, N x 3 or empty
  std::vector<std::uint8_t> movement;       ///< 1 where errors count, N or empty (= all)
  std::vector<std::uint64_t> timestamp_ns;  ///< per-sample time, N or empty (= uniform at sampling_rate_hz)

  std::size_t size() const { return static_cast<std::size_t>(gyr.rows()); }
  /// Timestamp of sample i: the recorded one, or i / sampling_rate_hz.
  std::uint64_t time_ns(std::size_t i) const;
  /// Whether sample i has a magnetometer reading: a row of three NaN means none (a slower magnetometer).
  bool has_mag(std::size_t i) const { return !mag.row(static_cast<Eigen::Index>(i)).array().isNaN().all(); }
  /// Sample i as the filters take it (has_mag(i) as above).
  fusion::ImuSample sample(std::size_t i) const;
  /// Throws IoError naming `source` if the sizes disagree or the rate is not positive.
  void validate(const std::string& source) const;
};

/// A recording of `rows` samples at `sampling_rate_hz` with a reference: gyr, acc, mag and opt_quat sized, their
/// values unset (a simulator's recording, filled row by row with set_measurement_row).
Recording sized_recording(double sampling_rate_hz, Eigen::Index rows);
/// Writes sample `s`'s gyroscope, accelerometer and magnetometer into row `row` (no magnetometer: a NaN row).
void set_measurement_row(Recording& rec, Eigen::Index row, const fusion::ImuSample& s);

/// Reads a BROAD-layout HDF5 file (imu_gyr, imu_acc, imu_mag, optional opt_quat, opt_pos, movement, attribute
/// sampling_rate), and bsn's optional timestamp_ns (uint64 per sample, written by `bsn export --format broad`).
Recording read_broad_hdf5(const std::string& path);

/// Writes a recording in the BROAD layout; optional parts that are empty are left out.
void write_broad_hdf5(const std::string& path, const Recording& rec);

/// Reads a CSV recording. The first line is a header naming the columns, in any order, each optionally with its unit
/// in brackets (`acc_x [g]`, `gyr_x [deg/s]`, `t [ms]`; units.hpp lists them), else the unit below or `units`':
///   t_s or t_ns, or t / time     sample time (seconds, integer nanoseconds, or t in a stated unit)  required
///   acc_x, acc_y, acc_z          m/s^2                                                         required
///   gyr_x, gyr_y, gyr_z          rad/s                                                         required
///   mag_x, mag_y, mag_z          uT; empty cells = no magnetometer sample                      optional
///   quat_w, quat_x, quat_y, quat_z   reference orientation, sensor-to-earth ENU                optional
///   movement                     0/1, where errors count                                       optional
/// Lines starting with '#' are comments. The sampling rate is the median sample interval's inverse. A column's unit
/// in the header and another in `units` is an error (never one silently chosen). Content errors are FormatError.
Recording read_csv(const std::string& path, const UnitOptions& units = {});
/// The same from a stream; `source` names it in errors.
Recording read_csv(std::istream& in, const std::string& source, const UnitOptions& units = {});

/// Reads by extension: .csv as CSV, anything else as BROAD HDF5.
Recording read_recording(const std::string& path);

}  // namespace bsn::io
