#include "process_command.hpp"

#include <fastdds/rtps/common/SerializedPayload.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <optional>
#include <stdexcept>

#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/eval/evaluation.hpp"
#include "bsn/fusion/orientation_error.hpp"
#include "bsn/io/importers.hpp"
#include "bsn/io/json.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/io/session_file.hpp"
#include "fusion_pipeline.hpp"
#include "progress_bar.hpp"
#include "sample_fields.hpp"
#include "session_columns.hpp"

#ifndef BSN_VERSION
#define BSN_VERSION "unknown"
#endif

namespace bsn::services {
namespace {

namespace fs = std::filesystem;

/// A usage error: a bad option, body or input (exit 2).
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// ---- Input -------------------------------------------------------------------------------------------------------

/// One node's samples, column by column, and where they came from.
struct NodeTrack {
  std::string node;
  std::size_t segment = 0;
  std::vector<std::uint64_t> timestamp_ns, seq, arrival_ns;
  std::vector<double> acc, gyr, mag;  ///< N x 3, row-major
  std::vector<std::uint32_t> channels;
  std::size_t size() const { return timestamp_ns.size(); }
};

struct TimedCalibration {
  std::uint64_t arrival_ns = 0;
  bsn::CalibrationResult result;
};

struct ProcessInput {
  std::vector<NodeTrack> tracks;
  std::vector<TimedCalibration> calibrations;  ///< from a session's bsn/calibration/result, in arrival order
  std::vector<bsn::Orientation> truth;         ///< bsn/truth/orientation to carry over
  std::vector<std::uint64_t> truth_arrival_ns;
  std::string recorded_body;  ///< a session's body_model attribute
  bool session = false;
};

template <class PubSub>
std::vector<typename PubSub::type> read_samples(const io::SessionReader& r, const io::SessionStream& s,
                                                std::vector<std::uint64_t>* arrival) {
  const auto cdr = r.read_u8(s, "cdr");
  const auto ends = r.read_u64(s, "cdr_end");
  if (arrival) *arrival = r.read_u64(s, "arrival_ns");
  std::vector<typename PubSub::type> out;
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

void read_session(const std::string& path, ProcessInput& in) {
  io::SessionReader r(path);
  in.session = true;
  if (const auto it = r.attributes().find("body_model"); it != r.attributes().end()) in.recorded_body = it->second;
  for (const io::SessionStream& s : r.streams_of(dds::kRawTopic.name)) {
    NodeTrack t;
    t.timestamp_ns = r.read_u64(s, "timestamp_ns");
    t.seq = r.read_u64(s, "seq");
    t.arrival_ns = r.read_u64(s, "arrival_ns");
    t.acc = r.read_f64(s, "acc", 3);
    t.gyr = r.read_f64(s, "gyr", 3);
    t.mag = r.read_f64(s, "mag", 3);
    t.channels = r.read_u32(s, "channels");
    const std::size_t n = t.timestamp_ns.size();
    if (t.seq.size() != n || t.arrival_ns.size() != n || t.acc.size() != 3 * n || t.gyr.size() != 3 * n ||
        t.mag.size() != 3 * n || t.channels.size() != n) {
      throw io::IoError(path + ": the datasets of '" + s.group + "' differ in length");
    }
    t.node = s.key;
    in.tracks.push_back(std::move(t));
  }
  for (const io::SessionStream& s : r.streams_of(dds::kCalibrationResultTopic.name)) {
    std::vector<std::uint64_t> arrival;
    auto results = read_samples<bsn::CalibrationResultPubSubType>(r, s, &arrival);
    for (std::size_t i = 0; i < results.size(); ++i) in.calibrations.push_back({arrival[i], std::move(results[i])});
  }
  std::stable_sort(in.calibrations.begin(), in.calibrations.end(),
                   [](const auto& a, const auto& b) { return a.arrival_ns < b.arrival_ns; });
  for (const io::SessionStream& s : r.streams_of(dds::kTruthOrientationTopic.name)) {
    std::vector<std::uint64_t> arrival;
    auto truth = read_samples<bsn::OrientationPubSubType>(r, s, &arrival);
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
    t.timestamp_ns.resize(n);
    t.seq.resize(n);
    t.acc.resize(3 * n);
    t.gyr.resize(3 * n);
    t.mag.resize(3 * n);
    t.channels.resize(n);
    for (std::size_t k = 0; k < n; ++k) {
      const fusion::ImuSample s = rec.sample(k);
      t.timestamp_ns[k] = s.timestamp_ns;
      t.seq[k] = k;
      for (int c = 0; c < 3; ++c) {
        t.acc[3 * k + c] = s.acc[c];
        t.gyr[3 * k + c] = s.gyr[c];
        t.mag[3 * k + c] = s.has_mag ? s.mag[c] : 0.0;
      }
      t.channels[k] = (s.has_acc ? bsn::CHANNEL_ACC : 0u) | (s.has_gyr ? bsn::CHANNEL_GYR : 0u) |
                      (s.has_mag ? bsn::CHANNEL_MAG : 0u);
      if (rec.opt_quat.rows() == static_cast<Eigen::Index>(n) &&
          rec.opt_quat.row(static_cast<Eigen::Index>(k)).allFinite()) {
        bsn::Orientation o;
        o.segment(spec.name);
        o.node_id(spec.node);
        o.timestamp_ns(s.timestamp_ns);
        const auto q = rec.opt_quat.row(static_cast<Eigen::Index>(k));
        dds::fill_orientation(fusion::Quat(q[0], q[1], q[2], q[3]).normalized(), o);
        in.truth.push_back(std::move(o));
        in.truth_arrival_ns.push_back(s.timestamp_ns);
      }
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

// ---- Output ------------------------------------------------------------------------------------------------------

/// The streams of one topic in the output, one per key, created on their first sample.
template <class PubSub>
class TopicOutput {
 public:
  TopicOutput(io::SessionWriter& writer, const char* topic) : writer_(writer), topic_(topic) {}
  /// Streams are looked up by a small index the caller keeps (a segment), so a sample costs no string work.
  void write(std::size_t index, const typename PubSub::type& sample, std::uint64_t arrival_ns) {
    if (index >= streams_.size()) streams_.resize(index + 1);
    auto& s = streams_[index];
    if (!s) {
      ColumnSpecVisitor spec;
      visit_fields(sample, spec);
      const std::string key = key_of(sample);
      s = Stream{writer_.add_stream(topic_, key.empty() ? "_" : key, type_.getName(), spec.specs), 0};
    }
    auto* data = const_cast<typename PubSub::type*>(&sample);
    if (!type_.serialize(data, &payload_)) throw io::IoError(std::string(topic_) + ": a sample does not serialise");
    writer_.append(s->id, kArrivalColumn, &arrival_ns, 1);
    writer_.append(s->id, kCdrColumn, payload_.data, payload_.length);
    s->cdr_bytes += payload_.length;
    writer_.append(s->id, kCdrEndColumn, &s->cdr_bytes, 1);
    AppendVisitor append(writer_, s->id);
    visit_fields(sample, append);
  }

 private:
  struct Stream {
    std::size_t id = 0;
    std::uint64_t cdr_bytes = 0;
  };
  io::SessionWriter& writer_;
  const char* topic_;
  PubSub type_;
  eprosima::fastrtps::rtps::SerializedPayload_t payload_{64 * 1024};  // larger than any bsn sample
  std::vector<std::optional<Stream>> streams_;
};

// ---- The run -----------------------------------------------------------------------------------------------------

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

/// One event of the merged input: a sample of a track, or (as-recorded) a calibration result.
struct Event {
  std::uint64_t key = 0;    ///< arrival or sensor time
  std::uint64_t tie = 0;    ///< sensor time (arrival order), 0 (time order)
  std::uint32_t rank = 0;   ///< segment index: a parent usually comes before its children in a body file
  std::uint32_t track = 0;  ///< track index, or kCalibration
  std::uint64_t index = 0;  ///< sample index in the track, or calibration index
  static constexpr std::uint32_t kCalibration = 0xffffffffu;
};

/// The merged order of every sample (and, with `calibrations`, every calibration result) of the input.
std::vector<Event> merge_events(const ProcessInput& in, const std::string& order, bool calibrations) {
  std::vector<Event> events;
  std::size_t total = 0;
  for (const NodeTrack& t : in.tracks) total += t.size();
  events.reserve(total + in.calibrations.size());
  const bool by_arrival = order == "arrival";
  for (std::uint32_t k = 0; k < in.tracks.size(); ++k) {
    const NodeTrack& t = in.tracks[k];
    const auto rank = static_cast<std::uint32_t>(t.segment);
    for (std::size_t i = 0; i < t.size(); ++i) {
      events.push_back(by_arrival ? Event{t.arrival_ns[i], t.timestamp_ns[i], rank, k, i}
                                  : Event{t.timestamp_ns[i], 0, rank, k, i});
    }
  }
  if (calibrations) {
    if (!by_arrival) throw UsageError("--calibrations as-recorded needs --order arrival (a session's arrival times)");
    for (std::size_t i = 0; i < in.calibrations.size(); ++i)
      events.push_back({in.calibrations[i].arrival_ns, 0, 0, Event::kCalibration, i});
  }
  std::stable_sort(events.begin(), events.end(), [](const Event& a, const Event& b) {
    if (a.key != b.key) return a.key < b.key;
    if (a.tie != b.tie) return a.tie < b.tie;
    return a.rank < b.rank;
  });
  return events;
}

std::string describe_filters(const fusion::BodyModel& body) {
  std::string filters;
  for (const auto& s : body.segments) {
    filters += s.name + ": " + s.filter.name;
    for (const auto& [k, v] : s.filter.parameters) filters += " " + k + "=" + std::to_string(v);
    filters += "\n";
  }
  return filters;
}

/// Reads the input and the body (nodes mapped to segments, --filter applied); checks the input and the options.
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

int process(const ProcessOptions& opt) {
  if (opt.calibrations != "first-sample" && opt.calibrations != "as-recorded")
    throw UsageError("--calibrations must be first-sample or as-recorded, not '" + opt.calibrations + "'");
  using Clock = std::chrono::steady_clock;
  const auto t_start = Clock::now();
  std::vector<std::string> notes;
  fusion::BodyModel body;
  ProcessInput in = load_input(opt, body, notes);
  fusion::BodyFusion::Calibrations calibrations =
      opt.body_path.empty() ? fusion::BodyFusion::Calibrations{} : config::load_body_calibrations(opt.body_path);
  // Calibration files from the command line: after the body's and the session's, so they win.
  std::vector<config::CalibrationDocument> documents;
  for (const std::string& file : opt.calibration_files) {
    config::CalibrationDocument d = config::load_calibration_document(file);
    if (d.node.empty()) throw UsageError(file + ": names no node (`node:`), so it applies to none");
    if (!body.segments.empty() &&
        std::none_of(body.segments.begin(), body.segments.end(), [&](const auto& s) { return s.node == d.node; }))
      throw UsageError(file + ":" + std::to_string(d.node_line) + ": node '" + d.node +
                       "' is on no segment of the body");
    documents.push_back(std::move(d));
  }
  const std::string order = !opt.order.empty() ? opt.order : in.session ? "arrival" : "time";

  FusionPipeline pipeline(body, calibrations, {}, 0);
  std::size_t applied_at_start = 0;
  if (opt.calibrations == "first-sample") {
    // The last successful result per node and kind, as the calibration service's store keeps it.
    std::map<std::pair<std::string, int>, const bsn::CalibrationResult*> last;
    for (const TimedCalibration& c : in.calibrations)
      if (c.result.success()) last[{c.result.node_id(), static_cast<int>(c.result.kind())}] = &c.result;
    for (const auto& [key, result] : last)
      if (pipeline.apply(*result).outcome == FusionPipeline::CalibrationOutcome::kApplied) ++applied_at_start;
  }
  for (const config::CalibrationDocument& d : documents) {
    pipeline.fusion().update_calibration(d.node, d.calibration);
    if (d.alignment) pipeline.fusion().update_alignment(d.node, d.alignment->sensor_to_segment);
    ++applied_at_start;
  }

  std::size_t total = 0;
  for (const NodeTrack& t : in.tracks) total += t.size();
  const std::vector<Event> events = merge_events(in, order, opt.calibrations == "as-recorded");
  std::map<std::string, std::string> attributes{
      {"bsn_version", BSN_VERSION},
      {"processed_by", "bsn process"},
      {"source", fs::path(opt.input).filename().string()},
      {"order", order},
      {"calibrations_mode", opt.calibrations},
      {"body_model_file", opt.body_path.empty() ? "(recorded in the source)" : opt.body_path},
      {"body_model", config::body_model_to_yaml(body)},
      {"filter_parameters", describe_filters(body)},
      {"topics",
       "bsn/orientation,bsn/joint_angles,bsn/status" + std::string(in.truth.empty() ? "" : ",bsn/truth/orientation")}};
  io::SessionWriter writer(opt.out, opt.overwrite, attributes);
  TopicOutput<bsn::OrientationPubSubType> orientations(writer, dds::kOrientationTopic.name);
  TopicOutput<bsn::JointAnglesPubSubType> joints(writer, dds::kJointAnglesTopic.name);
  TopicOutput<bsn::StatusPubSubType> status(writer, dds::kStatusTopic.name);
  TopicOutput<bsn::OrientationPubSubType> truth(writer, dds::kTruthOrientationTopic.name);
  TopicOutput<bsn::RawSamplePubSubType> raw_out(writer, dds::kRawTopic.name);
  // Truth first, by segment: carried over as it was.
  std::map<std::string, std::size_t> truth_index;
  for (std::size_t i = 0; i < in.truth.size(); ++i) {
    const std::size_t index = truth_index.try_emplace(in.truth[i].segment(), truth_index.size()).first->second;
    truth.write(index, in.truth[i], in.truth_arrival_ns[i]);
  }

  // One raw sample object per track: its node id is set once, so a sample copies numbers only.
  std::vector<bsn::RawSample> raws(in.tracks.size());
  for (std::size_t k = 0; k < in.tracks.size(); ++k) raws[k].node_id(body.segments[in.tracks[k].segment].node);
  const auto t_read = Clock::now();
  const ProgressBar progress(events.size());
  const bool show = !opt.quiet;
  const std::size_t step = std::max<std::size_t>(1, events.size() / 100);
  std::uint64_t first_ns = 0, last_ns = 0;
  std::size_t estimated = 0, joint_samples = 0;
  for (std::size_t e = 0; e < events.size(); ++e) {
    const Event& ev = events[e];
    if (ev.track == Event::kCalibration) {
      pipeline.apply(in.calibrations[ev.index].result);
      continue;
    }
    const NodeTrack& t = in.tracks[ev.track];
    const std::size_t i = ev.index;
    bsn::RawSample& raw = raws[ev.track];
    fill_raw(t, i, raw);
    if (opt.copy_raw) raw_out.write(ev.track, raw, t.arrival_ns[i]);
    if (e == 0) first_ns = t.arrival_ns[i];
    last_ns = std::max(last_ns, t.arrival_ns[i]);
    const fusion::SampleResult& r = pipeline.process(raw, t.timestamp_ns[i]);
    if (r.outcome == fusion::SampleOutcome::kEstimated) {
      orientations.write(r.segment, pipeline.orientation(), t.arrival_ns[i]);
      ++estimated;
      if (r.joint) {
        joints.write(r.segment, pipeline.joint(), t.arrival_ns[i]);
        ++joint_samples;
      }
    }
    if (show && e % step == 0) progress.show(e, "samples");
  }
  if (show) progress.finish();
  const auto t_fused = Clock::now();
  // The counters of the whole run, as one bsn/status sample.
  bsn::Status st;
  st.process_id("process:" + fs::path(opt.input).filename().string());
  st.wall_time_ns(last_ns);
  st.period_s(1e-9 * static_cast<double>(last_ns - first_ns));
  std::vector<bsn::NodeStatus> nodes;
  for (std::size_t i = 0; i < body.segments.size(); ++i) {
    bsn::NodeStatus n = pipeline.node_status(i);
    n.rate_hz(st.period_s() > 0.0 ? static_cast<double>(n.accepted()) / st.period_s() : 0.0);
    n.last_sample_age_s(-1.0);
    nodes.push_back(std::move(n));
  }
  st.nodes(std::move(nodes));
  st.unknown_node_samples(pipeline.fusion().unknown_node_samples());
  st.last_calibration_id(pipeline.last_calibration_id());
  status.write(0, st, last_ns);
  writer.close();
  const auto t_written = Clock::now();
  const auto seconds = [](Clock::duration d) { return std::chrono::duration<double>(d).count(); };
  for (const std::string& n : notes) std::fprintf(stderr, "bsn process: note: %s\n", n.c_str());
  std::fprintf(stderr,
               "bsn process: %zu samples of %zu nodes (%s order), %zu calibrations applied from the first sample%s: "
               "%zu orientations, %zu joint samples -> %s (read %.3f s, fusion %.3f s, write %.3f s)\n",
               total, in.tracks.size(), order.c_str(), applied_at_start,
               opt.calibrations == "as-recorded" ? " and the session's as recorded" : "", estimated, joint_samples,
               opt.out.c_str(), seconds(t_read - t_start), seconds(t_fused - t_read), seconds(t_written - t_fused));
  return 0;
}

}  // namespace

int run_process(const ProcessOptions& opt) {
  try {
    return process(opt);
  } catch (const UsageError& e) {
    std::fprintf(stderr, "bsn process: error: %s\n", e.what());
    return 2;
  } catch (const config::ConfigError& e) {
    std::fprintf(stderr, "bsn process: error: %s\n", e.what());
    return 2;
  } catch (const io::FormatError& e) {
    std::fprintf(stderr, "bsn process: error: %s\n", e.what());
    return 2;
  } catch (const io::IoError& e) {
    std::fprintf(stderr, "bsn process: error: %s\n", e.what());
    return std::string(e.what()).find("--overwrite") != std::string::npos ? 2 : 1;
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "bsn process: error: %s\n", e.what());
    return 2;
  }
}

void add_import_options(CLI::App* cmd, ImportSelection& import) {
  std::string formats = "auto";
  for (const io::RecordingImporter* i : io::recording_importers()) formats += ", " + i->name();
  cmd->add_option("--format", import.format, "the recordings' format: " + formats + " (docs/importers.md)")
      ->capture_default_str();
  cmd->add_option("--unit", import.units,
                  "QUANTITY=UNIT overriding the format's unit: acc (m/s^2, g), gyr (rad/s, deg/s), mag (uT, nT, G, "
                  "au, au:K), time (s, ms, us, ns); repeatable");
  cmd->add_option("--imu", import.imu, "DIODEM: which IMU of each segment, rigid or nonrigid")->capture_default_str();
}

Command process_command() {
  return {"process", "Run a recorded session or per-node recordings through the body pipeline, offline",
          [](CLI::App* cmd) {
            auto opt = std::make_shared<ProcessOptions>();
            cmd->add_option("INPUT", opt->input,
                            "session file (bsn record), folder of per-node recordings (<node>.hdf5/.csv), a recording "
                            "file or a DIODEM trial")
                ->required();
            add_import_options(cmd, opt->import);
            cmd->add_option("--body", opt->body_path, "YAML body model (default: the one recorded in the session)");
            cmd->add_option("--out", opt->out, "session file to write (.h5)")->required();
            cmd->add_flag("--overwrite", opt->overwrite, "replace an existing output file");
            cmd->add_option("--filter", opt->filters, "NAME[:k=v,...]: this filter on every segment");
            cmd->add_option("--calibration", opt->calibration_files,
                            "calibration file (bsn calibrate, the store's <node>.*.calib.yaml), applied from the "
                            "first sample (repeatable)");
            cmd->add_option("--calibrations", opt->calibrations,
                            "the session's calibration results: first-sample (the last of each node and kind, from "
                            "the start) or as-recorded (each when it arrived)")
                ->capture_default_str();
            cmd->add_option("--order", opt->order,
                            "arrival (as the live fusion saw them; default for a session) or time (by sensor time; "
                            "default for a folder)");
            cmd->add_flag("--quiet", opt->quiet, "no progress bar");
            cmd->add_flag("--raw", opt->copy_raw,
                          "write the input's raw samples as bsn/raw too: a complete session, for bsn replay, bsn "
                          "calibrate --alignment or bsn process again");
            return [opt] { return run_process(*opt); };
          }};
}

}  // namespace bsn::services

// ---- bsn eval --body ---------------------------------------------------------------------------------------------

namespace bsn::services {
namespace {

/// The reference of one segment: sensor-to-earth by timestamp.
using TruthTrack = std::map<std::uint64_t, fusion::Quat>;

struct JointSeries {
  std::string name;
  std::size_t parent = 0, child = 0;
  fusion::JointConvention convention;
  bool aligned = false;
  std::vector<double> t_s;
  std::vector<fusion::Quat> est, truth;  ///< relative orientations in the published frames
};

/// The mean rotation of unit quaternions (the dominant eigenvector of sum q q^T, Markley et al. 2007).
fusion::Quat mean_rotation(const std::vector<fusion::Quat>& qs) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Zero();
  for (const fusion::Quat& q : qs) {
    const Eigen::Vector4d v(q.w(), q.x(), q.y(), q.z());
    m += v * v.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> eig(m);
  const Eigen::Vector4d v = eig.eigenvectors().col(3);
  return fusion::Quat(v[0], v[1], v[2], v[3]).normalized();
}

double wrap(double a) { return std::remainder(a, 2.0 * std::numbers::pi); }

int body_eval(const BodyEvalOptions& opt) {
  double window_from = 0.0, window_to = std::numeric_limits<double>::infinity();
  const bool align = opt.align_window != "none";
  if (align && opt.align_window != "all") {
    const auto colon = opt.align_window.find(':');
    char* end = nullptr;
    bool ok = colon != std::string::npos;
    if (ok) {
      window_from = std::strtod(opt.align_window.c_str(), &end);
      ok = end == opt.align_window.c_str() + colon;
      window_to = std::strtod(opt.align_window.c_str() + colon + 1, &end);
      ok = ok && *end == '\0' && std::isfinite(window_from) && std::isfinite(window_to) && window_to > window_from &&
           window_from >= 0.0;
    }
    if (!ok)
      throw UsageError("--align-window must be all, none or A:B in seconds with B > A >= 0, not '" + opt.align_window +
                       "'");
  }
  ProcessOptions p;
  p.input = opt.input;
  p.body_path = opt.body_path;
  p.filters = opt.filters;
  p.import = opt.import;
  std::vector<std::string> notes;
  fusion::BodyModel body;
  ProcessInput in = load_input(p, body, notes);
  if (in.truth.empty())
    throw UsageError(opt.input + ": no reference orientation (opt_quat, or bsn/truth/orientation) to score against");
  std::vector<TruthTrack> truth(body.segments.size());
  for (const bsn::Orientation& o : in.truth) {
    const auto seg = body.find_segment(o.segment());
    if (seg) truth[*seg][o.timestamp_ns()] = dds::to_quat(o.quat());
  }
  const std::vector<Event> events =
      merge_events(in, p.order.empty() ? (in.session ? "arrival" : "time") : p.order, false);
  FusionPipeline pipeline(
      body, opt.body_path.empty() ? fusion::BodyFusion::Calibrations{} : config::load_body_calibrations(opt.body_path),
      {}, 0);
  // Per segment: the estimate and the truth in the published frame, and their time.
  std::vector<std::vector<fusion::Quat>> seg_est(body.segments.size()), seg_truth(body.segments.size());
  std::vector<std::vector<double>> seg_t(body.segments.size());
  std::vector<JointSeries> joints(body.segments.size());
  std::vector<bsn::RawSample> raws(in.tracks.size());
  for (std::size_t k = 0; k < in.tracks.size(); ++k) raws[k].node_id(body.segments[in.tracks[k].segment].node);
  std::optional<std::uint64_t> t0;
  auto frame_of = [&](std::size_t segment, const fusion::Quat& q_sensor, bool aligned) {
    return aligned ? fusion::segment_orientation(q_sensor, pipeline.fusion().segment(segment).sensor_to_segment)
                   : q_sensor;
  };
  for (const Event& ev : events) {
    const NodeTrack& t = in.tracks[ev.track];
    const std::size_t i = ev.index;
    bsn::RawSample& raw = raws[ev.track];
    fill_raw(t, i, raw);
    if (!t0) t0 = t.timestamp_ns[i];
    const fusion::SampleResult& r = pipeline.process(raw, t.timestamp_ns[i]);
    if (r.outcome != fusion::SampleOutcome::kEstimated) continue;
    const auto truth_now = truth[r.segment].find(t.timestamp_ns[i]);
    if (truth_now == truth[r.segment].end()) continue;
    const double ts = 1e-9 * static_cast<double>(t.timestamp_ns[i] - *t0);
    seg_t[r.segment].push_back(ts);
    seg_est[r.segment].push_back(r.orientation);
    seg_truth[r.segment].push_back(frame_of(r.segment, truth_now->second, r.aligned));
    if (!r.joint) continue;
    const auto parent_truth = truth[r.joint->parent].find(t.timestamp_ns[i]);
    if (parent_truth == truth[r.joint->parent].end()) continue;
    JointSeries& j = joints[r.segment];
    j.name = fusion::joint_name(body.segments[r.segment]);
    j.parent = r.joint->parent;
    j.child = r.segment;
    j.convention = r.joint->convention;
    j.aligned = r.joint->aligned;
    j.t_s.push_back(ts);
    j.est.push_back(r.joint->relative);
    j.truth.push_back(
        fusion::canonical(fusion::relative_orientation(frame_of(r.joint->parent, parent_truth->second, j.aligned),
                                                       frame_of(r.segment, truth_now->second, j.aligned))));
  }
  // The per-segment constant alignment: q_truth = q_est * B over the window (B in the published frame).
  std::vector<fusion::Quat> alignment(body.segments.size(), fusion::Quat::Identity());
  if (align) {
    for (std::size_t s = 0; s < body.segments.size(); ++s) {
      std::vector<fusion::Quat> d;
      for (std::size_t k = 0; k < seg_t[s].size(); ++k)
        if (seg_t[s][k] >= window_from && seg_t[s][k] <= window_to)
          d.push_back(seg_est[s][k].conjugate() * seg_truth[s][k]);
      if (!d.empty()) alignment[s] = mean_rotation(d);
    }
  }
  std::string json = "{\"input\": " + io::json_string(opt.input) +
                     ", \"align_window\": " + io::json_string(opt.align_window) + ", \"segments\": {";
  std::string table = "segment            total  heading  inclination  (deg RMS, aligned)\n";
  bool first = true;
  for (std::size_t s = 0; s < body.segments.size(); ++s) {
    if (seg_t[s].empty()) continue;
    fusion::RmsErrorAccumulator raw_acc, aligned_acc;
    for (std::size_t k = 0; k < seg_t[s].size(); ++k) {
      raw_acc.add(fusion::error_angles(seg_est[s][k], seg_truth[s][k]));
      aligned_acc.add(fusion::error_angles(seg_est[s][k] * alignment[s], seg_truth[s][k]));
    }
    auto angles = [](const fusion::ErrorAngles& e) {
      return "{\"total_deg\": " + io::json_number(e.total * 180 / std::numbers::pi, 9) +
             ", \"heading_deg\": " + io::json_number(e.heading * 180 / std::numbers::pi, 9) +
             ", \"inclination_deg\": " + io::json_number(e.inclination * 180 / std::numbers::pi, 9) + "}";
    };
    json += std::string(first ? "" : ", ") + io::json_string(body.segments[s].name) +
            ": {\"samples\": " + std::to_string(seg_t[s].size()) + ", \"unaligned\": " + angles(raw_acc.rms()) +
            ", \"aligned\": " + angles(aligned_acc.rms()) + "}";
    first = false;
    char line[200];
    const auto e = aligned_acc.rms();
    std::snprintf(line, sizeof line, "%-16s %7.2f %8.2f %12.2f\n", body.segments[s].name.c_str(),
                  e.total * 180 / std::numbers::pi, e.heading * 180 / std::numbers::pi,
                  e.inclination * 180 / std::numbers::pi);
    table += line;
  }
  json += "}, \"joints\": {";
  table += "joint              relative  anatomical 1/2/3   (deg RMS, unaligned | aligned)\n";
  first = true;
  for (const JointSeries& j : joints) {
    if (j.t_s.empty()) continue;
    const bool anatomical = j.convention.type != fusion::JointType::kNone && j.aligned;
    auto figures = [&](bool aligned) {
      double rel_sq = 0.0;
      Eigen::Vector3d anat_sq = Eigen::Vector3d::Zero();
      for (std::size_t k = 0; k < j.t_s.size(); ++k) {
        const fusion::Quat est =
            aligned ? fusion::Quat(alignment[j.parent].conjugate() * j.est[k] * alignment[j.child]) : j.est[k];
        const double e = fusion::angle_between(est, j.truth[k]);
        rel_sq += e * e;
        if (anatomical) {
          const fusion::Vec3 a =
              fusion::anatomical_angles(est, j.convention) - fusion::anatomical_angles(j.truth[k], j.convention);
          for (int c = 0; c < 3; ++c) anat_sq[c] += wrap(a[c]) * wrap(a[c]);
        }
      }
      const double n = static_cast<double>(j.t_s.size());
      std::array<double, 4> out{std::sqrt(rel_sq / n) * 180 / std::numbers::pi, 0, 0, 0};
      for (int c = 0; c < 3; ++c) out[c + 1] = std::sqrt(anat_sq[c] / n) * 180 / std::numbers::pi;
      return out;
    };
    const auto names = fusion::anatomical_angle_names(j.convention.type);
    auto to_json = [&](const std::array<double, 4>& f) {
      std::string s = "{\"relative_deg\": " + io::json_number(f[0], 9);
      if (anatomical) {
        s += ", \"anatomical_deg\": {";
        for (int c = 0; c < 3; ++c)
          s +=
              std::string(c ? ", " : "") + io::json_string(std::string(names[c])) + ": " + io::json_number(f[c + 1], 9);
        s += "}";
      }
      return s + "}";
    };
    const auto plain = figures(false), aligned = figures(true);
    json += std::string(first ? "" : ", ") + io::json_string(j.name) +
            ": {\"samples\": " + std::to_string(j.t_s.size()) + ", \"unaligned\": " + to_json(plain) +
            ", \"aligned\": " + to_json(aligned) + "}";
    first = false;
    char line[240];
    if (anatomical) {
      std::snprintf(line, sizeof line, "%-16s %8.2f  %5.2f %5.2f %5.2f | %8.2f  %5.2f %5.2f %5.2f\n", j.name.c_str(),
                    plain[0], plain[1], plain[2], plain[3], aligned[0], aligned[1], aligned[2], aligned[3]);
    } else {  // no anatomy, or a segment of the joint not aligned: the relative orientation only
      std::snprintf(line, sizeof line, "%-16s %8.2f      -     -     - | %8.2f      -     -     -\n", j.name.c_str(),
                    plain[0], aligned[0]);
    }
    table += line;
  }
  json += "}}";
  if (!opt.plot_path.empty()) {
    // Each joint's relative-orientation error (aligned) over time, one polyline per joint.
    constexpr double kW = 800, kH = 300;
    double t_max = 1e-9, e_max = 1e-9;
    std::vector<std::vector<std::pair<double, double>>> lines;
    for (const JointSeries& j : joints) {
      if (j.t_s.empty()) continue;
      auto& l = lines.emplace_back();
      for (std::size_t k = 0; k < j.t_s.size(); k += std::max<std::size_t>(1, j.t_s.size() / 2000)) {
        const double e =
            fusion::angle_between(fusion::Quat(alignment[j.parent].conjugate() * j.est[k] * alignment[j.child]),
                                  j.truth[k]) *
            180 / std::numbers::pi;
        l.emplace_back(j.t_s[k], e);
        t_max = std::max(t_max, j.t_s[k]);
        e_max = std::max(e_max, e);
      }
    }
    std::ofstream svg(opt.plot_path);
    svg << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << kW << "\" height=\"" << kH + 40 << "\">\n"
        << "<text x=\"10\" y=\"20\" font-size=\"14\">joint error (deg, aligned) over time (s); max " << e_max
        << " deg, " << t_max << " s</text>\n";
    const char* colours[] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2"};
    std::size_t c = 0;
    for (const JointSeries& j : joints) {
      if (j.t_s.empty()) continue;
      svg << "<polyline fill=\"none\" stroke=\"" << colours[c % 7] << "\" points=\"";
      for (const auto& [t, e] : lines[c]) svg << t / t_max * kW << "," << 30 + kH - e / e_max * kH << " ";
      svg << "\"><title>" << j.name << "</title></polyline>\n";
      ++c;
    }
    svg << "</svg>\n";
    if (!svg) throw io::IoError(opt.plot_path + ": cannot write");
  }
  for (const std::string& n : notes) std::fprintf(stderr, "bsn eval: note: %s\n", n.c_str());
  std::fputs(opt.json ? (json + "\n").c_str() : table.c_str(), stdout);
  return 0;
}

}  // namespace

int run_body_eval(const BodyEvalOptions& opt) {
  try {
    return body_eval(opt);
  } catch (const UsageError& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 2;
  } catch (const config::ConfigError& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 2;
  } catch (const io::FormatError& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 2;
  } catch (const io::IoError& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 1;
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 2;
  }
}

}  // namespace bsn::services
