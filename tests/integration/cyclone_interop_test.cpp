// Interoperability with another vendor's DDS: a Cyclone DDS program built from the same idl/bsn.idl publishes
// raw samples that a real `bsn fusion` fuses, and receives the orientations it publishes.
#include <gtest/gtest.h>

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
  EXPECT_NE(read_file(log).find("200 orientations of 'cy' received, 0 not unit"), std::string::npos) << read_file(log);
  EXPECT_TRUE(exited_cleanly(stop("fusion")));
}

}  // namespace
}  // namespace bsn::integration
