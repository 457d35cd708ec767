#include "node_service.hpp"

#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>

#include "bsn/config/body_config.hpp"
#include "bsn/config/yaml_reader.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/dds/shutdown.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/logging/log.hpp"
#include "sensor_source.hpp"

namespace bsn::services {
namespace {

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

// Everything a source hands over goes through here: rejections counted and logged at most once per second,
// readings mapped, timed and published.
class NodePublisher final : public ReadingSink {
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
  void reconnected() override { have_base_ = false; }

  void reject(InputRejection r, std::string_view sample_text = {}) override {
    ++received_;
    if (r == InputRejection::kIgnored) return;
    ++rejected_[static_cast<std::size_t>(r)];
    ++rejected_since_log_;
    if (!sample_text.empty()) last_bad_.assign(sample_text.substr(0, 60));
  }

  void accept(const io::DeviceReading& reading, double device_time_scale_s) override {
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

  double line_time_scale() const override { return map_.time_scale_s; }

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

}  // namespace

int run_node(const NodeOptions& opt) {
  logging::set_log_identity("node " + opt.node);
  if (opt.node.empty() || opt.node.size() > 63) {
    logging::log_error("--node must have 1 to 63 characters");
    return 2;
  }
  const auto uri = parse_source_uri(opt.source);
  std::unique_ptr<SensorSource> source = uri ? make_sensor_source(*uri) : nullptr;
  if (!source) {
    logging::log_error("--source '", opt.source, "' is not ", sensor_source_usages());
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
  // Opened before any DDS entity exists: a bad device is reported at once.
  if (const auto code = source->open()) return *code;
  DdsCommandFrame frame(opt.domain, "bsn node " + opt.node);
  NodePublisher pub(frame.participant(), opt, map);
  logging::log_info("publishing ", source->describe(), " on bsn/raw");
  while (!dds::shutdown_requested()) {
    pub.tick();
    if (const auto code = source->read_some(pub)) return *code;
  }
  return 0;
}

Command node_command() {
  return {"node", "A real sensor node: serial, UDP (lines or NGIMU OSC) or Linux IIO, published on bsn/raw",
          [](CLI::App* cmd) {
            auto opt = std::make_shared<NodeOptions>();
            cmd->add_option("--source", opt->source, sensor_source_usages())->required();
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
