#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "alignment_nodes.hpp"
#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/io/session_file.hpp"
#include "calibrate_modes.hpp"
#include "calibration_wire.hpp"
#include "session_streams.hpp"

namespace bsn::services {
namespace {

/// The bsn/raw streams of a session file as recordings, by node id (the sampling rate from the median interval).
std::map<std::string, io::Recording> session_recordings(const std::string& path) {
  const io::SessionReader r(path);
  std::map<std::string, io::Recording> out;
  for (const io::SessionStream& s : r.streams_of("bsn/raw")) {
    const RawColumns raw = read_raw_columns(r, s);
    if (!raw.measurement_lengths_agree())
      throw io::IoError(path + ": the datasets of '" + s.group + "' differ in length");
    io::Recording rec = raw_recording(raw, raw.size());
    std::vector<std::uint64_t> dt;
    for (std::size_t k = 1; k < rec.timestamp_ns.size(); ++k)
      if (rec.timestamp_ns[k] > rec.timestamp_ns[k - 1]) dt.push_back(rec.timestamp_ns[k] - rec.timestamp_ns[k - 1]);
    if (dt.empty()) continue;
    std::nth_element(dt.begin(), dt.begin() + static_cast<long>(dt.size() / 2), dt.end());
    rec.sampling_rate_hz = 1e9 / static_cast<double>(dt[dt.size() / 2]);
    out.emplace(s.key, std::move(rec));
  }
  return out;
}

namespace fs = std::filesystem;

/// The body whose nodes are aligned: --body, else a session file's recorded body, else the default lower body.
/// Throws config::ConfigError or io::IoError.
fusion::BodyModel alignment_body(const CalibrateOptions& opt, bool from_file) {
  if (!opt.live_options.body_path.empty()) return config::load_body_model(opt.live_options.body_path);
  if (from_file && io::SessionReader(opt.alignment).attributes().count("body_model"))
    return config::parse_body_model(io::SessionReader(opt.alignment).attributes().at("body_model"),
                                    opt.alignment + " (its body_model attribute)");
  return fusion::default_lower_body();
}

/// One recording per node, in the order of `nodes`: from the session file's bsn/raw, or DIR/<node>.hdf5. Returns 0, or
/// 2 (said on stderr) when a node's recording is missing or unreadable.
int node_recordings(const CalibrateOptions& opt, const std::vector<calib::AlignmentNode>& nodes,
                    std::map<std::string, io::Recording>* from_session, std::vector<io::Recording>& recordings) {
  for (const calib::AlignmentNode& n : nodes) {
    if (from_session != nullptr) {
      const auto it = from_session->find(n.node);
      if (it == from_session->end()) {
        std::fprintf(stderr,
                     "bsn calibrate: --alignment: %s has no bsn/raw samples of node '%s': the alignment needs every "
                     "node of the body (--body for another body)\n",
                     opt.alignment.c_str(), n.node.c_str());
        return 2;
      }
      recordings.push_back(std::move(it->second));
      continue;
    }
    const std::string path = (fs::path(opt.alignment) / (n.node + ".hdf5")).string();
    if (!fs::exists(path)) {
      std::fprintf(stderr,
                   "bsn calibrate: --alignment: %s is missing: the alignment needs a recording of every node of the "
                   "body (bsn export SESSION.h5 --format broad --out DIR writes DIR/<node>.hdf5; --body for another "
                   "body)\n",
                   path.c_str());
      return 2;
    }
    try {
      recordings.push_back(io::read_recording(path));
    } catch (const std::exception& e) {
      std::fprintf(stderr, "bsn calibrate: error: %s\n", e.what());
      return 2;
    }
  }
  return 0;
}

/// Runs the recordings through an AlignmentSession, the samples in time order across the nodes, arriving at their
/// sensor time, as a live collection sees them. Returns 0, or 2 (said on stderr) when there is nothing to align.
int align_recordings(const std::vector<calib::AlignmentNode>& nodes, const std::vector<io::Recording>& recordings,
                     double pose_s, calib::AlignmentSessionResult& result) {
  struct Arrival {
    std::uint64_t t;
    std::size_t node, index;
  };
  std::vector<Arrival> arrivals;
  for (std::size_t i = 0; i < recordings.size(); ++i)
    for (std::size_t k = 0; k < recordings[i].size(); ++k) arrivals.push_back({recordings[i].time_ns(k), i, k});
  std::sort(arrivals.begin(), arrivals.end(), [](const Arrival& a, const Arrival& b) { return a.t < b.t; });
  if (arrivals.empty()) {
    std::fprintf(stderr, "bsn calibrate: --alignment: the recordings hold no sample\n");
    return 2;
  }
  calib::AlignmentSessionParams params;
  const double span_s = static_cast<double>(arrivals.back().t - arrivals.front().t) * 1e-9;
  params.max_duration_s = std::max(params.max_duration_s, span_s + 10.0);
  params.max_samples = std::max(params.max_samples, arrivals.size());
  params.duration_s = span_s + 5.0;
  if (pose_s > 0.0) params.pose_s = pose_s;
  if (const std::string why = calib::validate(params); !why.empty()) {
    std::fprintf(stderr, "bsn calibrate: --alignment: %s\n", why.c_str());
    return 2;
  }
  calib::AlignmentSession session(nodes, params, arrivals.front().t);
  for (const Arrival& a : arrivals) {
    calib::SessionSample s = session_sample(recordings[a.node].sample(a.index), a.index);
    s.timestamp_ns = a.t;
    session.add(a.node, s, a.t);
  }
  result = session.finish(arrivals.back().t);
  return 0;
}

/// Writes OUT_DIR/<node>.alignment.calib.yaml per aligned node and reports each; returns 0 when every node aligned,
/// else 1.
int write_alignments(const std::vector<calib::AlignmentNode>& nodes, const calib::AlignmentSessionResult& r,
                     const std::string& out_dir) {
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  std::size_t aligned = 0;
  if (r.problem.empty())
    std::printf("N-pose %.1f .. %.1f s, flexions to %.1f s\n", r.pose_start_s, r.pose_end_s, r.moves_end_s);
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const calib::NodeAlignment& a = r.nodes[i];
    if (!a.success) {
      std::printf("%s: alignment FAILED: %s\n", nodes[i].node.c_str(), a.message.c_str());
      continue;
    }
    const config::AlignmentRecord record{nodes[i].segment,    a.sensor_to_segment,  a.source,
                                         a.relative_residual, a.axis_observability, a.samples};
    const std::string path = (fs::path(out_dir) / (nodes[i].node + ".alignment.calib.yaml")).string();
    std::ofstream(path) << config::alignment_to_yaml(nodes[i].node, record);
    const calib::Quat& q = a.sensor_to_segment;
    std::printf("%s: aligned to segment %s (%s", nodes[i].node.c_str(), nodes[i].segment.c_str(), a.source.c_str());
    if (a.axis_observability > 0.0)
      std::printf(", hinge residual %.3f, axis observability %.3f", a.relative_residual, a.axis_observability);
    std::printf(")\n  sensor_to_segment = [%.6f, %.6f, %.6f, %.6f] -> %s\n", q.w(), q.x(), q.y(), q.z(), path.c_str());
    ++aligned;
  }
  return aligned == nodes.size() ? 0 : 1;
}

}  // namespace

