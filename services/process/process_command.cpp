#include "process_command.hpp"

#include <malloc.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>

#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/io/importers.hpp"
#include "bsn/io/session_file.hpp"
#include "fusion_pipeline.hpp"
#include "process_input.hpp"
#include "process_output.hpp"
#include "progress_bar.hpp"

#ifndef BSN_VERSION
#define BSN_VERSION "unknown"
#endif

namespace bsn::services {
namespace {

namespace fs = std::filesystem;
using namespace process_detail;

// Samples between two writes of the output: the file is written in blocks of about this many input samples (a few
// MB), so the memory stays bounded on long inputs and each dataset's chunk holds a block (ChunkLayout::kBulk).
constexpr std::size_t kBlockSamples = std::size_t{1} << 16;

std::string describe_filters(const fusion::BodyModel& body) {
  std::string filters;
  for (const auto& s : body.segments) {
    filters += s.name + ": " + s.filter.name;
    for (const auto& [k, v] : s.filter.parameters) filters += " " + k + "=" + std::to_string(v);
    filters += "\n";
  }
  return filters;
}

/// The calibration files of the command line, each checked against the body.
std::vector<config::CalibrationDocument> load_calibration_files(const ProcessOptions& opt,
                                                                const fusion::BodyModel& body) {
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
  return documents;
}

/// Applies the calibrations that hold from the first sample: with first-sample the session's last successful
/// result per node and kind (as the calibration service's store keeps it), then the files (so they win). Returns
/// how many were applied.
std::size_t apply_start_calibrations(const ProcessOptions& opt, const ProcessInput& in,
                                     const std::vector<config::CalibrationDocument>& documents,
                                     FusionPipeline& pipeline) {
  std::size_t applied = 0;
  if (opt.calibrations == "first-sample") {
    std::map<std::pair<std::string, int>, const bsn::CalibrationResult*> last;
    for (const TimedCalibration& c : in.calibrations)
      if (c.result.success()) last[{c.result.node_id(), static_cast<int>(c.result.kind())}] = &c.result;
    for (const auto& [key, result] : last)
      if (pipeline.apply(*result).outcome == FusionPipeline::CalibrationOutcome::kApplied) ++applied;
  }
  for (const config::CalibrationDocument& d : documents) {
    pipeline.fusion().update_calibration(d.node, d.calibration);
    if (d.alignment) pipeline.fusion().update_alignment(d.node, d.alignment->sensor_to_segment);
    ++applied;
  }
  return applied;
}

std::map<std::string, std::string> output_attributes(const ProcessOptions& opt, const ProcessInput& in,
                                                     const fusion::BodyModel& body, const std::string& order) {
  return {{"bsn_version", BSN_VERSION},
          {"processed_by", "bsn process"},
          {"source", fs::path(opt.input).filename().string()},
          {"order", order},
          {"calibrations_mode", opt.calibrations},
          {"body_model_file", opt.body_path.empty() ? "(recorded in the source)" : opt.body_path},
          {"body_model", config::body_model_to_yaml(body)},
          {"filter_parameters", describe_filters(body)},
          {"topics", "bsn/orientation,bsn/joint_angles,bsn/status" +
                         std::string(in.truth.empty() && in.recorded_truth.empty() ? "" : ",bsn/truth/orientation")}};
}

/// The input's truth, carried over as it was, one stream per segment. Columns alone when every sample of a segment
/// names one node (a columns-only stream holds one), else serialised.
void write_truth(const ProcessInput& in, io::SessionWriter& writer) {
  std::map<std::string, std::size_t> index_of;
  std::vector<const bsn::Orientation*> first;
  bool one_node_each = true;
  std::vector<std::size_t> index(in.truth.size());
  for (std::size_t i = 0; i < in.truth.size(); ++i) {
    const auto [it, added] = index_of.try_emplace(in.truth[i].segment(), index_of.size());
    if (added) first.push_back(&in.truth[i]);
    index[i] = it->second;
    one_node_each = one_node_each && in.truth[i].node_id() == first[index[i]]->node_id();
  }
  TopicOutput<bsn::OrientationPubSubType> truth(writer, dds::kTruthOrientationTopic.name, !one_node_each);
  for (std::size_t i = 0; i < in.truth.size(); ++i) truth.write(index[i], in.truth[i], in.truth_arrival_ns[i]);
  // A recording's: one sample per segment whose texts are set once, its numbers made per row as the reading
  // stored them. Written a segment and a block at a time, each stream's buffers given back when it is complete, so
  // the truth never takes more memory than a block.
  TopicOutput<bsn::OrientationPubSubType> recorded(writer, dds::kTruthOrientationTopic.name, false);
  for (std::size_t k = 0; k < in.recorded_truth.size(); ++k) {
    const RecordedTruth& t = in.recorded_truth[k];
    bsn::Orientation o;
    o.segment(t.segment);
    o.node_id(t.node);
    recorded.reserve(k, std::min(t.size(), kBlockSamples));
    for (std::size_t i = 0; i < t.size(); ++i) {
      const double* q = &t.quat[4 * i];
      o.timestamp_ns(t.timestamp_ns[i]);
      dds::fill_orientation(fusion::Quat(q[0], q[1], q[2], q[3]).normalized(), o);
      recorded.write(k, o, t.timestamp_ns[i]);
      if ((i + 1) % kBlockSamples == 0 || i + 1 == t.size()) {
        writer.stage();
        writer.write_staged();
      }
    }
    if (const auto id = recorded.stream_id(k)) writer.release(*id);
  }
}

/// The counters of the whole run, as one bsn/status sample.
bsn::Status run_status(const ProcessOptions& opt, const FusionPipeline& pipeline, std::uint64_t first_ns,
                       std::uint64_t last_ns) {
  bsn::Status st;
  st.process_id("process:" + fs::path(opt.input).filename().string());
  st.wall_time_ns(last_ns);
  st.period_s(1e-9 * static_cast<double>(last_ns - first_ns));
  std::vector<bsn::NodeStatus> nodes;
  for (std::size_t i = 0; i < pipeline.body().segments.size(); ++i) {
    bsn::NodeStatus n = pipeline.node_status(i);
    n.rate_hz(st.period_s() > 0.0 ? static_cast<double>(n.accepted()) / st.period_s() : 0.0);
    n.last_sample_age_s(-1.0);
    nodes.push_back(std::move(n));
  }
  st.nodes(std::move(nodes));
  st.unknown_node_samples(pipeline.fusion().unknown_node_samples());
  st.last_calibration_id(pipeline.last_calibration_id());
  return st;
}

struct RunCounts {
  std::uint64_t first_ns = 0, last_ns = 0;  ///< arrival times of the first and the last sample
  std::size_t estimated = 0, joint_samples = 0;
};

/// Every event through the pipeline, the outputs into `writer` block by block.
RunCounts run_events(const ProcessOptions& opt, const ProcessInput& in, const std::vector<Event>& events,
                     FusionPipeline& pipeline, io::SessionWriter& writer) {
  TopicOutput<bsn::OrientationPubSubType> orientations(writer, dds::kOrientationTopic.name);
  TopicOutput<bsn::JointAnglesPubSubType> joints(writer, dds::kJointAnglesTopic.name);
  TopicOutput<bsn::RawSamplePubSubType> raw_out(writer, dds::kRawTopic.name);
  // One raw sample object per track: its node id is set once, so a sample copies numbers only.
  std::vector<bsn::RawSample> raws(in.tracks.size());
  std::vector<std::string_view> node(in.tracks.size());
  for (std::size_t k = 0; k < in.tracks.size(); ++k) {
    node[k] = pipeline.body().segments[in.tracks[k].segment].node;
    raws[k].node_id(std::string(node[k]));
  }
  // A segment's share of a block, and some: its columns then fill without being copied into larger buffers.
  for (const NodeTrack& t : in.tracks) {
    const std::size_t rows = std::min(t.size(), kBlockSamples / in.tracks.size() + kBlockSamples / 64);
    orientations.reserve(t.segment, rows);
    joints.reserve(t.segment, rows);
  }
  const ProgressBar progress(events.size());
  const bool show = !opt.quiet;
  const std::size_t step = std::max<std::size_t>(1, events.size() / 100);
  RunCounts n;
  for (std::size_t e = 0; e < events.size(); ++e) {
    const Event& ev = events[e];
    if (e % kBlockSamples == 0 && e > 0) {
      writer.stage();
      writer.write_staged();
    }
    if (ev.track == Event::kCalibration) {
      pipeline.apply(in.calibrations[ev.index].result);
      continue;
    }
    const NodeTrack& t = in.tracks[ev.track];
    const std::size_t i = ev.index;
    if (opt.copy_raw) {
      bsn::RawSample& raw = raws[ev.track];
      fill_raw(t, i, raw);
      raw_out.write(ev.track, raw, t.arrival_ns[i]);
    }
    if (e == 0) n.first_ns = t.arrival_ns[i];
    n.last_ns = std::max(n.last_ns, t.arrival_ns[i]);
    const fusion::SampleResult& r = pipeline.process({node[ev.track], t.seq[i], imu_sample(t, i)}, t.timestamp_ns[i]);
    if (r.outcome == fusion::SampleOutcome::kEstimated) {
      orientations.write(r.segment, pipeline.orientation(), t.arrival_ns[i]);
      ++n.estimated;
      if (r.joint) {
        joints.write(r.segment, pipeline.joint(), t.arrival_ns[i]);
        ++n.joint_samples;
      }
    }
    if (show && e % step == 0) progress.show(e, "samples");
  }
  if (show) progress.finish();
  return n;
}

int process(const ProcessOptions& opt) {
  // The input's arrays (tens of MB) are freed once read and the output's blocks allocated after: from the heap,
  // not each its own mapping, the freed memory serves again instead of every new page costing a fault (about a
  // quarter of the run's system time on 10 minutes of a 7-segment body).
  mallopt(M_MMAP_THRESHOLD, 1 << 30);
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
  if (opt.calibrations != "first-sample" && opt.calibrations != "as-recorded")
    throw UsageError("--calibrations must be first-sample or as-recorded, not '" + opt.calibrations + "'");
  using Clock = std::chrono::steady_clock;
  const auto t_start = Clock::now();
  std::vector<std::string> notes;
  fusion::BodyModel body;
  const ProcessInput in = load_input(opt, body, notes);
  const fusion::BodyFusion::Calibrations calibrations =
      opt.body_path.empty() ? fusion::BodyFusion::Calibrations{} : config::load_body_calibrations(opt.body_path);
  const std::vector<config::CalibrationDocument> documents = load_calibration_files(opt, body);
  const std::string order = !opt.order.empty() ? opt.order : in.session ? "arrival" : "time";
  FusionPipeline pipeline(body, calibrations, {}, 0);
  const std::size_t applied_at_start = apply_start_calibrations(opt, in, documents, pipeline);
  std::size_t total = 0;
  for (const NodeTrack& t : in.tracks) total += t.size();
  const std::vector<Event> events = merge_events(in, order, opt.calibrations == "as-recorded");

  io::SessionWriter writer(opt.out, opt.overwrite, output_attributes(opt, in, body, order), io::ChunkLayout::kBulk);
  write_truth(in, writer);
  const auto t_read = Clock::now();
  const RunCounts counts = run_events(opt, in, events, pipeline, writer);
  const auto t_fused = Clock::now();
  TopicOutput<bsn::StatusPubSubType> status(writer, dds::kStatusTopic.name);
  status.write(0, run_status(opt, pipeline, counts.first_ns, counts.last_ns), counts.last_ns);
  writer.close();
  const auto t_written = Clock::now();
  const auto seconds = [](Clock::duration d) { return std::chrono::duration<double>(d).count(); };
  for (const std::string& n : notes) std::fprintf(stderr, "bsn process: note: %s\n", n.c_str());
  std::fprintf(stderr,
               "bsn process: %zu samples of %zu nodes (%s order), %zu calibrations applied from the first sample%s: "
               "%zu orientations, %zu joint samples -> %s (read %.3f s, fusion and writing %.3f s, closing %.3f s)\n",
               total, in.tracks.size(), order.c_str(), applied_at_start,
               opt.calibrations == "as-recorded" ? " and the session's as recorded" : "", counts.estimated,
               counts.joint_samples, opt.out.c_str(), seconds(t_read - t_start), seconds(t_fused - t_read),
               seconds(t_written - t_fused));
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
