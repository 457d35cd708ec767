// DDS-Security by role, with real `bsn` processes and a PKI made by deploy/security/make-pki.sh (openssl):
// authorised processes exchange data; a participant without credentials, or with a certificate from another
// authority, reads nothing and gets nothing accepted; permissions stop a viewer from writing raw samples and a
// sensor from writing orientations; and the loopback traffic of the domain carries no plaintext joint angle.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <linux/if_packet.h>
#include <net/ethernet.h>
#include <net/if.h>
#include <netinet/ip.h>
#include <netinet/udp.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <sstream>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "bsn/dds/conversions.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/dds/topics.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;
using SampleInfo = eprosima::fastdds::dds::SampleInfo;

/// Runs make-pki.sh into `dir` with the given identities; returns its exit status.
int make_pki(const std::filesystem::path& dir, const std::string& identities) {
  const std::string command = std::string(BSN_DEPLOY_DIR) + "/security/make-pki.sh '" + dir.string() + "' " +
                              identities + " > '" + dir.string() + ".log' 2>&1";
  return std::system(command.c_str());
}

/// A participant of this test process with the identity in `security_dir` ("" for none).
std::unique_ptr<dds::Participant> participant_as(int domain, const std::filesystem::path& security_dir) {
  if (security_dir.empty()) {
    unsetenv("BSN_SECURITY_DIR");
    return std::make_unique<dds::Participant>(dds::Participant::Options{domain, "security test"});
  }
  setenv("BSN_SECURITY_DIR", security_dir.c_str(), 1);
  auto p = std::make_unique<dds::Participant>(dds::Participant::Options{domain, "security test"});
  unsetenv("BSN_SECURITY_DIR");
  return p;
}

/// Counts the joint-angle samples a participant receives.
struct JointCounter {
  std::atomic<int> samples{0};
  std::unique_ptr<dds::Reader<bsn::JointAngles>> reader;
  explicit JointCounter(dds::Participant& p)
      : reader(
            p.make_reader(dds::kJointAnglesTopic, [this](const bsn::JointAngles&, const SampleInfo&) { ++samples; })) {}
};

/// Captures the UDP datagrams on the loopback interface whose destination port belongs to one DDS domain
/// (the RTPS port formula: 7400 + 250 d ... + 249) and looks for byte strings in them. Needs CAP_NET_RAW.
class LoopbackCapture {
 public:
  explicit LoopbackCapture(int domain) : first_port_(7400 + 250 * domain) {
    fd_ = ::socket(AF_PACKET, SOCK_DGRAM, htons(ETH_P_IP));
    if (fd_ < 0) return;
    sockaddr_ll addr{};
    addr.sll_family = AF_PACKET;
    addr.sll_protocol = htons(ETH_P_IP);
    addr.sll_ifindex = static_cast<int>(if_nametoindex("lo"));
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
      ::close(fd_);
      fd_ = -1;
      return;
    }
    thread_ = std::thread([this] { run(); });
  }
  ~LoopbackCapture() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
    if (fd_ >= 0) ::close(fd_);
  }
  bool available() const { return fd_ >= 0; }
  std::size_t datagrams() {
    std::lock_guard lock(mutex_);
    return datagrams_;
  }
  bool saw(std::string_view needle) {
    std::lock_guard lock(mutex_);
    return payloads_.find(needle) != std::string::npos;
  }

 private:
  void run() {
    std::string buffer(65536, '\0');
    while (!stop_) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 50) <= 0) continue;
      const ssize_t n = ::recv(fd_, buffer.data(), buffer.size(), 0);
      if (n < static_cast<ssize_t>(sizeof(iphdr))) continue;
      const auto* ip = reinterpret_cast<const iphdr*>(buffer.data());
      const std::size_t ip_len = ip->ihl * 4u;
      if (ip->protocol != IPPROTO_UDP || static_cast<std::size_t>(n) < ip_len + sizeof(udphdr)) continue;
      const auto* udp = reinterpret_cast<const udphdr*>(buffer.data() + ip_len);
      const int port = ntohs(udp->dest);
      if (port < first_port_ || port >= first_port_ + 250) continue;
      std::lock_guard lock(mutex_);
      ++datagrams_;
      if (payloads_.size() < (64u << 20)) payloads_.append(buffer.data() + ip_len + sizeof(udphdr), n - ip_len - 8);
    }
  }
  int first_port_;
  int fd_ = -1;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  std::mutex mutex_;
  std::size_t datagrams_ = 0;
  std::string payloads_;
};

