// Reading a session file's streams back (`bsn export`, `bsn replay`, `bsn process`, `bsn calibrate --alignment`): the
// measurement columns of a bsn/raw stream (a stream's samples as their type: session_samples.hpp).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "bsn/io/recording.hpp"
#include "bsn/io/session_file.hpp"
#include "session_samples.hpp"  // read_stream_samples: a stream's samples as their type

namespace bsn::services {

/// The columns of one bsn/raw stream as `bsn record` writes them (sample_fields.cpp names them).
struct RawColumns {
  std::vector<std::uint64_t> timestamp_ns, seq, arrival_ns;
  std::vector<double> acc, gyr, mag;  ///< 3 per sample
  std::vector<std::uint32_t> channels;
  std::size_t size() const { return timestamp_ns.size(); }
  /// Every column to `rows` rows (three values a row for acc, gyr and mag); arrival_ns only when it holds any.
  void resize(std::size_t rows);
  /// Rows that every measurement column (time, acc, gyr, mag, channels) holds: a recording stopped by a crash may
  /// hold one column a write ahead of another.
  std::size_t measurement_rows() const;
  /// Whether every measurement column holds exactly size() rows.
  bool measurement_lengths_agree() const;
};

/// Reads the columns of bsn/raw stream `s`. Throws io::IoError naming the file and dataset.
RawColumns read_raw_columns(const io::SessionReader& r, const io::SessionStream& s);

/// The first `rows` rows of `c` as a recording: its times and three channels, the magnetometer NaN in rows
/// without CHANNEL_MAG. The sampling rate and reference are the caller's.
io::Recording raw_recording(const RawColumns& c, std::size_t rows);

}  // namespace bsn::services
