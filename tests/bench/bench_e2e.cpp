// bsn_bench_e2e: end-to-end DDS bench on one host (docs/design.md section 5, "How we measure").
//
// The bench starts one real `bsn fusion` process per run with a generated body model of N segments (nodes
// n0..n{N-1} on segments s0..s{N-1}, a chain by default) and plays all N sensor nodes itself: every 10 ms tick
// it writes one bsn/raw sample per node (the swinging body of `bsn sim --node`, one per node), stamped with
// CLOCK_MONOTONIC at the moment of writing. The fusion service copies that timestamp into bsn/orientation, and the
// bench's own bsn/orientation reader takes CLOCK_MONOTONIC again at reception: on one host both processes share the
// clock, so the difference is the end-to-end latency raw sample written -> orientation received.
//
// Pacing: by default the N samples of a tick are written back to back at the tick instant (a burst), as
// synchronised sensors would deliver them: the realistic worst case for queueing. `--pacing spread` spreads them
// evenly over the tick instead.
//
// Phase 1 (latency): 7 segments (the default lower body size) for --latency-seconds.
// Phase 2 (capacity): N = 7, 16, 32, ... up to --max-segments, a fresh fusion process per step. A step passes when
// every sample written in the measurement window produced exactly one orientation at the bench's reader (after a
// drain), and the fusion's bsn/status shows no missing and no rejected sample and no write failure. The sweep
// stops at the first failing step. If the bench itself could not keep the 100 Hz schedule, the step is reported as
// bench-limited rather than as a fusion failure.

#include <sys/utsname.h>
#include <time.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <deque>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bsn/config/body_config.hpp"
#include "bsn/dds/child_process.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/dds/shutdown.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/fusion/body_model.hpp"
#include "bsn/sim/scenario.hpp"

#ifndef BSN_EXECUTABLE
#error "BSN_EXECUTABLE must name the bsn program (set by tests/bench/CMakeLists.txt)"
#endif

namespace {

namespace fs = std::filesystem;
namespace dds = bsn::dds;
using Clock = std::chrono::steady_clock;
using SampleInfo = eprosima::fastdds::dds::SampleInfo;

constexpr std::uint64_t kNsPerS = 1000000000ull;

// ---------------------------------------------------------------------------------------------------------------
// Options

struct Options {
  std::string bsn = BSN_EXECUTABLE;
  int domain = 40;
  double rate_hz = 100.0;
  int latency_segments = 7;
  double latency_seconds = 20.0;
  double step_seconds = 8.0;
  int max_segments = 2048;
  double warmup_seconds = 1.0;
  double discovery_timeout_s = 30.0;
  std::string topology = "chain";
  std::string pacing = "burst";
  std::string phases = "all";
  int refine = 2;
  std::uint64_t socket_buffer = 0;
  std::string security;  ///< make-pki.sh output with identities `fusion` and `tester`; "" = security off
  bool quick = false;
  bool keep_logs = false;
  bool verbose = false;
};

std::string shell_quote(const std::string& s) {
  if (!s.empty() && s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-+=./:,@%") ==
                        std::string::npos) {
    return s;
  }
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// ---------------------------------------------------------------------------------------------------------------
// Small system probes

/// utime + stime of a process in seconds, from /proc/PID/stat; nullopt if it cannot be read.
std::optional<double> cpu_seconds(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string text;
  if (!std::getline(in, text)) return std::nullopt;
  const auto paren = text.rfind(')');
  if (paren == std::string::npos) return std::nullopt;
  std::istringstream rest(text.substr(paren + 2));
  std::string field;
  unsigned long long utime = 0, stime = 0;
  // Fields after "(comm)": 3 state ... 14 utime, 15 stime.
  for (int i = 3; i <= 15 && rest >> field; ++i) {
    if (i == 14) utime = std::stoull(field);
    if (i == 15) stime = std::stoull(field);
  }
  return static_cast<double>(utime + stime) / static_cast<double>(sysconf(_SC_CLK_TCK));
}

/// Datagrams the kernel dropped on the UDP sockets of a process (receive buffer full), summed from
/// /proc/PID/net/udp{,6} over the socket inodes the process holds. nullopt if it cannot be read.
std::set<unsigned long> socket_inodes(pid_t pid, std::error_code& ec) {
  std::set<unsigned long> inodes;
  for (fs::directory_iterator it("/proc/" + std::to_string(pid) + "/fd", ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code lec;
    const std::string target = fs::read_symlink(it->path(), lec).string();
    if (!lec && target.rfind("socket:[", 0) == 0) inodes.insert(std::stoul(target.substr(8)));
  }
  return inodes;
}

/// As above, counting only the sockets of `pid` that `other` does not hold too (a forked child may have inherited
/// its parent's sockets).
std::optional<std::uint64_t> udp_drops(pid_t pid, pid_t other = 0) {
  const std::string base = "/proc/" + std::to_string(pid);
  std::error_code ec;
  std::set<unsigned long> inodes = socket_inodes(pid, ec);
  if (ec) return std::nullopt;
  if (other > 0) {
    std::error_code oec;
    for (auto i : socket_inodes(other, oec)) inodes.erase(i);
  }
  std::uint64_t drops = 0;
  bool any = false;
  for (const char* table : {"/net/udp", "/net/udp6"}) {
    std::ifstream in(base + table);
    std::string line;
    std::getline(in, line);  // header
    while (std::getline(in, line)) {
      any = true;
      std::istringstream f(line);
      std::string tok[13];
      for (auto& t : tok) f >> t;
      // sl local rem st tx:rx tr:tm retrnsmt uid timeout inode ref pointer drops
      if (tok[12].empty()) continue;
      if (inodes.count(std::stoul(tok[9]))) drops += std::stoull(tok[12]);
    }
  }
  if (!any && inodes.empty()) return std::nullopt;
  return drops;
}

/// Jiffies of all CPUs from /proc/stat: {busy + idle (user..steal), steal}.
std::pair<std::uint64_t, std::uint64_t> cpu_jiffies() {
  std::ifstream in("/proc/stat");
  std::string cpu;
  std::uint64_t v[8] = {};
  in >> cpu;
  for (auto& x : v) in >> x;  // user nice system idle iowait irq softirq steal
  std::uint64_t total = 0;
  for (auto x : v) total += x;
  return {total, v[7]};
}

/// The kernel's cap on socket receive buffers (net.core.rmem_max), 0 if unknown.
std::uint64_t rmem_max() {
  std::ifstream in("/proc/sys/net/core/rmem_max");
  std::uint64_t v = 0;
  in >> v;
  return v;
}

/// Writes a Fast DDS XML profile whose default participant uses UDPv4 alone with the given socket buffer sizes.
void write_socket_buffer_profile(const std::string& path, std::uint64_t bytes) {
  std::ofstream(path) << R"(<?xml version="1.0" encoding="UTF-8" ?>
<dds>
  <profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
    <transport_descriptors>
      <transport_descriptor>
        <transport_id>bench_udp</transport_id>
        <type>UDPv4</type>
        <sendBufferSize>)"
                      << bytes << R"(</sendBufferSize>
        <receiveBufferSize>)"
                      << bytes << R"(</receiveBufferSize>
      </transport_descriptor>
    </transport_descriptors>
    <participant profile_name="bench_participant" is_default_profile="true">
      <rtps>
        <userTransports>
          <transport_id>bench_udp</transport_id>
        </userTransports>
        <useBuiltinTransports>false</useBuiltinTransports>
      </rtps>
    </participant>
  </profiles>
</dds>
)";
}

