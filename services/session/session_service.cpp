#include "session_service.hpp"

#include <poll.h>
#include <time.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <set>

#include "bsn/config/body_config.hpp"
#include "bsn/config/yaml_reader.hpp"
#include "bsn/dds/child_process.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/dds/shutdown.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/fusion/body_model.hpp"
#include "bsn/logging/log.hpp"

namespace bsn::services {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using Reader = config::YamlReader<SessionError>;

std::string absolute_from(const fs::path& base, const std::string& p) {
  return (fs::path(p).is_absolute() ? fs::path(p) : base / p).lexically_normal().string();
}

double wall_seconds() {
  timespec t{};
  clock_gettime(CLOCK_REALTIME, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

std::uint64_t clock_ns(clockid_t id) {
  timespec t{};
  clock_gettime(id, &t);
  return static_cast<std::uint64_t>(t.tv_sec) * 1'000'000'000ull + static_cast<std::uint64_t>(t.tv_nsec);
}

/// A trial or file name: letters, digits, '-', '_' and '.', not starting with '.'.
bool valid_name(const std::string& n) {
  if (n.empty() || n.size() > 64 || n[0] == '.') return false;
  for (const char c : n)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_' && c != '.') return false;
  return true;
}

/// The processes of a session, stopped in reverse start order.
class Processes {
 public:
  explicit Processes(fs::path logs) : logs_(std::move(logs)) {}
  ~Processes() { stop_all(); }
  dds::ChildProcess& start(const std::string& name, const std::vector<std::string>& argv) {
    list_.emplace_back(name, std::make_unique<dds::ChildProcess>(argv, log(name)));
    return *list_.back().second;
  }
  std::string log(const std::string& name) const { return (logs_ / (name + ".log")).string(); }
  /// The first process that has ended (its name), or "".
  std::string ended() {
    for (auto& [name, p] : list_)
      if (!p->running()) return name;
    return "";
  }
  /// Stops every process; false if one did not exit with 0.
  bool stop_all() {
    bool clean = true;
    for (auto it = list_.rbegin(); it != list_.rend(); ++it) {
      const auto status = it->second->stop();
      if (status != std::optional<int>(0)) {
        clean = false;
        logging::log_warn(it->first, " did not stop cleanly; see ", log(it->first));
      }
    }
    list_.clear();
    return clean;
  }

 private:
  fs::path logs_;
  std::vector<std::pair<std::string, std::unique_ptr<dds::ChildProcess>>> list_;
};

/// Runs `argv` to its end (a recorder's or an exporter's run), polling for a shutdown; its exit code, or -1.
int run_to_end(const std::vector<std::string>& argv, const std::string& log, std::chrono::seconds timeout) {
  dds::ChildProcess p(argv, log);
  const auto deadline = Clock::now() + timeout;
  while (p.running() && Clock::now() < deadline && dds::sleep_unless_shutdown(std::chrono::milliseconds(50))) {
  }
  const auto status = p.running() ? p.stop() : p.wait_for(std::chrono::milliseconds(0));
  return status && WIFEXITED(*status) ? WEXITSTATUS(*status) : -1;
}

/// The session's alignment request and the calibration service's replies to it.
struct AlignmentChannel {
  std::mutex mutex;
  std::string instruction;                                ///< the service's latest instruction
  std::map<std::string, bsn::CalibrationResult> results;  ///< by node
  const std::string request_id =
      "session-" + std::to_string(getpid()) + "-" + std::to_string(static_cast<long long>(std::time(nullptr)));
  std::unique_ptr<dds::Writer<bsn::CalibrationRequest>> request_writer;
  std::unique_ptr<dds::Reader<bsn::CalibrationProgress>> progress_reader;
  std::unique_ptr<dds::Reader<bsn::CalibrationResult>> result_reader;

  explicit AlignmentChannel(dds::Participant& participant) {
    request_writer = participant.make_writer(dds::kCalibrationRequestTopic);
    progress_reader = participant.make_reader(
        dds::kCalibrationProgressTopic,
        [this](const bsn::CalibrationProgress& p, const eprosima::fastdds::dds::SampleInfo&) {
          if (p.request_id() != request_id) return;
          std::lock_guard lock(mutex);
          instruction = logging::printable(
              p.phase() == bsn::CALIBRATION_PHASE_REFUSED ? "REFUSED: " + p.message() : p.instruction(), 200);
        });
    result_reader =
        participant.make_reader(dds::kCalibrationResultTopic,
                                [this](const bsn::CalibrationResult& r, const eprosima::fastdds::dds::SampleInfo&) {
                                  if (r.request_id() != request_id || r.kind() != bsn::CALIBRATION_SEGMENT_ALIGNMENT)
                                    return;
                                  std::lock_guard lock(mutex);
                                  results[r.node_id()] = r;
                                });
  }
};

/// What every step of a session run shares.
struct SessionRun {
  const SessionSpec& spec;
  const fusion::BodyModel& body;
  Processes& procs;
  std::string self;
  std::string dom;
};

/// The calibration service (once it answers), the fusion, the alignment request, the simulated or real nodes and
/// bsn view. Throws std::runtime_error when the calibration service does not answer.
void start_processes(const SessionRun& run, AlignmentChannel& alignment) {
  const SessionSpec& spec = run.spec;
  const std::string& self = run.self;
  const std::string& dom = run.dom;
  Processes& procs = run.procs;
  // The calibration service first: the alignment request must reach it before the N-pose begins.
  procs.start("calibration", {self, "calibration", "--domain", dom, "--store", spec.store_dir});
  const auto deadline = Clock::now() + std::chrono::seconds(20);
  while ((alignment.request_writer->matched() == 0 || alignment.progress_reader->matched() == 0 ||
          alignment.result_reader->matched() == 0) &&
         Clock::now() < deadline && dds::sleep_unless_shutdown(std::chrono::milliseconds(20))) {
  }
  if (alignment.request_writer->matched() == 0 || alignment.result_reader->matched() == 0)
    throw std::runtime_error("bsn calibration did not answer; see " + procs.log("calibration"));
  procs.start("fusion", {self, "fusion", "--domain", dom, "--body", spec.body_path});
  if (spec.align) {
    bsn::CalibrationRequest request;
    request.request_id(alignment.request_id);
    request.node_id("*");
    request.kind(bsn::CALIBRATION_SEGMENT_ALIGNMENT);
    request.body(config::body_model_to_yaml(run.body));
    request.pose_s(spec.pose_s);
    request.duration_s(spec.align_duration_s);
    request.until_good(true);
    alignment.request_writer->write(request);
  }
  if (!spec.scenario.empty()) {
    // One common start, a few seconds ahead: every process and its discovery are up by then.
    char start_at[32];
    std::snprintf(start_at, sizeof start_at, "%.3f", wall_seconds() + 3.0);
    for (const auto& s : run.body.segments)
      procs.start("sim-" + s.node, {self, "sim", "--domain", dom, "--node", s.node, "--segment", s.name, "--scenario",
                                    spec.scenario, "--start-at", start_at});
  }
  for (const auto& n : spec.nodes) {
    std::vector<std::string> argv{self, "node", "--domain", dom, "--node", n.node, "--source", n.source};
    if (!n.map.empty()) argv.insert(argv.end(), {"--map", n.map});
    procs.start("node-" + n.node, argv);
  }
  if (spec.view) {
    procs.start("view", {self, "view", "--domain", dom, "--port", std::to_string(spec.view_port)});
    std::printf("bsn session: live 3D view at http://127.0.0.1:%d/\n", spec.view_port);
  }
}

/// The alignment, guided by the service's instructions; every node of the body must succeed. Returns 0, else 1.
int guide_alignment(const SessionRun& run, AlignmentChannel& alignment) {
  int code = 0;
  std::string shown;
  auto last_print = Clock::now();
  const auto deadline = Clock::now() + std::chrono::duration<double>(run.spec.align_duration_s + 20.0);
  bool done = false;
  while (!done && Clock::now() < std::chrono::time_point_cast<Clock::duration>(deadline) &&
         dds::sleep_unless_shutdown(std::chrono::milliseconds(50))) {
    if (const std::string gone = run.procs.ended(); !gone.empty()) {
      logging::log_error(gone, " ended during the alignment; see ", run.procs.log(gone));
      code = 1;
      break;
    }
    std::lock_guard lock(alignment.mutex);
    // A new step at once; the same step's countdown at most once a second.
    const auto now = Clock::now();
    const auto step = [](const std::string& t) { return t.substr(0, t.find_first_of("0123456789")); };
    const std::string& instruction = alignment.instruction;
    if (instruction != shown && (step(instruction) != step(shown) || now - last_print >= std::chrono::seconds(1))) {
      shown = instruction;
      last_print = now;
      std::printf("alignment: %s\n", shown.c_str());
      std::fflush(stdout);
    }
    done = alignment.results.size() == run.body.segments.size();
  }
  std::lock_guard lock(alignment.mutex);
  if (code == 0 && !done) {
    logging::log_error("the alignment did not finish: ", alignment.results.size(), " of ", run.body.segments.size(),
                       " nodes answered (see ", run.procs.log("calibration"), ")");
    code = 1;
  }
  for (const auto& [node, r] : alignment.results) {
    if (r.success()) {
      std::printf("alignment: %s aligned (%s)\n", logging::printable(node).c_str(),
                  logging::printable(r.alignment_source()).c_str());
    } else {
      std::printf("alignment: %s FAILED: %s\n", logging::printable(node).c_str(),
                  logging::printable(r.message(), 200).c_str());
      code = 1;
    }
  }
  std::fflush(stdout);
  return code;
}

/// While `recorder` runs: each line on the terminal is an event, written to `events` with both clocks. Returns the
/// events marked; `stdin_open` goes false once the terminal's input is closed (or /dev/null).
int mark_events(dds::ChildProcess& recorder, std::ofstream& events, const std::string& trial, bool& stdin_open) {
  int marks = 0;
  while (recorder.running() && dds::sleep_unless_shutdown(std::chrono::milliseconds(20))) {
    if (!stdin_open) continue;
    pollfd in{STDIN_FILENO, POLLIN, 0};
    if (poll(&in, 1, 0) <= 0 || !(in.revents & (POLLIN | POLLHUP))) continue;
    char line[256];
    const ssize_t n = read(STDIN_FILENO, line, sizeof line - 1);
    if (n <= 0) {
      stdin_open = false;  // closed (or /dev/null): no markers from the terminal
      continue;
    }
    line[n] = '\0';
    std::string label(line);
    while (!label.empty() && (label.back() == '\n' || label.back() == '\r')) label.pop_back();
    // The monotonic clock is the simulated nodes' sensor clock on this host (bsn sim); real sensors have
    // their own, so the Unix time goes along.
    events << clock_ns(CLOCK_REALTIME) << "," << clock_ns(CLOCK_MONOTONIC) << ","
           << (label.empty() ? "event " + std::to_string(marks + 1) : logging::printable(label, 64)) << "\n";
    events.flush();
    std::printf("trial %s: event %d marked\n", trial.c_str(), ++marks);
    std::fflush(stdout);
  }
  return marks;
}

/// One trial: recorded for its duration, its event markers (a line on the terminal) beside it, exported. Returns 0,
/// or 1 (said) when the recording or an export failed.
int record_trial(const SessionRun& run, const std::string& trial, bool& stdin_open) {
  const SessionSpec& spec = run.spec;
  const std::string h5 = (fs::path(spec.out_dir) / (trial + ".h5")).string();
  std::printf("trial %s: recording %.0f s to %s (Enter marks an event)\n", trial.c_str(), spec.record_s, h5.c_str());
  std::fflush(stdout);
  std::vector<std::string> argv{
      run.self, "record",      "--domain", run.dom, "--out", h5, "--duration", std::to_string(spec.record_s),
      "--body", spec.body_path};
  for (const auto& topic : spec.topics) argv.insert(argv.end(), {"--topic", topic});
  dds::ChildProcess recorder(argv, run.procs.log("record-" + trial));
  const std::string events_path = (fs::path(spec.out_dir) / (trial + ".events.csv")).string();
  std::ofstream events(events_path);
  events << "unix_ns,monotonic_ns,label\n";
  const int marks = mark_events(recorder, events, trial, stdin_open);
  const auto status = recorder.running() ? recorder.stop() : recorder.wait_for(std::chrono::milliseconds(0));
  events.close();
  if (!status || !WIFEXITED(*status) || WEXITSTATUS(*status) != 0) {
    logging::log_error("recording ", h5, " failed; see ", run.procs.log("record-" + trial));
    return 1;
  }
  int code = 0;
  const fs::path export_dir = fs::path(spec.out_dir) / trial;
  for (const auto& format : spec.exports) {
    const int c = run_to_end({run.self, "export", h5, "--format", format, "--out", export_dir.string()},
                             run.procs.log("export-" + trial + "-" + format), std::chrono::seconds(300));
    if (c != 0) {
      logging::log_error("export of ", h5, " as ", format, " failed; see ",
                         run.procs.log("export-" + trial + "-" + format));
      code = 1;
    }
  }
  std::error_code ec;
  if (!spec.exports.empty())
    fs::copy_file(events_path, export_dir / "events.csv", fs::copy_options::overwrite_existing, ec);
  std::printf("trial %s: %d events; %s%s\n", trial.c_str(), marks, h5.c_str(),
              spec.exports.empty() ? "" : (", exported to " + export_dir.string()).c_str());
  std::fflush(stdout);
  return code;
}

int run_session(const std::string& file, int domain) {
  SessionSpec spec;
  fusion::BodyModel body;
  try {
    spec = load_session(file);
    body = config::load_body_model(spec.body_path);
  } catch (const SessionError& e) {
    std::fprintf(stderr, "bsn session: error: %s\n", e.what());
    return 2;
  } catch (const config::ConfigError& e) {
    std::fprintf(stderr, "bsn session: error: %s\n", e.what());
    return 2;
  }
  // Nothing is ever overwritten: a trial's file that exists stops the session before anything starts.
  for (const auto& t : spec.trials) {
    const fs::path h5 = fs::path(spec.out_dir) / (t + ".h5");
    if (fs::exists(h5)) {
      std::fprintf(stderr, "bsn session: error: %s exists (a trial's recording is never replaced)\n", h5.c_str());
      return 2;
    }
  }
  const fs::path logs = fs::path(spec.out_dir) / "logs";
  std::error_code ec;
  fs::create_directories(logs, ec);
  if (!fs::is_directory(logs)) {
    std::fprintf(stderr, "bsn session: error: cannot create %s\n", logs.c_str());
    return 1;
  }
  dds::install_shutdown_handlers();
  std::printf("bsn session '%s': body %s (%zu segments), domain %d, trials in %s\n", spec.name.c_str(),
              spec.body_path.c_str(), body.segments.size(), domain, spec.out_dir.c_str());
  std::fflush(stdout);

  int code = 0;
  Processes procs(logs);
  const SessionRun run{spec, body, procs, dds::self_executable(), std::to_string(domain)};
  {
    dds::Participant participant({domain, "bsn session"});
    AlignmentChannel alignment(participant);
    try {
      start_processes(run, alignment);
    } catch (const std::exception& e) {
      logging::log_error("cannot start the session's processes: ", e.what());
      code = 1;
    }
    if (code == 0 && spec.align) code = guide_alignment(run, alignment);
    bool stdin_open = true;
    for (std::size_t t = 0; code == 0 && t < spec.trials.size() && !dds::shutdown_requested(); ++t)
      code = record_trial(run, spec.trials[t], stdin_open);
  }
  if (!procs.stop_all() && code == 0) code = 1;
  std::printf("bsn session '%s': %s; every process stopped\n", spec.name.c_str(), code == 0 ? "done" : "FAILED");
  return code;
}

// The session's nodes: a simulated body (its scenario file) and/or real nodes, each with its source.
void read_nodes(const Reader& r, const YAML::Node& nodes, const fs::path& base, SessionSpec& s) {
  r.check_keys(nodes, {"simulated", "real"}, "nodes");
  if (nodes["simulated"]) {
    r.check_keys(nodes["simulated"], {"scenario"}, "nodes.simulated");
    if (!nodes["simulated"]["scenario"]) r.fail(nodes["simulated"], "nodes.simulated needs scenario: FILE");
    s.scenario = absolute_from(base, r.text(nodes["simulated"]["scenario"], "scenario"));
    if (!fs::is_regular_file(s.scenario)) r.fail(nodes["simulated"]["scenario"], "no scenario file " + s.scenario);
  }
  if (nodes["real"]) {
    if (!nodes["real"].IsSequence()) r.fail(nodes["real"], "nodes.real must be a list of {node, source, map}");
    for (const auto& n : nodes["real"]) {
      r.check_keys(n, {"node", "source", "map"}, "a real node");
      if (!n["node"] || !n["source"]) r.fail(n, "a real node needs node: ID and source: URI (serial:, udp:, iio:)");
      SessionSpec::RealNode real{r.text(n["node"], "node"), r.text(n["source"], "source"), ""};
      if (n["map"]) real.map = absolute_from(base, r.text(n["map"], "map"));
      s.nodes.push_back(real);
    }
  }
  if (s.scenario.empty() && s.nodes.empty()) r.fail(nodes, "nodes names no source (simulated or real)");
}

}  // namespace

SessionSpec load_session(const std::string& path) {
  const std::string text = config::read_config_file<SessionError>(path, "session");
  const Reader r(path);
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    r.fail_at(e.mark.line + 1, e.msg);
  }
  r.check_keys(root, {"name", "body", "nodes", "calibrations", "alignment", "record", "trials", "export", "view"},
               "the session");
  const fs::path base = fs::absolute(path).parent_path();
  SessionSpec s;
  s.name = root["name"] ? r.text(root["name"], "name") : fs::path(path).stem().string();
  if (!root["body"]) r.fail_at(1, "the session needs body: FILE (e.g. deploy/bodies/lower_body.yaml)");
  s.body_path = absolute_from(base, r.text(root["body"], "body"));
  // Inputs are relative to the session file; what the session writes (calibrations, trials) to the working folder.
  const fs::path here = fs::current_path();
  s.store_dir = absolute_from(here, root["calibrations"] ? r.text(root["calibrations"], "calibrations") : "calib");
  if (!root["nodes"]) r.fail_at(1, "the session needs nodes: (simulated: {scenario: FILE} and/or real: [...])");
  read_nodes(r, root["nodes"], base, s);
  if (const YAML::Node a = root["alignment"]) {
    if (a.IsScalar() && (a.as<std::string>() == "none" || a.as<std::string>() == "false")) {
      s.align = false;
    } else {
      r.check_keys(a, {"pose_s", "duration_s"}, "alignment");
      if (a["pose_s"]) s.pose_s = r.number(a["pose_s"], "alignment.pose_s");
      if (a["duration_s"]) s.align_duration_s = r.number(a["duration_s"], "alignment.duration_s");
      if (!(s.pose_s > 0 && s.pose_s <= 60)) r.fail(a, "alignment.pose_s must be in (0, 60] s");
      if (!(s.align_duration_s > s.pose_s && s.align_duration_s <= 3600))
        r.fail(a, "alignment.duration_s must be longer than pose_s and at most 3600 s");
    }
  }
  const YAML::Node rec = root["record"];
  if (!rec) r.fail_at(1, "the session needs record: {out: DIR, duration_s: S}");
  r.check_keys(rec, {"out", "duration_s", "topics"}, "record");
  s.out_dir = absolute_from(here, rec["out"] ? r.text(rec["out"], "record.out") : "trials");
  if (rec["duration_s"]) s.record_s = r.number(rec["duration_s"], "record.duration_s");
  if (!(s.record_s > 0 && s.record_s <= 86400)) r.fail(rec, "record.duration_s must be in (0, 86400] s");
  if (rec["topics"]) {
    if (!rec["topics"].IsSequence()) r.fail(rec["topics"], "record.topics must be a list of topic names");
    std::set<std::string> known;
    dds::for_each_topic([&](const auto& topic) { known.insert(topic.name); });
    for (const auto& t : rec["topics"]) {
      const std::string name = r.text(t, "a topic");
      if (!known.count(name)) r.fail(t, "unknown topic '" + name + "'");
      s.topics.push_back(name);
    }
  }
  if (const YAML::Node t = root["trials"]) {
    if (!t.IsSequence()) r.fail(t, "trials must be a list of names");
    for (const auto& n : t) {
      const std::string name = r.text(n, "a trial");
      if (!valid_name(name)) r.fail(n, "trial name '" + name + "': letters, digits, '-', '_', '.' only");
      s.trials.push_back(name);
    }
  }
  if (s.trials.empty()) s.trials.push_back("trial1");
  if (const YAML::Node e = root["export"]) {
    if (!e.IsSequence()) r.fail(e, "export must be a list of formats (sto, csv, broad)");
    for (const auto& f : e) {
      const std::string format = r.text(f, "a format");
      if (format != "sto" && format != "csv" && format != "broad") r.fail(f, "unknown format '" + format + "'");
      s.exports.push_back(format);
    }
  }
  if (const YAML::Node v = root["view"]) {
    if (v.IsScalar()) {
      const std::string b = v.as<std::string>();
      if (b != "true" && b != "false") r.fail(v, "view must be true, false or {port: P}");
      s.view = b == "true";
    } else {
      r.check_keys(v, {"port"}, "view");
      s.view = true;
      if (v["port"]) {
        const double p = r.number(v["port"], "view.port");
        if (!(p >= 1 && p <= 65535 && p == std::floor(p))) r.fail(v["port"], "view.port must be 1..65535");
        s.view_port = static_cast<int>(p);
      }
    }
  }
  return s;
}

Command session_command() {
  return {"session", "A lab session by one command: fusion, calibration, nodes, alignment, trials, export",
          [](CLI::App* cmd) {
            auto file = std::make_shared<std::string>();
            auto domain = std::make_shared<int>(0);
            cmd->add_option("file", *file, "session file (YAML; see README, deploy/sessions/)")->required();
            add_domain_option(cmd, *domain);
            return [file, domain] {
              logging::set_log_identity("session");
              return run_session(*file, *domain);
            };
          }};
}

}  // namespace bsn::services
