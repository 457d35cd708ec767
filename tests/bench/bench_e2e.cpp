// bsn_bench_e2e: end-to-end DDS bench on one host (docs/design.md section 5, "How we measure").
//
// The bench starts one real `bsn fusion` process per run with a generated body model of N segments (nodes
// n0..n{N-1} on segments s0..s{N-1}, a chain by default), and publisher processes (this program re-run with
// --publish; one per 250 nodes) that play the N sensor nodes: every 10 ms tick each writes one bsn/raw sample per
// node of its share (the swinging body of `bsn sim --node`), stamped with CLOCK_MONOTONIC at the moment of writing.
// The fusion service copies that timestamp into bsn/orientation, and the bench's own bsn/orientation reader takes
// CLOCK_MONOTONIC again at reception: on one host all processes share the clock, so the difference is the
// end-to-end latency raw sample written -> orientation received.
//
// Beside every fusion run the bench runs the same load through a bare relay (this program re-run with --relay):
// the same bsn::dds::Participant, topics, QoS and transports, one bsn/orientation of the same size written per raw
// sample and no fusion. Every latency and CPU figure is printed beside the relay's and as a ratio: what the service
// adds to the middleware, measured in the same invocation.
//
// Pacing: by default the N samples of a tick are written back to back at the tick instant (a burst), as
// synchronised sensors would deliver them: the realistic worst case for queueing. `--pacing spread` spreads them
// evenly over the tick instead.
//
// Phase 1 (latency): 7 segments (the default lower body size) for --latency-seconds.
// Phase 2 (capacity): N = 7, 16, 32, ... up to --max-segments, fresh processes per step. A step passes when
// every sample written in the measurement window produced exactly one orientation at the bench's reader (after a
// drain), and the fusion's bsn/status shows no missing and no rejected sample and no write failure. The sweep
// stops at the first failing step. If the bench itself could not keep the 100 Hz schedule (a publisher overran its
// ticks) or its own reader dropped datagrams, the step is reported as bench-limited rather than as a fusion failure.
// Soak (--phases soak): one fusion run of --soak-segments for --soak-seconds, its RSS sampled through the window.

#include <fcntl.h>
#include <sys/mman.h>
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
#include <cstring>
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
#include <span>
#include <sstream>
#include <stdexcept>
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
  int min_segments = 7;
  double warmup_seconds = 1.0;
  double discovery_timeout_s = 30.0;
  std::string topology = "chain";
  std::string pacing = "burst";
  std::string phases = "all";
  int refine = 2;
  int publishers = 0;  ///< publisher processes; 0 = one per 250 nodes
  bool relay = true;   ///< run the bare relay beside every fusion run
  int soak_segments = 1000;
  double soak_seconds = 60.0;
  double soak_rss_every_s = 10.0;
  std::uint64_t socket_buffer = 0;
  std::string wrap;      ///< command words put before the service's (e.g. valgrind --tool=callgrind)
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

/// {CPU time, of which in the kernel} of a process in seconds; nullopt if it cannot be read. The total is the sum
/// of its threads' run time in /proc/PID/task/*/schedstat (ns, exact; utime + stime in /proc/PID/stat count
/// 10 ms ticks, too coarse for a few thousand samples); the kernel's share is stime from /proc/PID/stat.
std::optional<std::pair<double, double>> cpu_times(pid_t pid) {
  const std::string base = "/proc/" + std::to_string(pid);
  std::ifstream in(base + "/stat");
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
  const auto tick = static_cast<double>(sysconf(_SC_CLK_TCK));
  double total = static_cast<double>(utime + stime) / tick;
  // Threads that ended are in stat's utime and stime but no longer in task/: the services' threads live as long as
  // the process, so schedstat is used when it can be read.
  std::error_code ec;
  std::uint64_t run_ns = 0;
  bool any = false;
  for (fs::directory_iterator it(base + "/task", ec), end; !ec && it != end; it.increment(ec)) {
    std::ifstream st(it->path() / "schedstat");
    std::uint64_t ns = 0;
    if (st >> ns) {
      run_ns += ns;
      any = true;
    }
  }
  if (any) total = static_cast<double>(run_ns) / 1e9;
  return std::pair{total, static_cast<double>(stime) / tick};
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

std::string load_average() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
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

/// Latencies in 1 us bins up to 100 ms (one overflow bin beyond): a 10-minute run at 1000 segments is 60 million
/// samples, too many to keep one by one.
class LatencyHistogram {
 public:
  static constexpr std::size_t kBins = 100000;
  LatencyHistogram() : bins_(kBins + 1, 0) {}
  void add(std::uint64_t ns) {
    ++bins_[std::min<std::uint64_t>(ns / 1000, kBins)];
    ++count_;
    sum_ns_ += ns;
    max_ns_ = std::max(max_ns_, ns);
  }
  /// Nearest-rank percentiles, to the bin's upper edge (1 us).
  LatencyStats stats() const {
    LatencyStats s;
    s.count = count_;
    if (count_ == 0) return s;
    auto pct = [&](double p) {
      const auto rank =
          std::clamp<std::uint64_t>(static_cast<std::uint64_t>(std::ceil(p * static_cast<double>(count_))), 1, count_);
      std::uint64_t seen = 0;
      for (std::size_t b = 0; b < bins_.size(); ++b) {
        seen += bins_[b];
        if (seen >= rank) return b == kBins ? static_cast<double>(max_ns_) / 1e3 : static_cast<double>(b + 1);
      }
      return static_cast<double>(max_ns_) / 1e3;
    };
    s.p50_us = pct(0.50);
    s.p90_us = pct(0.90);
    s.p99_us = pct(0.99);
    s.max_us = static_cast<double>(max_ns_) / 1e3;
    s.mean_us = static_cast<double>(sum_ns_) / static_cast<double>(count_) / 1e3;
    return s;
  }

 private:
  std::vector<std::uint64_t> bins_;
  std::uint64_t count_ = 0, sum_ns_ = 0, max_ns_ = 0;
};

/// Resident set of a process, bytes (VmRSS of /proc/PID/status); nullopt if it cannot be read.
std::optional<std::uint64_t> rss_bytes(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("VmRSS:", 0) == 0) return std::stoull(line.substr(6)) * 1024;
  }
  return std::nullopt;
}

// ---------------------------------------------------------------------------------------------------------------
// The bench's child processes share one control block, a file mapped into each of them: the publishers' schedule,
// the measurement window the parent chose, and each publisher's account of it.

constexpr std::size_t kMaxPublishers = 64;
constexpr std::uint64_t kNoWindow = std::numeric_limits<std::uint64_t>::max();