std::set<std::string> dev_shm_entries() {
  std::set<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it("/dev/shm", ec), end; !ec && it != end; it.increment(ec)) {
    names.insert(it->path().filename().string());
  }
  return names;
}

std::string host_description() {
  std::string model = "unknown CPU";
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("model name", 0) == 0) {
      model = line.substr(line.find(':') + 2);
      break;
    }
  }
  utsname u{};
  uname(&u);
  return std::to_string(std::thread::hardware_concurrency()) + " x " + model + ", Linux " + u.release;
}

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M UTC", &tm);
  return buf;
}

std::uint64_t wall_ns() {
  return static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count());
}

/// Sleeps until CLOCK_MONOTONIC reaches t_ns; false if shutdown was requested.
bool sleep_until_ns(std::uint64_t t_ns) {
  const timespec target{static_cast<time_t>(t_ns / kNsPerS), static_cast<long>(t_ns % kNsPerS)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &target, nullptr) == EINTR) {
    if (dds::shutdown_requested()) return false;
  }
  return !dds::shutdown_requested();
}

// ---------------------------------------------------------------------------------------------------------------
// Statistics

struct LatencyStats {
  std::size_t count = 0;
  double p50_us = NAN, p90_us = NAN, p99_us = NAN, max_us = NAN, mean_us = NAN;
};

LatencyStats latency_stats(std::vector<std::uint64_t> ns) {
  LatencyStats s;
  s.count = ns.size();
  if (ns.empty()) return s;
  std::sort(ns.begin(), ns.end());
  // Nearest-rank percentile.
  auto pct = [&](double p) {
    std::size_t rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(ns.size())));
    rank = std::clamp<std::size_t>(rank, 1, ns.size());
    return static_cast<double>(ns[rank - 1]) / 1e3;
  };
  s.p50_us = pct(0.50);
  s.p90_us = pct(0.90);
  s.p99_us = pct(0.99);
  s.max_us = static_cast<double>(ns.back()) / 1e3;
  long double sum = 0;
  for (auto v : ns) sum += v;
  s.mean_us = static_cast<double>(sum / ns.size()) / 1e3;
  return s;
}

// ---------------------------------------------------------------------------------------------------------------
// What the bench's readers collect

/// Orientations of one run. Written by the DDS receive thread, read by the main thread, both under `mutex`.
struct Reception {
  explicit Reception(std::size_t n) : warmup(n, 0), measured(n, 0), last_ts(n, 0) {}

  std::mutex mutex;
  std::uint64_t window_start_ns = std::numeric_limits<std::uint64_t>::max();  ///< measured: timestamp >= this
  std::vector<std::uint64_t> warmup;    ///< per segment, orientations before the window
  std::vector<std::uint64_t> measured;  ///< per segment, orientations in the window
  std::vector<std::uint64_t> last_ts;   ///< per segment, timestamp of the last orientation
  std::uint64_t measured_total = 0;
  std::uint64_t out_of_order = 0;  ///< timestamp not newer than the previous one of the segment (repeat/reorder)
  std::uint64_t foreign = 0;       ///< segments that are not ours
  std::size_t segments_seen = 0;   ///< segments with at least one orientation
  std::vector<std::uint64_t> latency_ns;

  void on_orientation(const bsn::Orientation& o) {
    const std::uint64_t now = dds::monotonic_ns();
    const std::string& name = o.segment();
    std::size_t idx = 0;
    const bool parsed = name.size() > 1 && name[0] == 's' &&
                        std::from_chars(name.data() + 1, name.data() + name.size(), idx).ec == std::errc{};
    std::lock_guard lock(mutex);
    if (!parsed || idx >= measured.size()) {
      ++foreign;
      return;
    }
    const std::uint64_t ts = o.timestamp_ns();
    if (warmup[idx] == 0 && measured[idx] == 0) ++segments_seen;
    if (ts <= last_ts[idx]) ++out_of_order;
    last_ts[idx] = std::max(last_ts[idx], ts);
    if (ts >= window_start_ns) {
      ++measured[idx];
      ++measured_total;
      latency_ns.push_back(now >= ts ? now - ts : 0);
    } else {
      ++warmup[idx];
    }
  }
};

/// The latest bsn/status of the fusion process under test.
struct StatusView {
  explicit StatusView(pid_t pid) : suffix(":" + std::to_string(pid)) {}
  std::mutex mutex;
  std::string suffix;  ///< process_id ends with ":<pid>"
  std::optional<bsn::Status> latest;

  void on_status(const bsn::Status& s) {
    const std::string& id = s.process_id();
    if (id.size() < suffix.size() || id.compare(id.size() - suffix.size(), suffix.size(), suffix) != 0) return;
    std::lock_guard lock(mutex);
    latest = s;
  }
  std::optional<bsn::Status> get() {
    std::lock_guard lock(mutex);
    return latest;
  }
};

struct StatusTotals {
  std::uint64_t received = 0, accepted = 0, missing = 0, rejected = 0, clock_resets = 0, unknown = 0,
                write_failures = 0, qos_mismatches = 0;
  std::map<std::string, std::uint64_t> rejected_by_reason;
};

