#include "session_streams.hpp"

#include <cmath>

#include "bsn_idl/bsn.h"

namespace bsn::services {

std::size_t RawColumns::measurement_rows() const {
  return std::min({timestamp_ns.size(), acc.size() / 3, gyr.size() / 3, mag.size() / 3, channels.size()});
}

bool RawColumns::measurement_lengths_agree() const {
  const std::size_t n = size();
  return acc.size() == 3 * n && gyr.size() == 3 * n && mag.size() == 3 * n && channels.size() == n;
}

void RawColumns::resize(std::size_t rows) {
  timestamp_ns.resize(rows);
  seq.resize(rows);
  if (!arrival_ns.empty()) arrival_ns.resize(rows);
  acc.resize(3 * rows);
  gyr.resize(3 * rows);
  mag.resize(3 * rows);
  channels.resize(rows);
}

RawColumns read_raw_columns(const io::SessionReader& r, const io::SessionStream& s) {
  RawColumns c;
  c.timestamp_ns = r.read_u64(s, "timestamp_ns");
  c.seq = r.read_u64(s, "seq");
  c.arrival_ns = r.read_u64(s, "arrival_ns");
  c.acc = r.read_f64(s, "acc", 3);
  c.gyr = r.read_f64(s, "gyr", 3);
  c.mag = r.read_f64(s, "mag", 3);
  c.channels = r.read_u32(s, "channels");
  return c;
}

io::Recording raw_recording(const RawColumns& c, std::size_t rows) {
  io::Recording rec;
  const auto n = static_cast<Eigen::Index>(rows);
  rec.timestamp_ns.assign(c.timestamp_ns.begin(), c.timestamp_ns.begin() + static_cast<long>(rows));
  rec.acc.resize(n, 3);
  rec.gyr.resize(n, 3);
  rec.mag.resize(n, 3);
  for (std::size_t i = 0; i < rows; ++i) {
    const auto row = static_cast<Eigen::Index>(i);
    const bool has_mag = (c.channels[i] & bsn::CHANNEL_MAG) != 0;
    for (int k = 0; k < 3; ++k) {
      const std::size_t at = 3 * i + static_cast<std::size_t>(k);
      rec.acc(row, k) = c.acc[at];
      rec.gyr(row, k) = c.gyr[at];
      rec.mag(row, k) = has_mag ? c.mag[at] : std::nan("");
    }
  }
  return rec;
}

}  // namespace bsn::services
