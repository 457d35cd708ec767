// bsn_bench_view: bsn view under load, with a real `bsn view` process and WebSocket clients in this process.
//
// Phase 1 (latency): this bench publishes bsn/orientation (and truth, and the 6 joints' angles) for a 7-segment
// body at 100 Hz, each sample stamped with the monotonic clock at the write; one WebSocket client notes when each
// orientation message arrives. Reported: median and p99 of (arrival - write), ms, over the messages bsn view passed on
// (at most 30 Hz per segment). Phase 2 (many browsers): --clients WebSocket clients (default 20) on the same body;
// reported: the slowest client's slowest segment rate, Hz (target >= 25), and bsn view's CPU time over the phase, % of
// one core (target < 10 %), from /proc/<pid>/stat.
#include <civetweb.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <regex>
#include <sstream>
#include <thread>
#include <vector>

#include "bsn/dds/child_process.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/dds/topics.hpp"

#ifndef BSN_EXECUTABLE
#error "BSN_EXECUTABLE must name the bsn program"
#endif

namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

std::uint64_t mono_ns() {
  return static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count());
}

const std::vector<std::string> kSegments{"pelvis", "thigh_l", "shank_l", "foot_l", "thigh_r", "shank_r", "foot_r"};

/// One WebSocket client: counts orientation messages per segment, and (if asked) their latencies.
struct Client {
  mg_connection* conn = nullptr;
  std::mutex mutex;
  std::map<std::string, std::uint64_t> count;
  std::vector<double> latency_ms;
  bool record_latency = false;
  std::string partial;

  static int on_data(mg_connection*, int bits, char* data, std::size_t len, void* self_ptr) {
    auto* self = static_cast<Client*>(self_ptr);
    const std::uint64_t now = mono_ns();
    std::lock_guard lock(self->mutex);
    self->partial.append(data, len);
    if (!(bits & 0x80)) return 1;
    const std::string& f = self->partial;
    static const std::string key = "{\"k\":\"o\",\"seg\":\"";
    for (auto at = f.find(key); at != std::string::npos; at = f.find(key, at + 1)) {
      const auto seg_end = f.find('"', at + key.size());
      const std::string seg = f.substr(at + key.size(), seg_end - at - key.size());
      ++self->count[seg];
      if (self->record_latency) {
        const auto ts = f.find("\"ts\":", seg_end);
        const double written = std::strtod(f.c_str() + ts + 5, nullptr);
        self->latency_ms.push_back((static_cast<double>(now) - written) / 1e6);
      }
    }
    self->partial.clear();
    return 1;
  }
  static void on_close(const mg_connection*, void*) {}
};

std::unique_ptr<Client> connect_client(int port) {
  auto c = std::make_unique<Client>();
  char error[256] = "";
  c->conn = mg_connect_websocket_client("127.0.0.1", port, 0, error, sizeof error, "/ws", nullptr, &Client::on_data,
                                        &Client::on_close, c.get());
  if (c->conn == nullptr) {
    std::fprintf(stderr, "bench: cannot connect: %s\n", error);
    std::exit(1);
  }
  return c;
}