struct PublisherSlot {
  std::atomic<std::uint64_t> ticks{0};    ///< ticks written so far
  std::atomic<std::uint64_t> matched{0};  ///< 1 once every writer of the process matched a reader
  std::atomic<std::uint64_t> sent{0};     ///< samples written in the window
  std::atomic<std::uint64_t> overrun_ticks{0};
  std::atomic<std::uint64_t> max_tick_ns{0};
  std::atomic<std::uint64_t> max_start_late_ns{0};
  std::atomic<std::uint64_t> write_failures{0};
  std::atomic<std::uint64_t> first_start_ns{0};
  std::atomic<std::uint64_t> last_start_ns{0};
  std::atomic<std::uint64_t> late_into_window{0};  ///< a warm-up tick was still being written when the window began
  std::atomic<std::uint64_t> done{0};              ///< the window's last tick is written
};

struct Control {
  std::atomic<std::uint64_t> t0_ns{0};  ///< tick k is due at t0 + k * period
  std::atomic<std::uint64_t> period_ns{0};
  std::atomic<std::uint64_t> window_ticks{0};
  std::atomic<std::uint64_t> window_first_tick{kNoWindow};  ///< set (after window_ticks) once discovery is done
  std::atomic<std::uint64_t> stop{0};
  PublisherSlot slots[kMaxPublishers];
};
static_assert(std::atomic<std::uint64_t>::is_always_lock_free, "the control block is shared between processes");

