// udp:PORT: the bsn line protocol in UDP datagrams (one or more lines each), or x-io NGIMU OSC /sensors messages.
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>

#include "bsn/logging/log.hpp"
#include "sensor_source.hpp"

namespace bsn::services {
namespace {

class UdpSource final : public SensorSource {
 public:
  explicit UdpSource(const SourceUri& uri) : where_(uri.where) {}
  ~UdpSource() override {
    if (fd_ >= 0) ::close(fd_);
  }

  std::optional<int> open() override {
    char* end = nullptr;
    port_ = std::strtol(where_.c_str(), &end, 10);
    if (end == where_.c_str() || *end != '\0' || port_ < 1 || port_ > 65535) {
      logging::log_error("udp: '", where_, "' is not a port number (1..65535)");
      return 2;
    }
    fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(static_cast<std::uint16_t>(port_));
    addr.sin_addr.s_addr = htonl(INADDR_ANY);
    if (fd_ < 0 || ::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
      logging::log_error("udp: cannot listen on port ", port_, ": ", std::strerror(errno));
      return 1;
    }
    logging::log_info("udp: listening on port ", port_);
    return std::nullopt;
  }

  std::optional<int> read_some(ReadingSink& sink) override {
    if (wait_readable(fd_) <= 0) return std::nullopt;
    // MSG_TRUNC returns the datagram's real length, so an oversized one is recognised, not silently cut.
    const ssize_t n = ::recv(fd_, buf_.data(), buf_.size(), MSG_TRUNC | MSG_DONTWAIT);
    if (n < 0) return std::nullopt;
    const std::size_t len = static_cast<std::size_t>(n);
    if (len > io::kMaxDatagram) {
      sink.reject(io::InputRejection::kOversized);
      return std::nullopt;
    }
    if (len > 0 && (buf_[0] == '/' || (len >= 8 && std::memcmp(buf_.data(), "#bundle", 8) == 0))) {
      const io::ParseResult r = io::parse_osc_sensors(std::span<const std::uint8_t>(buf_.data(), len));
      if (r.ok()) {
        sink.accept(r.reading, 1.0);
      } else {
        sink.reject(r.rejection);
      }
      return std::nullopt;
    }
    // Line protocol: one or more lines per datagram; the last may lack its newline.
    std::string_view text(reinterpret_cast<const char*>(buf_.data()), len);
    while (!text.empty()) {
      const auto nl = text.find('\n');
      handle_line(sink, text.substr(0, nl));
      if (nl == std::string_view::npos) break;
      text.remove_prefix(nl + 1);
    }
    return std::nullopt;
  }

  std::string describe() const override { return "udp port " + where_; }

 private:
  std::string where_;
  long port_ = 0;
  int fd_ = -1;
  std::array<std::uint8_t, io::kMaxDatagram + 1> buf_{};
};

}  // namespace

std::unique_ptr<SensorSource> make_udp_source(const SourceUri& uri) { return std::make_unique<UdpSource>(uri); }

}  // namespace bsn::services
