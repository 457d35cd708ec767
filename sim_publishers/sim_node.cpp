#include "sim_node.hpp"

#include <time.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>

#include "bsn/dds/conversions.hpp"
#include "bsn/dds/sample_source.hpp"
#include "bsn/dds/shutdown.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/logging/log.hpp"
#include "bsn/sim/scenario_file.hpp"

namespace bsn::sim {
namespace {

// Sleeps until `t_ns` on CLOCK_MONOTONIC; false if a shutdown was requested.
bool sleep_until(std::uint64_t t_ns) {
  const timespec target{static_cast<time_t>(t_ns / 1000000000ull), static_cast<long>(t_ns % 1000000000ull)};
  // Absolute sleeps keep the schedule exact; SIGINT/SIGTERM interrupt the sleep (EINTR) and end the loop.
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &target, nullptr) == EINTR && !dds::shutdown_requested()) {
  }
  return !dds::shutdown_requested();
}

// Every segment of the scenario to DIR/<segment>.hdf5 (BROAD layout). Dropped samples and timestamp jitter are
// properties of a live link: the files hold every sample at the nominal rate.
int write_scenario_files(const ScenarioSpec& spec, const SimNodeOptions& opt) {
  ScenarioRunner runner(spec, {}, opt.ideal);
  const auto n = static_cast<Eigen::Index>(runner.sample_count());
  std::vector<io::Recording> recs(runner.segment_names().size(), io::sized_recording(spec.rate_hz, n));
  for (io::Recording& r : recs) r.movement.resize(static_cast<std::size_t>(n));
  std::vector<ScenarioSample> out;
  for (Eigen::Index k = 0; runner.next(out); ++k) {
    for (std::size_t j = 0; j < out.size(); ++j) {
      io::Recording& r = recs[j];
      io::set_measurement_row(r, k, out[j].sample);
      const Quat q = fusion::canonical(out[j].truth);
      r.opt_quat.row(k) << q.w(), q.x(), q.y(), q.z();
      r.movement[static_cast<std::size_t>(k)] = out[j].movement ? 1 : 0;
    }
  }
  std::filesystem::create_directories(opt.out_dir);
  for (std::size_t j = 0; j < recs.size(); ++j) {
    const std::string path = (std::filesystem::path(opt.out_dir) / (runner.segment_names()[j] + ".hdf5")).string();
    io::write_broad_hdf5(path, recs[j]);
    logging::log_info("wrote ", path, " (", n, " samples at ", spec.rate_hz, " Hz)");
  }
  return 0;
}

// The monotonic instant of scenario time 0: `started`, or the monotonic equivalent of a Unix time (which may lie
// before `started`: a late joiner).
std::uint64_t scenario_start_ns(double start_at_unix_s, std::uint64_t started) {
  if (!(start_at_unix_s > 0.0)) return started;
  timespec real{};
  clock_gettime(CLOCK_REALTIME, &real);
  const double ahead_s =
      start_at_unix_s - (static_cast<double>(real.tv_sec) + 1e-9 * static_cast<double>(real.tv_nsec));
  const auto ahead_ns = static_cast<std::int64_t>(std::llround(ahead_s * 1e9));
  if (ahead_ns >= 0) return started + static_cast<std::uint64_t>(ahead_ns);
  return started - std::min(started, static_cast<std::uint64_t>(-ahead_ns));
}

// The true joint angles' message of `segment`'s joint to its parent (none without a parent): names and axes.
bsn::JointAngles truth_joint(const Body& body, const SegmentDef& def, const std::string& segment) {
  bsn::JointAngles joint;
  if (def.parent < 0) return joint;
  joint.joint(def.joint.empty() ? body.segment(static_cast<std::size_t>(def.parent)).name + "-" + segment : def.joint);
  joint.parent(body.segment(static_cast<std::size_t>(def.parent)).name);
  joint.child(segment);
  joint.axes("zxy");  // the ISB joint coordinate system's sequence
  return joint;
}

// The true joint angles of sample `s` (with s.joint_relative) at `sensor_ns`, in the segment frames.
void fill_truth_joint(const ScenarioSample& s, std::uint64_t sensor_ns, bsn::JointAngles& joint) {
  joint.timestamp_ns(sensor_ns);
  joint.quat(dds::to_wxyz(*s.joint_relative));
  const fusion::Vec3 zxy = fusion::decompose(*s.joint_relative, fusion::AxisSequence{{2, 0, 1}});
  joint.angles({zxy.x(), zxy.y(), zxy.z()});
  joint.flags(bsn::FLAG_SEGMENT_FRAME);
  dds::fill_anatomical(s.joint, s.joint_anatomical, joint);
}

