// bsn across machines: network namespaces as hosts (sensors, fusion, viewer, rogue) joined by a bridge in a namespace
// of its own, real `bsn` processes in them, and the test's viewer participant created inside the viewer host.
// With multicast, and with multicast blocked at the bridge through a discovery server, 7 sensor nodes reach
// the viewer at >= 95 % of 100 Hz per segment. Needs root (CAP_SYS_ADMIN, CAP_NET_ADMIN) and iproute2;
// otherwise the tests report themselves skipped with the reason. Every namespace is deleted on exit, also
// after a failure, and namespaces left by a killed earlier run are removed first.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sched.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <regex>
#include <sstream>
#include <string>
#include <thread>

#include "bsn/dds/conversions.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/fusion/rotation.hpp"
#include "netns_hosts.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;
using SampleInfo = eprosima::fastdds::dds::SampleInfo;

const std::vector<std::string> kNodes{"pelvis", "thigh_l", "shank_l", "foot_l", "thigh_r", "shank_r", "foot_r"};
/// Orientation samples per segment, as the viewer receives them.
struct OrientationCounts {
  std::mutex mutex;
  std::map<std::string, int> per_segment;
  int joints = 0;
  Clock::time_point first_joint{};
  std::map<std::string, int> snapshot() {
    std::lock_guard lock(mutex);
    return per_segment;
  }
};

/// From `bsn echo bsn/orientation` lines ("orientation SEGMENT t=SECONDSs ..."): expects every segment to have
/// >= 95 % of 100 Hz of its samples in a window of `window_s` of sensor time that starts 1 s after the last
/// segment's first sample.
void expect_full_rate_in_echo_log(const std::string& log, double window_s) {
  std::map<std::string, std::vector<double>> times;
  const std::regex line("^orientation (\\S+) t=([0-9.]+)s");
  std::istringstream in(log);
  for (std::string l; std::getline(in, l);) {
    std::smatch m;
    if (std::regex_search(l, m, line)) times[m[1]].push_back(std::stod(m[2]));
  }
  ASSERT_EQ(times.size(), kNodes.size()) << "segments in the echo output:\n" << log.substr(0, 2000);
  double start = 0;
  for (const auto& [segment, t] : times) start = std::max(start, t.front() + 1.0);
  for (const auto& [segment, t] : times) {
    const auto n = std::count_if(t.begin(), t.end(), [&](double x) { return x >= start && x < start + window_s; });
    EXPECT_GE(n, 0.95 * 100.0 * window_s) << segment << ": samples in " << window_s << " s of sensor time";
  }
}

class MultiHost : public ProcessTest {
 protected:
  void SetUp() override {
    ProcessTest::SetUp();
    if (const std::string why = namespaces_unavailable(); !why.empty()) GTEST_SKIP() << why;
    remove_stale_namespaces();
    hosts_ = std::make_unique<Hosts>(std::vector<std::string>{"sensors", "fusion", "viewer", "rogue"});
    ASSERT_TRUE(hosts_->ok()) << "could not create the namespaces and the bridge";
  }
  void TearDown() override {
    viewer_joints_.reset();
    viewer_orientations_.reset();
    viewer_.reset();
    ProcessTest::TearDown();  // stops the processes before their namespaces go
    hosts_.reset();
  }

  /// `bsn <args>` on `host`.
  void spawn_on(const std::string& host, const std::string& name, std::vector<std::string> args) {
    std::vector<std::string> argv{"/usr/sbin/ip", "netns", "exec", hosts_->ns(host), bsn_executable()};
    argv.insert(argv.end(), args.begin(), args.end());
    spawn_command(name, argv);
  }

  /// The viewer's participant, created inside the viewer host, counting orientations and joint angles.
  void start_viewer(int domain) {
    ASSERT_TRUE(run_in_namespace(hosts_->ns("viewer"), [&] {
      viewer_ = std::make_unique<dds::Participant>(dds::Participant::Options{domain, "multi-host viewer"});
      viewer_orientations_ =
          viewer_->make_reader(dds::kOrientationTopic, [this](const bsn::Orientation& o, const SampleInfo&) {
            std::lock_guard lock(counts_.mutex);
            ++counts_.per_segment[o.segment()];
          });
      viewer_joints_ = viewer_->make_reader(dds::kJointAnglesTopic, [this](const bsn::JointAngles&, const SampleInfo&) {
        std::lock_guard lock(counts_.mutex);
        if (counts_.joints++ == 0) counts_.first_joint = Clock::now();
      });
    })) << "cannot enter the viewer's namespace";
  }

