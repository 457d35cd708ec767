// iio:DEVICE[?sysfs=DIR&dev=FILE]: the Linux Industrial I/O buffered interface. The enabled scan elements, their
// order, storage and scales come from sysfs (DIR, default /sys/bus/iio/devices/DEVICE); the scans from FILE
// (default /dev/DEVICE).
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <vector>

#include "bsn/dds/shutdown.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/logging/log.hpp"
#include "sensor_source.hpp"

namespace bsn::services {
namespace {

namespace fs = std::filesystem;

std::optional<std::string> read_text(const fs::path& p) {
  std::ifstream f(p);
  if (!f) return std::nullopt;
  std::string s;
  std::getline(f, s);
  return s;
}

// One enabled scan element's channel: storage from its _type, and for a sensor axis its scale and offset (kernel ABI
// units: m/s^2, rad/s, Gauss for the magnetometer (to uT: x100), ns for the timestamp). Throws io::IoError naming
// the file.
io::IioScanLayout::Channel read_iio_channel(const fs::path& sysfs, const std::string& name) {
  static const std::map<std::string, int> kTargets = {
      {"in_accel_x", 0},   {"in_accel_y", 1}, {"in_accel_z", 2}, {"in_anglvel_x", 3}, {"in_anglvel_y", 4},
      {"in_anglvel_z", 5}, {"in_magn_x", 6},  {"in_magn_y", 7},  {"in_magn_z", 8},    {"in_timestamp", 9}};
  const fs::path scan = sysfs / "scan_elements";
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
    if (c.type.repeat != 1) throw io::IoError((scan / (name + "_type")).string() + ": repeated elements not supported");
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
  return c;
}

// The layout of the enabled scan elements under DIR/scan_elements, in scan order. Throws io::IoError naming the file.
io::IioScanLayout read_iio_layout(const fs::path& sysfs) {
  const fs::path scan = sysfs / "scan_elements";
  if (!fs::is_directory(scan)) throw io::IoError(scan.string() + ": no such folder (not an IIO device with a buffer?)");
  io::IioScanLayout layout;
  for (const auto& e : fs::directory_iterator(scan)) {
    const std::string file = e.path().filename().string();
    if (file.size() < 4 || file.substr(file.size() - 3) != "_en") continue;
    if (read_text(e.path()).value_or("0") != "1") continue;
    layout.channels.push_back(read_iio_channel(sysfs, file.substr(0, file.size() - 3)));
  }
  std::sort(layout.channels.begin(), layout.channels.end(),
            [](const auto& a, const auto& b) { return a.index < b.index; });
  bool any = false;
  for (const auto& c : layout.channels) any = any || (c.target >= 0 && c.target < 9);
  if (!any) throw io::IoError(scan.string() + ": no accelerometer, gyroscope or magnetometer channel is enabled");
  io::finish_iio_layout(layout);
  return layout;
}

class IioSource final : public SensorSource {
 public:
  explicit IioSource(const SourceUri& uri)
      : sysfs_(uri.query.count("sysfs") ? fs::path(uri.query.at("sysfs"))
                                        : fs::path("/sys/bus/iio/devices") / uri.where),
        dev_(uri.query.count("dev") ? uri.query.at("dev") : "/dev/" + uri.where),
        enable_(sysfs_ / "buffer" / "enable") {}
  ~IioSource() override {
    if (fd_ >= 0) ::close(fd_);
    if (started_ && fs::exists(enable_)) std::ofstream(enable_) << "0\n";
  }

  std::optional<int> open() override {
    try {
      layout_ = read_iio_layout(sysfs_);
    } catch (const io::IoError& e) {
      logging::log_error("iio: ", e.what());
      return 1;
    }
    // Starting the buffer is the kernel driver's switch; a fake tree has a plain file there.
    if (fs::exists(enable_)) std::ofstream(enable_) << "1\n";
    started_ = true;
    logging::log_info("iio: ", layout_.channels.size(), " channels, ", layout_.scan_bytes, " bytes per scan, from ",
                      dev_);
    return std::nullopt;
  }

  std::optional<int> read_some(ReadingSink& sink) override {
    if (fd_ < 0) {
      fd_ = ::open(dev_.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
      if (fd_ < 0) {
        logging::log_error("iio: cannot open ", dev_, ": ", std::strerror(errno));
        return 1;
      }
    }
    if (wait_readable(fd_) <= 0) return std::nullopt;
    const ssize_t n = ::read(fd_, buf_.data(), buf_.size());
    if (n > 0) {
      pending_.insert(pending_.end(), buf_.begin(), buf_.begin() + n);
      std::size_t pos = 0;
      for (; pending_.size() - pos >= layout_.scan_bytes; pos += layout_.scan_bytes) {
        const io::ParseResult r = io::parse_iio_scan({pending_.data() + pos, layout_.scan_bytes}, layout_);
        if (r.ok()) {
          sink.accept(r.reading, 1.0);
        } else {
          sink.reject(r.rejection);
        }
      }
      pending_.erase(pending_.begin(), pending_.begin() + static_cast<long>(pos));
    } else if (n == 0 || (errno != EAGAIN && errno != EINTR)) {
      // The writer went away (a FIFO) or the device did: a partial scan left over is a short read.
      if (!pending_.empty()) sink.reject(io::InputRejection::kShortRead);
      pending_.clear();
      ::close(fd_);
      fd_ = -1;
      sink.reconnected();
      dds::sleep_unless_shutdown(std::chrono::milliseconds(20));
    }
    return std::nullopt;
  }

  std::string describe() const override { return "iio " + dev_; }

 private:
  fs::path sysfs_;
  std::string dev_;
  fs::path enable_;
  io::IioScanLayout layout_;
  bool started_ = false;
  int fd_ = -1;
  std::vector<std::uint8_t> pending_;
  std::array<std::uint8_t, 4096> buf_{};
};

}  // namespace

std::unique_ptr<SensorSource> make_iio_source(const SourceUri& uri) { return std::make_unique<IioSource>(uri); }

}  // namespace bsn::services
