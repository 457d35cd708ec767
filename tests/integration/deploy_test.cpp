// What deploy/ ships works as shipped: every Fast DDS profile carries raw samples from a `bsn sim` to a
// `bsn echo` (the discovery-client profile through a real `fastdds discovery` server), a broken profile is a
// clear error, and the systemd units pass `systemd-analyze verify`.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <regex>
#include <string>

#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;

const std::string kProfiles = std::string(BSN_DEPLOY_DIR) + "/profiles/";

class DeployProfiles : public ProcessTest {
 protected:
  /// `bsn sim` and `bsn echo bsn/raw --count 50` with the same profile: true if echo got them in time.
  void expect_samples_flow(const std::string& profile, int domain) {
    const std::string d = std::to_string(domain);
    spawn("sim", {"sim", "--node", "pelvis", "--profile", profile, "--domain", d});
    spawn("echo", {"echo", "bsn/raw", "--count", "50", "--timeout", "15", "--profile", profile, "--domain", d});
    EXPECT_TRUE(exited_cleanly(child("echo").wait_for(20s))) << tail(log_path("echo"));
    EXPECT_TRUE(exited_cleanly(stop("sim"))) << tail(log_path("sim"));
  }
};

TEST_F(DeployProfiles, LanMulticast) { expect_samples_flow(kProfiles + "lan-multicast.xml", test_domain(34)); }
TEST_F(DeployProfiles, OneHostSharedMemory) { expect_samples_flow(kProfiles + "one-host-shm.xml", test_domain(35)); }
TEST_F(DeployProfiles, LargeBody) { expect_samples_flow(kProfiles + "large-body.xml", test_domain(36)); }

TEST_F(DeployProfiles, DiscoveryServer) {
  // The shipped client profile names the server at 127.0.0.1:11811; a server on another port keeps this test
  // clear of a server the machine may run, so the test's copy of the profile names that port.
  constexpr int kServerPort = 11917;
  std::string client = read_file(kProfiles + "discovery-client.xml");
  ASSERT_NE(client.find("<port>11811</port>"), std::string::npos);
  client =
      std::regex_replace(client, std::regex("<port>11811</port>"), "<port>" + std::to_string(kServerPort) + "</port>");
  const std::string client_path = (dir() / "client.xml").string();
  write_file(client_path, client);

  std::string server_profile = read_file(kProfiles + "discovery-server.xml");
  ASSERT_NE(server_profile.find("<port>11811</port>"), std::string::npos);
  server_profile = std::regex_replace(server_profile, std::regex("<port>11811</port>"),
                                      "<port>" + std::to_string(kServerPort) + "</port>");
  const std::string server_path = (dir() / "server.xml").string();
  write_file(server_path, server_profile);
  dds::ChildProcess server({"/usr/bin/fast-discovery-server", "-x", server_path}, log_path("server").string());
  expect_samples_flow(client_path, test_domain(37));
  server.stop(std::chrono::milliseconds(3000));
}

TEST_F(DeployProfiles, BrokenProfileIsAClearError) {
  const std::string broken = (dir() / "broken.xml").string();
  write_file(broken, "<dds><profiles><participant profile_name=\"x\" is_default_profile=\"true\">");
  spawn("sim", {"sim", "--node", "pelvis", "--profile", broken, "--domain", std::to_string(test_domain(40))});
  const auto status = child("sim").wait_for(15s);
  ASSERT_TRUE(status.has_value()) << "bsn sim kept running with a broken profile";
  EXPECT_FALSE(exited_cleanly(status));
  EXPECT_NE(read_file(log_path("sim")).find(broken), std::string::npos) << tail(log_path("sim"));
}

TEST(SystemdUnits, PassSystemdAnalyzeVerify) {
  if (std::system("command -v systemd-analyze > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "systemd-analyze is not installed (apt install systemd)";
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("bsn-units-" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string units = std::string(BSN_DEPLOY_DIR) + "/systemd/";
  // A template is verified as an instance.
  std::filesystem::copy_file(units + "bsn-sim@.service", dir / "bsn-sim@thigh_l.service");
  std::filesystem::copy_file(units + "bsn-fusion.service", dir / "bsn-fusion.service");
  std::filesystem::copy_file(units + "bsn-calibration.service", dir / "bsn-calibration.service");
  for (const char* unit : {"bsn-sim@thigh_l.service", "bsn-fusion.service", "bsn-calibration.service"}) {
    const std::filesystem::path log = dir / (std::string(unit) + ".log");
    const std::string command = "systemd-analyze verify '" + (dir / unit).string() + "' > '" + log.string() + "' 2>&1";
    EXPECT_EQ(std::system(command.c_str()), 0) << unit << ":\n" << read_file(log);
    // verify exits 0 on unknown keys; it still names them.
    EXPECT_EQ(read_file(log), "") << unit;
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace bsn::integration
