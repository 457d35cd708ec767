// Interoperability with another vendor's DDS: a Cyclone DDS program built from the same idl/bsn.idl publishes
// raw samples that a real `bsn fusion` fuses, and receives the orientations it publishes.
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

}  // namespace
}  // namespace bsn::integration