StatusTotals operator-(const StatusTotals& b, const StatusTotals& a) {
  StatusTotals d{b.received - a.received,
                 b.accepted - a.accepted,
                 b.missing - a.missing,
                 b.rejected - a.rejected,
                 b.clock_resets - a.clock_resets,
                 b.unknown - a.unknown,
                 b.write_failures - a.write_failures,
                 b.qos_mismatches - a.qos_mismatches,
                 {}};
  for (const auto& [reason, count] : b.rejected_by_reason) {
    const auto it = a.rejected_by_reason.find(reason);
    const std::uint64_t before = it == a.rejected_by_reason.end() ? 0 : it->second;
    if (count > before) d.rejected_by_reason[reason] = count - before;
  }
  return d;
}

StatusTotals totals(const bsn::Status& s) {
  StatusTotals t;
  for (const auto& n : s.nodes()) {
    t.received += n.received();
    t.accepted += n.accepted();
    t.missing += n.missing();
    for (const auto& r : n.rejected()) {
      t.rejected += r.count();
      if (r.count() > 0) t.rejected_by_reason[r.reason()] += r.count();
    }
    t.clock_resets += n.clock_resets();
  }
  t.unknown = s.unknown_node_samples();
  t.write_failures = s.write_failures();
  t.qos_mismatches = s.qos_mismatches();
  return t;
}

// ---------------------------------------------------------------------------------------------------------------
// The publisher of all N nodes

class NodeSet {
 public:
  NodeSet(std::size_t n, double rate_hz) {
    raw_.resize(n);
    nodes_.reserve(n);
    for (std::size_t i = 0; i < n; ++i) {
      raw_[i].node_id("n" + std::to_string(i));
      nodes_.emplace_back(bsn::sim::swing_scenario("s" + std::to_string(i), 1000 + i, rate_hz, 0.0),
                          std::vector<std::string>{}, false);
    }
  }

  /// Fills every node's sample of the next tick (everything but the timestamp), so a tick is only writes.
  void prepare(std::uint64_t k) {
    for (std::size_t i = 0; i < raw_.size(); ++i) {
      nodes_[i].next(out_);
      dds::fill_raw_sample(out_[0].sample, raw_[i]);
      raw_[i].seq(k);
    }
  }

  /// Writes node i's prepared sample stamped with the monotonic clock now.
  void write(std::size_t i, dds::Writer<bsn::RawSample>& writer) {
    raw_[i].timestamp_ns(dds::monotonic_ns());
    if (!writer.write(raw_[i])) ++write_failures_;
  }

  std::size_t size() const { return raw_.size(); }
  std::uint64_t write_failures() const { return write_failures_; }

 private:
  std::vector<bsn::RawSample> raw_;
  std::vector<bsn::sim::ScenarioRunner> nodes_;  ///< one swinging body per node, until stopped
  std::vector<bsn::sim::ScenarioSample> out_;
  std::uint64_t write_failures_ = 0;
};

// ---------------------------------------------------------------------------------------------------------------
// One run: one fusion process, N segments, one measurement window

struct RunResult {
  int n = 0;
  bool completed = false;  ///< the measurement ran (discovery succeeded, no abort)
  std::string error;       ///< why it did not complete, or why it failed
  double window_s = 0;
  std::uint64_t sent = 0, received = 0, out_of_order = 0, foreign = 0, write_failures = 0;
  std::size_t segments_short = 0;  ///< segments with fewer orientations than samples sent
  std::size_t segments_extra = 0;  ///< segments with more (repeats)
  LatencyStats latency;
  // Publisher schedule
  double achieved_rate_hz = 0;      ///< ticks per second actually achieved
  std::uint64_t overrun_ticks = 0;  ///< ticks whose writes did not finish before the next tick was due
  double max_tick_ms = 0;           ///< longest time to write one tick's samples
  double max_start_late_ms = 0;     ///< worst lateness of a tick start
  bool publisher_limited = false;
  bool bench_receive_limited = false;  ///< orientations lost in the bench's own socket, fusion clean
  double steal_pct = NAN;              ///< CPU time the hypervisor took from this VM during the window
  // Fusion's own account (deltas over the window, from bsn/status)
  bool have_status = false;
  StatusTotals status_delta;
  double fusion_cpu_pct = NAN, bench_cpu_pct = NAN, fusion_cpu_s = NAN;
  std::optional<std::uint64_t> fusion_udp_drops, bench_udp_drops;
  bool fusion_died = false;
  bool fusion_clean_exit = false;
  double discovery_s = 0;
  bool pass = false;
  std::string notes;  ///< anomalies that do not decide the verdict
  bool bench_limited() const { return publisher_limited || bench_receive_limited; }
};

class Bench {
 public:
  Bench(const Options& opt, fs::path dir) : opt_(opt), dir_(std::move(dir)) {}
  /// Later runs use DDS-Security: the fusion as ROOT/fusion, the bench's participant as ROOT/tester.
  void set_security(std::string root) { security_root_ = std::move(root); }

