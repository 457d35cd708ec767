#include "node_service.hpp"

#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>

#include "bsn/config/body_config.hpp"
#include "bsn/config/yaml_reader.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/dds/shutdown.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/logging/log.hpp"

namespace bsn::services {
namespace {

namespace fs = std::filesystem;
using io::InputRejection;

}  // namespace

io::AxisMap load_axis_map(const std::string& path, io::AxisMap map) {
  const config::YamlReader<config::ConfigError> r(path);
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw config::ConfigError(path + ": cannot read the file");
  } catch (const YAML::Exception& e) {
    r.fail_at(e.mark.line + 1, "YAML syntax error: " + e.msg);
  }
  r.check_keys(root, {"time_scale_s", "acc", "gyr", "mag"}, "the axis map");
  if (root["time_scale_s"]) {
    map.time_scale_s = r.number(root["time_scale_s"], "time_scale_s");
    if (!(map.time_scale_s > 0.0)) r.fail(root["time_scale_s"], "time_scale_s must be positive");
  }
  auto channel = [&](const char* name, io::ChannelMap& c) {
    const YAML::Node n = root[name];
    if (!n) return;
    r.check_keys(n, {"axes", "scale", "enabled"}, name);
    if (n["scale"]) {
      c.scale = r.number(n["scale"], std::string(name) + ".scale");
      if (c.scale == 0.0) r.fail(n["scale"], std::string(name) + ".scale must not be 0");
    }
    if (n["enabled"]) c.enabled = r.text(n["enabled"], std::string(name) + ".enabled") == "true";
    if (const YAML::Node axes = n["axes"]) {
      if (!axes.IsSequence() || axes.size() != 3)
        r.fail(axes, std::string(name) + ".axes must be three of x, -x, y, ...");
      std::array<bool, 3> used{};
      for (std::size_t i = 0; i < 3; ++i) {
        std::string a = r.text(axes[i], std::string(name) + ".axes");
        double sign = 1.0;
        if (!a.empty() && (a[0] == '-' || a[0] == '+')) {
          sign = a[0] == '-' ? -1.0 : 1.0;
          a.erase(0, 1);
        }
        if (a != "x" && a != "y" && a != "z") r.fail(axes[i], "axis '" + a + "' is not x, y or z (optionally with -)");
        const int src = a[0] - 'x';
        if (used[static_cast<std::size_t>(src)]) r.fail(axes[i], "axis " + a + " used twice in " + name + ".axes");
        used[static_cast<std::size_t>(src)] = true;
        c.source[i] = src;
        c.sign[i] = sign;
      }
    }
  };
  channel("acc", map.acc);
  channel("gyr", map.gyr);
  channel("mag", map.mag);
  return map;
}

namespace {

// The source URI: KIND:WHERE?key=value&key=value.
struct SourceUri {
  std::string kind, where;
  std::map<std::string, std::string> query;
};

std::optional<SourceUri> parse_uri(const std::string& uri) {
  const auto colon = uri.find(':');
  if (colon == std::string::npos) return std::nullopt;
  SourceUri u;
  u.kind = uri.substr(0, colon);
  std::string rest = uri.substr(colon + 1);
  const auto q = rest.find('?');
  if (q != std::string::npos) {
    std::string query = rest.substr(q + 1);
    rest = rest.substr(0, q);
    std::size_t pos = 0;
    while (pos <= query.size()) {
      const auto amp = query.find('&', pos);
      const std::string kv = query.substr(pos, amp == std::string::npos ? std::string::npos : amp - pos);
      const auto eq = kv.find('=');
      if (eq == std::string::npos) return std::nullopt;
      u.query[kv.substr(0, eq)] = kv.substr(eq + 1);
      if (amp == std::string::npos) break;
      pos = amp + 1;
    }
  }
  u.where = rest;
  if (u.where.empty()) return std::nullopt;
  return u;
}

// Everything a source hands over goes through here: rejections counted and logged at most once per second,
// readings mapped, timed and published.
class NodePublisher {
 public:
  NodePublisher(dds::Participant& participant, const NodeOptions& opt, io::AxisMap map)
      : opt_(opt),
        map_(map),
        participant_(participant),
        raw_writer_(participant.make_writer(dds::kRawTopic, std::nullopt, opt.node)),
        status_writer_(participant.make_writer(dds::kStatusTopic)) {
    participant.expect_peer(*raw_writer_, "reader of bsn/raw for node '" + opt.node + "' (fusion)");
    raw_.node_id(opt.node);
    char host[128] = {};
    gethostname(host, sizeof host - 1);
    process_id_ = "node " + opt.node + "@" + host + ":" + std::to_string(getpid());
  }

