// `bsn node` with real-sensor sources fed by the test: a pty for the serial port (garbage, partial and bad lines,
// unplugged and back), loopback UDP (lines and NGIMU OSC, truncated, oversized and mistyped datagrams), and a
// fake sysfs tree with a FIFO for Linux IIO (scaled values, a short read, missing and malformed scan elements).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <termios.h>
#include <unistd.h>

#include <cstring>
#include <map>
#include <mutex>
#include <numbers>
#include <thread>

#include "bsn/dds/participant.hpp"
#include "bsn/dds/topics.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;
using SampleInfo = eprosima::fastdds::dds::SampleInfo;

// What a subscriber sees of one node: its raw samples and its latest status.
struct Seen {
  std::mutex m;
  std::vector<bsn::RawSample> raw;
  std::map<std::string, std::uint64_t> rejected;  // of the node's latest status (one node per test, or:)
  std::map<std::string, std::map<std::string, std::uint64_t>> rejected_by_node;
  std::uint64_t accepted = 0;
};

class NodeSource : public ProcessTest {
 protected:
  void subscribe(int domain) {
    participant_ = std::make_unique<dds::Participant>(dds::Participant::Options{domain, "node test"});
    raw_reader_ = participant_->make_reader(dds::kRawTopic, [this](const bsn::RawSample& s, const SampleInfo&) {
      std::lock_guard lock(seen_.m);
      seen_.raw.push_back(s);
    });
    status_reader_ = participant_->make_reader(dds::kStatusTopic, [this](const bsn::Status& s, const SampleInfo&) {
      std::lock_guard lock(seen_.m);
      for (const auto& n : s.nodes()) {
        seen_.accepted = n.accepted();
        for (const auto& r : n.rejected()) {
          seen_.rejected[r.reason()] = r.count();
          seen_.rejected_by_node[n.node_id()][r.reason()] = r.count();
        }
      }
    });
  }
  std::size_t raw_count() {
    std::lock_guard lock(seen_.m);
    return seen_.raw.size();
  }
  void TearDown() override {
    raw_reader_.reset();
    status_reader_.reset();
    participant_.reset();
    ProcessTest::TearDown();
  }
  Seen seen_;
  std::unique_ptr<dds::Participant> participant_;
  std::unique_ptr<dds::Reader<bsn::RawSample>> raw_reader_;
  std::unique_ptr<dds::Reader<bsn::Status>> status_reader_;
};

// A pty whose slave is in raw mode, reachable through `link`.
int open_pty(const std::filesystem::path& link) {
  const int master = posix_openpt(O_RDWR | O_NOCTTY);
  if (master < 0 || grantpt(master) != 0 || unlockpt(master) != 0) return -1;
  const std::string slave = ptsname(master);
  const int s = ::open(slave.c_str(), O_RDWR | O_NOCTTY);
  termios tio{};
  tcgetattr(s, &tio);
  cfmakeraw(&tio);
  tcsetattr(s, TCSANOW, &tio);
  ::close(s);
  const std::filesystem::path tmp = link.string() + ".new";
  std::filesystem::remove(tmp);
  std::filesystem::create_symlink(slave, tmp);
  std::filesystem::rename(tmp, link);  // atomic: the node sees the old device or the new one
  return master;
}

void write_all(int fd, const std::string& s) {
  std::size_t done = 0;
  while (done < s.size()) {
    const ssize_t n = ::write(fd, s.data() + done, s.size() - done);
    if (n <= 0) return;
    done += static_cast<std::size_t>(n);
  }
}

std::string sample_line(std::uint64_t t_us, double gx) {
  return std::to_string(t_us) + ",0.1,-0.2,9.81," + std::to_string(gx) + ",0,0,20,0,-40\n";
}