  RunResult run(int n, double seconds) {
    RunResult r;
    r.n = n;
    const std::string body_file = write_body(n);
    const std::string log_file = (dir_ / ("fusion-" + std::to_string(n) + ".log")).string();
    const std::uint64_t period_ns = static_cast<std::uint64_t>(std::llround(1e9 / opt_.rate_hz));
    const std::uint64_t ticks = static_cast<std::uint64_t>(std::llround(seconds * opt_.rate_hz));
    const auto un = static_cast<std::size_t>(n);

    Reception rx(un);
    rx.latency_ns.reserve(ticks * un);
    std::unique_ptr<dds::ChildProcess> fusion;
    std::unique_ptr<StatusView> status;
    // The fusion starts before the bench's participant exists: ChildProcess does not close inherited descriptors,
    // so a child forked later would hold the bench's DDS sockets open.
    try {
      std::vector<std::string> argv{opt_.bsn, "fusion", "--domain", std::to_string(opt_.domain), "--body", body_file};
      if (!security_root_.empty()) argv.insert(argv.end(), {"--security", security_root_ + "/fusion"});
      fusion = std::make_unique<dds::ChildProcess>(argv, log_file);
    } catch (const std::exception& e) {
      r.error = std::string("cannot start bsn fusion: ") + e.what();
      return r;
    }
    status = std::make_unique<StatusView>(fusion->pid());
    {
      if (!security_root_.empty()) setenv("BSN_SECURITY_DIR", (security_root_ + "/tester").c_str(), 1);
      dds::Participant participant({opt_.domain, "bsn bench e2e"});
      unsetenv("BSN_SECURITY_DIR");
      auto orientation_reader = participant.make_reader(
          dds::kOrientationTopic, [&rx](const bsn::Orientation& o, const SampleInfo&) { rx.on_orientation(o); });
      auto status_reader = participant.make_reader(
          dds::kStatusTopic, [&status](const bsn::Status& s, const SampleInfo&) { status->on_status(s); });
      // Open: one writer for every node. Secured: one per node, each in its node's DDS partition (the tester
      // identity may write any), as N sensor processes would.
      std::vector<std::shared_ptr<dds::Writer<bsn::RawSample>>> writers;
      for (std::size_t i = 0; i < un; ++i)
        writers.push_back(
            i > 0 && !participant.secured()
                ? writers.front()
                : std::shared_ptr(participant.make_writer(dds::kRawTopic, std::nullopt, "n" + std::to_string(i))));
      auto& writer = writers.front();
      NodeSet nodes(un, opt_.rate_hz);

      // Ticks run on one absolute schedule from t0, through discovery, warm-up and measurement.
      const std::uint64_t t0 = dds::monotonic_ns() + period_ns;
      std::uint64_t k = 0;
      nodes.prepare(k);
      auto tick = [&](std::uint64_t& start_ns, std::uint64_t& end_ns) -> bool {
        const std::uint64_t due = t0 + k * period_ns;
        if (!sleep_until_ns(due)) return false;
        start_ns = dds::monotonic_ns();
        if (opt_.pacing == "spread") {
          for (std::size_t i = 0; i < un; ++i) {
            const std::uint64_t at = due + i * period_ns / un;
            if (at > dds::monotonic_ns() + 20000 && !sleep_until_ns(at)) return false;
            nodes.write(i, *writers[i]);
          }
        } else {
          for (std::size_t i = 0; i < un; ++i) nodes.write(i, *writers[i]);
        }
        end_ns = dds::monotonic_ns();
        ++k;
        nodes.prepare(k);
        return true;
      };

      // Discovery: publish until the fusion matched our writer, we matched its writer, every segment produced an
      // orientation and a status arrived.
      const auto discovery_start = Clock::now();
      const auto discovery_deadline = discovery_start + std::chrono::duration<double>(opt_.discovery_timeout_s);
      std::uint64_t s_ns = 0, e_ns = 0;
      for (;;) {
        if (!tick(s_ns, e_ns)) {
          r.error = "interrupted";
          break;
        }
        std::size_t seen = 0;
        {
          std::lock_guard lock(rx.mutex);
          seen = rx.segments_seen;
        }
        if (writer->matched() > 0 && orientation_reader->matched() > 0 && seen == un && status->get()) break;
        if (!fusion->running()) {
          r.error = "bsn fusion ended during discovery";
          r.fusion_died = true;
          break;
        }
        if (Clock::now() > discovery_deadline) {
          std::ostringstream m;
          m << "discovery timed out after " << opt_.discovery_timeout_s << " s (raw writer matched "
            << writer->matched() << ", orientation reader matched " << orientation_reader->matched() << ", " << seen
            << "/" << n << " segments seen, status " << (status->get() ? "yes" : "no") << ")";
          r.error = m.str();
          break;
        }
      }
      r.discovery_s = std::chrono::duration<double>(Clock::now() - discovery_start).count();

      // Warm-up.
      if (r.error.empty()) {
        const std::uint64_t warm_ticks = static_cast<std::uint64_t>(std::llround(opt_.warmup_seconds * opt_.rate_hz));
        for (std::uint64_t w = 0; w < warm_ticks && r.error.empty(); ++w) {
          if (!tick(s_ns, e_ns)) r.error = "interrupted";
        }
      }

      // Measurement window.
      std::optional<bsn::Status> baseline;
      std::optional<double> fusion_cpu0, bench_cpu0;
      if (r.error.empty()) {
        baseline = status->get();
        fusion_cpu0 = cpu_seconds(fusion->pid());
        bench_cpu0 = cpu_seconds(getpid());
        const auto jiffies0 = cpu_jiffies();
        r.fusion_udp_drops = udp_drops(fusion->pid(), getpid());
        r.bench_udp_drops = udp_drops(getpid(), fusion->pid());
        const std::uint64_t first_due = t0 + k * period_ns;
        const auto wall0 = dds::monotonic_ns();
        {
          // Every warm-up sample was written before this instant and every measured one is written after it, by
          // this thread: the timestamp tells them apart even if the schedule runs late.
          std::lock_guard lock(rx.mutex);
          rx.window_start_ns = wall0;
        }
        const std::uint64_t write_failures0 = nodes.write_failures();
        std::uint64_t last_start = first_due;
        for (std::uint64_t m = 0; m < ticks; ++m) {
          const std::uint64_t due = t0 + k * period_ns;
          if (!tick(s_ns, e_ns)) {
            r.error = "interrupted";
            break;
          }
          last_start = s_ns;
          r.sent += un;
          r.max_start_late_ms = std::max(r.max_start_late_ms, static_cast<double>(s_ns - due) / 1e6);
          r.max_tick_ms = std::max(r.max_tick_ms, static_cast<double>(e_ns - s_ns) / 1e6);
          if (e_ns > due + period_ns) ++r.overrun_ticks;
        }
        const std::uint64_t publish_end_wall = wall_ns();
        // CPU over the publishing window (what sustaining N nodes costs), not over the drain that follows.
        const auto wall1 = dds::monotonic_ns();
        const auto fusion_cpu1 = cpu_seconds(fusion->pid());
        const auto bench_cpu1 = cpu_seconds(getpid());
        const auto jiffies1 = cpu_jiffies();
        r.write_failures = nodes.write_failures() - write_failures0;
        r.window_s = static_cast<double>(last_start + period_ns - first_due) / 1e9;
        r.achieved_rate_hz = r.window_s > 0 ? static_cast<double>(ticks) / r.window_s : 0.0;
        r.publisher_limited = r.achieved_rate_hz < 0.99 * opt_.rate_hz ||
                              static_cast<double>(r.overrun_ticks) > 0.05 * static_cast<double>(ticks);

        // Drain: wait while orientations still arrive (up to 10 s), then for a status issued after the last write
        // (the fusion publishes one as soon as the nodes turn stale, 0.3 s after the last sample).
        auto last_progress = Clock::now();
        const auto drain_start = last_progress;
        std::uint64_t got = 0;
        while (r.error.empty()) {
          std::uint64_t now_got = 0;
          {
            std::lock_guard lock(rx.mutex);
            now_got = rx.measured_total;
          }
          if (now_got >= r.sent) break;
          if (now_got != got) {
            got = now_got;
            last_progress = Clock::now();
          }
          if (Clock::now() - last_progress > std::chrono::seconds(1) ||
              Clock::now() - drain_start > std::chrono::seconds(10) ||
              !dds::sleep_unless_shutdown(std::chrono::milliseconds(5))) {
            break;
          }
        }
        if (jiffies1.first > jiffies0.first) {
          r.steal_pct = 100.0 * static_cast<double>(jiffies1.second - jiffies0.second) /
                        static_cast<double>(jiffies1.first - jiffies0.first);
        }
        const double wall_s = static_cast<double>(wall1 - wall0) / 1e9;
        if (fusion_cpu0 && fusion_cpu1) {
          r.fusion_cpu_s = *fusion_cpu1 - *fusion_cpu0;
          r.fusion_cpu_pct = 100.0 * r.fusion_cpu_s / wall_s;
        }
        if (bench_cpu0 && bench_cpu1) r.bench_cpu_pct = 100.0 * (*bench_cpu1 - *bench_cpu0) / wall_s;
        if (r.fusion_udp_drops) {
          const auto d = udp_drops(fusion->pid(), getpid());
          r.fusion_udp_drops = d ? std::optional<std::uint64_t>(*d - *r.fusion_udp_drops) : std::nullopt;
        }
        if (r.bench_udp_drops) {
          const auto d = udp_drops(getpid(), fusion->pid());
          r.bench_udp_drops = d ? std::optional<std::uint64_t>(*d - *r.bench_udp_drops) : std::nullopt;
        }
        const auto status_deadline = Clock::now() + std::chrono::seconds(3);
        std::optional<bsn::Status> final_status;
        while (r.error.empty() && Clock::now() < status_deadline) {
          if (auto s = status->get(); s && s->wall_time_ns() > publish_end_wall) {
            final_status = s;
            break;
          }
          if (!dds::sleep_unless_shutdown(std::chrono::milliseconds(10))) break;
        }
        if (final_status && baseline) {
          r.have_status = true;
          const StatusTotals a = totals(*baseline), b = totals(*final_status);
          r.status_delta = b - a;
        }
        if (r.error.empty()) r.completed = true;
      }
      r.fusion_died = r.fusion_died || !fusion->running();
      // Stop the fusion while our participant still lives, so it leaves the domain in an orderly way.
      const auto exit_status = fusion->stop();
      r.fusion_clean_exit = !r.fusion_died && exit_status == std::optional<int>(0);
      if (!r.fusion_died && !r.fusion_clean_exit) {
        r.notes += "bsn fusion did not exit cleanly on SIGTERM (wait status " +
                   (exit_status ? std::to_string(*exit_status) : std::string("none: killed")) + "). ";
      }
    }  // readers, writer and participant go here; no callback runs after this

    std::lock_guard lock(rx.mutex);
    r.received = rx.measured_total;
    r.out_of_order = rx.out_of_order;
    r.foreign = rx.foreign;
    if (r.foreign > 0) {
      r.notes += std::to_string(r.foreign) + " orientations of segments not ours: another fusion in domain " +
                 std::to_string(opt_.domain) + "? ";
    }
    const std::uint64_t per_segment = r.sent / un;
    for (std::size_t i = 0; i < un; ++i) {
      if (rx.measured[i] < per_segment) ++r.segments_short;
      if (rx.measured[i] > per_segment) ++r.segments_extra;
    }
    r.latency = latency_stats(std::move(rx.latency_ns));
    judge(r);
    if (r.fusion_died)
      r.error += (r.error.empty() ? "" : "; ") + std::string("bsn fusion died; log:\n") + tail(log_file);
    return r;
  }