  void start_body(int domain, const std::vector<std::string>& extra = {}) {
    const std::string d = std::to_string(domain);
    auto with = [&](std::vector<std::string> args) {
      args.insert(args.end(), {"--domain", d});
      args.insert(args.end(), extra.begin(), extra.end());
      return args;
    };
    spawn_on("fusion", "fusion", with({"fusion"}));
    for (const std::string& node : kNodes) spawn_on("sensors", "sim-" + node, with({"sim", "--node", node}));
  }

  /// Expects every segment at >= 95 % of 100 Hz at the viewer over `window`, after the first sample of each.
  void expect_full_rate(std::chrono::seconds window) {
    ASSERT_TRUE(wait_until([&] { return counts_.snapshot().size() == kNodes.size(); }, 30s))
        << counts_.snapshot().size() << " of " << kNodes.size() << " segments reached the viewer";
    std::this_thread::sleep_for(2s);  // every filter past its start
    const auto before = counts_.snapshot();
    std::this_thread::sleep_for(window);
    const auto after = counts_.snapshot();
    for (const std::string& segment : kNodes) {
      const double rate = (after.at(segment) - before.at(segment)) / double(window.count());
      RecordProperty(segment + "_hz", std::to_string(rate));
      EXPECT_GE(rate, 0.95 * 100.0) << segment << " at the viewer";
    }
  }

  std::unique_ptr<Hosts> hosts_;
  OrientationCounts counts_;
  std::unique_ptr<dds::Participant> viewer_;
  std::unique_ptr<dds::Reader<bsn::Orientation>> viewer_orientations_;
  std::unique_ptr<dds::Reader<bsn::JointAngles>> viewer_joints_;
};

TEST_F(MultiHost, MulticastDiscovery) {
  const int domain = test_domain(38);
  start_viewer(domain);
  start_body(domain);
  expect_full_rate(5s);
}

TEST_F(MultiHost, DiscoveryServerWithMulticastBlocked) {
  const int domain = test_domain(39);
  ASSERT_TRUE(hosts_->block_multicast());
  // The shipped profiles, pointed at a server on the fusion host.
  const std::string server = hosts_->address("fusion");
  std::string client = read_file(std::string(BSN_DEPLOY_DIR) + "/profiles/discovery-client.xml");
  client =
      std::regex_replace(client, std::regex("<address>127\\.0\\.0\\.1</address>"), "<address>" + server + "</address>");
  const std::string client_path = (dir() / "client.xml").string();
  write_file(client_path, client);
  spawn_command("server", {"/usr/sbin/ip", "netns", "exec", hosts_->ns("fusion"), "/usr/bin/fast-discovery-server",
                           "-x", std::string(BSN_DEPLOY_DIR) + "/profiles/discovery-server.xml"});

  // Multicast is really blocked: an ordinary participant on the viewer host finds nothing.
  start_viewer(domain);
  start_body(domain, {"--profile", client_path});
  std::this_thread::sleep_for(3s);
  EXPECT_EQ(counts_.snapshot().size(), 0u) << "a multicast-discovery viewer received data with multicast blocked";
  viewer_joints_.reset();
  viewer_orientations_.reset();
  viewer_.reset();

  // `bsn echo` with the client profile on the viewer host: its first joint angle within 3 s of its start, then
  // every segment's samples over 4 s of sensor time.
  const std::vector<std::string> echo{
      "/usr/sbin/ip", "netns",     "exec",      hosts_->ns("viewer"), bsn_executable(),
      "echo",         "--profile", client_path, "--domain",           std::to_string(domain)};
  auto echo_of = [&](std::vector<std::string> args) {
    std::vector<std::string> argv = echo;
    argv.insert(argv.begin() + 6, args.begin(), args.end());
    return argv;
  };
  spawn_command("first-joint", echo_of({"bsn/joint_angles", "--count", "1", "--timeout", "3"}));
  EXPECT_TRUE(exited_cleanly(child("first-joint").wait_for(10s)))
      << "no joint angle within 3 s through the discovery server: " << tail(log_path("first-joint"));
  spawn_command("orientations", echo_of({"bsn/orientation", "--count", "4200", "--timeout", "10"}));
  child("orientations").wait_for(15s);
  expect_full_rate_in_echo_log(read_file(log_path("orientations")), 4.0);
}

