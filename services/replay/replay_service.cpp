#include "replay_service.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>

#include "bsn/dds/conversions.hpp"
#include "bsn/dds/shutdown.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/io/session_file.hpp"
#include "bsn/logging/log.hpp"

namespace bsn::services {
namespace {

namespace fs = std::filesystem;

std::vector<ReplayTrack> load_session(const std::string& path) {
  const io::SessionReader reader(path);
  std::vector<ReplayTrack> tracks;
  for (const io::SessionStream& s : reader.streams_of(dds::kRawTopic.name)) {
    ReplayTrack t;
    t.node = s.key;
    static_cast<RawColumns&>(t) = read_raw_columns(reader, s);
    // A recording stopped by a crash may hold one column a write ahead of another: keep the rows all have.
    const std::size_t n = std::min(t.seq.size(), t.measurement_rows());
    if (n != t.timestamp_ns.size() || n != t.channels.size()) {
      logging::log_warn(path, ": ", s.group, ": columns of different lengths, replaying the first ", n, " samples");
    }
    t.resize(n);
    if (n > 0) tracks.push_back(std::move(t));
  }
  if (tracks.empty()) throw io::IoError(path + ": no samples of bsn/raw in this session");
  return tracks;
}

ReplayTrack load_recording(const std::string& path) {
  const io::Recording rec = io::read_recording(path);
  ReplayTrack t;
  t.node = fs::path(path).stem().string();
  const std::size_t n = rec.size();
  t.timestamp_ns.resize(n);
  t.seq.resize(n);
  t.channels.resize(n);
  t.acc.resize(3 * n);
  t.gyr.resize(3 * n);
  t.mag.resize(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const fusion::ImuSample s = rec.sample(i);
    bsn::RawSample raw;
    dds::fill_raw_sample(s, raw);
    t.timestamp_ns[i] = raw.timestamp_ns();
    t.seq[i] = i;
    t.channels[i] = raw.channels();
    for (int k = 0; k < 3; ++k) {
      t.acc[3 * i + k] = raw.acc()[k];
      t.gyr[3 * i + k] = raw.gyr()[k];
      t.mag[3 * i + k] = raw.mag()[k];
    }
  }
  if (n == 0) throw io::IoError(path + ": no samples");
  return t;
}

std::vector<ReplayTrack> load_file(const std::string& path) {
  if (io::is_session_file(path)) return load_session(path);
  std::vector<ReplayTrack> one;
  one.push_back(load_recording(path));
  return one;
}

}  // namespace

std::vector<ReplayTrack> load_replay_tracks(const std::string& path) {
  if (!fs::exists(path)) throw io::IoError(path + ": no such file or folder");
  if (!fs::is_directory(path)) return load_file(path);
  std::vector<std::string> files;
  for (const auto& e : fs::directory_iterator(path)) {
    const std::string ext = e.path().extension().string();
    if (e.is_regular_file() && (ext == ".h5" || ext == ".hdf5" || ext == ".csv")) files.push_back(e.path().string());
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) throw io::IoError(path + ": no .h5, .hdf5 or .csv files in this folder");
  std::vector<ReplayTrack> tracks;
  for (const std::string& f : files) {
    for (ReplayTrack& t : load_file(f)) tracks.push_back(std::move(t));
  }
  return tracks;
}

namespace {

// Applies --node-map; two tracks with one name are refused (their sequence numbers would collide).
bool map_nodes(std::vector<ReplayTrack>& tracks, const std::vector<std::string>& mapping) {
  for (const std::string& m : mapping) {
    const auto eq = m.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == m.size()) {
      std::fprintf(stderr, "bsn replay: error: --node-map '%s' is not FROM=TO\n", m.c_str());
      return false;
    }
    const std::string from = m.substr(0, eq), to = m.substr(eq + 1);
    auto it = std::find_if(tracks.begin(), tracks.end(), [&](const ReplayTrack& t) { return t.node == from; });
    if (it == tracks.end()) {
      std::string names;
      for (const auto& t : tracks) names += (names.empty() ? "" : ", ") + t.node;
      std::fprintf(stderr, "bsn replay: error: --node-map: no node '%s' in the input (nodes: %s)\n", from.c_str(),
                   names.c_str());
      return false;
    }
    it->node = to;
  }
  std::map<std::string, int> count;
  for (const auto& t : tracks) {
    if (t.node.empty() || t.node.size() > 63) {
      std::fprintf(stderr, "bsn replay: error: node id '%s' must have 1 to 63 characters (use --node-map)\n",
                   t.node.c_str());
      return false;
    }
    if (++count[t.node] == 2) {
      std::fprintf(stderr, "bsn replay: error: two inputs hold node '%s' (use --node-map to rename one)\n",
                   t.node.c_str());
      return false;
    }
  }
  return true;
}

/// The tracks' common time: one origin for all (they share the recording host's clock), so their alignment is kept.
struct Timeline {
  std::uint64_t t0 = UINT64_MAX, t_end = 0, samples = 0;
  std::uint64_t loop_span = 0;  ///< a loop's next pass starts this much later
};

Timeline timeline_of(const std::vector<ReplayTrack>& tracks) {
  Timeline tl;
  for (const auto& t : tracks) {
    tl.t0 = std::min(tl.t0, t.timestamp_ns.front());
    tl.t_end = std::max(tl.t_end, t.timestamp_ns.back());
    tl.samples += t.size();
  }
  // A loop continues time and sequence numbers: the next pass starts one mean interval after the last sample.
  std::uint64_t mean_dt = 10000000u;  // 10 ms when no track has two samples
  for (const auto& t : tracks) {
    if (t.size() >= 2) {
      mean_dt = std::max<std::uint64_t>(1, (t.timestamp_ns.back() - t.timestamp_ns.front()) / (t.size() - 1));
      break;
    }
  }
  tl.loop_span = tl.t_end - tl.t0 + mean_dt;
  return tl;
}

/// Waits (at most --wait s) until --readers readers have matched; false at a shutdown.
bool wait_for_readers(const dds::Writer<bsn::RawSample>& writer, const ReplayOptions& opt) {
  if (opt.readers <= 0) return true;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(opt.wait_s);
  while (writer.matched() < opt.readers && std::chrono::steady_clock::now() < deadline) {
    if (!dds::sleep_unless_shutdown(std::chrono::milliseconds(20))) return false;
  }
  if (writer.matched() < opt.readers) {
    logging::log_warn("only ", writer.matched(), " of ", opt.readers, " readers matched after ", opt.wait_s,
                      " s; starting anyway");
  }
  // The reader side learns of this writer a moment after the writer sees it; samples before that are lost.
  return dds::sleep_unless_shutdown(std::chrono::milliseconds(300));
}

}  // namespace

