// Reading a session file's streams back (`bsn export`, `bsn replay`, `bsn process`, `bsn calibrate --alignment`): the
// serialised samples of a stream as their type, and the measurement columns of a bsn/raw stream.
#pragma once

#include <fastdds/rtps/common/SerializedPayload.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "bsn/io/recording.hpp"
#include "bsn/io/session_file.hpp"

namespace bsn::services {

/// The samples of stream `s`, deserialised from its "cdr" and "cdr_end" columns; with `arrival`, also its
/// "arrival_ns" column, one per sample. Throws io::IoError naming the file and dataset when an offset points
/// outside the data, a sample is over 1 MiB (no bsn type comes near; a corrupt offset would allocate it) or does
/// not deserialise as its type.
template <class PubSub>
std::vector<typename PubSub::type> read_samples(const io::SessionReader& r, const io::SessionStream& s,
                                                std::vector<std::uint64_t>* arrival = nullptr) {
  const auto cdr = r.read_u8(s, "cdr");
  const auto ends = r.read_u64(s, "cdr_end");
  if (arrival) *arrival = r.read_u64(s, "arrival_ns");
  std::vector<typename PubSub::type> out;
  out.reserve(ends.size());
  PubSub type;
  std::uint64_t begin = 0;
  for (const std::uint64_t end : ends) {
    if (end < begin || end > cdr.size() || end - begin > (1u << 20)) {
      throw io::IoError(r.path() + ": dataset '" + s.group + "/cdr_end' points outside '" + s.group + "/cdr'");
    }
    eprosima::fastrtps::rtps::SerializedPayload_t payload(static_cast<std::uint32_t>(end - begin));
    std::copy(cdr.begin() + static_cast<long>(begin), cdr.begin() + static_cast<long>(end), payload.data);
    payload.length = static_cast<std::uint32_t>(end - begin);
    typename PubSub::type sample;
    if (!type.deserialize(&payload, &sample)) {
      throw io::IoError(r.path() + ": a sample in '" + s.group + "/cdr' does not deserialise as " + s.type);
    }
    out.push_back(std::move(sample));
    begin = end;
  }
  if (arrival && arrival->size() != out.size())
    throw io::IoError(r.path() + ": '" + s.group + "/arrival_ns' and '" + s.group + "/cdr_end' differ in length");
  return out;
}

/// The columns of one bsn/raw stream as `bsn record` writes them (sample_fields.cpp names them).
struct RawColumns {
  std::vector<std::uint64_t> timestamp_ns, seq, arrival_ns;
  std::vector<double> acc, gyr, mag;  ///< 3 per sample
  std::vector<std::uint32_t> channels;
  std::size_t size() const { return timestamp_ns.size(); }
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
