#include <algorithm>
#include <array>
#include <cmath>
#include <map>

#include "bsn/dds/topics.hpp"
#include "bsn/io/recording.hpp"
#include "export_formats.hpp"
#include "session_streams.hpp"

namespace bsn::services {

namespace {

// Per node: its segment (from the truth's or the estimates' node_id) and the truth's orientations by sensor time.
struct NodeTruth {
  std::map<std::string, std::string> segment_of;
  std::map<std::string, std::map<std::uint64_t, std::array<double, 4>>> truth_of;
};

NodeTruth node_truth(const io::SessionReader& r) {
  NodeTruth out;
  for (const char* topic : {dds::kOrientationTopic.name, dds::kTruthOrientationTopic.name}) {
    for (const auto& s : r.streams_of(topic)) {
      const auto samples = read_stream_samples<bsn::OrientationPubSubType>(r, s);
      for (const auto& o : samples) {
        out.segment_of[o.node_id()] = o.segment();
        if (topic == std::string(dds::kTruthOrientationTopic.name))
          out.truth_of[o.node_id()][o.timestamp_ns()] = o.quat();
      }
    }
  }
  return out;
}

// opt_quat = the truth at each sample's timestamp (NaN where none).
void add_reference(io::Recording& rec, const std::map<std::uint64_t, std::array<double, 4>>& truth) {
  rec.opt_quat.resize(static_cast<Eigen::Index>(rec.size()), 4);
  for (std::size_t i = 0; i < rec.size(); ++i) {
    const auto q = truth.find(rec.timestamp_ns[i]);
    for (int k = 0; k < 4; ++k)
      rec.opt_quat(static_cast<Eigen::Index>(i), k) =
          q == truth.end() ? std::nan("") : q->second[static_cast<std::size_t>(k)];
  }
}

}  // namespace

// Per node of bsn/raw: <segment>.hdf5 (segment from the truth's or the estimates' node_id, else the node id),
// with opt_quat = the truth at the same timestamp (NaN where none).
int export_broad(const io::SessionReader& r, const std::filesystem::path& out) {
  const NodeTruth nodes = node_truth(r);
  int files = 0;
  for (const auto& s : r.streams_of(dds::kRawTopic.name)) {
    const RawColumns raw = read_raw_columns(r, s);
    const std::size_t n = raw.measurement_rows();
    if (n < 2) continue;
    io::Recording rec = raw_recording(raw, n);
    if (const auto truth = nodes.truth_of.find(s.key); truth != nodes.truth_of.end()) add_reference(rec, truth->second);
    // The nominal rate for tools that read BROAD; the samples' own times go along, so gaps and rate changes stay.
    std::vector<std::uint64_t> dts;
    for (std::size_t i = 1; i < n; ++i) dts.push_back(rec.timestamp_ns[i] - rec.timestamp_ns[i - 1]);
    std::nth_element(dts.begin(), dts.begin() + static_cast<long>(dts.size() / 2), dts.end());
    const std::uint64_t median_dt = dts[dts.size() / 2];
    if (median_dt == 0) throw io::IoError(r.path() + ": stream '" + s.group + "' has no time between samples");
    rec.sampling_rate_hz = 1e9 / static_cast<double>(median_dt);
    const std::string segment = nodes.segment_of.count(s.key) ? nodes.segment_of.at(s.key) : s.key;
    io::write_broad_hdf5((out / (segment + ".hdf5")).string(), rec);
    ++files;
  }
  return files;
}

}  // namespace bsn::services