 private:
  std::string write_body(int n) const {
    bsn::fusion::BodyModel body;
    body.name = "bench_" + opt_.topology + "_" + std::to_string(n);
    for (int i = 0; i < n; ++i) {
      bsn::fusion::SegmentSpec s;
      s.name = "s" + std::to_string(i);
      s.node = "n" + std::to_string(i);
      if (i > 0) s.parent = opt_.topology == "star" ? "s0" : "s" + std::to_string(i - 1);
      body.segments.push_back(std::move(s));
    }
    const std::string path = (dir_ / ("body-" + std::to_string(n) + ".yaml")).string();
    std::ofstream(path) << bsn::config::body_model_to_yaml(body);
    return path;
  }

  static std::string tail(const std::string& path, std::size_t lines = 15) {
    std::ifstream in(path);
    std::vector<std::string> all;
    for (std::string l; std::getline(in, l);) all.push_back(l);
    std::string out;
    for (std::size_t i = all.size() > lines ? all.size() - lines : 0; i < all.size(); ++i)
      out += "    " + all[i] + "\n";
    return out;
  }

  static void judge(RunResult& r) {
    std::vector<std::string> why;
    if (!r.completed) why.push_back(r.error.empty() ? "did not complete" : r.error);
    if (r.completed) {
      if (r.received < r.sent || r.segments_short > 0) {
        why.push_back(std::to_string(r.sent - std::min(r.sent, r.received)) + " orientations lost (" +
                      std::to_string(r.segments_short) + " segments short)");
      }
      if (r.segments_extra > 0 || r.out_of_order > 0) why.push_back("repeated or reordered orientations");
      if (r.write_failures > 0) why.push_back(std::to_string(r.write_failures) + " raw writes refused");
      if (!r.have_status) {
        why.push_back("no bsn/status from the fusion after the run");
      } else {
        const auto& d = r.status_delta;
        if (d.missing > 0) why.push_back("fusion reports " + std::to_string(d.missing) + " missing raw samples");
        if (d.rejected > 0) {
          std::string reasons;
          for (const auto& [reason, count] : d.rejected_by_reason) {
            reasons += (reasons.empty() ? "" : ", ") + reason + " " + std::to_string(count);
          }
          why.push_back("fusion rejected " + std::to_string(d.rejected) + " samples (" + reasons + ")");
        }
        if (d.write_failures > 0) why.push_back("fusion write failures " + std::to_string(d.write_failures));
        if (d.unknown > 0) why.push_back("fusion saw unknown nodes");
      }
      if (r.fusion_died) why.push_back("bsn fusion died");
    }
    r.pass = why.empty();
    // Lost in the bench's own receive socket while the fusion saw and fused everything: not the fusion's fault.
    r.bench_receive_limited = !r.pass && r.completed && r.have_status && r.status_delta.missing == 0 &&
                              r.status_delta.rejected == 0 && r.bench_udp_drops.value_or(0) > 0 &&
                              r.fusion_udp_drops.value_or(0) == 0 && !r.fusion_died;
    if (!why.empty() && r.completed) {
      std::string s;
      for (const auto& w : why) s += (s.empty() ? "" : "; ") + w;
      r.error = s;
    }
  }