TEST_F(NodeSource, SerialSkipsBadLinesAndSurvivesUnplugging) {
  const int domain = test_domain(20);
  subscribe(domain);
  const auto tty = dir() / "ttyBSN";
  int master = open_pty(tty);
  ASSERT_GE(master, 0);
  spawn("node", {"node", "--source", "serial:" + tty.string() + "?baud=115200", "--node", "wrist", "--domain",
                 std::to_string(domain), "--status-period", "0.2"});
  std::this_thread::sleep_for(1500ms);  // the node opens the port and matches the subscriber
  int good = 0;
  for (int i = 0; i < 100; ++i) {
    if (i == 10) write_all(master, "\x01\x02\xff garbage\n\xfe\xff,0,0,9.8,0,0,0\n");  // one field; bytes as a number
    if (i == 20) write_all(master, "1,2,3\n");
    if (i == 30) write_all(master, "123,0,0,9.8,abc,0,0\n");
    if (i == 40) {  // a line in two pieces
      const std::string l = sample_line(static_cast<std::uint64_t>(i) * 10000, 0.5);
      write_all(master, l.substr(0, 9));
      std::this_thread::sleep_for(5ms);
      write_all(master, l.substr(9));
    } else {
      write_all(master, sample_line(static_cast<std::uint64_t>(i) * 10000, 0.5));
    }
    ++good;
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_TRUE(wait_until([&] { return raw_count() == 100; }, 5s)) << raw_count();
  write_all(master, "777,0,0");  // unplugged mid-line
  ::close(master);
  std::this_thread::sleep_for(500ms);
  master = open_pty(tty);  // plugged in again; the device restarted its clock
  ASSERT_GE(master, 0);
  std::this_thread::sleep_for(800ms);
  for (int i = 0; i < 50; ++i) {
    write_all(master, sample_line(static_cast<std::uint64_t>(i) * 10000, 0.25));
    ++good;
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_TRUE(wait_until([&] { return raw_count() == static_cast<std::size_t>(good); }, 5s)) << raw_count();
  ASSERT_TRUE(wait_until(
      [&] {
        std::lock_guard lock(seen_.m);
        return seen_.accepted == static_cast<std::uint64_t>(good);
      },
      3s));
  ::close(master);
  std::lock_guard lock(seen_.m);
  EXPECT_EQ(seen_.rejected["not_a_number"], 2u);  // the bytes in a number field, "abc"
  EXPECT_EQ(seen_.rejected["column_count"], 2u);  // the garbage line without commas, "1,2,3"
  for (std::size_t i = 0; i < seen_.raw.size(); ++i) {
    const auto& s = seen_.raw[i];
    EXPECT_EQ(s.node_id(), "wrist");
    EXPECT_EQ(s.seq(), i);
    EXPECT_EQ(s.channels(), bsn::CHANNEL_ACC | bsn::CHANNEL_GYR | bsn::CHANNEL_MAG);
    EXPECT_EQ(s.gyr()[0], i < 100 ? 0.5 : 0.25);
    if (i > 0) {
      ASSERT_GT(s.timestamp_ns(), seen_.raw[i - 1].timestamp_ns()) << i;
      if (i != 100) {
        EXPECT_EQ(s.timestamp_ns() - seen_.raw[i - 1].timestamp_ns(), 10000000u) << i;  // device clock
      }
    }
  }
  EXPECT_NE(read_file(log_path("node")).find("disconnected"), std::string::npos);
}

void send_to(int port, const std::vector<std::uint8_t>& bytes) {
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::sendto(fd, bytes.data(), bytes.size(), 0, reinterpret_cast<sockaddr*>(&a), sizeof a);
  ::close(fd);
}
void send_to(int port, const std::string& s) { send_to(port, std::vector<std::uint8_t>(s.begin(), s.end())); }

std::vector<std::uint8_t> osc_sensors(const std::string& tags, int floats, float gyro_x_deg) {
  std::vector<std::uint8_t> m;
  auto str = [&m](const std::string& s) {
    m.insert(m.end(), s.begin(), s.end());
    m.push_back(0);
    while (m.size() % 4) m.push_back(0);
  };
  str("/sensors");
  str(tags);
  for (int i = 0; i < floats; ++i) {
    const float f = i == 0 ? gyro_x_deg : (i == 5 ? 1.0f : 0.0f);  // gyro x, accelerometer z = 1 g
    std::uint32_t bits;
    std::memcpy(&bits, &f, 4);
    for (int b = 3; b >= 0; --b) m.push_back(static_cast<std::uint8_t>(bits >> (8 * b)));
  }
  return m;
}

TEST_F(NodeSource, UdpLinesAndNgimuOscWithBadDatagramsCounted) {
  const int domain = test_domain(22);
  subscribe(domain);
  const int port = 30000 + domain * 4;
  spawn("lines", {"node", "--source", "udp:" + std::to_string(port), "--node", "phone", "--domain",
                  std::to_string(domain), "--status-period", "0.2"});
  spawn("osc", {"node", "--source", "udp:" + std::to_string(port + 1), "--node", "ngimu", "--domain",
                std::to_string(domain), "--status-period", "0.2"});
  std::this_thread::sleep_for(1500ms);
  for (int i = 0; i < 50; ++i) {
    send_to(port, sample_line(static_cast<std::uint64_t>(i) * 10000, 0.5));
    send_to(port + 1, osc_sensors(",ffffffffff", 10, 90.0f));
    if (i == 10) {
      send_to(port + 1, osc_sensors(",fff", 3, 0.0f));  // wrong type tags
      auto cut = osc_sensors(",ffffffffff", 10, 0.0f);
      cut.resize(cut.size() - 12);
      send_to(port + 1, cut);                                   // truncated
      send_to(port + 1, std::vector<std::uint8_t>(3000, '/'));  // oversized
      send_to(port, "5,1,2,x,4,5,6\n");                         // text in a number
    }
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_TRUE(wait_until([&] { return raw_count() == 100; }, 5s)) << raw_count();
  std::this_thread::sleep_for(500ms);
  std::lock_guard lock(seen_.m);
  EXPECT_EQ(seen_.raw.size(), 100u);
  EXPECT_EQ(seen_.rejected_by_node["ngimu"]["wrong_type_tags"], 1u);
  EXPECT_EQ(seen_.rejected_by_node["ngimu"]["truncated"], 1u);
  EXPECT_EQ(seen_.rejected_by_node["ngimu"]["oversized"], 1u);
  EXPECT_EQ(seen_.rejected_by_node["phone"]["not_a_number"], 1u);
  for (const auto& s : seen_.raw) {
    if (s.node_id() == "ngimu") {
      EXPECT_DOUBLE_EQ(s.gyr()[0], std::numbers::pi / 2);  // 90 deg/s
      EXPECT_NEAR(s.acc()[2], 9.80665, 1e-6);              // 1 g (a float)
    } else {
      EXPECT_EQ(s.node_id(), "phone");
      EXPECT_EQ(s.acc()[2], 9.81);
    }
  }
}

// A fake IIO device: accelerometer and gyroscope (s16) and a timestamp (s64), with the kernel's scales.
std::filesystem::path fake_iio(const std::filesystem::path& root, bool with_accel_x_type, const char* gyro_type) {
  const auto scan = root / "scan_elements";
  std::filesystem::create_directories(scan);
  std::filesystem::create_directories(root / "buffer");
  int index = 0;
  for (const char* kind : {"accel", "anglvel"}) {
    for (const char* axis : {"x", "y", "z"}) {
      const std::string name = std::string("in_") + kind + "_" + axis;
      write_file(scan / (name + "_en"), "1\n");
      write_file(scan / (name + "_index"), std::to_string(index++) + "\n");
      if (with_accel_x_type || name != "in_accel_x")
        write_file(scan / (name + "_type"), std::string(kind) == "accel" ? "le:s16/16>>0\n" : gyro_type);
    }
  }
  write_file(scan / "in_timestamp_en", "1\n");
  write_file(scan / "in_timestamp_index", "6\n");
  write_file(scan / "in_timestamp_type", "le:s64/64>>0\n");
  write_file(root / "in_accel_scale", "0.000598\n");
  write_file(root / "in_anglvel_scale", "0.000133090\n");
  write_file(root / "buffer" / "enable", "0\n");
  return root;
}

TEST_F(NodeSource, IioFifoScansAreScaledAndAShortReadIsCounted) {
  const int domain = test_domain(23);
  subscribe(domain);
  const auto sysfs = fake_iio(dir() / "iio", true, "le:s16/16>>0\n");
  const auto fifo = dir() / "iio_dev";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  spawn("node", {"node", "--source", "iio:iio:device0?sysfs=" + sysfs.string() + "&dev=" + fifo.string(), "--node",
                 "hub", "--domain", std::to_string(domain), "--status-period", "0.2"});
  int fd = -1;
  ASSERT_TRUE(wait_until(
      [&] {
        fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
        return fd >= 0;
      },
      10s));
  std::this_thread::sleep_for(1000ms);  // the node's writer matches the subscriber
  EXPECT_EQ(read_file(sysfs / "buffer" / "enable"), "1\n");
  // 6 x s16 (12 bytes), then the s64 timestamp aligned to 8: 24 bytes per scan.
  for (int i = 0; i < 100; ++i) {
    std::array<std::uint8_t, 24> scan{};
    const std::int16_t v[6] = {100, -200, 16384, 7, -8, static_cast<std::int16_t>(i)};
    std::memcpy(scan.data(), v, sizeof v);
    const std::int64_t ts = 1000000000 + static_cast<std::int64_t>(i) * 10000000;
    std::memcpy(scan.data() + 16, &ts, 8);
    ASSERT_EQ(::write(fd, scan.data(), scan.size()), 24);
    std::this_thread::sleep_for(5ms);
  }
  ASSERT_EQ(::write(fd, "\x01\x02\x03\x04\x05", 5), 5);  // a partial scan, then the device goes away
  ::close(fd);
  ASSERT_TRUE(wait_until([&] { return raw_count() == 100; }, 5s)) << raw_count();
  ASSERT_TRUE(wait_until(
      [&] {
        std::lock_guard lock(seen_.m);
        return seen_.rejected["short_read"] == 1u;
      },
      3s));
  std::lock_guard lock(seen_.m);
  for (std::size_t i = 0; i < seen_.raw.size(); ++i) {
    const auto& s = seen_.raw[i];
    EXPECT_DOUBLE_EQ(s.acc()[0], 100 * 0.000598);
    EXPECT_DOUBLE_EQ(s.acc()[1], -200 * 0.000598);
    EXPECT_DOUBLE_EQ(s.acc()[2], 16384 * 0.000598);
    EXPECT_DOUBLE_EQ(s.gyr()[2], static_cast<double>(i) * 0.000133090);
    EXPECT_EQ(s.channels(), bsn::CHANNEL_ACC | bsn::CHANNEL_GYR);
    if (i > 0) {
      EXPECT_EQ(s.timestamp_ns() - seen_.raw[i - 1].timestamp_ns(), 10000000u);
    }
  }
}

// The layout is read before any DDS entity exists, so these runs need no domain of their own.
TEST_F(NodeSource, IioMissingOrMalformedScanElementNamesTheFile) {
  const auto missing = fake_iio(dir() / "missing", false, "le:s16/16>>0\n");
  spawn("missing", {"node", "--source", "iio:x?sysfs=" + missing.string() + "&dev=/nonexistent", "--node", "hub",
                    "--domain", "0"});
  EXPECT_EQ(exit_code(child("missing").wait_for(10s)), 1);
  EXPECT_NE(read_file(log_path("missing")).find((missing / "scan_elements" / "in_accel_x_type").string()),
            std::string::npos)
      << read_file(log_path("missing"));
  const auto endian = fake_iio(dir() / "endian", true, "me:s16/16>>0\n");
  spawn("endian",
        {"node", "--source", "iio:x?sysfs=" + endian.string() + "&dev=/nonexistent", "--node", "hub", "--domain", "0"});
  EXPECT_EQ(exit_code(child("endian").wait_for(10s)), 1);
  const std::string log = read_file(log_path("endian"));
  EXPECT_NE(log.find("scan_elements/in_anglvel_"), std::string::npos) << log;
  EXPECT_NE(log.find("endianness"), std::string::npos) << log;
}

// Seven real-sensor nodes (four serial ports, three UDP senders) at 100 Hz reach one fusion service with no loss.
TEST_F(NodeSource, SevenNodesReachFusionAt100HzWithoutLoss) {
  const int domain = test_domain(28);
  const std::vector<std::string> nodes{"pelvis", "thigh_l", "shank_l", "foot_l", "thigh_r", "shank_r", "foot_r"};
  std::string body = "segments:\n";
  for (const auto& n : nodes) body += "  - name: " + n + "\n";
  write_file(dir() / "body.yaml", body);
  std::mutex m;
  std::map<std::string, std::pair<std::uint64_t, std::uint64_t>> accepted_missing;
  dds::Participant participant({domain, "node test fusion"});
  auto status = participant.make_reader(dds::kStatusTopic, [&](const bsn::Status& st, const SampleInfo&) {
    std::lock_guard lock(m);
    if (st.process_id().rfind("fusion", 0) != 0) return;
    for (const auto& n : st.nodes()) accepted_missing[n.node_id()] = {n.accepted(), n.missing()};
  });
  spawn("fusion", {"fusion", "--body", (dir() / "body.yaml").string(), "--domain", std::to_string(domain),
                   "--status-period", "0.2"});
  std::vector<int> masters;
  const int port = 30000 + domain * 4;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    std::string source;
    if (i < 4) {
      const auto tty = dir() / ("tty" + std::to_string(i));
      masters.push_back(open_pty(tty));
      ASSERT_GE(masters.back(), 0);
      source = "serial:" + tty.string();
    } else {
      source = "udp:" + std::to_string(port + static_cast<int>(i));
    }
    spawn(nodes[i], {"node", "--source", source, "--node", nodes[i], "--domain", std::to_string(domain)});
  }
  std::this_thread::sleep_for(2500ms);  // every node matched with the fusion service
  constexpr int kSamples = 300;         // 3 s at 100 Hz
  auto next = Clock::now();
  for (int k = 0; k < kSamples; ++k) {
    for (std::size_t i = 0; i < nodes.size(); ++i) {
      const std::string line = sample_line(static_cast<std::uint64_t>(k) * 10000, 0.1);
      if (i < 4) {
        write_all(masters[i], line);
      } else {
        send_to(port + static_cast<int>(i), line);
      }
    }
    next += 10ms;
    std::this_thread::sleep_until(next);
  }
  const bool all = wait_until(
      [&] {
        std::lock_guard lock(m);
        for (const auto& n : nodes)
          if (accepted_missing[n].first != static_cast<std::uint64_t>(kSamples)) return false;
        return true;
      },
      5s);
  for (const int fd : masters) ::close(fd);
  std::lock_guard lock(m);
  for (const auto& n : nodes) {
    EXPECT_EQ(accepted_missing[n].first, static_cast<std::uint64_t>(kSamples)) << n;
    EXPECT_EQ(accepted_missing[n].second, 0u) << n;
  }
  EXPECT_TRUE(all);
}

}  // namespace
}  // namespace bsn::integration
