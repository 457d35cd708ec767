// bsn_bench_sessions: how fast the session tools go on this host.
//
// Phase 1 (recorder): one real `bsn record` process records every topic of an N-segment body (default 64) at
// 100 Hz, all written by this bench: raw, orientation and truth per segment, joint angles per joint, and one
// bsn/status per second, for --seconds. Reported: samples written and recorded (loss), the recorder's RSS every
// second (flat = no growth), and the file's size.
// Phase 2 (replay): a synthetic session of 7 nodes x --replay-seconds at 100 Hz is replayed at rising --speed into
// a real `bsn record --topic bsn/raw`; reported per speed: samples recorded of those in the file, and the
// wall time. The highest speed without loss is the figure of merit.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <thread>

#include "bsn/dds/child_process.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/io/session_file.hpp"

#ifndef BSN_EXECUTABLE
#error "BSN_EXECUTABLE must name the bsn program"
#endif

namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

double rss_mb(int pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(f, line);) {
    if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  }
  return -1.0;
}

std::uint64_t rows_of(const bsn::io::SessionReader& r, const std::string& topic) {
  std::uint64_t n = 0;
  for (const auto& s : r.streams_of(topic)) n += r.rows(s, "arrival_ns");
  return n;
}

void recorder_phase(int domain, int segments, double seconds, const std::filesystem::path& dir) {
  const std::string out = (dir / "record_bench.h5").string();
  bsn::dds::ChildProcess rec(
      {BSN_EXECUTABLE, "record", "--out", out, "--overwrite", "--domain", std::to_string(domain)},
      (dir / "record.log").string());
  bsn::dds::Participant p({domain, "bench sessions"});
  auto raw_w = p.make_writer(bsn::dds::kRawTopic);
  auto ori_w = p.make_writer(bsn::dds::kOrientationTopic);
  auto truth_w = p.make_writer(bsn::dds::kTruthOrientationTopic);
  auto joint_w = p.make_writer(bsn::dds::kJointAnglesTopic);
  auto status_w = p.make_writer(bsn::dds::kStatusTopic);
  const auto deadline = Clock::now() + 10s;
  while ((raw_w->matched() < 1 || ori_w->matched() < 1 || truth_w->matched() < 1 || joint_w->matched() < 1 ||
          status_w->matched() < 1) &&
         Clock::now() < deadline) {
    std::this_thread::sleep_for(20ms);
  }
  std::this_thread::sleep_for(500ms);
  std::vector<bsn::RawSample> raw(static_cast<std::size_t>(segments));
  std::vector<bsn::Orientation> ori(static_cast<std::size_t>(segments));
  std::vector<bsn::JointAngles> joints(static_cast<std::size_t>(segments - 1));
  for (int i = 0; i < segments; ++i) {
    raw[static_cast<std::size_t>(i)].node_id("n" + std::to_string(i));
    raw[static_cast<std::size_t>(i)].channels(7);
    ori[static_cast<std::size_t>(i)].segment("s" + std::to_string(i));
    ori[static_cast<std::size_t>(i)].node_id("n" + std::to_string(i));
    if (i > 0) joints[static_cast<std::size_t>(i - 1)].joint("j" + std::to_string(i));
  }
  std::uint64_t written_raw = 0, written_ori = 0, written_truth = 0, written_joint = 0, written_status = 0;
  std::vector<double> rss;
  const auto start = Clock::now();
  auto next = start;
  auto next_second = start + 1s;
  for (std::uint64_t k = 0; Clock::now() - start < std::chrono::duration<double>(seconds); ++k) {
    const std::uint64_t ts = bsn::dds::monotonic_ns();
    for (int i = 0; i < segments; ++i) {
      auto& r = raw[static_cast<std::size_t>(i)];
      r.seq(k);
      r.timestamp_ns(ts);
      r.acc({0.1 * static_cast<double>(i), 0.0, 9.81});
      written_raw += raw_w->write(r) ? 1 : 0;
      auto& o = ori[static_cast<std::size_t>(i)];
      o.timestamp_ns(ts);
      o.quat({1, 0, 0, 0});
      written_ori += ori_w->write(o) ? 1 : 0;
      written_truth += truth_w->write(o) ? 1 : 0;
      if (i > 0) {
        auto& j = joints[static_cast<std::size_t>(i - 1)];
        j.timestamp_ns(ts);
        written_joint += joint_w->write(j) ? 1 : 0;
      }
    }
    if (Clock::now() >= next_second) {
      bsn::Status st;
      st.process_id("bench");
      st.nodes(std::vector<bsn::NodeStatus>(static_cast<std::size_t>(segments)));
      written_status += status_w->write(st) ? 1 : 0;
      rss.push_back(rss_mb(rec.pid()));
      next_second += 1s;
    }
    next += 10ms;
    std::this_thread::sleep_until(next);
  }
  const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
  std::this_thread::sleep_for(1500ms);
  rec.stop(10000ms);
  const bsn::io::SessionReader r(out);
  const std::uint64_t got_raw = rows_of(r, "bsn/raw"), got_ori = rows_of(r, "bsn/orientation"),
                      got_truth = rows_of(r, "bsn/truth/orientation"), got_joint = rows_of(r, "bsn/joint_angles"),
                      got_status = rows_of(r, "bsn/status");
  const std::uint64_t written = written_raw + written_ori + written_truth + written_joint + written_status;
  const std::uint64_t got = got_raw + got_ori + got_truth + got_joint + got_status;
  std::printf("recorder: %d segments x 100 Hz, every topic, %.1f s\n", segments, elapsed);
  std::printf("  written %llu samples (%.0f/s), recorded %llu (%.4f %% lost)\n",
              static_cast<unsigned long long>(written), static_cast<double>(written) / elapsed,
              static_cast<unsigned long long>(got),
              100.0 * (1.0 - static_cast<double>(got) / static_cast<double>(written)));
  std::printf(
      "  per topic recorded/written: raw %llu/%llu, orientation %llu/%llu, truth %llu/%llu, joints %llu/%llu, "
      "status %llu/%llu\n",
      static_cast<unsigned long long>(got_raw), static_cast<unsigned long long>(written_raw),
      static_cast<unsigned long long>(got_ori), static_cast<unsigned long long>(written_ori),
      static_cast<unsigned long long>(got_truth), static_cast<unsigned long long>(written_truth),
      static_cast<unsigned long long>(got_joint), static_cast<unsigned long long>(written_joint),
      static_cast<unsigned long long>(got_status), static_cast<unsigned long long>(written_status));
  std::printf("  recorder RSS per second (MB):");
  for (double m : rss) std::printf(" %.1f", m);
  std::printf("\n  file %.1f MB (%.2f MB/s)\n", static_cast<double>(std::filesystem::file_size(out)) / 1e6,
              static_cast<double>(std::filesystem::file_size(out)) / 1e6 / elapsed);
}