/// `--alignment DIR`: the alignment of a recorded lab procedure (N-pose, flexions) from DIR/<node>.hdf5 per node of
/// the body, as the calibration service would align it live; writes DIR/<node>.alignment.calib.yaml (or --output).
int run_offline_alignment(const CalibrateOptions& opt) {
  // A session file (bsn record) instead of a folder: its bsn/raw per node, its recorded body unless --body.
  const bool from_file = fs::is_regular_file(opt.alignment) && io::is_session_file(opt.alignment);
  std::map<std::string, io::Recording> from_session;
  fusion::BodyModel body;
  try {
    if (from_file) from_session = session_recordings(opt.alignment);
    body = alignment_body(opt, from_file);
  } catch (const config::ConfigError& e) {
    std::fprintf(stderr, "bsn calibrate: error: %s\n", e.what());
    return 2;
  } catch (const io::IoError& e) {
    std::fprintf(stderr, "bsn calibrate: error: %s\n", e.what());
    return 2;
  }
  std::string problem;
  const std::vector<calib::AlignmentNode> nodes = alignment_nodes(body, {}, problem);
  std::vector<io::Recording> recordings;
  if (const int code = node_recordings(opt, nodes, from_file ? &from_session : nullptr, recordings); code != 0)
    return code;
  calib::AlignmentSessionResult result;
  if (const int code = align_recordings(nodes, recordings, opt.live_options.pose_s, result); code != 0) return code;
  const std::string out_dir = !opt.output.empty() ? opt.output
                              : from_file         ? fs::path(opt.alignment).parent_path().string()
                                                  : opt.alignment;
  return write_alignments(nodes, result, out_dir);
}

}  // namespace bsn::services
