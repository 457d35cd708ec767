#include "export_service.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>

#include "bsn/dds/topics.hpp"
#include "bsn/fusion/rotation.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/io/session_file.hpp"
#include "sample_fields.hpp"

namespace bsn::services {
namespace {

namespace fs = std::filesystem;

// The serialised samples of one stream, deserialised.
template <class PubSub>
std::vector<typename PubSub::type> read_samples(const io::SessionReader& r, const io::SessionStream& s) {
  const auto cdr = r.read_u8(s, "cdr");
  const auto ends = r.read_u64(s, "cdr_end");
  std::vector<typename PubSub::type> out;
  out.reserve(ends.size());
  PubSub type;
  std::uint64_t begin = 0;
  for (const std::uint64_t end : ends) {
    if (end < begin || end > cdr.size()) {
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
  return out;
}

template <class T>
struct TopicPubSubOf;
template <class P>
struct TopicPubSubOf<dds::Topic<P>> {
  using type = P;
};

std::string file_stem_of(const std::string& topic) {
  std::string stem = topic.rfind("bsn/", 0) == 0 ? topic.substr(4) : topic;
  std::replace(stem.begin(), stem.end(), '/', '_');
  return stem;
}

int export_csv(const io::SessionReader& r, const fs::path& out) {
  int files = 0;
  dds::for_each_topic([&](const auto& topic) {
    using PubSub = typename TopicPubSubOf<std::remove_cvref_t<decltype(topic)>>::type;
    using T = typename PubSub::type;
    const auto streams = r.streams_of(topic.name);
    if (streams.empty()) return;
    if constexpr (HasFields<T>) {
      const fs::path path = out / (file_stem_of(topic.name) + ".csv");
      std::ofstream f(path);
      bool header = false;
      for (const auto& s : streams) {
        const auto arrival = r.read_u64(s, "arrival_ns");
        const auto samples = read_samples<PubSub>(r, s);
        for (std::size_t i = 0; i < samples.size(); ++i) {
          if (!header) {
            f << "arrival_ns [ns since 1970]," << csv_header(samples[i]) << "\n";
            header = true;
          }
          f << csv_row(samples[i], std::to_string(i < arrival.size() ? arrival[i] : 0)) << "\n";
        }
      }
      if (!f) throw io::IoError(path.string() + ": cannot write");
      ++files;
    } else {
      std::fprintf(stderr, "bsn export: %s has no CSV layout yet; skipped\n", topic.name);
    }
  });
  return files;
}

struct Track {
  std::vector<std::uint64_t> ts;
  std::vector<fusion::Quat> q;
};

// One OpenSense orientation file of the streams of `topic`: a time column, then per segment "<segment>_imu" with
// "w,x,y,z" (scalar first), tab-separated, after OpenSim's header (DataRate, DataType=Quaternion, version=3,
// OpenSimVersion, endheader). Rows follow the segment with the most samples; the others are held at their
// latest sample at or before each row's time, and rows before every segment has one are left out.
bool write_sto(const io::SessionReader& r, const std::string& topic, const fs::path& path, bool opensim_frame) {
  std::map<std::string, Track> tracks;
  for (const auto& s : r.streams_of(topic)) {
    Track& t = tracks[s.key];
    t.ts = r.read_u64(s, "timestamp_ns");
    const auto q = r.read_f64(s, "quat", 4);
    const std::size_t n = std::min(t.ts.size(), q.size() / 4);
    t.ts.resize(n);
    for (std::size_t i = 0; i < n; ++i) t.q.emplace_back(q[4 * i], q[4 * i + 1], q[4 * i + 2], q[4 * i + 3]);
  }
  if (tracks.empty()) return false;
  // ENU (z up) to OpenSim's ground (y up): -90 degrees about x, so up -> +Y, east -> +X, north -> -Z.
  const fusion::Quat to_opensim(std::cos(-std::numbers::pi / 4), std::sin(-std::numbers::pi / 4), 0.0, 0.0);
  const auto clock = std::max_element(tracks.begin(), tracks.end(), [](const auto& a, const auto& b) {
    return a.second.ts.size() < b.second.ts.size();
  });
  const std::vector<std::uint64_t>& rows = clock->second.ts;
  if (rows.empty()) return false;
  std::map<std::string, std::size_t> at;  // latest sample index per segment
  std::vector<std::string> lines;
  std::uint64_t t0 = 0;
  for (const std::uint64_t t : rows) {
    std::string line;
    bool complete = true;
    for (const auto& [segment, track] : tracks) {
      std::size_t& k = at[segment];
      while (k + 1 < track.ts.size() && track.ts[k + 1] <= t) ++k;
      if (track.ts.empty() || track.ts[k] > t) {
        complete = false;
        break;
      }
      fusion::Quat q = opensim_frame ? to_opensim * track.q[k] : track.q[k];
      char cell[128];
      std::snprintf(cell, sizeof cell, "\t%.12f,%.12f,%.12f,%.12f", q.w(), q.x(), q.y(), q.z());
      line += cell;
    }
    if (!complete) continue;
    if (lines.empty()) t0 = t;
    char time[40];
    std::snprintf(time, sizeof time, "%.6f", static_cast<double>(t - t0) * 1e-9);
    lines.push_back(time + line);
  }
  if (lines.empty()) return false;
  const double duration = static_cast<double>(rows.back() - t0) * 1e-9;
  const double rate = lines.size() > 1 && duration > 0 ? static_cast<double>(lines.size() - 1) / duration : 0.0;
  std::ofstream f(path);
  f << "DataRate=" << std::to_string(rate) << "\nDataType=Quaternion\nversion=3\nOpenSimVersion=4.5\nendheader\ntime";
  for (const auto& [segment, track] : tracks) f << "\t" << segment << "_imu";
  f << "\n";
  for (const auto& l : lines) f << l << "\n";
  if (!f) throw io::IoError(path.string() + ": cannot write");
  return true;
}

int export_sto(const io::SessionReader& r, const fs::path& out, bool opensim_frame) {
  int files = 0;
  if (write_sto(r, dds::kOrientationTopic.name, out / "orientations.sto", opensim_frame)) ++files;
  if (write_sto(r, dds::kTruthOrientationTopic.name, out / "truth_orientations.sto", opensim_frame)) ++files;
  return files;
}

// Per node of bsn/raw: <segment>.hdf5 (segment from the truth's or the estimates' node_id, else the node id),
// with opt_quat = the truth at the same timestamp (NaN where none).
int export_broad(const io::SessionReader& r, const fs::path& out) {
  std::map<std::string, std::string> segment_of;
  std::map<std::string, std::map<std::uint64_t, std::array<double, 4>>> truth_of;  // by node
  for (const char* topic : {dds::kOrientationTopic.name, dds::kTruthOrientationTopic.name}) {
    for (const auto& s : r.streams_of(topic)) {
      const auto samples = read_samples<bsn::OrientationPubSubType>(r, s);
      for (const auto& o : samples) {
        segment_of[o.node_id()] = o.segment();
        if (topic == std::string(dds::kTruthOrientationTopic.name)) truth_of[o.node_id()][o.timestamp_ns()] = o.quat();
      }
    }
  }
  int files = 0;
  for (const auto& s : r.streams_of(dds::kRawTopic.name)) {
    const auto ts = r.read_u64(s, "timestamp_ns");
    const auto acc = r.read_f64(s, "acc", 3), gyr = r.read_f64(s, "gyr", 3), mag = r.read_f64(s, "mag", 3);
    const auto channels = r.read_u32(s, "channels");
    const std::size_t n = std::min({ts.size(), acc.size() / 3, gyr.size() / 3, mag.size() / 3, channels.size()});
    if (n < 2) continue;
    io::Recording rec;
    const auto rows = static_cast<Eigen::Index>(n);
    rec.acc.resize(rows, 3);
    rec.gyr.resize(rows, 3);
    rec.mag.resize(rows, 3);
    const auto truth = truth_of.find(s.key);
    if (truth != truth_of.end()) rec.opt_quat.resize(rows, 4);
    std::vector<std::uint64_t> dts;
    for (std::size_t i = 0; i < n; ++i) {
      const auto row = static_cast<Eigen::Index>(i);
      const bool has_mag = (channels[i] & bsn::CHANNEL_MAG) != 0;
      for (int k = 0; k < 3; ++k) {
        rec.acc(row, k) = acc[3 * i + static_cast<std::size_t>(k)];
        rec.gyr(row, k) = gyr[3 * i + static_cast<std::size_t>(k)];
        rec.mag(row, k) = has_mag ? mag[3 * i + static_cast<std::size_t>(k)] : std::nan("");
      }
      if (truth != truth_of.end()) {
        const auto q = truth->second.find(ts[i]);
        for (int k = 0; k < 4; ++k)
          rec.opt_quat(row, k) = q == truth->second.end() ? std::nan("") : q->second[static_cast<std::size_t>(k)];
      }
      if (i > 0) dts.push_back(ts[i] - ts[i - 1]);
    }
    // The nominal rate for tools that read BROAD; the samples' own times go along, so gaps and rate changes stay.
    rec.timestamp_ns.assign(ts.begin(), ts.begin() + static_cast<long>(n));
    std::nth_element(dts.begin(), dts.begin() + static_cast<long>(dts.size() / 2), dts.end());
    const std::uint64_t median_dt = dts[dts.size() / 2];
    if (median_dt == 0) throw io::IoError(r.path() + ": stream '" + s.group + "' has no time between samples");
    rec.sampling_rate_hz = 1e9 / static_cast<double>(median_dt);
    const std::string segment = segment_of.count(s.key) ? segment_of.at(s.key) : s.key;
    io::write_broad_hdf5((out / (segment + ".hdf5")).string(), rec);
    ++files;
  }
  return files;
}

}  // namespace

int run_export(const ExportOptions& opt) {
  try {
    const io::SessionReader r(opt.session);
    std::error_code ec;
    fs::create_directories(opt.out_dir, ec);
    if (!fs::is_directory(opt.out_dir)) {
      std::fprintf(stderr, "bsn export: error: cannot create folder %s\n", opt.out_dir.c_str());
      return 1;
    }
    int files = 0;
    if (opt.format == "csv") files = export_csv(r, opt.out_dir);
    if (opt.format == "sto") files = export_sto(r, opt.out_dir, opt.frame == "opensim");
    if (opt.format == "broad") files = export_broad(r, opt.out_dir);
    if (files == 0) {
      std::fprintf(stderr, "bsn export: error: %s holds nothing to export as %s\n", opt.session.c_str(),
                   opt.format.c_str());
      return 1;
    }
    std::fprintf(stderr, "bsn export: %d files in %s\n", files, opt.out_dir.c_str());
    return 0;
  } catch (const io::IoError& e) {
    std::fprintf(stderr, "bsn export: error: %s\n", e.what());
    return 1;
  }
}

Command export_command() {
  return {"export", "Export a session file: OpenSim .sto, CSV per topic, or BROAD HDF5 per node", [](CLI::App* cmd) {
            auto opt = std::make_shared<ExportOptions>();
            cmd->add_option("session", opt->session, "session file from bsn record")->required();
            cmd->add_option("--format", opt->format, "sto, csv or broad")
                ->required()
                ->check(CLI::IsMember({"sto", "csv", "broad"}));
            cmd->add_option("--out", opt->out_dir, "output folder")->required();
            cmd->add_option("--frame", opt->frame, "sto: opensim (ground Y up) or enu (as recorded, Z up)")
                ->check(CLI::IsMember({"opensim", "enu"}))
                ->capture_default_str();
            return [opt] { return run_export(*opt); };
          }};
}

}  // namespace bsn::services