// A 5 s cut of the sensor host's link is an outage, not a clock reset: every node is stale within 0.5 s of the
// cut, back within 1 s of the link's return, its filter restarted by the gap rule, and no clock reset or time
// jump is counted.
TEST_F(MultiHost, LinkCutIsAGapNotAClockReset) {
  const int domain = test_domain(54);
  std::mutex mutex;
  struct NodeSeen {
    bool stale = false;
    std::uint64_t clock_resets = 0, time_jumps = 0, missing = 0;
  };
  std::map<std::string, NodeSeen> nodes;
  std::optional<Clock::time_point> all_stale_at;
  Clock::time_point link_up{};
  std::map<std::string, Clock::time_point> back_at;  // first orientation after the link returned
  std::map<std::string, bool> restarted;             // ... and whether it says the filter re-initialised
  std::unique_ptr<dds::Reader<bsn::Status>> status_reader;
  std::unique_ptr<dds::Reader<bsn::Orientation>> orientation_reader;
  ASSERT_TRUE(run_in_namespace(hosts_->ns("viewer"), [&] {
    viewer_ = std::make_unique<dds::Participant>(dds::Participant::Options{domain, "multi-host viewer"});
    status_reader = viewer_->make_reader(dds::kStatusTopic, [&](const bsn::Status& st, const SampleInfo&) {
      std::lock_guard lock(mutex);
      bool every_stale = st.nodes().size() == kNodes.size();
      for (const auto& n : st.nodes()) {
        NodeSeen& seen = nodes[n.node_id()];
        seen.stale = n.stale();
        seen.clock_resets = n.clock_resets();
        seen.missing = n.missing();
        for (const auto& r : n.rejected())
          if (r.reason() == "time_jump") seen.time_jumps = r.count();
        every_stale = every_stale && n.stale();
      }
      if (every_stale && !all_stale_at) all_stale_at = Clock::now();
    });
    orientation_reader =
        viewer_->make_reader(dds::kOrientationTopic, [&](const bsn::Orientation& o, const SampleInfo&) {
          std::lock_guard lock(mutex);
          ++counts_.per_segment[o.segment()];
          if (link_up != Clock::time_point{} && !back_at.count(o.segment()) && !(o.flags() & bsn::FLAG_STALE)) {
            back_at[o.segment()] = Clock::now();
            restarted[o.segment()] = (o.flags() & bsn::FLAG_REINITIALISED) != 0;
          }
        });
  })) << "cannot enter the viewer's namespace";
  start_body(domain);
  ASSERT_TRUE(wait_until([&] { return counts_.snapshot().size() == kNodes.size(); }, 30s));
  std::this_thread::sleep_for(2s);

  const std::string link = "ip -n " + hosts_->ns("sensors") + " link set eth0 ";
  const auto cut_at = Clock::now();
  ASSERT_TRUE(run(link + "down"));
  ASSERT_TRUE(wait_until(
      [&] {
        std::lock_guard lock(mutex);
        return all_stale_at.has_value();
      },
      3s))
      << "not every node was reported stale after the cut";
  {
    std::lock_guard lock(mutex);
    EXPECT_LE(std::chrono::duration<double>(*all_stale_at - cut_at).count(), 0.5);
  }
  std::this_thread::sleep_until(cut_at + 5s);
  {
    std::lock_guard lock(mutex);
    link_up = Clock::now();
  }
  ASSERT_TRUE(run(link + "up"));
  EXPECT_TRUE(wait_until(
      [&] {
        std::lock_guard lock(mutex);
        return back_at.size() == kNodes.size();
      },
      3s))
      << "segments back after the link returned: " << back_at.size();
  std::this_thread::sleep_for(1500ms);  // a status period after the return
  // Readers first: a callback may be waiting for `mutex` while holding the reader's callback lock.
  status_reader.reset();
  orientation_reader.reset();
  std::lock_guard lock(mutex);
  for (const std::string& node : kNodes) {
    SCOPED_TRACE(node);
    ASSERT_TRUE(back_at.count(node));
    EXPECT_LE(std::chrono::duration<double>(back_at[node] - link_up).count(), 1.0);
    EXPECT_TRUE(restarted[node]) << "the first estimate after the outage does not say the filter restarted";
    EXPECT_FALSE(nodes[node].stale);
    EXPECT_EQ(nodes[node].clock_resets, 0u);
    EXPECT_EQ(nodes[node].time_jumps, 0u);
    EXPECT_GE(nodes[node].missing, 400u) << "the samples of the outage are not counted missing";
  }
}

