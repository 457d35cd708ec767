// Hostile input over DDS and from the process table: a foreign writer's sample that fastddsgen's code cannot hold,
// ids carrying terminal escapes, more instances than a reader holds, two fusion services on one domain, and a
// demo killed with SIGKILL. Every bsn process involved must keep running (or clean up) and say what happened.
#include <gtest/gtest.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string>
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

class HostileInput : public ProcessTest {};

/// The newest bsn/status sample of the process whose id starts with `prefix`, as seen by a reader in the test.
struct StatusLog {
  std::mutex mutex;
  std::vector<bsn::Status> all;
  std::optional<bsn::Status> latest(const std::string& prefix = "") {
    std::lock_guard lock(mutex);
    for (auto it = all.rbegin(); it != all.rend(); ++it)
      if (it->process_id().starts_with(prefix)) return *it;
    return std::nullopt;
  }
};

TEST_F(HostileInput, ForeignWriterWithANodeIdTooLongForTheGeneratedKeyCode) {
  // Cyclone DDS sends node ids of 300 characters: the IDL's `string` is unbounded, fastddsgen's key code holds 255.
  // bsn fusion and bsn echo aborted on the first such sample; now both keep running and the
  // fusion reports the samples as an unknown node.
  const int kDomain = test_domain(49);
  const std::string domain = std::to_string(kDomain);
  write_file(dir() / "body.yaml", "segments:\n  - name: cy\n    node: cy\n");
  spawn("fusion", {"fusion", "--domain", domain, "--body", (dir() / "body.yaml").string()});
  spawn("echo", {"echo", "bsn/raw", "--domain", domain});
  StatusLog statuses;
  dds::Participant participant({kDomain, "bsn hostile test"});
  auto status_reader = participant.make_reader(dds::kStatusTopic, [&](const bsn::Status& s, const SampleInfo&) {
    std::lock_guard lock(statuses.mutex);
    statuses.all.push_back(s);
  });

  const std::string log = (dir() / "peer.log").string();
  dds::ChildProcess peer({BSN_CYCLONE_PEER, domain, "cy", "200", "20", "300"}, log);
  const auto st = peer.wait_for(30s);
  EXPECT_TRUE(exited_cleanly(st)) << describe_status(st) << "\n" << read_file(log);
  int sent = 0, chars = 0;
  const std::string out = read_file(log);
  const std::size_t at = out.find("cyclone peer: ", out.find('\n'));
  ASSERT_NE(at, std::string::npos) << out;
  ASSERT_EQ(std::sscanf(out.c_str() + at, "cyclone peer: %d samples with a %d-character node id sent", &sent, &chars),
            2)
      << out;
  EXPECT_GE(sent, 10) << out;

  EXPECT_TRUE(child("fusion").running()) << "bsn fusion died on a 300-character node id";
  EXPECT_TRUE(child("echo").running()) << "bsn echo bsn/raw died on a 300-character node id";
  // The fusion saw them as samples of a node on no segment, listed under a shortened id.
  ASSERT_TRUE(wait_until(
      [&] {
        const auto s = statuses.latest("fusion@");
        return s && s->unknown_node_samples() > 0;
      },
      5s))
      << "no bsn/status counting the long-id samples as unknown";
  const auto s = statuses.latest("fusion@");
  ASSERT_FALSE(s->unknown_nodes().empty());
  EXPECT_EQ(s->unknown_nodes().front(), std::string(64, 'x'));
  EXPECT_EQ(s->undecodable_samples(), 0u) << "the samples are legal CDR: decoded, not dropped";
  // bsn echo prints them, cut short.
  EXPECT_NE(read_file(log_path("echo")).find("raw " + std::string(64, 'x') + "...(236 more)"), std::string::npos);
  EXPECT_TRUE(exited_cleanly(stop("echo")));
  EXPECT_TRUE(exited_cleanly(stop("fusion")));
}

