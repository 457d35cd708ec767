// serial:PATH[?baud=N]: the bsn line protocol from a microcontroller; reconnects when the device comes back.
#include <fcntl.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <chrono>
#include <cstring>

#include "bsn/dds/shutdown.hpp"
#include "bsn/logging/log.hpp"
#include "sensor_source.hpp"

namespace bsn::services {
namespace {

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

class SerialSource final : public SensorSource {
 public:
  explicit SerialSource(const SourceUri& uri) : path_(uri.where) {
    if (uri.query.count("baud")) baud_ = std::strtol(uri.query.at("baud").c_str(), nullptr, 10);
  }
  ~SerialSource() override {
    if (fd_ >= 0) ::close(fd_);
  }

  std::optional<int> open() override {
    if (baud_constant(baud_) == B0) {
      logging::log_error("serial: unsupported baud rate ", baud_, " (9600 ... 921600)");
      return 2;
    }
    return std::nullopt;
  }

  std::optional<int> read_some(ReadingSink& sink) override {
    if (fd_ < 0 && !connect(sink)) return std::nullopt;
    if (wait_readable(fd_) <= 0) return std::nullopt;
    const ssize_t n = ::read(fd_, buf_.data(), buf_.size());
    if (n > 0) {
      lines_.feed(
          std::span<const std::uint8_t>(buf_.data(), static_cast<std::size_t>(n)),
          [&sink](std::string_view line) { handle_line(sink, line); },
          [&sink] { sink.reject(io::InputRejection::kLineTooLong); });
    } else if (n == 0 || (errno != EAGAIN && errno != EINTR)) {
      // The device went away (unplugged: EIO, or the other end closed): drop the partial line and reconnect.
      logging::log_warn("serial: ", path_, " disconnected (", n == 0 ? "end of file" : std::strerror(errno),
                        "); waiting for it to come back");
      ::close(fd_);
      fd_ = -1;
    }
    return std::nullopt;
  }

  std::string describe() const override { return "serial " + path_ + " at " + std::to_string(baud_) + " baud"; }

 private:
  /// Opens the device, at most every 200 ms; false while it is not there.
  bool connect(ReadingSink& sink) {
    if (std::chrono::steady_clock::now() - last_attempt_ < std::chrono::milliseconds(200)) {
      dds::sleep_unless_shutdown(std::chrono::milliseconds(20));
      return false;
    }
    last_attempt_ = std::chrono::steady_clock::now();
    fd_ = ::open(path_.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (fd_ < 0) {
      if (!announced_wait_) logging::log_warn("serial: waiting for ", path_, ": ", std::strerror(errno));
      announced_wait_ = true;
      return false;
    }
    termios tio{};
    if (tcgetattr(fd_, &tio) == 0) {
      cfmakeraw(&tio);
      tio.c_cflag |= CLOCAL | CREAD;
      const speed_t speed = baud_constant(baud_);
      cfsetispeed(&tio, speed);
      cfsetospeed(&tio, speed);
      tcsetattr(fd_, TCSANOW, &tio);
    }
    lines_.reset();
    sink.reconnected();
    announced_wait_ = false;
    logging::log_info("serial: reading ", path_, " at ", baud_, " baud");
    return true;
  }

  std::string path_;
  long baud_ = 115200;
  int fd_ = -1;
  io::LineAssembler lines_;
  std::chrono::steady_clock::time_point last_attempt_ = std::chrono::steady_clock::now() - std::chrono::seconds(1);
  bool announced_wait_ = false;
  std::array<std::uint8_t, 4096> buf_{};
};

}  // namespace

std::unique_ptr<SensorSource> make_serial_source(const SourceUri& uri) { return std::make_unique<SerialSource>(uri); }

}  // namespace bsn::services