  /// A new time base at the next sample (the device was reconnected and may have restarted its clock).
  void reconnected() { have_base_ = false; }

  void reject(InputRejection r, std::string_view sample_text = {}) {
    ++received_;
    if (r == InputRejection::kIgnored) return;
    ++rejected_[static_cast<std::size_t>(r)];
    ++rejected_since_log_;
    if (!sample_text.empty()) last_bad_.assign(sample_text.substr(0, 60));
  }

  void accept(const io::DeviceReading& reading, double device_time_scale_s) {
    ++received_;
    const std::uint64_t arrival = dds::monotonic_ns();
    fusion::ImuSample s = io::apply_axis_map(reading, map_);
    // The sensor's clock, moved onto this host's monotonic clock at the first sample and whenever it restarts
    // (goes back, or jumps by more than a minute), so every interval is the device's own.
    std::uint64_t ts = arrival;
    if (reading.device_time) {
      const double t = *reading.device_time * device_time_scale_s;
      const std::int64_t device_ns = static_cast<std::int64_t>(std::llround(t * 1e9));
      if (!have_base_ || device_ns < last_device_ns_ || device_ns - last_device_ns_ > 60'000'000'000LL) {
        base_ = static_cast<std::int64_t>(arrival) - device_ns;
        have_base_ = true;
      }
      last_device_ns_ = device_ns;
      ts = static_cast<std::uint64_t>(device_ns + base_);
    }
    s.timestamp_ns = ts;
    dds::fill_raw_sample(s, raw_);
    raw_.seq(seq_++);
    if (raw_writer_->write(raw_)) {
      ++accepted_;
    } else {
      ++write_failures_;
    }
  }

  double line_time_scale() const { return map_.time_scale_s; }

  void tick() {
    participant_.watch_peers();
    const auto now = std::chrono::steady_clock::now();
    if (rejected_since_log_ > 0 && now - last_log_ >= std::chrono::seconds(1)) {
      std::string reasons;
      for (std::size_t i = 0; i < rejected_.size(); ++i) {
        if (rejected_[i] == 0) continue;
        reasons += (reasons.empty() ? "" : ", ") +
                   std::string(io::input_rejection_name(static_cast<InputRejection>(i))) + " " +
                   std::to_string(rejected_[i]);
      }
      logging::log_warn(rejected_since_log_, " inputs rejected in the last second (totals: ", reasons, "; last: '",
                        last_bad_, "')");
      rejected_since_log_ = 0;
      last_log_ = now;
    }
    if (now - last_status_ >= std::chrono::duration<double>(opt_.status_period_s)) publish_status(now);
  }

 private:
  void publish_status(std::chrono::steady_clock::time_point now) {
    const double period = std::chrono::duration<double>(now - last_status_).count();
    bsn::Status st;
    st.process_id(process_id_);
    st.wall_time_ns(static_cast<std::uint64_t>(
        std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
            .count()));
    st.period_s(period);
    bsn::NodeStatus n;
    n.node_id(opt_.node);
    n.rate_hz(period > 0 ? static_cast<double>(accepted_ - accepted_at_status_) / period : 0.0);
    accepted_at_status_ = accepted_;
    n.received(received_);
    n.accepted(accepted_);
    for (std::size_t i = 2; i < rejected_.size(); ++i) {  // every reason but none and ignored
      bsn::ReasonCount& rc = n.rejected().emplace_back();
      rc.reason(io::input_rejection_name(static_cast<InputRejection>(i)));
      rc.count(rejected_[i]);
    }
    st.nodes({n});
    st.write_failures(write_failures_);
    st.participant_rejoins(participant_.rejoins());
    status_writer_->write(st);
    last_status_ = now;
  }