TEST_F(HostileInput, IdsFromTheNetworkArePrintedEscaped) {
  // A node id that clears the screen and forges a log line reaches the log and bsn echo as
  // visible escapes.
  const int kDomain = test_domain(53);
  const std::string domain = std::to_string(kDomain);
  write_file(dir() / "body.yaml", "segments:\n  - name: solo\n    node: b1\n");
  spawn("fusion", {"fusion", "--domain", domain, "--body", (dir() / "body.yaml").string()});
  spawn("echo", {"echo", "bsn/raw", "--domain", domain});
  dds::Participant participant({kDomain, "bsn hostile test"});
  auto writer = participant.make_writer(dds::kRawTopic);
  const std::string forged = "\x1b[2J\x1b[H\rfusion: node 'pelvis' is stale\n";
  bsn::RawSample raw;
  raw.node_id(forged);
  raw.channels(bsn::CHANNEL_ACC);
  raw.acc({0.0, 0.0, 9.81});
  const bool logged = wait_until(
      [&] {
        raw.seq(raw.seq() + 1);
        raw.timestamp_ns(dds::monotonic_ns());
        writer->write(raw);
        return read_file(log_path("fusion")).find("on no segment") != std::string::npos &&
               read_file(log_path("echo")).find("raw ") != std::string::npos;
      },
      20s);
  ASSERT_TRUE(logged) << read_file(log_path("fusion")) << read_file(log_path("echo"));
  EXPECT_TRUE(exited_cleanly(stop("echo")));
  EXPECT_TRUE(exited_cleanly(stop("fusion")));
  for (const char* name : {"fusion", "echo"}) {
    const std::string text = read_file(log_path(name));
    EXPECT_EQ(text.find('\x1b'), std::string::npos) << name << " printed a raw ESC";
    EXPECT_EQ(text.find('\r'), std::string::npos) << name << " printed a raw carriage return";
    EXPECT_NE(text.find("\\x1b[2J\\x1b[H\\x0dfusion: node 'pelvis' is stale\\x0a"), std::string::npos) << name << ":\n"
                                                                                                       << text;
  }
}