  const Options& opt_;
  fs::path dir_;
  std::string security_root_;
};

// ---------------------------------------------------------------------------------------------------------------
// Output

std::string fmt(const char* f, double v) {
  if (std::isnan(v)) return "-";
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

std::string drops_text(const std::optional<std::uint64_t>& d) { return d ? std::to_string(*d) : "?"; }

const char* verdict(const RunResult& r) {
  if (r.bench_limited()) return r.pass ? "pass, bench-limited" : "bench-limited";
  return r.pass ? "pass" : "FAIL";
}

void print_run_details(const RunResult& r, const Options& opt) {
  std::printf("    sent %llu, received %llu, lost %lld; latency us: median %s, p90 %s, p99 %s, max %s\n",
              static_cast<unsigned long long>(r.sent), static_cast<unsigned long long>(r.received),
              static_cast<long long>(r.sent) - static_cast<long long>(r.received),
              fmt("%.0f", r.latency.p50_us).c_str(), fmt("%.0f", r.latency.p90_us).c_str(),
              fmt("%.0f", r.latency.p99_us).c_str(), fmt("%.0f", r.latency.max_us).c_str());
  std::printf(
      "    publisher: %.2f Hz per node achieved (target %.0f), longest tick %.2f ms, worst start delay %.2f ms, "
      "%llu ticks overran%s\n",
      r.achieved_rate_hz, opt.rate_hz, r.max_tick_ms, r.max_start_late_ms,
      static_cast<unsigned long long>(r.overrun_ticks),
      r.publisher_limited ? "  => the bench could not keep the schedule" : "");
  std::printf(
      "    CPU: fusion %s %% (%s us per sample), bench %s %% (100 %% = one core), steal %s %%; UDP receive-buffer "
      "drops: fusion %s, bench %s\n",
      fmt("%.1f", r.fusion_cpu_pct).c_str(),
      fmt("%.1f", r.sent > 0 ? 1e6 * r.fusion_cpu_s / static_cast<double>(r.sent) : NAN).c_str(),
      fmt("%.1f", r.bench_cpu_pct).c_str(), fmt("%.1f", r.steal_pct).c_str(), drops_text(r.fusion_udp_drops).c_str(),
      drops_text(r.bench_udp_drops).c_str());
  if (r.have_status) {
    const auto& d = r.status_delta;
    std::printf(
        "    fusion bsn/status over the window: received %llu, accepted %llu, missing %llu, rejected %llu, "
        "write failures %llu\n",
        static_cast<unsigned long long>(d.received), static_cast<unsigned long long>(d.accepted),
        static_cast<unsigned long long>(d.missing), static_cast<unsigned long long>(d.rejected),
        static_cast<unsigned long long>(d.write_failures));
  } else {
    std::printf("    fusion bsn/status: not received after the run\n");
  }
  if (!r.notes.empty()) std::printf("    note: %s\n", r.notes.c_str());
  if (r.pass) {
    std::printf("    %s\n", verdict(r));
  } else {
    std::printf(
        "    %s: %s%s\n", verdict(r), r.error.c_str(),
        r.bench_receive_limited ? " (lost in the bench's own receive socket; the fusion fused every sample)" : "");
  }
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  CLI::App app{
      "bsn_bench_e2e: end-to-end latency (raw sample written -> orientation received) through one real `bsn "
      "fusion` process, and the largest number of segments at 100 Hz it sustains with no loss. All processes run "
      "on this host. The bench plays all N sensor nodes itself and subscribes to bsn/orientation."};
  app.add_option("--bsn", opt.bsn, "the bsn program whose `bsn fusion` is measured")
      ->check(CLI::ExistingFile)
      ->capture_default_str();
  app.add_option("--domain", opt.domain, "DDS domain id (bench range 40..49)")
      ->check(CLI::Range(0, 232))
      ->capture_default_str();
  app.add_option("--rate", opt.rate_hz, "samples per second per node")
      ->check(CLI::Range(1.0, 1000.0))
      ->capture_default_str();
  app.add_option("--latency-segments", opt.latency_segments, "segments in the latency phase")
      ->check(CLI::Range(1, 4096))
      ->capture_default_str();
  auto* lat_s = app.add_option("--latency-seconds", opt.latency_seconds, "length of the latency measurement, s")
                    ->check(CLI::Range(0.1, 3600.0))
                    ->capture_default_str();
  auto* step_s = app.add_option("--step-seconds", opt.step_seconds, "length of each capacity step, s")
                     ->check(CLI::Range(0.1, 3600.0))
                     ->capture_default_str();
  auto* max_seg = app.add_option("--max-segments", opt.max_segments,
                                 "largest N the capacity sweep tries (steps 7, 16, 32, 64, ... doubling)")
                      ->check(CLI::Range(1, 4096))
                      ->capture_default_str();
  auto* refine =
      app.add_option("--refine", opt.refine, "extra bisection steps between the last passing and the first failing N")
          ->check(CLI::Range(0, 10))
          ->capture_default_str();
  auto* warm = app.add_option("--warmup-seconds", opt.warmup_seconds, "publishing before each measurement, s")
                   ->check(CLI::Range(0.0, 60.0))
                   ->capture_default_str();
  app.add_option("--discovery-timeout", opt.discovery_timeout_s, "give up a run after this long without a match, s")
      ->check(CLI::Range(1.0, 600.0))
      ->capture_default_str();
  app.add_option("--topology", opt.topology, "body shape: chain (s_i's parent is s_{i-1}) or star (all on s0)")
      ->check(CLI::IsMember({"chain", "star"}))
      ->capture_default_str();
  app.add_option("--pacing", opt.pacing,
                 "burst: a tick's N samples back to back (synchronised sensors, the worst case); spread: evenly "
                 "over the tick")
      ->check(CLI::IsMember({"burst", "spread"}))
      ->capture_default_str();
  app.add_option("--socket-buffer", opt.socket_buffer,
                 "run the bench and the fusion with UDP socket buffers of BYTES (an XML profile in "
                 "FASTRTPS_DEFAULT_PROFILES_FILE; the kernel caps it at net.core.rmem_max); 0 = product default")
      ->check(CLI::Range(std::uint64_t{0}, std::uint64_t{1} << 30))
      ->capture_default_str();
  app.add_option("--phases", opt.phases, "which phases to run")
      ->check(CLI::IsMember({"all", "latency", "capacity"}))
      ->capture_default_str();
  app.add_option("--security", opt.security,
                 "also run every phase with DDS-Security, from this deploy/security/make-pki.sh folder with "
                 "identities fusion:fusion and tester:tester, and compare")
      ->check(CLI::ExistingDirectory);
  app.add_flag("--quick", opt.quick,
               "smoke run: 3 s latency phase, 2 s steps up to 64 segments, no refinement, 0.5 s warm-up");
  app.add_flag("--keep-logs", opt.keep_logs, "keep the temporary folder with the body files and fusion logs");
  CLI11_PARSE(app, argc, argv);
  opt.bsn = fs::absolute(opt.bsn).string();
  if (opt.quick) {
    if (lat_s->count() == 0) opt.latency_seconds = 3.0;
    if (step_s->count() == 0) opt.step_seconds = 2.0;
    if (max_seg->count() == 0) opt.max_segments = 64;
    if (refine->count() == 0) opt.refine = 0;
    if (warm->count() == 0) opt.warmup_seconds = 0.5;
  }

  std::string command;
  for (int i = 0; i < argc; ++i) command += (i ? " " : "") + shell_quote(argv[i]);

  bsn::dds::install_shutdown_handlers();
  const auto started = Clock::now();
  const auto shm_before = dev_shm_entries();
  char dir_template[] = "/tmp/bsn-bench-e2e-XXXXXX";
  if (mkdtemp(dir_template) == nullptr) {
    std::perror("bsn_bench_e2e: mkdtemp");
    return 1;
  }
  const fs::path dir = dir_template;
  const std::string host = host_description();

  std::string buffers;
  {
    std::ifstream in("/proc/sys/net/core/rmem_max");
    std::uint64_t max = 0;
    in >> max;
    buffers = "UDP socket receive buffers: bsn's default 4 MiB request, capped by net.core.rmem_max = " +
              std::to_string(max) + " bytes";
  }
  if (opt.socket_buffer > 0) {
    // Set before the first DDS call: the participant factory reads the profile once. The fusion child inherits it.
    const std::string profile = (dir / "socket-buffers.xml").string();
    write_socket_buffer_profile(profile, opt.socket_buffer);
    if (std::getenv("FASTRTPS_DEFAULT_PROFILES_FILE")) {
      std::printf("note: --socket-buffer replaces FASTRTPS_DEFAULT_PROFILES_FILE=%s\n",
                  std::getenv("FASTRTPS_DEFAULT_PROFILES_FILE"));
    }
    setenv("FASTRTPS_DEFAULT_PROFILES_FILE", profile.c_str(), 1);
    const std::uint64_t cap = rmem_max();
    buffers =
        "UDP socket buffers: " + std::to_string(opt.socket_buffer) + " bytes requested by XML profile" +
        (cap > 0 && cap < opt.socket_buffer ? " (capped by the kernel at rmem_max " + std::to_string(cap) + ")" : "");
  } else if (std::getenv("FASTRTPS_DEFAULT_PROFILES_FILE")) {
    buffers += "; FASTRTPS_DEFAULT_PROFILES_FILE is set";
  }
  // Fast DDS 2.9.1 reads the XML profiles lazily (in create_participant): get_default_participant_qos(), which
  // bsn::dds::Participant starts from, ignores them unless they were loaded first.
  eprosima::fastdds::dds::DomainParticipantFactory::get_instance()->load_profiles();

  std::printf("bsn_bench_e2e  %s\n  host: %s\n  bsn: %s\n  domain %d, %.0f Hz per node, pacing %s, topology %s\n  %s\n",
              utc_now().c_str(), host.c_str(), opt.bsn.c_str(), opt.domain, opt.rate_hz, opt.pacing.c_str(),
              opt.topology.c_str(), buffers.c_str());
  std::fflush(stdout);

  int exit_code = 0;
  Bench bench(opt, dir);
  struct Outcome {
    std::optional<RunResult> latency;
    int largest = 0;
  };
  // One latency phase and capacity sweep, with their summary; run twice (open, then secured) with --security.
  auto measure = [&](const char* label) -> Outcome {
    std::optional<RunResult> latency;
    std::deque<RunResult> steps;         // stable addresses: failed and limited point into it
    int largest = 0;                     // largest N verified without loss at the full rate
    const RunResult* failed = nullptr;   // smallest N at which the fusion lost samples (or a run failed)
    const RunResult* limited = nullptr;  // a step at which the bench itself was the bottleneck
    auto step = [&](int n) -> const RunResult& {
      std::printf("  N = %d ...\n", n);
      std::fflush(stdout);
      steps.push_back(bench.run(n, opt.step_seconds));
      print_run_details(steps.back(), opt);
      return steps.back();
    };
    try {
      if (opt.phases != "capacity") {
        std::printf("\n== Phase 1: latency, %d segments at %.0f Hz for %.0f s ==\n", opt.latency_segments, opt.rate_hz,
                    opt.latency_seconds);
        std::fflush(stdout);
        latency = bench.run(opt.latency_segments, opt.latency_seconds);
        print_run_details(*latency, opt);
        if (!latency->pass) exit_code = 1;
      }
      if (opt.phases != "latency" && !bsn::dds::shutdown_requested()) {
        std::printf(
            "\n== Phase 2: capacity, N segments at %.0f Hz, %.0f s per step, fresh fusion process per step ==\n",
            opt.rate_hz, opt.step_seconds);
        std::vector<int> ns;
        for (int n : {7, 16}) ns.push_back(n);
        for (int n = 32; n < opt.max_segments; n *= 2) ns.push_back(n);
        std::erase_if(ns, [&](int n) { return n > opt.max_segments; });
        if (ns.empty() || ns.back() != opt.max_segments) ns.push_back(opt.max_segments);
        for (int n : ns) {
          if (bsn::dds::shutdown_requested()) break;
          const RunResult& r = step(n);
          if (r.bench_limited()) {
            limited = &r;
            break;
          }
          if (!r.pass) {
            failed = &r;
            break;
          }
          largest = n;
        }
        // Bisect between the last pass and the first failure.
        for (int i = 0; i < opt.refine && failed && largest > 0 && !bsn::dds::shutdown_requested(); ++i) {
          const int mid = (largest + failed->n) / 2;
          if (mid <= largest || mid >= failed->n) break;
          std::printf("  refining between %d and %d:\n", largest, failed->n);
          const RunResult& r = step(mid);
          if (r.bench_limited()) {
            limited = &r;
            break;
          }
          if (r.pass) {
            largest = mid;
          } else {
            failed = &r;
          }
        }
      }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "bsn_bench_e2e: error: %s\n", e.what());
      exit_code = 1;
    }

    // Summary.
    std::printf("\n---- summary%s ----\n", label);
    std::printf("bsn_bench_e2e, %s, %s\n", utc_now().c_str(), host.c_str());
    std::printf("command: %s\n", command.c_str());
    std::printf(
        "setup: Fast DDS 2.9.1 over UDPv4 on one host; one `bsn fusion` process; the bench publishes all N nodes (%s "
        "pacing, %s body) and subscribes to bsn/orientation. %s.\n",
        opt.pacing.c_str(), opt.topology.c_str(), buffers.c_str());
    if (latency) {
      const auto& r = *latency;
      std::printf(
          "latency, raw sample written -> orientation received, %d segments x %.0f Hz, %.0f s: median %s us, p90 %s "
          "us, p99 %s us, max %s us (%llu sent, %llu received)%s\n",
          r.n, opt.rate_hz, opt.latency_seconds, fmt("%.0f", r.latency.p50_us).c_str(),
          fmt("%.0f", r.latency.p90_us).c_str(), fmt("%.0f", r.latency.p99_us).c_str(),
          fmt("%.0f", r.latency.max_us).c_str(), static_cast<unsigned long long>(r.sent),
          static_cast<unsigned long long>(r.received), r.pass ? "" : ("  FAILED: " + r.error).c_str());
    }
    if (!steps.empty()) {
      std::printf("capacity at %.0f Hz per segment, %.0f s per step, no loss allowed:\n", opt.rate_hz,
                  opt.step_seconds);
      std::printf("  %6s %9s %9s %7s %8s %8s %9s %9s %9s %8s  %s\n", "N", "sent", "received", "lost", "p50 us",
                  "p99 us", "fusion %", "us/sample", "bench %", "pub Hz", "result");
      std::vector<const RunResult*> sorted;
      for (const auto& r : steps) sorted.push_back(&r);
      std::stable_sort(sorted.begin(), sorted.end(), [](auto* a, auto* b) { return a->n < b->n; });
      for (const RunResult* r : sorted) {
        std::printf("  %6d %9llu %9llu %7lld %8s %8s %9s %9s %9s %8.1f  %s\n", r->n,
                    static_cast<unsigned long long>(r->sent), static_cast<unsigned long long>(r->received),
                    static_cast<long long>(r->sent) - static_cast<long long>(r->received),
                    fmt("%.0f", r->latency.p50_us).c_str(), fmt("%.0f", r->latency.p99_us).c_str(),
                    fmt("%.1f", r->fusion_cpu_pct).c_str(),
                    fmt("%.1f", r->sent > 0 ? 1e6 * r->fusion_cpu_s / static_cast<double>(r->sent) : NAN).c_str(),
                    fmt("%.1f", r->bench_cpu_pct).c_str(), r->achieved_rate_hz, verdict(*r));
      }
      std::printf("largest N with no loss at %.0f Hz: %d\n", opt.rate_hz, largest);
      if (failed) {
        std::printf("  first failing N = %d: %s\n", failed->n, failed->error.c_str());
        if (failed->fusion_udp_drops.value_or(0) > 0) {
          std::printf(
              "  the fusion's UDP receive socket overflowed (%llu datagrams dropped by the kernel) at %.0f %% CPU: the "
              "limit is the socket buffer against a burst of %d samples, not the fusion's compute.\n",
              static_cast<unsigned long long>(*failed->fusion_udp_drops), failed->fusion_cpu_pct, failed->n);
        }
      }
      if (limited) {
        std::printf(
            "  stopped at N = %d because the bench itself was the bottleneck (%s); the fusion limit is at least %d and "
            "was not reached.\n",
            limited->n,
            limited->publisher_limited
                ? ("its publisher achieved " + fmt("%.1f", limited->achieved_rate_hz) + " Hz per node").c_str()
                : "its own orientation reader dropped datagrams while the fusion fused every sample",
            largest);
      }
      if (!failed && !limited && !steps.empty() && largest == opt.max_segments) {
        std::printf("  every step passed up to --max-segments %d; the limit is higher.\n", opt.max_segments);
      }
    }
    return Outcome{latency, largest};
  };
  const Outcome open = measure(opt.security.empty() ? "" : " (DDS-Security off)");
  if (!opt.security.empty() && !bsn::dds::shutdown_requested()) {
    bench.set_security(opt.security);
    const Outcome secured = measure(" (DDS-Security on: authenticated, encrypted payloads and discovery)");
    std::printf("\n---- DDS-Security on against off, this run ----\n");
    if (open.latency && secured.latency) {
      std::printf("median latency: %s us on, %s us off: overhead %s us\n",
                  fmt("%.0f", secured.latency->latency.p50_us).c_str(),
                  fmt("%.0f", open.latency->latency.p50_us).c_str(),
                  fmt("%.0f", secured.latency->latency.p50_us - open.latency->latency.p50_us).c_str());
    }
    if (open.largest > 0) {
      std::printf("capacity: %d segments on, %d off: %.0f %%\n", secured.largest, open.largest,
                  100.0 * secured.largest / open.largest);
    }
  }
  const double total_s = std::chrono::duration<double>(Clock::now() - started).count();
  std::printf("run time: %.0f s\n", total_s);

  // Cleanup checks.
  if (opt.keep_logs) {
    std::printf("logs kept in %s\n", dir.c_str());
  } else {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  std::vector<std::string> new_shm;
  for (const auto& name : dev_shm_entries())
    if (!shm_before.count(name)) new_shm.push_back(name);
  if (!new_shm.empty()) {
    std::printf("warning: %zu new entries in /dev/shm since the start (first: %s); they may be another process's\n",
                new_shm.size(), new_shm.front().c_str());
  }
  if (bsn::dds::shutdown_requested()) {
    std::printf("interrupted\n");
    exit_code = 130;
  }
  std::fflush(stdout);
  return exit_code;
}