// Unsecured, a rogue host runs `bsn sim --node thigh_l` while the real thigh_l flows (before the check: 0 rejected, and
// thigh_l's error went from 0.3 deg to 10-35 deg). Its samples are rejected as conflicting_source, the real
// thigh_l's estimate stays within 2 deg of the real simulator's truth, and no other node is touched.
TEST_F(MultiHost, RogueSimIsAConflictingSource) {
  const int domain = test_domain(29);
  constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;
  std::mutex mutex;
  std::optional<eprosima::fastrtps::rtps::GUID_t> real_truth_writer;  // the first writer of thigh_l's truth
  std::map<std::uint64_t, fusion::Quat> truth;                        // of that writer, by sensor timestamp
  bool rogue_running = false;
  double max_error_deg = 0.0, max_error_before_deg = 0.0;
  int compared = 0, compared_before = 0;
  std::map<std::string, std::uint64_t> conflicting;  // per node, from bsn/status
  std::unique_ptr<dds::Reader<bsn::Orientation>> truth_reader, estimate_reader;
  std::unique_ptr<dds::Reader<bsn::Status>> status_reader;
  ASSERT_TRUE(run_in_namespace(hosts_->ns("viewer"), [&] {
    viewer_ = std::make_unique<dds::Participant>(dds::Participant::Options{domain, "multi-host viewer"});
    truth_reader =
        viewer_->make_reader(dds::kTruthOrientationTopic, [&](const bsn::Orientation& o, const SampleInfo& info) {
          if (o.segment() != "thigh_l") return;
          std::lock_guard lock(mutex);
          if (!real_truth_writer) {
            if (rogue_running) return;  // only the real simulator's truth counts
            real_truth_writer = info.sample_identity.writer_guid();
          }
          if (info.sample_identity.writer_guid() != *real_truth_writer) return;
          truth[o.timestamp_ns()] = dds::to_quat(o.quat());
          if (truth.size() > 2000) truth.erase(truth.begin());
        });
    estimate_reader = viewer_->make_reader(dds::kOrientationTopic, [&](const bsn::Orientation& o, const SampleInfo&) {
      {
        std::lock_guard counts_lock(counts_.mutex);
        ++counts_.per_segment[o.segment()];
      }
      std::lock_guard lock(mutex);
      if (o.segment() != "thigh_l" || (o.flags() & bsn::FLAG_INITIALISING)) return;
      const auto t = truth.find(o.timestamp_ns());
      if (t == truth.end()) return;
      // NaN compares false: `!(e <= max)` records it as a failure.
      const double e = fusion::angle_between(dds::to_quat(o.quat()), t->second) * kRadToDeg;
      double& max = rogue_running ? max_error_deg : max_error_before_deg;
      if (!(e <= max)) max = e;
      ++(rogue_running ? compared : compared_before);
    });
    status_reader = viewer_->make_reader(dds::kStatusTopic, [&](const bsn::Status& st, const SampleInfo&) {
      std::lock_guard lock(mutex);
      for (const auto& n : st.nodes())
        for (const auto& r : n.rejected())
          if (r.reason() == "conflicting_source") conflicting[n.node_id()] = r.count();
    });
  })) << "cannot enter the viewer's namespace";
  start_body(domain);
  ASSERT_TRUE(wait_until([&] { return counts_.snapshot().size() == kNodes.size(); }, 30s));
  std::this_thread::sleep_for(4s);  // every filter past its start, and a baseline error
  {
    std::lock_guard lock(mutex);
    ASSERT_TRUE(real_truth_writer) << "no truth of thigh_l from its simulator";
    rogue_running = true;
  }
  // Another motion (seed) from another host: interleaved, it would tear the estimate apart.
  spawn_on("rogue", "rogue", {"sim", "--node", "thigh_l", "--seed", "4242", "--domain", std::to_string(domain)});
  // 8 s of the rogue, once the fusion service rejects it.
  ASSERT_TRUE(wait_until(
      [&] {
        std::lock_guard lock(mutex);
        return conflicting["thigh_l"] > 0;
      },
      30s))
      << "the rogue's samples are not reported as conflicting_source: " << tail(log_path("fusion"));
  std::this_thread::sleep_for(8s);
  truth_reader.reset();
  estimate_reader.reset();
  status_reader.reset();
  std::lock_guard lock(mutex);
  std::printf("[ measure  ] thigh_l max error %.3f deg before the rogue (%d compared), %.3f deg with it (%d)\n",
              max_error_before_deg, compared_before, max_error_deg, compared);
  EXPECT_GE(compared, 200) << "too few estimates matched to the truth with the rogue running";
  // The real sensor's estimate is as good as without the rogue (0.3 deg measured); 2 deg is what a lab accepts.
  EXPECT_LT(max_error_deg, 2.0) << "thigh_l's estimate follows the rogue's samples";
  // 8 s of a 100 Hz rogue; half of it leaves room for a loaded machine and the status period.
  EXPECT_GE(conflicting["thigh_l"], 400u) << "the rogue's samples are not all rejected as conflicting_source";
  for (const std::string& node : kNodes) {
    if (node == "thigh_l") continue;
    EXPECT_EQ(conflicting[node], 0u) << node;
  }
  const std::string log = read_file(log_path("fusion"));
  EXPECT_NE(log.find("rejected as conflicting_source"), std::string::npos) << tail(log_path("fusion"));
  const std::string rogue_writer = [&] {
    std::smatch m;
    const std::string text = read_file(log_path("rogue"));
    return std::regex_search(text, m, std::regex("raw samples from writer ([0-9a-f.|]+)\\)")) ? m[1].str() : "";
  }();
  EXPECT_FALSE(rogue_writer.empty());
  EXPECT_NE(log.find(rogue_writer + ", rejected as conflicting_source"), std::string::npos)
      << "the fusion log does not name the rogue's writer " << rogue_writer;
}

