// Interoperability with clients that are not bsn: a Cyclone DDS program built from the same idl/bsn.idl publishes
// raw samples that a real `bsn fusion` fuses, and receives the orientations it publishes; the README's Fast DDS
// subscriber, built from fastddsgen's output alone, reads the joint angles.
#include <gtest/gtest.h>

#include <cstdio>

#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

class CycloneInterop : public ProcessTest {};

TEST_F(CycloneInterop, CyclonePublishesRawAndReceivesOrientations) {
  const int kDomain = test_domain(8);
  write_file(dir() / "body.yaml", "segments:\n  - name: cy\n    node: cy\n");
  spawn("fusion", {"fusion", "--domain", std::to_string(kDomain), "--body", (dir() / "body.yaml").string()});
  const std::string log = (dir() / "peer.log").string();
  dds::ChildProcess peer({BSN_CYCLONE_PEER, std::to_string(kDomain), "cy", "200", "20"}, log);
  const auto st = peer.wait_for(std::chrono::seconds(30));
  EXPECT_TRUE(exited_cleanly(st)) << describe_status(st) << "\n" << read_file(log);
  // The peer stops taking once it has 200; a last take may bring one or two more.
  int received = 0, not_unit = -1;
  const std::string out = read_file(log);
  const std::size_t at = out.find("cyclone peer: ");
  ASSERT_NE(at, std::string::npos) << out;
  ASSERT_EQ(std::sscanf(out.c_str() + at, "cyclone peer: %d orientations of 'cy' received, %d not unit", &received,
                        &not_unit),
            2)
      << out;
  EXPECT_GE(received, 200) << out;
  EXPECT_EQ(not_unit, 0) << out;
  EXPECT_TRUE(exited_cleanly(stop("fusion")));
}

class FastDdsExample : public ProcessTest {};

TEST_F(FastDdsExample, TheReadmeSubscriberReadsJointAngles) {
  const std::string domain = std::to_string(test_domain(55));
  write_file(dir() / "body.yaml",
             "segments:\n  - name: thigh\n    node: thigh\n  - name: shank\n    node: shank\n    parent: thigh\n"
             "    joint: knee\n");
  spawn("fusion", {"fusion", "--domain", domain, "--body", (dir() / "body.yaml").string()});
  spawn("thigh", {"sim", "--node", "thigh", "--domain", domain});
  spawn("shank", {"sim", "--node", "shank", "--domain", domain});
  spawn_command("subscriber", {BSN_FASTDDS_SUBSCRIBER, domain, "20", "60"});
  const auto st = child("subscriber").wait_for(std::chrono::seconds(70));
  const std::string out = read_file(log_path("subscriber"));
  ASSERT_EQ(exit_code(st), 0) << describe_status(st) << "\n" << out;
  // Twenty lines like "knee (thigh -> shank) zyx: 12.3 -4.5 6.7 deg".
  int lines = 0;
  for (std::size_t at = out.find("knee (thigh -> shank) "); at != std::string::npos;
       at = out.find("knee (thigh -> shank) ", at + 1)) {
    ++lines;
  }
  EXPECT_GE(lines, 20) << out;
}

}  // namespace
}  // namespace bsn::integration