TEST_F(HostileInput, SamplesBeyondTheInstanceLimitAreCounted) {
  // 5009 distinct unknown node ids, one sample each, from a writer whose own limit is high enough (a bsn writer
  // stops at 4096 instances itself), and nothing more: the writer never gets a sample through. The fusion's reader
  // holds 4096 instances and Fast DDS 2.9.1 drops a sample beyond them without a word, so only a count taken before
  // its history sees them all. Every sample is an unknown-node sample, and the flood takes no instance from the
  // body's nodes.
  const int kDomain = test_domain(50);
  constexpr int kIds = 5009;
  spawn("fusion", {"fusion", "--domain", std::to_string(kDomain)});
  StatusLog statuses;
  dds::Participant participant({kDomain, "bsn hostile test"});
  auto status_reader = participant.make_reader(dds::kStatusTopic, [&](const bsn::Status& s, const SampleInfo&) {
    std::lock_guard lock(statuses.mutex);
    statuses.all.push_back(s);
  });
  namespace fdds = eprosima::fastdds::dds;
  fdds::DomainParticipant* native = participant.native();
  fdds::TypeSupport type(new dds::Guarded<bsn::RawSamplePubSubType>());
  ASSERT_EQ(type.register_type(native), ReturnCode_t::RETCODE_OK);
  fdds::Topic* topic = native->create_topic(dds::kRawTopic.name, type.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
  ASSERT_NE(topic, nullptr);
  fdds::Publisher* publisher = native->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
  fdds::DataWriterQos qos = dds::writer_qos(dds::TopicQos::kSensorData, publisher->get_default_datawriter_qos());
  qos.resource_limits().max_instances = 2 * kIds;
  qos.resource_limits().max_samples = 2 * kIds * qos.resource_limits().max_samples_per_instance;
  fdds::DataWriter* writer = publisher->create_datawriter(topic, qos);
  ASSERT_NE(writer, nullptr);
  ASSERT_TRUE(wait_until(
      [&] {
        fdds::PublicationMatchedStatus m;
        writer->get_publication_matched_status(m);
        return m.current_count > 0 && status_reader->matched() > 0;
      },
      20s));
  std::this_thread::sleep_for(500ms);  // the fusion's reader matches the writer a moment after the writer does

  bsn::RawSample raw;
  raw.channels(bsn::CHANNEL_ACC);
  raw.acc({0.0, 0.0, 9.81});
  int written = 0;
  for (int i = 0; i < kIds; ++i) {
    raw.node_id("intruder_" + std::to_string(i));
    raw.timestamp_ns(dds::monotonic_ns());
    if (writer->write(&raw)) ++written;
    if (i % 100 == 99) std::this_thread::sleep_for(5ms);  // paced like many nodes, not one burst
  }
  ASSERT_EQ(written, kIds);
  const bool all = wait_until(
      [&] {
        const auto s = statuses.latest("fusion@");
        return s && s->unknown_node_samples() >= static_cast<std::uint64_t>(kIds);
      },
      10s);
  const auto s = statuses.latest("fusion@");
  ASSERT_TRUE(s.has_value());
  EXPECT_TRUE(all) << "of " << kIds << " samples: " << s->unknown_node_samples() << " unknown-node samples, "
                   << s->dds_lost_samples() << " lost in DDS";
  EXPECT_EQ(s->unknown_node_samples(), static_cast<std::uint64_t>(kIds)) << "a sample counted twice";

  // A node of the body that starts after the flood still gets its instance.
  spawn("pelvis", {"sim", "--node", "pelvis", "--domain", std::to_string(kDomain)});
  EXPECT_TRUE(wait_until(
      [&] {
        const auto st = statuses.latest("fusion@");
        if (!st) return false;
        for (const auto& n : st->nodes())
          if (n.node_id() == "pelvis" && n.accepted() > 50) return true;
        return false;
      },
      20s))
      << "fusion accepted no pelvis sample after the flood";
  stop("pelvis");
  EXPECT_TRUE(child("fusion").running());
  publisher->delete_datawriter(writer);
  native->delete_publisher(publisher);
  native->delete_topic(topic);
  EXPECT_TRUE(exited_cleanly(stop("fusion")));
}

TEST_F(HostileInput, TwoFusionServicesOnOneDomainNoticeEachOther) {
  // Both would publish every orientation and joint angle under the same keys: each warns and
  // lists the other's process id on its own bsn/status.
  const int kDomain = test_domain(51);
  const std::string domain = std::to_string(kDomain);
  auto& a = spawn("fusion_a", {"fusion", "--domain", domain});
  auto& b = spawn("fusion_b", {"fusion", "--domain", domain});
  StatusLog statuses;
  dds::Participant participant({kDomain, "bsn hostile test"});
  auto status_reader = participant.make_reader(dds::kStatusTopic, [&](const bsn::Status& s, const SampleInfo&) {
    std::lock_guard lock(statuses.mutex);
    statuses.all.push_back(s);
  });
  // The newest status of `self` lists `other` (process ids are "fusion@<host>:<pid>").
  auto listed = [&](pid_t self, pid_t other) {
    std::lock_guard lock(statuses.mutex);
    for (auto it = statuses.all.rbegin(); it != statuses.all.rend(); ++it) {
      if (!it->process_id().ends_with(":" + std::to_string(self))) continue;
      for (const auto& o : it->other_fusion_processes())
        if (o.ends_with(":" + std::to_string(other))) return true;
      return false;
    }
    return false;
  };
  EXPECT_TRUE(wait_until([&] { return listed(a.pid(), b.pid()) && listed(b.pid(), a.pid()); }, 20s))
      << "each fusion's bsn/status lists the other's process id";
  for (const char* name : {"fusion_a", "fusion_b"})
    EXPECT_NE(read_file(log_path(name)).find("another fusion service"), std::string::npos) << name;
  EXPECT_TRUE(exited_cleanly(stop("fusion_b")));
  EXPECT_TRUE(exited_cleanly(stop("fusion_a")));
}

TEST_F(HostileInput, DemoKilledWithSigkillLeavesNoFolder) {
  // SIGKILL gives the demo no chance to clean up; its reaper removes the log folder.
  const int kDomain = test_domain(52);
  const std::filesystem::path tmp = dir() / "tmp";
  std::filesystem::create_directories(tmp);
  const char* old_tmpdir = std::getenv("TMPDIR");
  const std::string saved = old_tmpdir ? old_tmpdir : "";
  setenv("TMPDIR", tmp.c_str(), 1);
  auto& demo = spawn("demo", {"demo", "--domain", std::to_string(kDomain)});
  if (old_tmpdir) {
    setenv("TMPDIR", saved.c_str(), 1);
  } else {
    unsetenv("TMPDIR");
  }
  ASSERT_TRUE(wait_until([&] { return !directory_entries(tmp).empty() && children_of(demo.pid()).size() >= 8; }, 20s))
      << "the demo made no folder in $TMPDIR or started no children";
  std::this_thread::sleep_for(1s);
  demo.signal(SIGKILL);
  EXPECT_TRUE(wait_until([&] { return directory_entries(tmp).empty(); }, 10s))
      << "left in $TMPDIR: " << ::testing::PrintToString(directory_entries(tmp));
  std::vector<std::pair<int, std::string>> left;
  wait_until([&] { return (left = bsn_processes_in_domain(kDomain)).empty(); }, 10s);
  for (const auto& [pid, cmd] : left) {
    ADD_FAILURE() << "process " << pid << " left behind: " << cmd;
    ::kill(pid, SIGKILL);
  }
}

}  // namespace
}  // namespace bsn::integration