  const NodeOptions& opt_;
  io::AxisMap map_;
  dds::Participant& participant_;
  std::unique_ptr<dds::Writer<bsn::RawSample>> raw_writer_;
  std::unique_ptr<dds::Writer<bsn::Status>> status_writer_;
  bsn::RawSample raw_;
  std::string process_id_;
  std::uint64_t seq_ = 0, received_ = 0, accepted_ = 0, accepted_at_status_ = 0, write_failures_ = 0;
  std::array<std::uint64_t, static_cast<std::size_t>(InputRejection::kCount)> rejected_{};
  std::uint64_t rejected_since_log_ = 0;
  std::string last_bad_;
  bool have_base_ = false;
  std::int64_t base_ = 0, last_device_ns_ = 0;
  std::chrono::steady_clock::time_point last_log_{}, last_status_ = std::chrono::steady_clock::now();
};

// Waits up to 50 ms for `fd` to be readable (poll's result: > 0 readable or hung up, 0 timeout, < 0 error).
int wait_readable(int fd) {
  pollfd p{fd, POLLIN, 0};
  return ::poll(&p, 1, 50);
}

speed_t baud_constant(long baud) {
  switch (baud) {
    case 9600:
      return B9600;
    case 19200:
      return B19200;
    case 38400:
      return B38400;
    case 57600:
      return B57600;
    case 115200:
      return B115200;
    case 230400:
      return B230400;
    case 460800:
      return B460800;
    case 921600:
      return B921600;
    default:
      return B0;
  }
}

void handle_line(NodePublisher& pub, std::string_view line) {
  const io::ParseResult r = io::parse_sensor_line(line);
  if (r.ok()) {
    pub.accept(r.reading, pub.line_time_scale());
  } else {
    pub.reject(r.rejection, line);
  }
}

int run_serial(NodePublisher& pub, const SourceUri& uri) {
  long baud = 115200;
  if (uri.query.count("baud")) baud = std::strtol(uri.query.at("baud").c_str(), nullptr, 10);
  const speed_t speed = baud_constant(baud);
  if (speed == B0) {
    logging::log_error("serial: unsupported baud rate ", baud, " (9600 ... 921600)");
    return 2;
  }
  io::LineAssembler lines;
  int fd = -1;
  auto last_attempt = std::chrono::steady_clock::now() - std::chrono::seconds(1);
  bool announced_wait = false;
  std::array<std::uint8_t, 4096> buf{};
  while (!dds::shutdown_requested()) {
    pub.tick();
    if (fd < 0) {
      if (std::chrono::steady_clock::now() - last_attempt < std::chrono::milliseconds(200)) {
        dds::sleep_unless_shutdown(std::chrono::milliseconds(20));
        continue;
      }
      last_attempt = std::chrono::steady_clock::now();
      fd = ::open(uri.where.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
      if (fd < 0) {
        if (!announced_wait) logging::log_warn("serial: waiting for ", uri.where, ": ", std::strerror(errno));
        announced_wait = true;
        continue;
      }
      termios tio{};
      if (tcgetattr(fd, &tio) == 0) {
        cfmakeraw(&tio);
        tio.c_cflag |= CLOCAL | CREAD;
        cfsetispeed(&tio, speed);
        cfsetospeed(&tio, speed);
        tcsetattr(fd, TCSANOW, &tio);
      }
      lines.reset();
      pub.reconnected();
      announced_wait = false;
      logging::log_info("serial: reading ", uri.where, " at ", baud, " baud");
    }
    if (wait_readable(fd) <= 0) continue;
    const ssize_t n = ::read(fd, buf.data(), buf.size());
    if (n > 0) {
      lines.feed(
          std::span<const std::uint8_t>(buf.data(), static_cast<std::size_t>(n)),
          [&pub](std::string_view line) { handle_line(pub, line); },
          [&pub] { pub.reject(InputRejection::kLineTooLong); });
    } else if (n == 0 || (errno != EAGAIN && errno != EINTR)) {
      // The device went away (unplugged: EIO, or the other end closed): drop the partial line and reconnect.
      logging::log_warn("serial: ", uri.where, " disconnected (", n == 0 ? "end of file" : std::strerror(errno),
                        "); waiting for it to come back");
      ::close(fd);
      fd = -1;
    }
  }
  if (fd >= 0) ::close(fd);
  return 0;
}

int run_udp(NodePublisher& pub, const SourceUri& uri) {
  char* end = nullptr;
  const long port = std::strtol(uri.where.c_str(), &end, 10);
  if (end == uri.where.c_str() || *end != '\0' || port < 1 || port > 65535) {
    logging::log_error("udp: '", uri.where, "' is not a port number (1..65535)");
    return 2;
  }
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_ANY);
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    logging::log_error("udp: cannot listen on port ", port, ": ", std::strerror(errno));
    if (fd >= 0) ::close(fd);
    return 1;
  }
  logging::log_info("udp: listening on port ", port);
  std::array<std::uint8_t, io::kMaxDatagram + 1> buf{};
  while (!dds::shutdown_requested()) {
    pub.tick();
    if (wait_readable(fd) <= 0) continue;
    // MSG_TRUNC returns the datagram's real length, so an oversized one is recognised, not silently cut.
    const ssize_t n = ::recv(fd, buf.data(), buf.size(), MSG_TRUNC | MSG_DONTWAIT);
    if (n < 0) continue;
    const std::size_t len = static_cast<std::size_t>(n);
    if (len > io::kMaxDatagram) {
      pub.reject(InputRejection::kOversized);
      continue;
    }
    const std::span<const std::uint8_t> dgram(buf.data(), len);
    if (len > 0 && (buf[0] == '/' || (len >= 8 && std::memcmp(buf.data(), "#bundle", 8) == 0))) {
      const io::ParseResult r = io::parse_osc_sensors(dgram);
      if (r.ok()) {
        pub.accept(r.reading, 1.0);
      } else {
        pub.reject(r.rejection);
      }
      continue;
    }
    // Line protocol: one or more lines per datagram; the last may lack its newline.
    std::string_view text(reinterpret_cast<const char*>(buf.data()), len);
    while (!text.empty()) {
      const auto nl = text.find('\n');
      handle_line(pub, text.substr(0, nl));
      if (nl == std::string_view::npos) break;
      text.remove_prefix(nl + 1);
    }
  }
  ::close(fd);
  return 0;
}