class Security : public ProcessTest {
 protected:
  void SetUp() override {
    ProcessTest::SetUp();
    pki_ = dir() / "pki";
    ASSERT_EQ(make_pki(pki_, "sensor:sensor:pelvis,thigh_l fusion:fusion viewer:viewer"), 0)
        << read_file(pki_.string() + ".log");
  }
  /// Starts fusion and two sensor nodes (pelvis, thigh_l: joint hip_l), secured with their roles if `secured`.
  void start_body(int domain, bool secured) {
    auto with = [&](std::vector<std::string> args, const char* identity) {
      args.insert(args.end(), {"--domain", std::to_string(domain)});
      if (secured) args.insert(args.end(), {"--security", (pki_ / identity).string()});
      return args;
    };
    spawn("fusion", with({"fusion", "--status-period", "0.5"}, "fusion"));
    spawn("pelvis", with({"sim", "--node", "pelvis"}, "sensor"));
    spawn("thigh_l", with({"sim", "--node", "thigh_l"}, "sensor"));
  }
  /// The body of the two tests below: the processes in `domain` (fusion; the calibration service in
  /// `calibration_domain`), bsn view and bsn record in `lonely`.
  void SecuredProcessesWithoutTheirPeer(int domain, int lonely, int calibration_domain);
  std::filesystem::path pki_;
};

// Every payload is encrypted whatever --submessages says; it chooses only what also protects the submessage around
// the payload (the default, none, halves the fusion service's crypto work per sample; README: DDS-Security).
TEST_F(Security, MakePkiEncryptsEveryPayloadAndChoosesTheSubmessageProtection) {
  const std::string governance = read_file((pki_ / "ca" / "governance.xml").string());
  EXPECT_NE(governance.find("<data_protection_kind>ENCRYPT</data_protection_kind>"), std::string::npos);
  EXPECT_NE(governance.find("<metadata_protection_kind>NONE</metadata_protection_kind>"), std::string::npos);
  EXPECT_NE(governance.find("<discovery_protection_kind>ENCRYPT</discovery_protection_kind>"), std::string::npos);
  const std::string script = std::string(BSN_DEPLOY_DIR) + "/security/make-pki.sh";
  for (const std::string kind : {"sign", "encrypt"}) {
    const std::filesystem::path other = dir() / ("pki-" + kind);
    ASSERT_EQ(std::system(
                  (script + " --submessages " + kind + " '" + other.string() + "' viewer:viewer > /dev/null").c_str()),
              0);
    std::string upper = kind;
    for (char& c : upper) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    EXPECT_NE(read_file((other / "ca" / "governance.xml").string())
                  .find("<metadata_protection_kind>" + upper + "</metadata_protection_kind>"),
              std::string::npos)
        << kind;
  }
  const int bad = std::system((script + " --submessages secret '" + (dir() / "pki-bad").string() + "' > '" +
                               (dir() / "pki-bad.log").string() + "' 2>&1")
                                  .c_str());
  EXPECT_EQ(WEXITSTATUS(bad), 2);
  EXPECT_NE(read_file((dir() / "pki-bad.log").string()).find("--submessages takes encrypt, sign or none"),
            std::string::npos);
}