// Secured, per-node permissions: the real sensors' hub may write all seven nodes; a second hub has a valid sensor
// key for shank_r only. Its `bsn sim --node thigh_l` fails at start, and its writer in its own partition that
// writes thigh_l samples gets none of them fused: not while thigh_l flows, not while the sensors' link is down
// and thigh_l is stale (the takeover per-role permissions allowed), and thigh_l comes back from its own sensor.
// Handshakes among the namespace hosts fail more often than on one host: every bsn process makes its participant
// again when its peer stays unmatched and no handshake progresses (dds::Participant::watch_peers), and the test's own
// participants are made again after 20 s. On a 2-core machine at load 12-17: 5 of 5 runs alone passed in 11-13 s, 2
// of 2 beside MultiHost.LinkCutIsAGapNotAClockReset and two busy loops in 13 and 34 s. Before watch_peers waited
// for stalled handshakes (every process re-made its participant at once), 5 runs gave 2 passes, 1 failure and 2
// hangs past 300 s that were not diagnosed.
TEST_F(MultiHost, SecuredTakeoverByAnotherIdentityIsRefusedAndCounted) {
  const int domain = test_domain(85);
  const std::string pki = (dir() / "pki").string();
  std::string all_nodes;
  for (const std::string& node : kNodes) all_nodes += (all_nodes.empty() ? "" : ",") + node;
  ASSERT_TRUE(run(std::string(BSN_DEPLOY_DIR) + "/security/make-pki.sh '" + pki + "' hub1:sensor:" + all_nodes +
                  " hub2:sensor:shank_r fusion:fusion viewer:viewer"));
  std::mutex mutex;
  struct Thigh {
    std::uint64_t accepted = 0, not_permitted = 0, conflicting = 0, handovers = 0;
    bool stale = false;
  } thigh;
  auto snapshot = [&] {
    std::lock_guard lock(mutex);
    return thigh;
  };
  std::unique_ptr<dds::Reader<bsn::Status>> status_reader;
  std::unique_ptr<dds::Participant> rogue;
  std::unique_ptr<dds::Writer<bsn::RawSample>> rogue_raw;
  // The test's own participants: a viewer of fusion's status, and the second hub's writer in its own partition.
  auto connect = [&] {
    status_reader.reset();
    viewer_.reset();
    rogue_raw.reset();
    rogue.reset();
    setenv("BSN_SECURITY_DIR", (pki + "/viewer").c_str(), 1);
    const bool entered = run_in_namespace(hosts_->ns("viewer"), [&] {
      viewer_ = std::make_unique<dds::Participant>(dds::Participant::Options{domain, "multi-host viewer"});
      status_reader = viewer_->make_reader(dds::kStatusTopic, [&](const bsn::Status& st, const SampleInfo&) {
        std::lock_guard lock(mutex);
        for (const auto& n : st.nodes()) {
          if (n.node_id() != "thigh_l") continue;
          thigh.accepted = n.accepted();
          thigh.stale = n.stale();
          thigh.handovers = n.source_handovers();
          for (const auto& r : n.rejected()) {
            if (r.reason() == "not_permitted") thigh.not_permitted = r.count();
            if (r.reason() == "conflicting_source") thigh.conflicting = r.count();
          }
        }
      });
    });
    setenv("BSN_SECURITY_DIR", (pki + "/hub2").c_str(), 1);
    const bool rogue_entered = run_in_namespace(hosts_->ns("rogue"), [&] {
      rogue = std::make_unique<dds::Participant>(dds::Participant::Options{domain, "multi-host rogue"});
      rogue_raw = rogue->make_writer(dds::kRawTopic, std::nullopt, "shank_r");
    });
    unsetenv("BSN_SECURITY_DIR");
    return entered && rogue_entered;
  };
  ASSERT_TRUE(connect()) << "cannot enter the viewer's or the rogue's namespace";

  const std::string d = std::to_string(domain);
  spawn_on("fusion", "fusion", {"fusion", "--status-period", "0.5", "--domain", d, "--security", pki + "/fusion"});
  for (const std::string& node : kNodes)
    spawn_on("sensors", "sim-" + node, {"sim", "--node", node, "--domain", d, "--security", pki + "/hub1"});
  spawn_on("rogue", "rogue-sim", {"sim", "--node", "thigh_l", "--domain", d, "--security", pki + "/hub2"});
  const auto refused = child("rogue-sim").wait_for(30s);
  ASSERT_TRUE(refused.has_value()) << "the second hub's bsn sim --node thigh_l kept running";
  EXPECT_FALSE(exited_cleanly(refused));
  EXPECT_NE(read_file(log_path("rogue-sim")).find("bsn/raw for node thigh_l"), std::string::npos)
      << tail(log_path("rogue-sim"));
  // Authentication handshakes among the hosts: seconds on a loaded machine. Fast DDS 2.9.1 sometimes never completes
  // the handshake of a pair of participants (about 1 run in 4 here left this test's viewer without fusion's status
  // for 60 s while fusion fused every node); a participant that is not matched in 20 s is made again.
  bool joined = false;
  for (int attempt = 0; attempt < 3 && !joined; ++attempt) {
    if (attempt > 0) {
      std::printf("[ retry    ] the test's participants matched nothing in 20 s; making them again\n");
      ASSERT_TRUE(connect());
    }
    joined = wait_until([&] { return snapshot().accepted > 200 && rogue_raw->matched() > 0; }, 20s);
  }
  ASSERT_TRUE(joined) << "thigh_l accepted " << snapshot().accepted << ", rogue writer matched "
                      << rogue_raw->matched();

  bsn::RawSample sample;
  sample.node_id("thigh_l");
  sample.acc({0, 0, 9.81});
  sample.channels(bsn::CHANNEL_ACC | bsn::CHANNEL_GYR);
  std::uint64_t seq = 0;
  auto write_rogue = [&](int n) {
    for (int i = 0; i < n; ++i, ++seq) {
      sample.seq(seq);
      sample.timestamp_ns(dds::monotonic_ns());
      rogue_raw->write(sample);
      std::this_thread::sleep_for(10ms);
    }
  };
  write_rogue(100);
  ASSERT_TRUE(wait_until([&] { return snapshot().not_permitted > 0; }, 10s))
      << "no rogue sample rejected as not_permitted: " << tail(log_path("fusion"));

  const std::string link = "ip -n " + hosts_->ns("sensors") + " link set eth0 ";
  ASSERT_TRUE(run(link + "down"));
  ASSERT_TRUE(wait_until([&] { return snapshot().stale; }, 3s)) << "thigh_l not stale after the cut";
  const Thigh cut = snapshot();
  write_rogue(200);  // 2 s past the 0.3 s stale timeout
  std::this_thread::sleep_for(1200ms);
  const Thigh during = snapshot();
  ASSERT_TRUE(run(link + "up"));
  EXPECT_EQ(during.accepted, cut.accepted) << "fusion accepted the rogue's thigh_l samples";
  EXPECT_EQ(during.handovers, 0u) << "the rogue took thigh_l over";
  EXPECT_TRUE(during.stale);
  EXPECT_GE(during.not_permitted - cut.not_permitted, 150u) << "the rogue's samples are not counted as not_permitted";
  // The real thigh_l returns and is fused again: the rogue locked nobody out.
  EXPECT_TRUE(wait_until([&] { return snapshot().accepted > during.accepted + 100 && !snapshot().stale; }, 10s))
      << "thigh_l did not come back from its own sensor";
  EXPECT_EQ(snapshot().conflicting, 0u);
  status_reader.reset();
  rogue_raw.reset();
  rogue.reset();
}

}  // namespace
}  // namespace bsn::integration