// --- IIO --------------------------------------------------------------------------------------------------------

std::optional<std::string> read_text(const fs::path& p) {
  std::ifstream f(p);
  if (!f) return std::nullopt;
  std::string s;
  std::getline(f, s);
  return s;
}

// The layout of the enabled scan elements under DIR/scan_elements, with their scales (kernel ABI units: m/s^2,
// rad/s, Gauss for the magnetometer (to uT: x100), ns for the timestamp). Throws io::IoError naming the file.
io::IioScanLayout read_iio_layout(const fs::path& sysfs) {
  const fs::path scan = sysfs / "scan_elements";
  if (!fs::is_directory(scan)) throw io::IoError(scan.string() + ": no such folder (not an IIO device with a buffer?)");
  static const std::map<std::string, int> kTargets = {
      {"in_accel_x", 0},   {"in_accel_y", 1}, {"in_accel_z", 2}, {"in_anglvel_x", 3}, {"in_anglvel_y", 4},
      {"in_anglvel_z", 5}, {"in_magn_x", 6},  {"in_magn_y", 7},  {"in_magn_z", 8},    {"in_timestamp", 9}};
  io::IioScanLayout layout;
  for (const auto& e : fs::directory_iterator(scan)) {
    const std::string file = e.path().filename().string();
    if (file.size() < 4 || file.substr(file.size() - 3) != "_en") continue;
    const std::string name = file.substr(0, file.size() - 3);
    if (read_text(e.path()).value_or("0") != "1") continue;
    io::IioScanLayout::Channel c;
    const auto index = read_text(scan / (name + "_index"));
    if (!index) throw io::IoError((scan / (name + "_index")).string() + ": missing scan element");
    c.index = std::atoi(index->c_str());
    const auto type_text = read_text(scan / (name + "_type"));
    if (!type_text) throw io::IoError((scan / (name + "_type")).string() + ": missing scan element");
    std::string error;
    const auto type = io::parse_iio_channel_type(*type_text, &error);
    if (!type) throw io::IoError((scan / (name + "_type")).string() + ": " + error);
    c.type = *type;
    const auto target = kTargets.find(name);
    c.target = target == kTargets.end() ? -1 : target->second;
    if (c.target >= 0 && c.target < 9) {
      if (c.type.repeat != 1)
        throw io::IoError((scan / (name + "_type")).string() + ": repeated elements not supported");
      const std::string kind = name.substr(0, name.rfind('_'));  // in_accel
      auto scale = read_text(sysfs / (name + "_scale"));
      if (!scale) scale = read_text(sysfs / (kind + "_scale"));
      if (!scale) throw io::IoError((sysfs / (kind + "_scale")).string() + ": missing (no scale for " + name + ")");
      c.scale = std::strtod(scale->c_str(), nullptr);
      if (!(std::isfinite(c.scale) && c.scale != 0.0)) {
        throw io::IoError((sysfs / (kind + "_scale")).string() + ": not a scale: '" + *scale + "'");
      }
      if (c.target >= 6) c.scale *= 100.0;  // Gauss -> uT
      auto offset = read_text(sysfs / (name + "_offset"));
      if (!offset) offset = read_text(sysfs / (kind + "_offset"));
      if (offset) c.value_offset = std::strtod(offset->c_str(), nullptr);
    } else if (c.target == 9) {
      c.scale = 1e-9;
    }
    layout.channels.push_back(c);
  }
  std::sort(layout.channels.begin(), layout.channels.end(),
            [](const auto& a, const auto& b) { return a.index < b.index; });
  bool any = false;
  for (const auto& c : layout.channels) any = any || (c.target >= 0 && c.target < 9);
  if (!any) throw io::IoError(scan.string() + ": no accelerometer, gyroscope or magnetometer channel is enabled");
  io::finish_iio_layout(layout);
  return layout;
}

