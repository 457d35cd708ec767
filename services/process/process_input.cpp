#include "process_input.hpp"

#include <algorithm>
#include <filesystem>
#include <iterator>

#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/eval/evaluation.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/io/importers.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/io/session_file.hpp"
#include "session_samples.hpp"

namespace bsn::services::process_detail {
namespace {

namespace fs = std::filesystem;

void read_session(const std::string& path, ProcessInput& in) {
  io::SessionReader r(path);
  in.session = true;
  if (const auto it = r.attributes().find("body_model"); it != r.attributes().end()) in.recorded_body = it->second;
  for (const io::SessionStream& s : r.streams_of(dds::kRawTopic.name)) {
    NodeTrack t;
    static_cast<RawColumns&>(t) = read_raw_columns(r, s);
    const std::size_t n = t.size();
    if (t.seq.size() != n || t.arrival_ns.size() != n || !t.measurement_lengths_agree()) {
      throw io::IoError(path + ": the datasets of '" + s.group + "' differ in length");
    }
    t.node = s.key;
    in.tracks.push_back(std::move(t));
  }
  for (const io::SessionStream& s : r.streams_of(dds::kCalibrationResultTopic.name)) {
    std::vector<std::uint64_t> arrival;
    auto results = read_stream_samples<bsn::CalibrationResultPubSubType>(r, s, &arrival);
    for (std::size_t i = 0; i < results.size(); ++i) in.calibrations.push_back({arrival[i], std::move(results[i])});
  }
  std::stable_sort(in.calibrations.begin(), in.calibrations.end(),
                   [](const auto& a, const auto& b) { return a.arrival_ns < b.arrival_ns; });
  for (const io::SessionStream& s : r.streams_of(dds::kTruthOrientationTopic.name)) {
    std::vector<std::uint64_t> arrival;
    auto truth = read_stream_samples<bsn::OrientationPubSubType>(r, s, &arrival);
    in.truth.insert(in.truth.end(), std::make_move_iterator(truth.begin()), std::make_move_iterator(truth.end()));
    in.truth_arrival_ns.insert(in.truth_arrival_ns.end(), arrival.begin(), arrival.end());
  }
}

// Recordings (a folder of per-node files, one file, a DIODEM trial) through the importers; each node named after its
// node or its segment in the body.
std::string read_recordings(const ProcessOptions& opt, ProcessInput& in, const fusion::BodyModel& body,
                            std::vector<std::string>& notes) {
  if (opt.import.imu != "rigid" && opt.import.imu != "nonrigid")
    throw UsageError("--imu must be rigid or nonrigid, not '" + opt.import.imu + "'");
  io::ImportOptions import;
  import.imu = opt.import.imu;
  for (const std::string& u : opt.import.units) io::add_unit_option(import.units, u);
  auto wanted = [&](const std::string& name) {
    return std::any_of(body.segments.begin(), body.segments.end(),
                       [&](const fusion::SegmentSpec& s) { return s.node == name || s.name == name; });
  };
  std::vector<std::string> left_out;
  std::vector<io::ImportedNode> nodes = io::import_recordings(opt.input, opt.import.format, import, wanted, &left_out);
  for (std::size_t i = 0; i < body.segments.size(); ++i) {
    const fusion::SegmentSpec& spec = body.segments[i];
    auto it = std::find_if(nodes.begin(), nodes.end(), [&](const io::ImportedNode& n) { return n.name == spec.node; });
    if (it == nodes.end())
      it = std::find_if(nodes.begin(), nodes.end(), [&](const io::ImportedNode& n) { return n.name == spec.name; });
    if (it == nodes.end()) {
      notes.push_back("segment '" + spec.name + "' (node '" + spec.node + "') has no recording in " + opt.input);
      continue;
    }
    const io::Recording& rec = it->rec;
    NodeTrack t;
    t.node = spec.node;
    t.segment = i;
    const std::size_t n = rec.size();
    // Column by column from the recording's row-major N x 3 arrays, the values Recording::sample gives.
    t.timestamp_ns.resize(n);
    t.seq.resize(n);
    t.channels.resize(n);
    t.acc.assign(rec.acc.data(), rec.acc.data() + 3 * n);
    t.gyr.assign(rec.gyr.data(), rec.gyr.data() + 3 * n);
    t.mag.assign(rec.mag.data(), rec.mag.data() + 3 * n);
    for (std::size_t k = 0; k < n; ++k) {
      t.timestamp_ns[k] = rec.time_ns(k);
      t.seq[k] = k;
      const bool has_mag = rec.has_mag(k);
      if (!has_mag) std::fill_n(&t.mag[3 * k], 3, 0.0);
      t.channels[k] = bsn::CHANNEL_ACC | bsn::CHANNEL_GYR | (has_mag ? bsn::CHANNEL_MAG : 0u);
    }
    if (rec.opt_quat.rows() == static_cast<Eigen::Index>(n)) {
      RecordedTruth truth;
      truth.segment = spec.name;
      truth.node = spec.node;
      truth.timestamp_ns.reserve(n);
      truth.quat.reserve(4 * n);
      for (std::size_t k = 0; k < n; ++k) {
        const auto q = rec.opt_quat.row(static_cast<Eigen::Index>(k));
        if (!q.allFinite()) continue;
        truth.timestamp_ns.push_back(t.timestamp_ns[k]);
        truth.quat.insert(truth.quat.end(), q.data(), q.data() + 4);
      }
      if (truth.size() > 0) in.recorded_truth.push_back(std::move(truth));
    }
    t.arrival_ns = t.timestamp_ns;
    in.tracks.push_back(std::move(t));
  }
  for (const std::string& what : left_out)
    notes.push_back(what + " is the recording of no node or segment of the body: left out");
  // What was found, for the error when no segment has a recording.
  std::string found;
  for (const std::string& what : left_out) found += (found.empty() ? "" : ", ") + what;
  return found;
}

fusion::BodyModel load_body(const ProcessOptions& opt, const ProcessInput* session) {
  if (!opt.body_path.empty()) {
    fusion::BodyModel body = config::load_body_model(opt.body_path);
    config::apply_body_alignments(opt.body_path, body);
    return body;
  }
  if (session && !session->recorded_body.empty())
    return config::parse_body_model(session->recorded_body, opt.input + " (its body_model attribute)");
  throw UsageError("--body is required for a folder of recordings (and for a session without a recorded body)");
}

}  // namespace

std::vector<Event> merge_events(const ProcessInput& in, const std::string& order, bool calibrations) {
  std::vector<Event> events;
  std::size_t total = 0;
  for (const NodeTrack& t : in.tracks) total += t.size();
  events.reserve(total + in.calibrations.size());
  const bool by_arrival = order == "arrival";
  std::vector<std::size_t> run_ends;  // one run per track, then the calibrations
  for (std::uint32_t k = 0; k < in.tracks.size(); ++k) {
    const NodeTrack& t = in.tracks[k];
    const auto rank = static_cast<std::uint32_t>(t.segment);
    for (std::size_t i = 0; i < t.size(); ++i) {
      events.push_back(by_arrival ? Event{t.arrival_ns[i], t.timestamp_ns[i], rank, k, i}
                                  : Event{t.timestamp_ns[i], 0, rank, k, i});
    }
    run_ends.push_back(events.size());
  }
  if (calibrations) {
    if (!by_arrival) throw UsageError("--calibrations as-recorded needs --order arrival (a session's arrival times)");
    for (std::size_t i = 0; i < in.calibrations.size(); ++i)
      events.push_back({in.calibrations[i].arrival_ns, 0, 0, Event::kCalibration, i});
    run_ends.push_back(events.size());
  }
  const auto before = [](const Event& a, const Event& b) {
    if (a.key != b.key) return a.key < b.key;
    if (a.tie != b.tie) return a.tie < b.tie;
    return a.rank < b.rank;
  };
  // The stable sort of the whole, done as the stable merge of the runs, each stably sorted first (a track comes in
  // time order, so that is a check): the same order in a few passes instead of a sort of every sample.
  std::vector<std::size_t> starts{0};
  for (const std::size_t end : run_ends) {
    if (!std::is_sorted(events.begin() + static_cast<long>(starts.back()), events.begin() + static_cast<long>(end),
                        before))
      std::stable_sort(events.begin() + static_cast<long>(starts.back()), events.begin() + static_cast<long>(end),
                       before);
    starts.push_back(end);
  }
  while (starts.size() > 2) {  // starts: the bounds of the runs, first 0, last events.size()
    std::vector<std::size_t> merged{0};
    for (std::size_t r = 0; r + 1 < starts.size(); r += 2) {
      if (r + 2 < starts.size()) {
        const auto at = [&](std::size_t k) { return events.begin() + static_cast<long>(starts[k]); };
        std::inplace_merge(at(r), at(r + 1), at(r + 2), before);
        merged.push_back(starts[r + 2]);
      } else {
        merged.push_back(starts[r + 1]);
      }
    }
    starts = std::move(merged);
  }
  return events;
}

ProcessInput load_input(const ProcessOptions& opt, fusion::BodyModel& body, std::vector<std::string>& notes) {
  if (!opt.order.empty() && opt.order != "arrival" && opt.order != "time")
    throw UsageError("--order must be arrival or time, not '" + opt.order + "'");
  if (!fs::exists(opt.input)) throw UsageError(opt.input + ": no such file or folder");
  const bool folder = fs::is_directory(opt.input);
  const std::string ext = fs::path(opt.input).extension().string();
  const bool session = !folder && io::is_session_file(opt.input);
  if (!folder && !session && (ext == ".h5" || ext == ".hdf5"))
    throw UsageError(opt.input + ": not a bsn session file (bsn record) nor a folder of per-node recordings");
  if (fs::exists(opt.out) && fs::equivalent(opt.out, opt.input)) throw UsageError("--out must not be the input");

  ProcessInput in;
  std::string found;  // recordings of no segment
  if (!session) {
    body = load_body(opt, nullptr);
    found = read_recordings(opt, in, body, notes);
  } else {
    read_session(opt.input, in);
    body = load_body(opt, &in);
    // Nodes to segments by the body.
    std::vector<NodeTrack> mapped;
    for (NodeTrack& t : in.tracks) {
      const auto seg = std::find_if(body.segments.begin(), body.segments.end(),
                                    [&](const fusion::SegmentSpec& s) { return s.node == t.node; });
      if (seg == body.segments.end()) {
        notes.push_back("node '" + t.node + "' is on no segment of the body: its " + std::to_string(t.size()) +
                        " samples are left out");
        continue;
      }
      t.segment = static_cast<std::size_t>(seg - body.segments.begin());
      mapped.push_back(std::move(t));
    }
    in.tracks = std::move(mapped);
  }
  if (!opt.filters.empty()) {
    fusion::FilterSpec spec;
    try {
      spec = eval::parse_filter_argument(opt.filters.back());
      (void)fusion::make_filter(spec);
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("--filter: ") + e.what());
    }
    for (auto& s : body.segments) s.filter = spec;
  }
  // Nothing to process is a mistake (files named otherwise than the body's nodes), not an empty result.
  if (!session && in.tracks.empty())
    throw UsageError(opt.input + ": no recording of any node or segment of the body" +
                     (found.empty() ? std::string(" (no recordings found)")
                                    : " (found: " + found + "; name each after its node or segment)"));
  return in;
}

void fill_raw(const NodeTrack& t, std::size_t i, bsn::RawSample& raw) {
  raw.timestamp_ns(t.timestamp_ns[i]);
  raw.seq(t.seq[i]);
  raw.acc({t.acc[3 * i], t.acc[3 * i + 1], t.acc[3 * i + 2]});
  raw.gyr({t.gyr[3 * i], t.gyr[3 * i + 1], t.gyr[3 * i + 2]});
  raw.mag({t.mag[3 * i], t.mag[3 * i + 1], t.mag[3 * i + 2]});
  raw.channels(t.channels[i]);
}

fusion::ImuSample imu_sample(const NodeTrack& t, std::size_t i) {
  return dds::to_imu_sample(t.timestamp_ns[i], &t.acc[3 * i], &t.gyr[3 * i], &t.mag[3 * i], t.channels[i]);
}

fusion::Quat truth_quat(const RecordedTruth& t, std::size_t i) {
  const double* q = &t.quat[4 * i];
  return fusion::canonical(fusion::Quat(q[0], q[1], q[2], q[3]).normalized());
}

}  // namespace bsn::services::process_detail
