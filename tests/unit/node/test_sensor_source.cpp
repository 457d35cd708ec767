// bsn node's sources without DDS: the URI, the registry of input kinds, and a source read into a plain sink.
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <set>
#include <vector>

#include "sensor_source.hpp"

namespace bsn::services {
namespace {

struct RecordingSink final : ReadingSink {
  std::vector<io::DeviceReading> accepted;
  std::vector<io::InputRejection> rejected;
  int reconnects = 0;
  void accept(const io::DeviceReading& reading, double) override { accepted.push_back(reading); }
  void reject(io::InputRejection r, std::string_view) override { rejected.push_back(r); }
  void reconnected() override { ++reconnects; }
  double line_time_scale() const override { return 1e-6; }
};

TEST(SensorSource, TheUriNamesKindPlaceAndOptions) {
  const auto iio = parse_source_uri("iio:iio:device0?sysfs=/tmp/fake&dev=/tmp/fifo");
  ASSERT_TRUE(iio);
  EXPECT_EQ(iio->kind, "iio");
  EXPECT_EQ(iio->where, "iio:device0");
  EXPECT_EQ(iio->query.at("sysfs"), "/tmp/fake");
  EXPECT_EQ(iio->query.at("dev"), "/tmp/fifo");
  EXPECT_FALSE(parse_source_uri("serial"));              // no kind
  EXPECT_FALSE(parse_source_uri("udp:"));                // nowhere
  EXPECT_FALSE(parse_source_uri("serial:/dev/x?baud"));  // an option without a value
}

TEST(SensorSource, EveryKindOfTheRegistryMakesItsSource) {
  std::set<std::string> names;
  for (const SensorSourceKind& k : sensor_source_kinds()) {
    EXPECT_TRUE(names.insert(k.name).second) << k.name << " is registered twice";
    EXPECT_EQ(std::string(k.usage).rfind(std::string(k.name) + ":", 0), 0U) << k.usage;
    EXPECT_NE(make_sensor_source({k.name, "x", {}}), nullptr) << k.name;
  }
  EXPECT_EQ(make_sensor_source({"bluetooth", "x", {}}), nullptr);
  EXPECT_EQ(sensor_source_usages(), "serial:PATH[?baud=N], udp:PORT or iio:DEVICE[?sysfs=DIR&dev=FILE]");
}

TEST(SensorSource, ABadPlaceIsAnExitCodeBeforeAnythingRuns) {
  EXPECT_EQ(make_sensor_source({"udp", "not-a-port", {}})->open(), 2);
  EXPECT_EQ(make_sensor_source({"serial", "/dev/null", {{"baud", "1234"}}})->open(), 2);
  EXPECT_EQ(make_sensor_source({"iio", "x", {{"sysfs", "/nonexistent"}}})->open(), 1);
}

TEST(SensorSource, UdpLinesReachTheSinkAndBadOnesAreCounted) {
  // A free port: bind port 0, read it back, close, and let the source take it.
  const int probe = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(probe, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  socklen_t len = sizeof addr;
  ASSERT_EQ(::getsockname(probe, reinterpret_cast<sockaddr*>(&addr), &len), 0);
  ::close(probe);
  auto source = make_sensor_source({"udp", std::to_string(ntohs(addr.sin_port)), {}});
  ASSERT_EQ(source->open(), std::nullopt);

  const int sender = ::socket(AF_INET, SOCK_DGRAM, 0);
  const std::string datagram = "1000,0,0,9.81,0.1,0,0\n2000,0,0,9.81,x,0,0\n3000,0,0,9.81,0.1,0,0";
  ASSERT_EQ(::sendto(sender, datagram.data(), datagram.size(), 0, reinterpret_cast<sockaddr*>(&addr), sizeof addr),
            static_cast<ssize_t>(datagram.size()));
  ::close(sender);
  RecordingSink sink;
  for (int i = 0; i < 20 && sink.accepted.size() + sink.rejected.size() < 3; ++i)
    EXPECT_EQ(source->read_some(sink), std::nullopt);
  ASSERT_EQ(sink.accepted.size(), 2U);
  EXPECT_EQ(*sink.accepted[1].device_time, 3000.0);
  ASSERT_EQ(sink.rejected.size(), 1U);
  EXPECT_EQ(sink.rejected[0], io::InputRejection::kNotANumber);
}

}  // namespace
}  // namespace bsn::services