double cpu_seconds(int pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  std::string s((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  std::istringstream in(s.substr(s.rfind(')') + 2));
  std::string field;
  double utime = 0, stime = 0;
  for (int i = 3; i <= 15 && in >> field; ++i) {
    if (i == 14) utime = std::stod(field);
    if (i == 15) stime = std::stod(field);
  }
  return (utime + stime) / static_cast<double>(sysconf(_SC_CLK_TCK));
}

/// Publishes the 7 segments (orientation and truth) and their 6 joints at 100 Hz until `stop`: what a simulated
/// 7-segment body gives bsn view.
void publish(bsn::dds::Writer<bsn::Orientation>& w, bsn::dds::Writer<bsn::Orientation>& truth,
             bsn::dds::Writer<bsn::JointAngles>& joints, const std::atomic<bool>& stop) {
  bsn::Orientation o;
  bsn::JointAngles j;
  j.axes("zyx");
  auto next = Clock::now();
  double angle = 0.0;
  while (!stop) {
    angle += 0.01;
    for (const auto& seg : kSegments) {
      o.segment(seg);
      o.node_id(seg);
      o.quat({std::cos(angle / 2), 0.0, 0.0, std::sin(angle / 2)});
      o.timestamp_ns(mono_ns());
      truth.write(o);
      w.write(o);
      if (seg == "pelvis") continue;
      j.joint(seg + "_joint");
      j.child(seg);
      j.timestamp_ns(o.timestamp_ns());
      j.angles({angle, 0.0, 0.0});
      joints.write(j);
    }
    next += 10ms;
    std::this_thread::sleep_until(next);
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app("bsn view: latency orientation -> WebSocket frame, and many browsers");
  int domain = 230;
  int clients = 20;
  double seconds = 10.0;
  app.add_option("--domain", domain, "DDS domain")->capture_default_str();
  app.add_option("--clients", clients, "browsers in phase 2")->capture_default_str();
  app.add_option("--seconds", seconds, "length of each phase, s")->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  mg_init_library(0);
  const auto dir = std::filesystem::temp_directory_path() / ("bsn-bench-view-" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  bsn::dds::ChildProcess view({BSN_EXECUTABLE, "view", "--port", "0", "--domain", std::to_string(domain)},
                              (dir / "view.log").string());
  int port = 0;
  for (auto end = Clock::now() + 20s; port == 0 && Clock::now() < end; std::this_thread::sleep_for(50ms)) {
    std::ifstream in(dir / "view.log");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::smatch m;
    if (std::regex_search(text, m, std::regex("http://[^:/]+:([0-9]+)/"))) port = std::stoi(m[1]);
  }
  if (port == 0) {
    std::fprintf(stderr, "bench: bsn view did not start\n");
    return 1;
  }
  bsn::dds::Participant p({domain, "bench view"});
  auto writer = p.make_writer(bsn::dds::kOrientationTopic);
  auto truth_writer = p.make_writer(bsn::dds::kTruthOrientationTopic);
  auto joint_writer = p.make_writer(bsn::dds::kJointAnglesTopic);
  for (auto end = Clock::now() + 10s;
       (writer->matched() < 1 || truth_writer->matched() < 1 || joint_writer->matched() < 1) && Clock::now() < end;)
    std::this_thread::sleep_for(20ms);

  std::atomic<bool> stop{false};
  std::thread publisher([&] { publish(*writer, *truth_writer, *joint_writer, stop); });

  {  // phase 1
    auto c = connect_client(port);
    std::this_thread::sleep_for(1s);  // warm-up
    {
      std::lock_guard lock(c->mutex);
      c->record_latency = true;
    }
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
    std::vector<double> l;
    {
      std::lock_guard lock(c->mutex);
      c->record_latency = false;
      l = c->latency_ms;
    }
    mg_close_connection(c->conn);
    std::sort(l.begin(), l.end());
    if (l.empty()) {
      std::fprintf(stderr, "bench: no orientation message arrived\n");
      return 1;
    }
    std::printf("latency bsn/orientation write -> WebSocket message: median %.3f ms, p99 %.3f ms (%zu messages)\n",
                l[l.size() / 2], l[l.size() * 99 / 100], l.size());
  }

  {  // phase 2
    std::vector<std::unique_ptr<Client>> cs;
    for (int i = 0; i < clients; ++i) cs.push_back(connect_client(port));
    std::this_thread::sleep_for(1s);
    std::vector<std::map<std::string, std::uint64_t>> before;
    for (auto& c : cs) {
      std::lock_guard lock(c->mutex);
      before.push_back(c->count);
    }
    const double cpu0 = cpu_seconds(view.pid());
    const auto t0 = Clock::now();
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
    const double wall = std::chrono::duration<double>(Clock::now() - t0).count();
    const double cpu = cpu_seconds(view.pid()) - cpu0;
    double slowest = 1e9;
    for (std::size_t i = 0; i < cs.size(); ++i) {
      std::lock_guard lock(cs[i]->mutex);
      for (const auto& seg : kSegments)
        slowest = std::min(slowest, static_cast<double>(cs[i]->count[seg] - before[i][seg]) / wall);
    }
    for (auto& c : cs) mg_close_connection(c->conn);
    std::printf(
        "%d clients, 7 segments at 100 Hz: slowest client's slowest segment %.1f Hz; bsn view CPU %.1f %% "
        "of one core\n",
        clients, slowest, 100.0 * cpu / wall);
  }
  stop = true;
  publisher.join();
  view.stop();
  std::filesystem::remove_all(dir);
  return 0;
}
