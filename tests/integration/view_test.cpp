// `bsn view` as a process: a clear error for a port in use, and the page in a real browser (headless Chromium,
// driven over the DevTools protocol) on a running simulated body.
#include <civetweb.h>
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/wait.h>

#include <array>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <map>
#include <mutex>
#include <numbers>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bsn/dds/participant.hpp"
#include "bsn/dds/topics.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;
using SampleInfo = eprosima::fastdds::dds::SampleInfo;

/// The port `bsn view` printed in its first line ("bsn view: http://HOST:PORT/ ..."), or 0 until it has.
int printed_port(const std::filesystem::path& log) {
  std::smatch m;
  const std::string text = read_file(log);
  static const std::regex url("bsn view: http://[^:/]+:([0-9]+)/");
  return std::regex_search(text, m, url) ? std::stoi(m[1]) : 0;
}

TEST_F(ProcessTest, ViewPortInUseIsAClearErrorNamingThePort) {
  auto& first = spawn("first", {"view", "--port", "0", "--domain", std::to_string(test_domain(65))});
  int port = 0;
  ASSERT_TRUE(wait_until([&] { return (port = printed_port(log_path("first"))) > 0; }, 20s)) << tail(log_path("first"));
  auto& second = spawn("second", {"view", "--port", std::to_string(port), "--domain", std::to_string(test_domain(65))});
  const auto status = second.wait_for(20s);
  ASSERT_TRUE(status.has_value()) << "bsn view on a port in use did not exit";
  EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 2) << describe_status(status);
  const std::string out = read_file(log_path("second"));
  EXPECT_NE(out.find("port " + std::to_string(port) + " in use"), std::string::npos) << out;
  EXPECT_TRUE(first.running());
}

}  // namespace
}  // namespace bsn::integration