void replay_phase(int domain, double seconds, const std::vector<double>& speeds, const std::filesystem::path& dir) {
  const std::string input = (dir / "replay_input.h5").string();
  const int nodes = 7;
  const auto n = static_cast<std::uint64_t>(seconds * 100.0);
  {
    bsn::io::SessionWriter w(input, true, {});
    for (int k = 0; k < nodes; ++k) {
      const std::size_t s = w.add_stream("bsn/raw", "n" + std::to_string(k), "bsn::RawSample",
                                         {{"arrival_ns", bsn::io::ColumnType::kU64, 1, ""},
                                          {"timestamp_ns", bsn::io::ColumnType::kU64, 1, ""},
                                          {"seq", bsn::io::ColumnType::kU64, 1, ""},
                                          {"acc", bsn::io::ColumnType::kF64, 3, ""},
                                          {"gyr", bsn::io::ColumnType::kF64, 3, ""},
                                          {"mag", bsn::io::ColumnType::kF64, 3, ""},
                                          {"channels", bsn::io::ColumnType::kU32, 1, ""}});
      for (std::uint64_t i = 0; i < n; ++i) {
        const std::uint64_t ts = 1000000000ull + i * 10000000ull + static_cast<std::uint64_t>(k) * 1000ull;
        const double v[3] = {0.0, 0.0, 9.81};
        const std::uint32_t ch = 7;
        w.append(s, 0, &ts, 1);
        w.append(s, 1, &ts, 1);
        w.append(s, 2, &i, 1);
        w.append(s, 3, v, 1);
        w.append(s, 4, v, 1);
        w.append(s, 5, v, 1);
        w.append(s, 6, &ch, 1);
      }
    }
    w.close();
  }
  std::printf("replay: %d nodes x %.0f s at 100 Hz (%llu samples) into bsn record\n", nodes, seconds,
              static_cast<unsigned long long>(n * nodes));
  for (const double speed : speeds) {
    const std::string out = (dir / "replayed.h5").string();
    bsn::dds::ChildProcess rec({BSN_EXECUTABLE, "record", "--out", out, "--overwrite", "--topic", "bsn/raw", "--domain",
                                std::to_string(domain)},
                               (dir / "record2.log").string());
    const auto start = Clock::now();
    bsn::dds::ChildProcess rep(
        {BSN_EXECUTABLE, "replay", input, "--speed", std::to_string(speed), "--domain", std::to_string(domain)},
        (dir / "replay.log").string());
    rep.wait_for(std::chrono::seconds(static_cast<long>(seconds * 2 + 60)));
    const double wall = std::chrono::duration<double>(Clock::now() - start).count();
    std::this_thread::sleep_for(1000ms);
    rec.stop(10000ms);
    const bsn::io::SessionReader r(out);
    const std::uint64_t got = rows_of(r, "bsn/raw");
    std::printf("  --speed %-5g recorded %llu of %llu (%s), %.1f s wall incl. discovery\n", speed,
                static_cast<unsigned long long>(got), static_cast<unsigned long long>(n * nodes),
                got == n * nodes ? "no loss" : "LOSS", wall);
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app("bsn session tools bench");
  int domain = 0, segments = 64;
  double seconds = 20.0, replay_seconds = 60.0;
  std::vector<double> speeds{10, 20, 50, 100, 0};
  app.add_option("--domain", domain, "DDS domain")->capture_default_str();
  app.add_option("--segments", segments, "segments of the recorded body")->capture_default_str();
  app.add_option("--seconds", seconds, "recorder phase length, s")->capture_default_str();
  app.add_option("--replay-seconds", replay_seconds, "length of the replayed session, s")->capture_default_str();
  app.add_option("--speed", speeds, "replay speeds to try (0 = as fast as possible)");
  CLI11_PARSE(app, argc, argv);
  char tmpl[] = "/tmp/bsn-bench-sessions-XXXXXX";
  const std::filesystem::path dir = mkdtemp(tmpl);
  recorder_phase(domain, segments, seconds, dir);
  replay_phase(domain, replay_seconds, speeds, dir);
  std::filesystem::remove_all(dir);
  return 0;
}