/// The control block in `path`, mapped shared; `create` makes the file and a fresh block.
Control* map_control(const std::string& path, bool create) {
  const int fd = open(path.c_str(), create ? O_RDWR | O_CREAT | O_TRUNC : O_RDWR, 0600);
  if (fd < 0) throw std::runtime_error("cannot open " + path + ": " + std::strerror(errno));
  if (create && ftruncate(fd, sizeof(Control)) != 0) {
    close(fd);
    throw std::runtime_error("cannot size " + path);
  }
  void* p = mmap(nullptr, sizeof(Control), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  close(fd);
  if (p == MAP_FAILED) throw std::runtime_error("cannot map " + path);
  return create ? new (p) Control() : static_cast<Control*>(p);
}

void store_max(std::atomic<std::uint64_t>& a, std::uint64_t v) {
  if (v > a.load()) a.store(v);  // one writer per slot
}

/// Node index of a name "<prefix><index>", nullopt for any other name.
std::optional<std::size_t> index_of(const std::string& name, char prefix) {
  std::size_t idx = 0;
  if (name.size() < 2 || name[0] != prefix ||
      std::from_chars(name.data() + 1, name.data() + name.size(), idx).ec != std::errc{})
    return std::nullopt;
  return idx;
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
  LatencyHistogram latency;

  void on_orientation(const bsn::Orientation& o) {
    const std::uint64_t now = dds::monotonic_ns();
    const auto parsed = index_of(o.segment(), 's');
    std::lock_guard lock(mutex);
    if (!parsed || *parsed >= measured.size()) {
      ++foreign;
      return;
    }
    const std::size_t idx = *parsed;
    const std::uint64_t ts = o.timestamp_ns();
    if (warmup[idx] == 0 && measured[idx] == 0) ++segments_seen;
    if (ts <= last_ts[idx]) ++out_of_order;
    last_ts[idx] = std::max(last_ts[idx], ts);
    if (ts >= window_start_ns) {
      ++measured[idx];
      ++measured_total;
      latency.add(now >= ts ? now - ts : 0);
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
// A publisher process: nodes first..first+count-1 of N

class NodeSet {
 public:
  NodeSet(std::size_t first, std::size_t count, double rate_hz) {
    raw_.resize(count);
    nodes_.reserve(count);
    for (std::size_t i = 0; i < count; ++i) {
      raw_[i].node_id("n" + std::to_string(first + i));
      nodes_.emplace_back(bsn::sim::swing_scenario("s" + std::to_string(first + i), 1000 + first + i, rate_hz, 0.0),
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

  /// Writes node i's prepared sample stamped with the monotonic clock now; false if DDS refused it.
  bool write(std::size_t i, dds::Writer<bsn::RawSample>& writer) {
    raw_[i].timestamp_ns(dds::monotonic_ns());
    return writer.write(raw_[i]);
  }

  std::size_t size() const { return raw_.size(); }

 private:
  std::vector<bsn::RawSample> raw_;
  std::vector<bsn::sim::ScenarioRunner> nodes_;  ///< one swinging body per node, until stopped
  std::vector<bsn::sim::ScenarioSample> out_;
};

/// `--publish CONTROL SLOT FIRST COUNT N DOMAIN RATE PACING`: writes its nodes' samples on the control block's
/// schedule from t0 through discovery, warm-up and the window, accounts for the window in its slot, and then waits
/// for the parent's stop.
int publisher_main(const std::vector<std::string>& a) {
  if (a.size() != 8) {
    std::fprintf(stderr, "bsn_bench_e2e --publish: expected 8 arguments\n");
    return 2;
  }
  Control* control = map_control(a[0], false);
  PublisherSlot& slot = control->slots[std::stoul(a[1])];
  const std::size_t first = std::stoul(a[2]), count = std::stoul(a[3]), n = std::stoul(a[4]);
  const int domain = std::stoi(a[5]);
  const bool spread = a[7] == "spread";
  dds::install_shutdown_handlers();
  dds::Participant participant({domain, "bsn bench publisher"});
  // Open: one writer for the process's nodes. Secured: one per node, each in its node's DDS partition (the tester
  // identity may write any), as N sensor processes would.
  std::vector<std::shared_ptr<dds::Writer<bsn::RawSample>>> writers;
  for (std::size_t i = 0; i < count; ++i)
    writers.push_back(
        i > 0 && !participant.secured()
            ? writers.front()
            : std::shared_ptr(participant.make_writer(dds::kRawTopic, std::nullopt, "n" + std::to_string(first + i))));
  NodeSet nodes(first, count, std::stod(a[6]));
  const std::uint64_t t0 = control->t0_ns.load(), period = control->period_ns.load();
  nodes.prepare(0);
  for (std::uint64_t k = 0;; ++k) {
    const std::uint64_t due = t0 + k * period;
    if (!sleep_until_ns(due) || control->stop.load()) break;
    const std::uint64_t start = dds::monotonic_ns();
    std::uint64_t failures = 0;
    for (std::size_t i = 0; i < count; ++i) {
      if (spread) {
        const std::uint64_t at = due + (first + i) * period / n;
        if (at > dds::monotonic_ns() + 20000 && !sleep_until_ns(at)) break;
      }
      if (!nodes.write(i, *writers[i])) ++failures;
    }
    const std::uint64_t end = dds::monotonic_ns();
    if (slot.matched.load() == 0 &&
        std::all_of(writers.begin(), writers.end(), [](const auto& w) { return w->matched() > 0; }))
      slot.matched.store(1);
    const std::uint64_t w = control->window_first_tick.load(std::memory_order_acquire);
    if (w != kNoWindow) {
      const std::uint64_t m = control->window_ticks.load();
      if (k < w) {
        if (end >= t0 + w * period) slot.late_into_window.store(1);
      } else if (k < w + m) {
        if (k == w) slot.first_start_ns.store(start);
        slot.last_start_ns.store(start);
        slot.sent.fetch_add(count);
        slot.write_failures.fetch_add(failures);
        store_max(slot.max_tick_ns, end - start);
        store_max(slot.max_start_late_ns, start - due);
        if (end > due + period) slot.overrun_ticks.fetch_add(1);
      }
      if (k + 1 >= w + m) {
        slot.ticks.store(k + 1);
        slot.done.store(1);
        break;
      }
    }
    slot.ticks.store(k + 1);
    nodes.prepare(k + 1);
  }
  // Alive until the parent has read this process's CPU time.
  while (!control->stop.load() && dds::sleep_unless_shutdown(std::chrono::milliseconds(10))) {
  }
  return 0;
}

/// `--relay DOMAIN`: the bare middleware. Takes bsn/raw and writes one bsn/orientation per sample (segment s<i> for
/// node n<i>) through the same bsn::dds::Participant, topics and QoS as `bsn fusion`, with no fusion: what the
/// service's figures are compared with.
int relay_main(const std::vector<std::string>& a) {
  if (a.size() != 1) {
    std::fprintf(stderr, "bsn_bench_e2e --relay: expected 1 argument\n");
    return 2;
  }
  dds::install_shutdown_handlers();
  dds::Participant participant({std::stoi(a[0]), "bsn bench relay"});
  auto writer = participant.make_writer(dds::kOrientationTopic);
  std::mutex mutex;
  std::vector<bsn::Orientation> out;  // per node index, names filled once
  std::uint64_t received = 0, written = 0, failures = 0, foreign = 0;
  auto reader = participant.make_reader(dds::kRawTopic, [&](const bsn::RawSample& raw, const SampleInfo&) {
    const auto idx = index_of(raw.node_id(), 'n');
    std::lock_guard lock(mutex);
    ++received;
    if (!idx || *idx >= 65536) {
      ++foreign;
      return;
    }
    if (*idx >= out.size()) {
      const std::size_t from = out.size();
      out.resize(*idx + 1);
      for (std::size_t i = from; i < out.size(); ++i) {
        out[i].segment("s" + std::to_string(i));
        out[i].node_id("n" + std::to_string(i));
        out[i].quat({1.0, 0.0, 0.0, 0.0});
      }
    }
    bsn::Orientation& o = out[*idx];
    o.timestamp_ns(raw.timestamp_ns());
    if (writer->write(o)) {
      ++written;
    } else {
      ++failures;
    }
  });
  while (dds::sleep_unless_shutdown(std::chrono::milliseconds(100))) {
  }
  reader.reset();
  std::printf("relay: received %llu, written %llu, write failures %llu, foreign %llu\n",
              static_cast<unsigned long long>(received), static_cast<unsigned long long>(written),
              static_cast<unsigned long long>(failures), static_cast<unsigned long long>(foreign));
  return 0;
}

// ---------------------------------------------------------------------------------------------------------------
// One run: one service process (`bsn fusion` or the relay), N segments, one measurement window

enum class Service { kFusion, kRelay };
const char* service_name(Service s) { return s == Service::kFusion ? "fusion" : "relay"; }

struct RunResult {
  int n = 0;
  Service service = Service::kFusion;
  bool completed = false;  ///< the measurement ran (discovery succeeded, no abort)
  std::string error;       ///< why it did not complete, or why it failed
  double window_s = 0;
  std::uint64_t sent = 0, received = 0, out_of_order = 0, foreign = 0, write_failures = 0;
  std::size_t segments_short = 0;  ///< segments with fewer orientations than samples sent
  std::size_t segments_extra = 0;  ///< segments with more (repeats)
  LatencyStats latency;
  // Publisher schedule (the worst of the publisher processes)
  int publishers = 0;
  double achieved_rate_hz = 0;      ///< ticks per second actually achieved
  std::uint64_t overrun_ticks = 0;  ///< ticks whose writes did not finish before the next tick was due
  double max_tick_ms = 0;           ///< longest time to write one tick's samples
  double max_start_late_ms = 0;     ///< worst lateness of a tick start
  bool late_into_window = false;    ///< a publisher was still writing warm-up samples when the window began
  bool publisher_limited = false;
  bool bench_receive_limited = false;  ///< orientations lost in the bench's own socket, service clean
  double steal_pct = NAN;              ///< CPU time the hypervisor took from this VM during the window
  // Fusion's own account (deltas over the window, from bsn/status)
  bool have_status = false;
  StatusTotals status_delta;
  double service_cpu_pct = NAN, bench_cpu_pct = NAN, service_cpu_s = NAN, service_sys_s = NAN;
  std::optional<std::uint64_t> service_rss;                  ///< at the end of the window, bytes
  std::vector<std::pair<double, std::uint64_t>> rss_series;  ///< (s into the window, RSS bytes)
  std::optional<std::uint64_t> service_udp_drops, bench_udp_drops;
  bool service_died = false;
  bool service_clean_exit = false;
  double discovery_s = 0;
  bool pass = false;
  std::string notes;  ///< anomalies that do not decide the verdict
  bool bench_limited() const { return publisher_limited || bench_receive_limited; }
  double service_idle_cpu_s_per_s = NAN;  ///< the service's CPU when idle after the window, s per s
  double service_window_s = NAN;
  double us_per_sample() const { return sent > 0 ? 1e6 * service_cpu_s / static_cast<double>(sent) : NAN; }
  /// CPU per sample above the service's idle cost.
  double marginal_us_per_sample() const {
    return sent > 0 ? 1e6 * (service_cpu_s - service_idle_cpu_s_per_s * service_window_s) / static_cast<double>(sent)
                    : NAN;
  }
};

class Bench {
 public:
  Bench(const Options& opt, fs::path dir) : opt_(opt), dir_(std::move(dir)) {}
  /// Later runs use DDS-Security: the fusion (and the relay) as ROOT/fusion, the bench's participants as
  /// ROOT/tester.
  void set_security(std::string root) { security_root_ = std::move(root); }

  /// Publisher processes for N nodes: --publishers, or one per 250 nodes.
  int publishers_for(int n) const {
    const int p = opt_.publishers > 0 ? opt_.publishers : (n + 249) / 250;
    return std::clamp(p, 1, std::min<int>(n, static_cast<int>(kMaxPublishers)));
  }

  /// rss_every_s > 0: sample the service's RSS this often during the window.
  RunResult run(int n, double seconds, Service service, double rss_every_s = 0) {
    RunResult r;
    r.n = n;
    r.service = service;
    const std::string tag = std::string(service_name(service)) + "-" + std::to_string(n);
    const std::string body_file = write_body(n);
    const std::string log_file = (dir_ / (tag + ".log")).string();
    const std::uint64_t period_ns = static_cast<std::uint64_t>(std::llround(1e9 / opt_.rate_hz));
    const std::uint64_t ticks = static_cast<std::uint64_t>(std::llround(seconds * opt_.rate_hz));
    const auto un = static_cast<std::size_t>(n);
    const std::string control_path = (dir_ / (tag + ".control")).string();
    Control* control = map_control(control_path, true);
    struct Unmap {
      Control* c;
      ~Unmap() { munmap(c, sizeof(Control)); }
    } unmap{control};

    Reception rx(un);
    std::unique_ptr<dds::ChildProcess> child;
    std::unique_ptr<StatusView> status;
    std::vector<std::unique_ptr<dds::ChildProcess>> publishers;
    try {
      std::vector<std::string> argv;
      if (service == Service::kFusion) {
        argv = {opt_.bsn, "fusion", "--domain", std::to_string(opt_.domain), "--body", body_file};
        if (!security_root_.empty()) argv.insert(argv.end(), {"--security", security_root_ + "/fusion"});
      } else {
        argv = {dds::self_executable(), "--relay", std::to_string(opt_.domain)};
        if (!security_root_.empty()) setenv("BSN_SECURITY_DIR", (security_root_ + "/fusion").c_str(), 1);
      }
      if (!opt_.wrap.empty()) {
        std::istringstream words(opt_.wrap);
        std::vector<std::string> prefix;
        for (std::string w; words >> w;) {
          if (const auto at = w.find("%s"); at != std::string::npos) w.replace(at, 2, (dir_ / tag).string());
          prefix.push_back(w);
        }
        argv.insert(argv.begin(), prefix.begin(), prefix.end());
      }
      child = std::make_unique<dds::ChildProcess>(argv, log_file);
      unsetenv("BSN_SECURITY_DIR");
    } catch (const std::exception& e) {
      unsetenv("BSN_SECURITY_DIR");
      r.error = std::string("cannot start the ") + service_name(service) + ": " + e.what();
      return r;
    }
    status = std::make_unique<StatusView>(child->pid());
    const int pubs = publishers_for(n);
    r.publishers = pubs;
    control->period_ns.store(period_ns);
    control->t0_ns.store(dds::monotonic_ns() + 200 * 1000000ull);  // after the publishers' participants exist
    if (!security_root_.empty()) setenv("BSN_SECURITY_DIR", (security_root_ + "/tester").c_str(), 1);
    try {
      for (int p = 0; p < pubs; ++p) {
        const std::size_t first = un * static_cast<std::size_t>(p) / static_cast<std::size_t>(pubs);
        const std::size_t last = un * static_cast<std::size_t>(p + 1) / static_cast<std::size_t>(pubs);
        publishers.push_back(std::make_unique<dds::ChildProcess>(
            std::vector<std::string>{dds::self_executable(), "--publish", control_path, std::to_string(p),
                                     std::to_string(first), std::to_string(last - first), std::to_string(n),
                                     std::to_string(opt_.domain), std::to_string(opt_.rate_hz), opt_.pacing},
            (dir_ / (tag + "-publisher-" + std::to_string(p) + ".log")).string()));
      }
    } catch (const std::exception& e) {
      r.error = std::string("cannot start a publisher: ") + e.what();
    }
    {
      dds::Participant participant({opt_.domain, "bsn bench e2e"});
      unsetenv("BSN_SECURITY_DIR");
      auto orientation_reader = participant.make_reader(
          dds::kOrientationTopic, [&rx](const bsn::Orientation& o, const SampleInfo&) { rx.on_orientation(o); });
      auto status_reader = participant.make_reader(
          dds::kStatusTopic, [&status](const bsn::Status& s, const SampleInfo&) { status->on_status(s); });
      const bool fusion = service == Service::kFusion;
      auto pub_slots = [&] { return std::span<PublisherSlot>(control->slots, static_cast<std::size_t>(pubs)); };
      auto publisher_ended = [&] {
        return std::any_of(publishers.begin(), publishers.end(), [](auto& p) { return !p->running(); });
      };

      // Discovery: the publishers write until every one matched a reader, we matched the service's writer, every
      // segment produced an orientation and (fusion) a status arrived.
      const auto discovery_start = Clock::now();
      const auto discovery_deadline = discovery_start + std::chrono::duration<double>(opt_.discovery_timeout_s);
      while (r.error.empty()) {
        if (!dds::sleep_unless_shutdown(std::chrono::milliseconds(10))) {
          r.error = "interrupted";
          break;
        }
        std::size_t seen = 0;
        {
          std::lock_guard lock(rx.mutex);
          seen = rx.segments_seen;
        }
        const auto slots = pub_slots();
        const bool matched = std::all_of(slots.begin(), slots.end(), [](auto& s) { return s.matched.load() > 0; });
        if (matched && orientation_reader->matched() > 0 && seen == un && (!fusion || status->get())) break;
        if (!child->running()) {
          r.error = std::string(service_name(service)) + " ended during discovery";
          r.service_died = true;
          break;
        }
        if (publisher_ended()) {
          r.error = "a publisher process ended during discovery";
          break;
        }
        if (Clock::now() > discovery_deadline) {
          std::ostringstream m;
          m << "discovery timed out after " << opt_.discovery_timeout_s << " s (publishers matched "
            << (matched ? "all" : "not all") << ", orientation reader matched " << orientation_reader->matched() << ", "
            << seen << "/" << n << " segments seen, status " << (status->get() ? "yes" : "no") << ")";
          r.error = m.str();
          break;
        }
      }
      r.discovery_s = std::chrono::duration<double>(Clock::now() - discovery_start).count();

      // The window: from a tick after the warm-up, for `ticks` ticks. Every sample of an earlier tick is written
      // before it begins (or the publisher says so: late_into_window), every measured one after: the timestamp tells
      // them apart.
      std::optional<bsn::Status> baseline;
      if (r.error.empty()) {
        std::uint64_t latest = 0;
        for (auto& s : pub_slots()) latest = std::max(latest, s.ticks.load());
        const std::uint64_t warm_ticks = static_cast<std::uint64_t>(std::llround(opt_.warmup_seconds * opt_.rate_hz));
        const std::uint64_t first_tick = latest + 2 + warm_ticks;
        const std::uint64_t t0 = control->t0_ns.load();
        const std::uint64_t window_start = t0 + first_tick * period_ns;
        {
          std::lock_guard lock(rx.mutex);
          rx.window_start_ns = window_start;
        }
        control->window_ticks.store(ticks);
        control->window_first_tick.store(first_tick, std::memory_order_release);
        if (!sleep_until_ns(window_start)) r.error = "interrupted";
        baseline = status->get();
      }
      if (r.error.empty()) {
        const auto service_cpu0 = cpu_times(child->pid());
        auto bench_cpu = [&] {
          double total = cpu_times(getpid()).value_or(std::pair{0.0, 0.0}).first;
          for (auto& p : publishers) total += cpu_times(p->pid()).value_or(std::pair{0.0, 0.0}).first;
          return total;
        };
        const double bench_cpu0 = bench_cpu();
        const auto jiffies0 = cpu_jiffies();
        r.service_udp_drops = udp_drops(child->pid(), getpid());
        r.bench_udp_drops = udp_drops(getpid(), child->pid());
        const auto wall0 = dds::monotonic_ns();
        double next_rss_s = 0;
        while (r.error.empty()) {
          const auto slots = pub_slots();
          if (std::all_of(slots.begin(), slots.end(), [](auto& s) { return s.done.load() > 0; })) break;
          if (publisher_ended()) {
            r.error = "a publisher process ended during the window";
            break;
          }
          const double t = static_cast<double>(dds::monotonic_ns() - wall0) / 1e9;
          if (rss_every_s > 0 && t >= next_rss_s) {
            if (auto rss = rss_bytes(child->pid())) r.rss_series.emplace_back(t, *rss);
            next_rss_s += rss_every_s;
          }
          if (!dds::sleep_unless_shutdown(std::chrono::milliseconds(20))) r.error = "interrupted";
        }
        const std::uint64_t publish_end_wall = wall_ns();
        // CPU over the publishing window (what sustaining N nodes costs), not over the drain that follows.
        const auto wall1 = dds::monotonic_ns();
        const auto service_cpu1 = cpu_times(child->pid());
        const double bench_cpu1 = bench_cpu();
        const auto jiffies1 = cpu_jiffies();
        r.service_rss = rss_bytes(child->pid());
        if (rss_every_s > 0 && r.service_rss)
          r.rss_series.emplace_back(static_cast<double>(wall1 - wall0) / 1e9, *r.service_rss);
        double worst_rate = std::numeric_limits<double>::infinity();
        for (auto& s : pub_slots()) {
          r.sent += s.sent.load();
          r.write_failures += s.write_failures.load();
          r.overrun_ticks = std::max(r.overrun_ticks, s.overrun_ticks.load());
          r.max_tick_ms = std::max(r.max_tick_ms, static_cast<double>(s.max_tick_ns.load()) / 1e6);
          r.max_start_late_ms = std::max(r.max_start_late_ms, static_cast<double>(s.max_start_late_ns.load()) / 1e6);
          r.late_into_window = r.late_into_window || s.late_into_window.load() > 0;
          const double span = static_cast<double>(s.last_start_ns.load() + period_ns - s.first_start_ns.load()) / 1e9;
          worst_rate = std::min(worst_rate, span > 0 ? static_cast<double>(ticks) / span : 0.0);
          r.window_s = std::max(r.window_s, span);
        }
        r.achieved_rate_hz = std::isfinite(worst_rate) ? worst_rate : 0.0;
        r.publisher_limited = r.late_into_window || r.achieved_rate_hz < 0.99 * opt_.rate_hz ||
                              static_cast<double>(r.overrun_ticks) > 0.05 * static_cast<double>(ticks);
        control->stop.store(1);

        // Drain: wait while orientations still arrive (up to 10 s), then (fusion) for a status issued after the
        // last write (the fusion publishes one as soon as the nodes turn stale, 0.3 s after the last sample).
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
        if (service_cpu0 && service_cpu1) {
          r.service_cpu_s = service_cpu1->first - service_cpu0->first;
          r.service_sys_s = service_cpu1->second - service_cpu0->second;
          r.service_cpu_pct = 100.0 * r.service_cpu_s / wall_s;
        }
        r.bench_cpu_pct = 100.0 * (bench_cpu1 - bench_cpu0) / wall_s;
        if (r.service_udp_drops) {
          const auto d = udp_drops(child->pid(), getpid());
          r.service_udp_drops = d ? std::optional<std::uint64_t>(*d - *r.service_udp_drops) : std::nullopt;
        }
        if (r.bench_udp_drops) {
          const auto d = udp_drops(getpid(), child->pid());
          r.bench_udp_drops = d ? std::optional<std::uint64_t>(*d - *r.bench_udp_drops) : std::nullopt;
        }
        if (fusion) {
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
        }
        // The service idle (publishers stopped): its fixed cost (DDS's own threads and timers, status), to tell the
        // cost of a sample from the cost of running at all.
        if (r.error.empty()) {
          const auto idle0 = cpu_times(child->pid());
          const auto i0 = dds::monotonic_ns();
          dds::sleep_unless_shutdown(std::chrono::seconds(2));
          const auto idle1 = cpu_times(child->pid());
          if (idle0 && idle1)
            r.service_idle_cpu_s_per_s =
                (idle1->first - idle0->first) / (static_cast<double>(dds::monotonic_ns() - i0) / 1e9);
          r.service_window_s = wall_s;
        }
        if (r.error.empty()) r.completed = true;
      }
      control->stop.store(1);
      for (auto& p : publishers) p->stop();
      r.service_died = r.service_died || !child->running();
      // Stop the service while our participant still lives, so it leaves the domain in an orderly way.
      const auto exit_status = child->stop();
      r.service_clean_exit = !r.service_died && exit_status == std::optional<int>(0);
      if (!r.service_died && !r.service_clean_exit) {
        r.notes += std::string("the ") + service_name(service) + " did not exit cleanly on SIGTERM (wait status " +
                   (exit_status ? std::to_string(*exit_status) : std::string("none: killed")) + "). ";
      }
    }  // readers and participant go here; no callback runs after this

    std::lock_guard lock(rx.mutex);
    r.received = rx.measured_total;
    r.out_of_order = rx.out_of_order;
    r.foreign = rx.foreign;
    if (r.foreign > 0) {
      r.notes += std::to_string(r.foreign) + " orientations of segments not ours: another service in domain " +
                 std::to_string(opt_.domain) + "? ";
    }
    const std::uint64_t per_segment = r.sent / un;
    for (std::size_t i = 0; i < un; ++i) {
      if (rx.measured[i] < per_segment) ++r.segments_short;
      if (rx.measured[i] > per_segment) ++r.segments_extra;
    }
    r.latency = rx.latency.stats();
    judge(r);
    if (r.service_died)
      r.error += (r.error.empty() ? "" : "; ") + std::string(service_name(service)) + " died; log:\n" + tail(log_file);
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
    const bool fusion = r.service == Service::kFusion;
    std::vector<std::string> why;
    if (!r.completed) why.push_back(r.error.empty() ? "did not complete" : r.error);
    if (r.completed) {
      if (r.received < r.sent || r.segments_short > 0) {
        why.push_back(std::to_string(r.sent - std::min(r.sent, r.received)) + " orientations lost (" +
                      std::to_string(r.segments_short) + " segments short)");
      }
      if (r.segments_extra > 0 || r.out_of_order > 0) why.push_back("repeated or reordered orientations");
      if (r.write_failures > 0) why.push_back(std::to_string(r.write_failures) + " raw writes refused");
      if (fusion && !r.have_status) {
        why.push_back("no bsn/status from the fusion after the run");
      } else if (fusion) {
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
      if (r.service_died) why.push_back(std::string(service_name(r.service)) + " died");
    }
    r.pass = why.empty();
    // Lost in the bench's own receive socket while the service saw and handled everything: not the service's fault.
    const bool service_clean =
        !fusion || (r.have_status && r.status_delta.missing == 0 && r.status_delta.rejected == 0);
    r.bench_receive_limited = !r.pass && r.completed && service_clean && r.bench_udp_drops.value_or(0) > 0 &&
                              r.service_udp_drops.value_or(0) == 0 && !r.service_died;
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
  std::printf("    %s: sent %llu, received %llu, lost %lld; latency us: median %s, p90 %s, p99 %s, max %s\n",
              service_name(r.service), static_cast<unsigned long long>(r.sent),
              static_cast<unsigned long long>(r.received),
              static_cast<long long>(r.sent) - static_cast<long long>(r.received),
              fmt("%.0f", r.latency.p50_us).c_str(), fmt("%.0f", r.latency.p90_us).c_str(),
              fmt("%.0f", r.latency.p99_us).c_str(), fmt("%.0f", r.latency.max_us).c_str());
  std::printf(
      "    publishers: %d processes, worst %.2f Hz per node achieved (target %.0f), longest tick %.2f ms, worst start "
      "delay %.2f ms, %llu ticks overran%s%s\n",
      r.publishers, r.achieved_rate_hz, opt.rate_hz, r.max_tick_ms, r.max_start_late_ms,
      static_cast<unsigned long long>(r.overrun_ticks), r.late_into_window ? ", warm-up ran into the window" : "",
      r.publisher_limited ? "  => the bench could not keep the schedule" : "");
  std::printf(
      "    CPU: %s %s %% (%s us per sample, %s above its idle %s %%; system %s), bench %s %% (all its processes; 100 "
      "%% = one core), "
      "steal %s %%; %s RSS %s MB; UDP receive-buffer drops: %s %s, bench %s\n",
      service_name(r.service), fmt("%.1f", r.service_cpu_pct).c_str(), fmt("%.2f", r.us_per_sample()).c_str(),
      fmt("%.2f", r.marginal_us_per_sample()).c_str(), fmt("%.1f", 100.0 * r.service_idle_cpu_s_per_s).c_str(),
      fmt("%.2f", r.sent > 0 ? 1e6 * r.service_sys_s / static_cast<double>(r.sent) : NAN).c_str(),
      fmt("%.1f", r.bench_cpu_pct).c_str(), fmt("%.1f", r.steal_pct).c_str(), service_name(r.service),
      fmt("%.1f", r.service_rss ? static_cast<double>(*r.service_rss) / 1e6 : NAN).c_str(), service_name(r.service),
      drops_text(r.service_udp_drops).c_str(), drops_text(r.bench_udp_drops).c_str());
  if (r.service == Service::kRelay) {
  } else if (r.have_status) {
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
        r.bench_receive_limited ? " (lost in the bench's own receive socket; the service handled every sample)" : "");
  }
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  // The bench's own child processes (not options for a user): the publishers and the bare relay.
  if (argc >= 2 && (std::strcmp(argv[1], "--publish") == 0 || std::strcmp(argv[1], "--relay") == 0)) {
    const std::vector<std::string> args(argv + 2, argv + argc);
    try {
      return std::strcmp(argv[1], "--publish") == 0 ? publisher_main(args) : relay_main(args);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "bsn_bench_e2e %s: error: %s\n", argv[1], e.what());
      return 1;
    }
  }
  Options opt;
  CLI::App app{
      "bsn_bench_e2e: end-to-end latency (raw sample written -> orientation received) through one real `bsn "
      "fusion` process, and the largest number of segments at 100 Hz it sustains with no loss, each beside a bare "
      "relay (bsn/raw in, one bsn/orientation out per sample, same DDS participant, topics and QoS, no fusion). All "
      "processes run on this host. Publisher processes play the N sensor nodes; the bench subscribes to "
      "bsn/orientation."};
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
  app.add_option("--min-segments", opt.min_segments, "smallest N the capacity sweep tries")
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
  app.add_option("--phases", opt.phases,
                 "which phases to run (all = latency and capacity; soak: one long run, --soak-segments for "
                 "--soak-seconds, RSS sampled)")
      ->check(CLI::IsMember({"all", "latency", "capacity", "soak"}))
      ->capture_default_str();
  app.add_option("--wrap", opt.wrap,
                 "run each service under this command (words split at spaces, absolute program path; %s is replaced "
                 "by a per-run path prefix), e.g. \"/usr/bin/valgrind --tool=callgrind --callgrind-out-file=%s.out\"");
  app.add_option("--publishers", opt.publishers, "publisher processes (0: one per 250 nodes)")
      ->check(CLI::Range(0, static_cast<int>(kMaxPublishers)))
      ->capture_default_str();
  app.add_flag("!--no-relay", opt.relay, "skip the bare relay runs (no ratios)");
  app.add_option("--soak-segments", opt.soak_segments, "segments of the soak run")
      ->check(CLI::Range(1, 4096))
      ->capture_default_str();
  app.add_option("--soak-seconds", opt.soak_seconds, "length of the soak run, s (600: the 10-minute memory run)")
      ->check(CLI::Range(1.0, 86400.0))
      ->capture_default_str();
  app.add_option("--soak-rss-every", opt.soak_rss_every_s, "seconds between RSS samples of the soak run")
      ->check(CLI::Range(0.1, 3600.0))
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
    std::optional<RunResult> latency, latency_relay;
    int largest = 0;
  };
  // One latency phase and capacity sweep, with their summary; run twice (open, then secured) with --security.
  auto ratio = [](double a, double b) { return b > 0 ? fmt("%.2f", a / b) : std::string("-"); };
  auto measure = [&](const char* label) -> Outcome {
    std::optional<RunResult> latency, latency_relay, soak;
    std::deque<RunResult> steps;  // stable addresses: failed and limited point into it
    std::map<int, RunResult> relay_steps;
    int largest = 0;                     // largest N verified without loss at the full rate
    const RunResult* failed = nullptr;   // smallest N at which the fusion lost samples (or a run failed)
    const RunResult* limited = nullptr;  // a step at which the bench itself was the bottleneck
    auto step = [&](int n) -> const RunResult& {
      if (opt.relay) {
        std::printf("  N = %d, relay ...\n", n);
        std::fflush(stdout);
        relay_steps[n] = bench.run(n, opt.step_seconds, Service::kRelay);
        print_run_details(relay_steps[n], opt);
      }
      std::printf("  N = %d, fusion ...\n", n);
      std::fflush(stdout);
      steps.push_back(bench.run(n, opt.step_seconds, Service::kFusion));
      print_run_details(steps.back(), opt);
      return steps.back();
    };
    try {
      if (opt.phases == "all" || opt.phases == "latency") {
        std::printf("\n== Phase 1: latency, %d segments at %.0f Hz for %.0f s, bare relay then fusion ==\n",
                    opt.latency_segments, opt.rate_hz, opt.latency_seconds);
        std::fflush(stdout);
        if (opt.relay) {
          latency_relay = bench.run(opt.latency_segments, opt.latency_seconds, Service::kRelay);
          print_run_details(*latency_relay, opt);
        }
        latency = bench.run(opt.latency_segments, opt.latency_seconds, Service::kFusion);
        print_run_details(*latency, opt);
        if (!latency->pass) exit_code = 1;
      }
      if ((opt.phases == "all" || opt.phases == "capacity") && !bsn::dds::shutdown_requested()) {
        std::printf("\n== Phase 2: capacity, N segments at %.0f Hz, %.0f s per step, fresh processes per step ==\n",
                    opt.rate_hz, opt.step_seconds);
        std::vector<int> ns;
        for (int n : {7, 16}) ns.push_back(n);
        for (int n = 32; n < opt.max_segments; n *= 2) ns.push_back(n);
        std::erase_if(ns, [&](int n) { return n > opt.max_segments || n < opt.min_segments; });
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
      if (opt.phases == "soak" && !bsn::dds::shutdown_requested()) {
        std::printf("\n== Soak: %d segments at %.0f Hz for %.0f s into one fusion process, RSS every %.0f s ==\n",
                    opt.soak_segments, opt.rate_hz, opt.soak_seconds, opt.soak_rss_every_s);
        std::fflush(stdout);
        soak = bench.run(opt.soak_segments, opt.soak_seconds, Service::kFusion, opt.soak_rss_every_s);
        print_run_details(*soak, opt);
        if (!soak->pass) exit_code = 1;
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
        "setup: Fast DDS 2.9.1 on one host; one `bsn fusion` process, and beside it in the same invocation the bare "
        "relay (same participant, topics, QoS and transports, one orientation per raw sample, no fusion); the N "
        "nodes from publisher processes (one per 250 nodes unless --publishers; %s pacing, %s body); the bench "
        "subscribes to bsn/orientation. %s.\n",
        opt.pacing.c_str(), opt.topology.c_str(), buffers.c_str());
    std::printf("load average at the end: %s\n", load_average().c_str());
    if (latency) {
      auto line = [&](const RunResult& r) {
        std::printf(
            "  %-6s median %s us, p90 %s us, p99 %s us, max %s us; %s us CPU per sample, %s above idle (%llu "
            "sent, %llu received)%s\n",
            service_name(r.service), fmt("%.0f", r.latency.p50_us).c_str(), fmt("%.0f", r.latency.p90_us).c_str(),
            fmt("%.0f", r.latency.p99_us).c_str(), fmt("%.0f", r.latency.max_us).c_str(),
            fmt("%.2f", r.us_per_sample()).c_str(), fmt("%.2f", r.marginal_us_per_sample()).c_str(),
            static_cast<unsigned long long>(r.sent), static_cast<unsigned long long>(r.received),
            r.pass ? "" : ("  FAILED: " + r.error).c_str());
      };
      std::printf("latency, raw sample written -> orientation received, %d segments x %.0f Hz, %.0f s, %s pacing:\n",
                  latency->n, opt.rate_hz, opt.latency_seconds, opt.pacing.c_str());
      if (latency_relay) line(*latency_relay);
      line(*latency);
      if (latency_relay) {
        std::printf("  fusion / relay: median %s x, p99 %s x, CPU per sample %s x (above idle %s x)\n",
                    ratio(latency->latency.p50_us, latency_relay->latency.p50_us).c_str(),
                    ratio(latency->latency.p99_us, latency_relay->latency.p99_us).c_str(),
                    ratio(latency->us_per_sample(), latency_relay->us_per_sample()).c_str(),
                    ratio(latency->marginal_us_per_sample(), latency_relay->marginal_us_per_sample()).c_str());
      }
    }
    if (!steps.empty()) {
      std::printf("capacity at %.0f Hz per segment, %.0f s per step, no loss allowed (fusion, relay, fusion/relay):\n",
                  opt.rate_hz, opt.step_seconds);
      std::printf("  %6s %4s %9s %7s %18s %18s %16s %16s %9s %8s %8s  %s\n", "N", "pubs", "sent", "lost", "p50 us",
                  "p99 us", "us/sample", "above idle", "fusion %", "RSS MB", "pub Hz", "result");
      std::vector<const RunResult*> sorted;
      for (const auto& r : steps) sorted.push_back(&r);
      std::stable_sort(sorted.begin(), sorted.end(), [](auto* a, auto* b) { return a->n < b->n; });
      for (const RunResult* r : sorted) {
        const auto it = relay_steps.find(r->n);
        const RunResult* b = it == relay_steps.end() ? nullptr : &it->second;
        auto triple = [&](double f, double rel, const char* format) {
          return fmt(format, f) + " " + (b ? fmt(format, rel) : "-") + " " + (b ? ratio(f, rel) : "-");
        };
        std::printf("  %6d %4d %9llu %7lld %18s %18s %16s %16s %9s %8s %8.1f  %s%s\n", r->n, r->publishers,
                    static_cast<unsigned long long>(r->sent),
                    static_cast<long long>(r->sent) - static_cast<long long>(r->received),
                    triple(r->latency.p50_us, b ? b->latency.p50_us : NAN, "%.0f").c_str(),
                    triple(r->latency.p99_us, b ? b->latency.p99_us : NAN, "%.0f").c_str(),
                    triple(r->us_per_sample(), b ? b->us_per_sample() : NAN, "%.2f").c_str(),
                    triple(r->marginal_us_per_sample(), b ? b->marginal_us_per_sample() : NAN, "%.2f").c_str(),
                    fmt("%.1f", r->service_cpu_pct).c_str(),
                    fmt("%.1f", r->service_rss ? static_cast<double>(*r->service_rss) / 1e6 : NAN).c_str(),
                    r->achieved_rate_hz, verdict(*r),
                    b && !b->pass ? (std::string(", relay ") + verdict(*b)).c_str() : "");
      }
      // Memory per segment: the fusion's RSS grows with N over the steps that passed (each a fresh process).
      const RunResult* lo = nullptr;
      const RunResult* hi = nullptr;
      for (const RunResult* r : sorted) {
        if (!r->pass || !r->service_rss) continue;
        if (!lo) lo = r;
        hi = r;
      }
      if (lo && hi && hi->n > lo->n) {
        std::printf("fusion memory per segment: %.0f bytes (RSS %.1f MB at N = %d, %.1f MB at N = %d)\n",
                    static_cast<double>(*hi->service_rss - std::min(*hi->service_rss, *lo->service_rss)) /
                        static_cast<double>(hi->n - lo->n),
                    static_cast<double>(*lo->service_rss) / 1e6, lo->n, static_cast<double>(*hi->service_rss) / 1e6,
                    hi->n);
      }
      std::printf("largest N with no loss at %.0f Hz: %d\n", opt.rate_hz, largest);
      if (failed) {
        std::printf("  first failing N = %d: %s\n", failed->n, failed->error.c_str());
        if (failed->service_udp_drops.value_or(0) > 0) {
          std::printf(
              "  the fusion's UDP receive socket overflowed (%llu datagrams dropped by the kernel) at %.0f %% CPU: the "
              "limit is the socket buffer against a burst of %d samples, not the fusion's compute.\n",
              static_cast<unsigned long long>(*failed->service_udp_drops), failed->service_cpu_pct, failed->n);
        }
        const auto it = relay_steps.find(failed->n);
        if (it != relay_steps.end() && !it->second.pass)
          std::printf("  the bare relay failed at this N too: %s\n", it->second.error.c_str());
      }
      if (limited) {
        std::printf(
            "  stopped at N = %d because the bench itself was the bottleneck (%s); the fusion limit is at least %d and "
            "was not reached.\n",
            limited->n,
            limited->publisher_limited
                ? ("its publishers achieved " + fmt("%.1f", limited->achieved_rate_hz) + " Hz per node" +
                   (limited->late_into_window ? ", one still writing warm-up samples when the window began" : ""))
                      .c_str()
                : "its own orientation reader dropped datagrams while the fusion fused every sample",
            largest);
      }
      if (!failed && !limited && !steps.empty() && largest == opt.max_segments) {
        std::printf("  every step passed up to --max-segments %d; the limit is higher.\n", opt.max_segments);
      }
    }
    if (soak) {
      const RunResult& r = *soak;
      std::printf(
          "soak, %d segments x %.0f Hz for %.0f s: %s; lost %lld of %llu; latency median %s us, p99 %s us; "
          "%s us CPU per sample, fusion at %s %% of a core\n",
          r.n, opt.rate_hz, opt.soak_seconds, verdict(r),
          static_cast<long long>(r.sent) - static_cast<long long>(r.received), static_cast<unsigned long long>(r.sent),
          fmt("%.0f", r.latency.p50_us).c_str(), fmt("%.0f", r.latency.p99_us).c_str(),
          fmt("%.2f", r.us_per_sample()).c_str(), fmt("%.1f", r.service_cpu_pct).c_str());
      if (!r.pass) std::printf("  %s\n", r.error.c_str());
      if (!r.rss_series.empty()) {
        std::printf("  fusion RSS (s: MB):");
        for (const auto& [t, rss] : r.rss_series) std::printf(" %.0f: %.2f", t, static_cast<double>(rss) / 1e6);
        const auto [lo, hi] = std::minmax_element(r.rss_series.begin(), r.rss_series.end(),
                                                  [](auto& a, auto& b) { return a.second < b.second; });
        std::printf(
            "\n  fusion RSS %.2f MB at the start of the window, %.2f MB at its end (min %.2f, max %.2f); "
            "%.0f bytes per segment at the end\n",
            static_cast<double>(r.rss_series.front().second) / 1e6,
            static_cast<double>(r.rss_series.back().second) / 1e6, static_cast<double>(lo->second) / 1e6,
            static_cast<double>(hi->second) / 1e6,
            static_cast<double>(r.rss_series.back().second) / static_cast<double>(r.n));
      }
    }
    return Outcome{latency, latency_relay, largest};
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
    // What DDS-Security costs the bare relay is Fast DDS's own security layer (the same participant, topics and QoS,
    // one orientation out per raw sample in); what it costs the fusion beyond that is bsn's own secured overhead.
    if (open.latency && secured.latency && open.latency_relay && secured.latency_relay) {
      const RunResult &fusion_off = *open.latency, &fusion_on = *secured.latency, &relay_off = *open.latency_relay,
                      &relay_on = *secured.latency_relay;
      auto overhead = [&](const char* what, double relay, double fusion) {
        std::printf("  %s: relay %s us (Fast DDS's own layer), fusion %s us: fusion / relay %s x (target <= 1.2)\n",
                    what, fmt("%.1f", relay).c_str(), fmt("%.1f", fusion).c_str(), ratio(fusion, relay).c_str());
      };
      std::printf("secured overhead (on - off), %d segments:\n", opt.latency_segments);
      overhead("median latency", relay_on.latency.p50_us - relay_off.latency.p50_us,
               fusion_on.latency.p50_us - fusion_off.latency.p50_us);
      overhead("p99 latency", relay_on.latency.p99_us - relay_off.latency.p99_us,
               fusion_on.latency.p99_us - fusion_off.latency.p99_us);
      overhead("CPU per sample", relay_on.us_per_sample() - relay_off.us_per_sample(),
               fusion_on.us_per_sample() - fusion_off.us_per_sample());
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