int run_replay(const ReplayOptions& opt) {
  logging::set_log_identity("replay");
  std::vector<ReplayTrack> tracks;
  try {
    for (const std::string& in : opt.inputs)
      for (ReplayTrack& t : load_replay_tracks(in)) tracks.push_back(std::move(t));
  } catch (const io::IoError& e) {
    std::fprintf(stderr, "bsn replay: error: %s\n", e.what());
    return 2;  // bad input: unreadable, empty or cut short
  }
  if (!map_nodes(tracks, opt.node_map)) return 2;

  const Timeline tl = timeline_of(tracks);
  const std::uint64_t t0 = tl.t0, t_end = tl.t_end, samples = tl.samples, loop_span = tl.loop_span;

  DdsCommandFrame frame(opt.domain, "bsn replay");
  // One writer for every node, or, secured, one per node: each in its node's partition (Participant::make_writer).
  std::vector<std::shared_ptr<dds::Writer<bsn::RawSample>>> writers;
  for (const ReplayTrack& t : tracks) {
    if (!writers.empty() && !frame.participant().secured()) {
      writers.push_back(writers.front());
      continue;
    }
    writers.push_back(frame.participant().make_writer(dds::kRawTopic, std::nullopt, t.node));
  }
  dds::Writer<bsn::RawSample>* writer = writers.front().get();
  if (!wait_for_readers(*writer, opt)) return 0;
  logging::log_info("replaying ", samples, " samples of ", tracks.size(), " nodes (",
                    static_cast<double>(t_end - t0) * 1e-9, " s) at ",
                    opt.speed == 0.0 ? std::string("full speed") : "speed " + std::to_string(opt.speed));

  std::vector<bsn::RawSample> msgs(tracks.size());
  for (std::size_t k = 0; k < tracks.size(); ++k) msgs[k].node_id(tracks[k].node);
  std::vector<std::size_t> next(tracks.size(), 0);
  const std::uint64_t base = dds::monotonic_ns();
  const auto start = std::chrono::steady_clock::now();
  std::uint64_t published = 0, write_failures = 0;
  for (std::uint64_t pass = 0;; ++pass) {
    std::fill(next.begin(), next.end(), 0);
    const std::uint64_t time_offset = pass * loop_span;
    for (;;) {
      std::size_t best = tracks.size();
      for (std::size_t k = 0; k < tracks.size(); ++k) {
        if (next[k] < tracks[k].size() &&
            (best == tracks.size() || tracks[k].timestamp_ns[next[k]] < tracks[best].timestamp_ns[next[best]])) {
          best = k;
        }
      }
      if (best == tracks.size()) break;
      const ReplayTrack& t = tracks[best];
      const std::size_t i = next[best]++;
      const std::uint64_t rel = t.timestamp_ns[i] - t0 + time_offset;
      if (opt.speed > 0.0) {
        const auto due =
            start + std::chrono::nanoseconds(static_cast<std::int64_t>(static_cast<double>(rel) / opt.speed));
        const auto now = std::chrono::steady_clock::now();
        if (due > now && !dds::sleep_unless_shutdown(due - now)) break;
      }
      if (dds::shutdown_requested()) break;
      bsn::RawSample& m = msgs[best];
      m.timestamp_ns(base + rel);
      m.seq(t.seq[i] + pass * (t.seq.back() - t.seq.front() + 1));
      for (int c = 0; c < 3; ++c) {
        m.acc()[c] = t.acc[3 * i + c];
        m.gyr()[c] = t.gyr[3 * i + c];
        m.mag()[c] = t.mag[3 * i + c];
      }
      m.channels(t.channels[i]);
      if (writers[best]->write(m)) {
        ++published;
      } else {
        ++write_failures;
      }
    }
    if (!opt.loop || dds::shutdown_requested()) break;
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  logging::log_info("published ", published, " samples in ", wall, " s", write_failures ? " (" : "",
                    write_failures ? std::to_string(write_failures) + " could not be written)" : "");
  dds::sleep_unless_shutdown(std::chrono::milliseconds(200));  // let the last samples leave
  return write_failures == 0 ? 0 : 1;
}

Command replay_command() {
  return {
      "replay", "Publish recorded raw samples on bsn/raw with their timing", [](CLI::App* cmd) {
        auto opt = std::make_shared<ReplayOptions>();
        cmd->add_option("input", opt->inputs, "session .h5, BROAD .hdf5, eval .csv, or a folder of them")->required();
        cmd->add_option("--speed", opt->speed, "times real time (0 = as fast as possible)")
            ->check(CLI::NonNegativeNumber)
            ->capture_default_str();
        cmd->add_flag("--loop", opt->loop, "start over at the end (time and sequence numbers continue)");
        cmd->add_option("--node-map", opt->node_map, "publish node FROM as TO (FROM=TO, repeatable)");
        cmd->add_option("--readers", opt->readers, "wait until N bsn/raw readers have matched (0 = start at once)")
            ->check(CLI::NonNegativeNumber)
            ->capture_default_str();
        cmd->add_option("--wait", opt->wait_s, "wait for the readers at most S seconds")
            ->check(CLI::NonNegativeNumber)
            ->capture_default_str();
        add_domain_option(cmd, opt->domain);
        return [opt] { return run_replay(*opt); };
      }};
}

}  // namespace bsn::services