fs::path iio_sysfs(const SourceUri& uri) {
  return uri.query.count("sysfs") ? fs::path(uri.query.at("sysfs")) : fs::path("/sys/bus/iio/devices") / uri.where;
}

int run_iio(NodePublisher& pub, const SourceUri& uri, const io::IioScanLayout& layout) {
  const fs::path sysfs = iio_sysfs(uri);
  const std::string dev = uri.query.count("dev") ? uri.query.at("dev") : "/dev/" + uri.where;
  // Starting the buffer is the kernel driver's switch; a fake tree has a plain file there.
  const fs::path enable = sysfs / "buffer" / "enable";
  if (fs::exists(enable)) std::ofstream(enable) << "1\n";
  logging::log_info("iio: ", layout.channels.size(), " channels, ", layout.scan_bytes, " bytes per scan, from ", dev);
  std::vector<std::uint8_t> pending;
  std::array<std::uint8_t, 4096> buf{};
  int fd = -1;
  while (!dds::shutdown_requested()) {
    pub.tick();
    if (fd < 0) {
      fd = ::open(dev.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
      if (fd < 0) {
        logging::log_error("iio: cannot open ", dev, ": ", std::strerror(errno));
        return 1;
      }
    }
    if (wait_readable(fd) <= 0) continue;
    const ssize_t n = ::read(fd, buf.data(), buf.size());
    if (n > 0) {
      pending.insert(pending.end(), buf.begin(), buf.begin() + n);
      std::size_t pos = 0;
      for (; pending.size() - pos >= layout.scan_bytes; pos += layout.scan_bytes) {
        const io::ParseResult r = io::parse_iio_scan({pending.data() + pos, layout.scan_bytes}, layout);
        if (r.ok()) {
          pub.accept(r.reading, 1.0);
        } else {
          pub.reject(r.rejection);
        }
      }
      pending.erase(pending.begin(), pending.begin() + static_cast<long>(pos));
    } else if (n == 0 || (errno != EAGAIN && errno != EINTR)) {
      // The writer went away (a FIFO) or the device did: a partial scan left over is a short read.
      if (!pending.empty()) pub.reject(InputRejection::kShortRead);
      pending.clear();
      ::close(fd);
      fd = -1;
      pub.reconnected();
      dds::sleep_unless_shutdown(std::chrono::milliseconds(20));
    }
  }
  if (fd >= 0) ::close(fd);
  if (fs::exists(enable)) std::ofstream(enable) << "0\n";
  return 0;
}

}  // namespace