TEST_F(Security, AuthorisedRolesFlowAndOutsidersGetNothing) {
  const int domain = test_domain(30);
  // Another authority's identity with the same name and role as the real viewer.
  const std::filesystem::path other_pki = dir() / "other-pki";
  ASSERT_EQ(make_pki(other_pki, "viewer:viewer"), 0) << read_file(other_pki.string() + ".log");

  auto viewer = participant_as(domain, pki_ / "viewer");
  auto no_credentials = participant_as(domain, "");
  auto other_authority = participant_as(domain, other_pki / "viewer");
  JointCounter viewer_joints(*viewer), open_joints(*no_credentials), foreign_joints(*other_authority);
  // A rogue sensor without credentials publishing for a node of the body.
  auto rogue_raw = no_credentials->make_writer(dds::kRawTopic);

  std::mutex mutex;
  std::uint64_t thigh_accepted = 0, thigh_received = 0;
  auto status = viewer->make_reader(dds::kStatusTopic, [&](const bsn::Status& s, const SampleInfo&) {
    std::lock_guard lock(mutex);
    for (const auto& n : s.nodes())
      if (n.node_id() == "thigh_l") thigh_accepted = n.accepted(), thigh_received = n.received();
  });

  start_body(domain, true);
  // Authentication handshakes between six participants: about 1 s on an idle machine, several on a loaded one.
  ASSERT_TRUE(wait_until([&] { return viewer_joints.samples > 200; }, 45s))
      << "the authorised viewer received " << viewer_joints.samples << " joint-angle samples";

  // The rogue writes thigh_l samples with sequence numbers and timestamps far from the real node's.
  bsn::RawSample rogue;
  rogue.node_id("thigh_l");
  rogue.acc({0, 0, 9.81});
  rogue.mag({0, 20, -40});
  rogue.channels(bsn::CHANNEL_ACC | bsn::CHANNEL_GYR | bsn::CHANNEL_MAG);
  for (int i = 0; i < 200; ++i) {
    rogue.seq(1'000'000 + i);
    rogue.timestamp_ns(1'000'000'000ull * 1000 + i * 10'000'000ull);
    rogue_raw->write(rogue);
    std::this_thread::sleep_for(5ms);
  }
  std::this_thread::sleep_for(1500ms);  // two status periods after the last rogue sample

  EXPECT_EQ(open_joints.samples, 0) << "a participant without credentials read joint angles";
  EXPECT_EQ(foreign_joints.samples, 0) << "a participant with another authority's certificate read joint angles";
  EXPECT_EQ(rogue_raw->matched(), 0) << "the fusion service matched a writer without credentials";
  std::lock_guard lock(mutex);
  EXPECT_GT(thigh_accepted, 0u);
  // Everything fusion received for thigh_l came from the real node, and it accepted all of it.
  EXPECT_EQ(thigh_received, thigh_accepted) << "fusion received samples it did not accept (the rogue's?)";
}

TEST_F(Security, PermissionsLimitEachRoleToItsTopics) {
  const int domain = test_domain(31);
  // A viewer identity cannot publish raw samples: `bsn sim` refuses to start, naming the topic.
  spawn("sim-as-viewer",
        {"sim", "--node", "pelvis", "--domain", std::to_string(domain), "--security", (pki_ / "viewer").string()});
  const auto status = child("sim-as-viewer").wait_for(20s);
  ASSERT_TRUE(status.has_value()) << "bsn sim with viewer credentials kept running";
  EXPECT_FALSE(exited_cleanly(status));
  EXPECT_NE(read_file(log_path("sim-as-viewer")).find("bsn/raw"), std::string::npos)
      << read_file(log_path("sim-as-viewer"));

  // A sensor identity can write raw samples of its nodes but not orientations.
  auto sensor = participant_as(domain, pki_ / "sensor");
  EXPECT_NO_THROW(sensor->make_writer(dds::kRawTopic, std::nullopt, "pelvis"));
  EXPECT_THROW(sensor->make_writer(dds::kOrientationTopic), std::runtime_error);
  // And a viewer can read joint angles but not write them.
  auto viewer = participant_as(domain, pki_ / "viewer");
  EXPECT_NO_THROW(viewer->make_reader(dds::kJointAnglesTopic, [](const bsn::JointAngles&, const SampleInfo&) {}));
  EXPECT_THROW(viewer->make_writer(dds::kJointAnglesTopic), std::runtime_error);
}

/// The counts fusion reports for one node on bsn/status.
struct NodeCounts {
  std::uint64_t received = 0, accepted = 0, not_permitted = 0, conflicting = 0, handovers = 0;
  bool stale = false;
};

// A sensor identity may write only its own nodes: the middleware refuses it a writer in another node's partition,
// and fusion refuses, and counts, samples of a node from a writer outside that node's partition, also once the
// node's own sensor has gone stale (the takeover after a link drop that per-role permissions let through).
TEST_F(Security, ASensorIdentityWritesOnlyItsOwnNodes) {
  const int domain = test_domain(82);
  ASSERT_EQ(make_pki(pki_, "knee:sensor:shank_r"), 0) << read_file(pki_.string() + ".log");
  // bsn sim with an identity for shank_r refuses to publish thigh_l, naming the topic and the node.
  spawn("sim-other-node",
        {"sim", "--node", "thigh_l", "--domain", std::to_string(domain), "--security", (pki_ / "knee").string()});
  const auto refused = child("sim-other-node").wait_for(20s);
  ASSERT_TRUE(refused.has_value()) << "bsn sim with another node's identity kept running";
  EXPECT_FALSE(exited_cleanly(refused));
  const std::string refusal = read_file(log_path("sim-other-node"));
  EXPECT_NE(refusal.find("bsn/raw for node thigh_l"), std::string::npos) << refusal;

  auto viewer = participant_as(domain, pki_ / "viewer");
  std::mutex mutex;
  NodeCounts thigh;
  auto status = viewer->make_reader(dds::kStatusTopic, [&](const bsn::Status& st, const SampleInfo&) {
    std::lock_guard lock(mutex);
    for (const auto& n : st.nodes()) {
      if (n.node_id() != "thigh_l") continue;
      thigh.received = n.received();
      thigh.accepted = n.accepted();
      thigh.stale = n.stale();
      thigh.handovers = n.source_handovers();
      for (const auto& r : n.rejected()) {
        if (r.reason() == "not_permitted") thigh.not_permitted = r.count();
        if (r.reason() == "conflicting_source") thigh.conflicting = r.count();
      }
    }
  });
  auto counts = [&] {
    std::lock_guard lock(mutex);
    return thigh;
  };
  start_body(domain, true);
  ASSERT_TRUE(wait_until([&] { return counts().accepted > 100; }, 45s)) << "thigh_l accepted " << counts().accepted;

  // The other identity writes thigh_l samples in its own node's partition (its permissions allow that writer).
  auto rogue = participant_as(domain, pki_ / "knee");
  auto rogue_raw = rogue->make_writer(dds::kRawTopic, std::nullopt, "shank_r");
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
  ASSERT_TRUE(wait_until([&] { return rogue_raw->matched() > 0; }, 30s)) << "the rogue's writer matched no reader";
  write_rogue(100);
  ASSERT_TRUE(wait_until([&] { return counts().not_permitted > 0; }, 10s)) << "no sample rejected as not_permitted";

  // The real thigh_l goes silent (its link drops); the rogue keeps writing past the stale timeout.
  stop("thigh_l");
  ASSERT_TRUE(wait_until([&] { return counts().stale; }, 5s)) << "thigh_l not reported stale";
  const NodeCounts before = counts();
  write_rogue(150);                     // 1.5 s, five stale timeouts
  std::this_thread::sleep_for(1200ms);  // two status periods
  const NodeCounts after = counts();
  EXPECT_EQ(after.accepted, before.accepted) << "fusion accepted the rogue's thigh_l samples";
  EXPECT_EQ(after.handovers, 0u) << "the rogue took thigh_l over";
  EXPECT_TRUE(after.stale);
  EXPECT_GE(after.not_permitted - before.not_permitted, 100u) << "the rogue's samples are not counted as not_permitted";
  EXPECT_NE(read_file(log_path("fusion")).find("rejected as not_permitted"), std::string::npos)
      << tail(log_path("fusion"));
}

// Discovery's participant announcements (SPDP) are not encrypted even with DDS-Security: a secured participant's
// name says nothing about the process or its node (open, `bsn sim thigh_l`).
TEST_F(Security, SecuredParticipantNamesNameNoProcessOrNode) {
  const int domain = test_domain(83);
  LoopbackCapture capture(domain);
  if (!capture.available()) GTEST_SKIP() << "a packet socket needs CAP_NET_RAW (run as root): " << strerror(errno);
  auto viewer = participant_as(domain, pki_ / "viewer");
  JointCounter joints(*viewer);
  start_body(domain, true);
  ASSERT_TRUE(wait_until([&] { return joints.samples > 200; }, 45s)) << joints.samples << " joint-angle samples";
  EXPECT_FALSE(capture.saw("bsn sim")) << "a participant name tells a sensor process and its node";
  EXPECT_FALSE(capture.saw("bsn fusion")) << "a participant name tells the fusion process";
  EXPECT_FALSE(capture.saw("security test")) << "this test's own participant name travels";
}

// Fast DDS's own log lines (here: access control refusing a reader the identity may not have) go to stderr with
// bsn's log, not into the stdout of `bsn echo --format csv`, which scripts parse (Fast DDS's default: stdout).
TEST_F(Security, MiddlewareErrorsStayOutOfEchoOutput) {
  const std::string out = (dir() / "echo.csv").string(), err = (dir() / "echo.err").string();
  spawn_command("echo", {"/bin/sh", "-c",
                         "exec '" + bsn_executable() + "' echo bsn/raw --format csv --count 5 --timeout 10 --domain " +
                             std::to_string(test_domain(84)) + " --security '" + (pki_ / "viewer").string() + "' > '" +
                             out + "' 2> '" + err + "'"});
  const auto status = child("echo").wait_for(30s);
  ASSERT_TRUE(status.has_value()) << "bsn echo kept running";
  EXPECT_FALSE(exited_cleanly(status)) << "a viewer identity read bsn/raw";
  const std::string csv = read_file(out), log = read_file(err);
  EXPECT_EQ(csv, "") << "bsn echo's data stream holds:\n" << csv.substr(0, 1000);
  EXPECT_NE(log.find("error: Fast DDS [SECURITY] bsn/raw topic not found in allow rule"), std::string::npos)
      << "the middleware's refusal is not in stderr:\n"
      << log;
  EXPECT_EQ(log.find('\x1b'), std::string::npos) << "terminal escapes in the log";
}

// Seven secured sensor nodes and fusion start at once on a loaded machine (two busy processes): every node joins.
// Fast DDS 2.9.1 sometimes never completes the handshake of a pair of participants (3 of 13 secured starts once left
// a node at 0 received for 150 s, silently); a secured node that no reader matched in 10 s says so and makes a new
// participant (dds::Participant::watch_peers). The test's own viewer does the same for itself.
TEST_F(Security, SecuredNodesAllJoinUnderLoad) {
  const int domain = test_domain(86);
  const std::vector<std::string> nodes{"pelvis", "thigh_l", "shank_l", "foot_l", "thigh_r", "shank_r", "foot_r"};
  ASSERT_EQ(make_pki(pki_, "hub:sensor:pelvis,thigh_l,shank_l,foot_l,thigh_r,shank_r,foot_r"), 0)
      << read_file(pki_.string() + ".log");
  for (int i = 0; i < 2; ++i) spawn_command("load-" + std::to_string(i), {"/bin/sh", "-c", "while :; do :; done"});
  std::mutex mutex;
  std::map<std::string, std::uint64_t> accepted;
  std::unique_ptr<dds::Participant> viewer = participant_as(domain, pki_ / "viewer");
  std::unique_ptr<dds::Reader<bsn::Status>> status =
      viewer->make_reader(dds::kStatusTopic, [&](const bsn::Status& st, const SampleInfo&) {
        std::lock_guard lock(mutex);
        for (const auto& n : st.nodes()) accepted[n.node_id()] = n.accepted();
      });
  viewer->expect_peer(*status, "writer of bsn/status (fusion)");
  auto joined = [&] {
    viewer->watch_peers();  // the viewer's own handshake, not the nodes'
    std::lock_guard lock(mutex);
    return std::count_if(nodes.begin(), nodes.end(), [&](const std::string& n) { return accepted[n] > 0; });
  };
  const std::string d = std::to_string(domain);
  // A node that no reader matches says so loudly after 10 s and starts over on a new participant, which then joins.
  spawn("pelvis", {"sim", "--node", "pelvis", "--domain", d, "--security", (pki_ / "hub").string()});
  EXPECT_TRUE(wait_until(
      [&] {
        return read_file(log_path("pelvis"))
                   .find("error: no reader of bsn/raw for node 'pelvis' (fusion) matched in 10 s") != std::string::npos;
      },
      20s))
      << tail(log_path("pelvis"));
  spawn("fusion", {"fusion", "--status-period", "0.5", "--domain", d, "--security", (pki_ / "fusion").string()});
  for (const std::string& node : nodes)
    if (node != "pelvis") spawn(node, {"sim", "--node", node, "--domain", d, "--security", (pki_ / "hub").string()});
  const auto start = Clock::now();
  const bool all = wait_until([&] { return joined() == static_cast<long>(nodes.size()); }, 60s);
  int rejoins = 0;  // besides pelvis's
  std::vector<std::string> processes(nodes.begin(), nodes.end());
  processes.push_back("fusion");
  for (const std::string& process : processes) {
    const std::string log = read_file(log_path(process));
    for (std::size_t at = log.find("error: no "); at != std::string::npos; at = log.find("error: no ", at + 1)) {
      if (process != "pelvis") ++rejoins;
      // Which handshakes were unfinished when the process made its participant again.
      std::printf("[ rejoin   ] %s: %s\n", process.c_str(), log.substr(at, log.find('\n', at) - at).c_str());
    }
    // The GUID prefix each process had before it made its participant again, to find it in the lines below.
    for (std::size_t at = log.find("the new DDS participant is "); at != std::string::npos;
         at = log.find("the new DDS participant is ", at + 1))
      std::printf("[ remade   ] %s: %s\n", process.c_str(), log.substr(at, log.find('\n', at) - at).c_str());
    // Two participants whose security endpoints Fast DDS matched at once (builtin_match_guard.cpp).
    for (std::size_t at = log.find("Fast DDS matched the "); at != std::string::npos;
         at = log.find("Fast DDS matched the ", at + 1))
      std::printf("[ overlap  ] %s: %s\n", process.c_str(), log.substr(at, log.find('\n', at) - at).c_str());
  }
  std::printf("[ measure  ] %ld of %zu nodes joined in %.1f s; %d new participants besides pelvis's\n", joined(),
              nodes.size(), std::chrono::duration<double>(Clock::now() - start).count(), rejoins);
  EXPECT_TRUE(all) << joined() << " of " << nodes.size() << " secured nodes joined within 60 s";
  status.reset();
}

// Every secured long-running process whose expected peer stays unmatched says so as an error within the bound
// (10 s), counts it (bsn/status participant_rejoins, for the processes that publish a status) and makes its
// participant again, which then works: fusion with no sensor node, the calibration service with none (a domain of
// its own; the test after this one puts it beside the fusion), bsn view and bsn record with no fusion (another
// domain); then two nodes start and the re-made fusion fuses them. Before, only bsn sim did so, and a fusion whose
// handshakes never completed was silent.
TEST_F(Security, SecuredProcessesWithoutTheirPeerSaySoCountItAndMakeTheirParticipantAgain) {
  SecuredProcessesWithoutTheirPeer(test_domain(91), test_domain(92), test_domain(93));
}

// The same with the calibration service in the fusion's domain, so that each node's expectation ("a reader of
// bsn/raw") is met by the calibration service's reader whether or not its handshake with the fusion completes: here
// only the fix of the cause keeps a node from being lost silently. Before builtin_match_guard.cpp (Fast DDS 2.9.1
// matches two discovered participants' handshake endpoints at once through one scratch object; fixed upstream in
// 2.9.2), one of the two nodes never reached the re-made fusion in 2 of 2 CI runs, and no process said so.
TEST_F(Security, TwoNodesBesideTheCalibrationServiceBothReachTheRemadeFusion) {
  SecuredProcessesWithoutTheirPeer(test_domain(97), test_domain(98), test_domain(97));
}

void Security::SecuredProcessesWithoutTheirPeer(int domain, int lonely, int calibration_domain) {
  ASSERT_EQ(make_pki(pki_,
                     "sensor:sensor:pelvis,thigh_l fusion:fusion viewer:viewer calibration:calibration "
                     "recorder:recorder"),
            0)
      << read_file(pki_.string() + ".log");
  const std::string d = std::to_string(domain), l = std::to_string(lonely);
  auto as = [&](const char* identity) { return (pki_ / identity).string(); };
  spawn("fusion", {"fusion", "--status-period", "0.5", "--domain", d, "--security", as("fusion")});
  spawn("calibration", {"calibration", "--store", (dir() / "store").string(), "--domain",
                        std::to_string(calibration_domain), "--security", as("calibration")});
  spawn("view", {"view", "--port", "0", "--domain", l, "--security", as("viewer")});
  spawn("record", {"record", "--out", (dir() / "lonely.h5").string(), "--duration", "60", "--domain", l, "--security",
                   as("recorder")});
  const std::map<std::string, std::string> expected{
      {"fusion", "error: no writer of bsn/raw (a sensor node) matched in 10 s"},
      {"calibration", "error: no writer of bsn/raw (a sensor node) matched in 10 s"},
      {"view", "error: no writer of bsn/orientation or bsn/status (fusion) matched in 10 s"},
      {"record", "error: no writer of a recorded topic matched in 10 s"}};
  for (const auto& [process, line] : expected) {
    EXPECT_TRUE(wait_until([&] { return read_file(log_path(process)).find(line) != std::string::npos; }, 25s))
        << process << " did not say '" << line << "':\n"
        << tail(log_path(process));
    EXPECT_NE(read_file(log_path(process)).find("Making a new participant (1; counted on bsn/status"),
              std::string::npos)
        << tail(log_path(process));
  }
  // The re-made fusion: its status counts the rejoin, and it fuses nodes that start now.
  std::mutex mutex;
  std::uint64_t rejoins = 0;
  std::map<std::string, std::uint64_t> accepted;
  std::unique_ptr<dds::Participant> viewer = participant_as(domain, pki_ / "viewer");
  std::unique_ptr<dds::Reader<bsn::Status>> status =
      viewer->make_reader(dds::kStatusTopic, [&](const bsn::Status& st, const SampleInfo&) {
        std::lock_guard lock(mutex);
        if (st.process_id().rfind("fusion", 0) != 0) return;
        rejoins = st.participant_rejoins();
        for (const auto& n : st.nodes()) accepted[n.node_id()] = n.accepted();
      });
  viewer->expect_peer(*status, "writer of bsn/status (fusion)");
  spawn("pelvis", {"sim", "--node", "pelvis", "--domain", d, "--security", as("sensor")});
  spawn("thigh_l", {"sim", "--node", "thigh_l", "--domain", d, "--security", as("sensor")});
  // Bound: the handshakes with the re-made participant, and, should one of them stick (the Fast DDS fault the
  // re-creation exists for), the next re-creation 20 s later (the bound doubles) and its handshakes.
  const bool fused = wait_until(
      [&] {
        viewer->watch_peers();
        std::lock_guard lock(mutex);
        return rejoins >= 1 && accepted["pelvis"] > 100 && accepted["thigh_l"] > 100;
      },
      60s);
  std::lock_guard lock(mutex);
  EXPECT_TRUE(fused) << "fusion's status: participant_rejoins " << rejoins << ", pelvis accepted " << accepted["pelvis"]
                     << ", thigh_l accepted " << accepted["thigh_l"] << "\n"
                     << tail(log_path("fusion")) << "\n"
                     << tail(log_path("pelvis")) << "\n"
                     << tail(log_path("thigh_l"));
}

// The capture sees the joint's name and the topic's name in the open (so it would catch a leak) ...
TEST_F(Security, CaptureSeesJointAnglesOnAnOpenNetwork) {
  const int domain = test_domain(32);
  LoopbackCapture capture(domain);
  if (!capture.available()) GTEST_SKIP() << "a packet socket needs CAP_NET_RAW (run as root): " << strerror(errno);
  auto viewer = participant_as(domain, "");
  JointCounter joints(*viewer);
  start_body(domain, false);
  ASSERT_TRUE(wait_until([&] { return joints.samples > 200; }, 45s)) << joints.samples << " joint-angle samples";
  EXPECT_GT(capture.datagrams(), 200u);
  EXPECT_TRUE(capture.saw("hip_l")) << "the joint's name in no datagram";
  EXPECT_TRUE(capture.saw("bsn/joint_angles")) << "the topic's name in no datagram";
}

// ... and neither once the body is secured.
TEST_F(Security, NoPlaintextJointAnglesOnASecuredNetwork) {
  const int domain = test_domain(33);
  LoopbackCapture capture(domain);
  if (!capture.available()) GTEST_SKIP() << "a packet socket needs CAP_NET_RAW (run as root): " << strerror(errno);
  auto viewer = participant_as(domain, pki_ / "viewer");
  JointCounter joints(*viewer);
  start_body(domain, true);
  ASSERT_TRUE(wait_until([&] { return joints.samples > 200; }, 45s)) << joints.samples << " joint-angle samples";
  EXPECT_GT(capture.datagrams(), 200u);
  EXPECT_FALSE(capture.saw("hip_l")) << "a datagram holds the joint's name (a joint-angle key) in plaintext";
  // Topic names do travel in plaintext, by design: inside the signed permissions document that each participant
  // sends in the authentication handshake (DDS-Security 9.3.2.3); the data and discovery are encrypted.
}

}  // namespace
}  // namespace bsn::integration