int publish_scenario(const ScenarioSpec& spec, const SimNodeOptions& opt) {
  // A one-segment scenario (a free body) needs no --segment; otherwise it defaults to the node id.
  const Body body = build_body(spec);
  const std::string segment = !opt.segment.empty() ? opt.segment : body.size() == 1 ? body.segment(0).name : opt.node;
  ScenarioRunner runner(spec, {segment}, opt.ideal);
  services::DdsCommandFrame frame(opt.domain, "bsn sim " + opt.node);
  // The joint to the segment's parent, if it has one: its true angles on bsn/truth/joint_angles.
  const SegmentDef& def = body.segment(*body.find(segment));
  dds::Participant& participant = frame.participant();
  struct Outputs {
    std::unique_ptr<dds::Writer<bsn::RawSample>> raw;
    std::unique_ptr<dds::Writer<bsn::Orientation>> truth;
    std::unique_ptr<dds::Writer<bsn::Orientation>> segment_truth;
    std::unique_ptr<dds::Writer<bsn::JointAngles>> joint;
  } outputs;
  outputs.raw = participant.make_writer(dds::kRawTopic, std::nullopt, opt.node);
  outputs.truth = participant.make_writer(dds::kTruthOrientationTopic);
  outputs.segment_truth = participant.make_writer(dds::kTruthSegmentOrientationTopic);
  if (def.parent >= 0) outputs.joint = participant.make_writer(dds::kTruthJointAnglesTopic);
  // Secured, a raw writer that no fusion matched within dds::kPeerBound_s says so and makes its participant again
  // (Participant::watch_peers, called below at each sample).
  participant.expect_peer(*outputs.raw, "reader of bsn/raw for node '" + opt.node + "' (fusion)");
  logging::log_info("publishing segment '", segment, "' of scenario '", spec.name, "' as node '", opt.node, "' at ",
                    spec.rate_hz, " Hz x", opt.speed, " for ", spec.duration_s, " s in domain ", opt.domain,
                    " (raw samples from writer ", dds::writer_name(outputs.raw->guid()), ")");
  bsn::RawSample raw;
  raw.node_id(opt.node);
  bsn::Orientation truth;
  truth.segment(segment);
  truth.node_id(opt.node);
  bsn::Orientation segment_truth = truth;
  bsn::JointAngles joint = truth_joint(body, def, segment);
  std::vector<ScenarioSample> out;
  std::uint64_t write_failures = 0, dropped = 0;
  const std::uint64_t started = dds::monotonic_ns();
  const std::uint64_t t0 = scenario_start_ns(opt.start_at_unix_s, started);
  if (t0 > started + 1'000'000'000ull)
    logging::log_info("waiting ", (t0 - started) / 1'000'000'000ull, " s for the common start");
  for (std::uint64_t k = 0; !dds::shutdown_requested() && runner.next(out); ++k) {
    const ScenarioSample& s = out[0];
    // Sensor time runs at scenario speed; the wall clock `speed` times faster.
    const std::uint64_t sensor_ns = t0 + s.sample.timestamp_ns;
    const std::uint64_t due_ns =
        t0 + static_cast<std::uint64_t>(static_cast<double>(s.sample.timestamp_ns) / opt.speed);
    if (due_ns < started) continue;  // a late joiner: the body moved on before this node started
    if (!sleep_until(due_ns)) break;
    if (s.dropped) {
      ++dropped;  // lost on the link: the sequence number still advances
      continue;
    }
    fusion::ImuSample sample = s.sample;
    sample.timestamp_ns = sensor_ns;
    dds::fill_raw_sample(sample, raw);
    raw.seq(k);
    if (!outputs.raw->write(raw)) ++write_failures;
    truth.timestamp_ns(sensor_ns);
    dds::fill_orientation(s.truth, truth);
    outputs.truth->write(truth);
    // The same instant in the segment's ISB frame: the truth of an aligned estimate (FLAG_SEGMENT_FRAME).
    segment_truth.timestamp_ns(sensor_ns);
    dds::fill_orientation(s.segment_truth, segment_truth);
    segment_truth.flags(bsn::FLAG_SEGMENT_FRAME);
    outputs.segment_truth->write(segment_truth);
    if (outputs.joint && s.joint_relative) {
      fill_truth_joint(s, sensor_ns, joint);
      outputs.joint->write(joint);
    }
    participant.watch_peers();
  }
  if (write_failures > 0) logging::log_warn(write_failures, " raw samples could not be written");
  logging::log_info("node '", opt.node, "' stopped (", dropped, " samples dropped by the sensor model)");
  return 0;
}

int run_scenario(const SimNodeOptions& opt) {
  if (opt.rate_given) {
    logging::log_error("--rate does not apply with --scenario: the scenario's rate_hz sets the rate");
    return 2;
  }
  if (!(opt.speed > 0.0 && opt.speed <= 1e6)) {
    logging::log_error("--speed must be in (0, 1e6]");
    return 2;
  }
  if (opt.out_dir.empty() && (opt.node.empty() || opt.node.size() > 63)) {
    logging::log_error("--scenario needs --node ID (1 to 63 characters) to publish, or --out DIR to write files");
    return 2;
  }
  try {
    ScenarioSpec spec = load_scenario(opt.scenario);
    if (opt.seed != 0) spec.seed = opt.seed;
    if (opt.duration_s > 0.0) spec.duration_s = std::min(spec.duration_s, opt.duration_s);
    return opt.out_dir.empty() ? publish_scenario(spec, opt) : write_scenario_files(spec, opt);
  } catch (const ScenarioError& e) {
    logging::log_error(e.what());
  } catch (const std::invalid_argument& e) {
    logging::log_error(opt.scenario, ": ", e.what());
  } catch (const io::IoError& e) {
    logging::log_error(e.what());
  } catch (const std::filesystem::filesystem_error& e) {
    logging::log_error(e.what());
  }
  return 2;
}

}  // namespace

int run_sim_node(const SimNodeOptions& opt) {
  if (!opt.scenario.empty()) return run_scenario(opt);
  if (!opt.out_dir.empty() || opt.speed != 1.0) {
    logging::log_error("--out and --speed need --scenario");
    return 2;
  }
  if (opt.node.empty() || opt.node.size() > 63) {
    logging::log_error("--node must be 1 to 63 characters");
    return 2;
  }
  if (!(opt.rate_hz > 0.0 && opt.rate_hz <= 10000.0)) {
    logging::log_error("--rate must be in (0, 10000] Hz");
    return 2;
  }
  const std::string segment = opt.segment.empty() ? opt.node : opt.segment;
  const std::uint64_t seed = opt.seed != 0 ? opt.seed : std::hash<std::string>{}(opt.node);
  return publish_scenario(swing_scenario(segment, seed, opt.rate_hz, opt.duration_s), opt);
}

services::Command sim_command() {
  return {"sim", "Simulated sensor node: publishes bsn/raw and its truth (bsn/truth/*)", [](CLI::App* cmd) {
            auto opt = std::make_shared<SimNodeOptions>();
            cmd->add_option("--node", opt->node, "node id on bsn/raw (required unless --scenario with --out)");
            cmd->add_option("--segment", opt->segment, "segment name on bsn/truth/orientation (default: node id)");
            cmd->add_option("--rate", opt->rate_hz, "sample rate in Hz")
                ->capture_default_str()
                ->check(services::positive_number(10000.0));
            cmd->add_option("--seed", opt->seed, "motion and noise seed (default: from the node id)");
            cmd->add_option("--duration", opt->duration_s, "stop after S seconds (default: run until Ctrl-C)")
                ->check(services::non_negative_number(1e9));
            cmd->add_flag("--ideal", opt->ideal, "no sensor noise (with --scenario: every sensor error off)");
            cmd->add_option("--scenario", opt->scenario,
                            "scenario YAML file: publish its segment --segment (default: node id)")
                ->check(CLI::ExistingFile);
            cmd->add_option("--speed", opt->speed, "with --scenario: publish N times faster than real time")
                ->capture_default_str()
                ->check(services::positive_number(1e6));
            cmd->add_option("--start-at", opt->start_at_unix_s,
                            "the motion's time 0 at this Unix time, s (e.g. $(($(date +%s) + 3))): "
                            "nodes given the same instant move as one body")
                ->check(services::positive_number(1e11));
            cmd->add_option("--out", opt->out_dir, "with --scenario: write DIR/<segment>.hdf5 (BROAD layout) and exit");
            services::add_domain_option(cmd, opt->domain);
            return [opt, cmd] {
              if (opt->scenario.empty() && opt->node.empty()) throw CLI::RequiredError("--node");
              opt->rate_given = cmd->count("--rate") > 0;
              logging::set_log_identity("sim " + (opt->node.empty() ? std::string("scenario") : opt->node));
              return run_sim_node(*opt);
            };
          }};
}

}  // namespace bsn::sim