int run_node(const NodeOptions& opt) {
  logging::set_log_identity("node " + opt.node);
  if (opt.node.empty() || opt.node.size() > 63) {
    logging::log_error("--node must have 1 to 63 characters");
    return 2;
  }
  const auto uri = parse_uri(opt.source);
  if (!uri || (uri->kind != "serial" && uri->kind != "udp" && uri->kind != "iio")) {
    logging::log_error("--source '", opt.source,
                       "' is not serial:PATH[?baud=N], udp:PORT or iio:DEVICE[?sysfs=DIR&dev=FILE]");
    return 2;
  }
  // Every parser hands over SI units (the line protocol is SI by definition, the NGIMU's documented units and the
  // IIO sysfs scales are converted), so the map's default is the identity with microsecond line times.
  io::AxisMap map;
  try {
    if (!opt.map_path.empty()) map = load_axis_map(opt.map_path, map);
  } catch (const config::ConfigError& e) {
    logging::log_error(e.what());
    return 2;
  }
  io::IioScanLayout layout;  // read before any DDS entity exists: a bad device is reported at once
  if (uri->kind == "iio") {
    try {
      layout = read_iio_layout(iio_sysfs(*uri));
    } catch (const io::IoError& e) {
      logging::log_error("iio: ", e.what());
      return 1;
    }
  }
  DdsCommandFrame frame(opt.domain, "bsn node " + opt.node);
  NodePublisher pub(frame.participant(), opt, map);
  if (uri->kind == "serial") return run_serial(pub, *uri);
  if (uri->kind == "udp") return run_udp(pub, *uri);
  return run_iio(pub, *uri, layout);
}

Command node_command() {
  return {"node", "A real sensor node: serial, UDP (lines or NGIMU OSC) or Linux IIO, published on bsn/raw",
          [](CLI::App* cmd) {
            auto opt = std::make_shared<NodeOptions>();
            cmd->add_option("--source", opt->source, "serial:PATH[?baud=N], udp:PORT or iio:DEVICE")->required();
            cmd->add_option("--node", opt->node, "node_id on bsn/raw")->required();
            cmd->add_option("--map", opt->map_path, "axis and unit map (YAML)");
            cmd->add_option("--status-period", opt->status_period_s, "seconds between bsn/status samples")
                ->check(CLI::PositiveNumber)
                ->capture_default_str();
            add_domain_option(cmd, opt->domain);
            return [opt] { return run_node(*opt); };
          }};
}

}  // namespace bsn::services
