// `bsn view` under hostile clients, over real TCP on loopback: one address that opens 64 WebSockets and never
// reads them, and 70 requests that never finish, must not keep a browser at another address from the page or its
// live view; idle WebSockets are closed within seconds; with --token nothing is served without it.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <regex>
#include <string>
#include <vector>

#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;

/// A TCP connection from `source` (any 127.x.y.z: all of 127/8 is this host) to 127.0.0.1:port; -1 on failure.
class Connection {
 public:
  Connection(const char* source, int port) {
    fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd_ < 0) return;
    sockaddr_in from{};
    from.sin_family = AF_INET;
    inet_pton(AF_INET, source, &from.sin_addr);
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(static_cast<std::uint16_t>(port));
    inet_pton(AF_INET, "127.0.0.1", &to.sin_addr);
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&from), sizeof from) != 0 ||
        ::connect(fd_, reinterpret_cast<sockaddr*>(&to), sizeof to) != 0) {
      ::close(fd_);
      fd_ = -1;
    }
  }
  ~Connection() {
    if (fd_ >= 0) ::close(fd_);
  }
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;
  bool ok() const { return fd_ >= 0; }
  bool send(const std::string& text) {
    return ::send(fd_, text.data(), text.size(), MSG_NOSIGNAL) == ssize_t(text.size());
  }
  /// What arrives until the server closes, `until` is seen, or `timeout` passes.
  std::string receive(std::chrono::milliseconds timeout, const std::string& until = "") {
    std::string got;
    const auto deadline = Clock::now() + timeout;
    while (Clock::now() < deadline) {
      pollfd p{fd_, POLLIN, 0};
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
      if (::poll(&p, 1, static_cast<int>(std::max<long long>(left, 1))) <= 0) continue;
      char buf[4096];
      const ssize_t n = ::recv(fd_, buf, sizeof buf, 0);
      if (n <= 0) {
        closed_ = true;
        break;
      }
      got.append(buf, static_cast<std::size_t>(n));
      if (!until.empty() && got.find(until) != std::string::npos) break;
    }
    return got;
  }
  bool closed() const { return closed_; }

 private:
  int fd_ = -1;
  bool closed_ = false;
};

std::string get_request(const std::string& path, const std::string& extra_headers = "") {
  return "GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\n" + extra_headers + "Connection: close\r\n\r\n";
}

std::string websocket_request(const std::string& extra_headers = "") {
  return "GET /ws HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
         "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n" +
         extra_headers + "\r\n";
}

/// The status code of an HTTP response (0 if there is none).
int status_of(const std::string& response) {
  std::smatch m;
  static const std::regex line("^HTTP/1\\.[01] ([0-9]{3})");
  return std::regex_search(response, m, line) ? std::stoi(m[1]) : 0;
}

class ViewLimits : public ProcessTest {
 protected:
  /// Starts `bsn view` on a free port with `extra` options; returns the port (0 if it did not come up).
  int start_view(int domain, std::vector<std::string> extra = {}) {
    std::vector<std::string> args = {"view", "--port", "0", "--domain", std::to_string(domain)};
    args.insert(args.end(), extra.begin(), extra.end());
    spawn("view", args);
    int port = 0;
    wait_until(
        [&] {
          std::smatch m;
          const std::string text = read_file(log_path("view"));
          static const std::regex url("bsn view: http://[^:/]+:([0-9]+)/");
          if (std::regex_search(text, m, url)) port = std::stoi(m[1]);
          return port > 0;
        },
        20s);
    return port;
  }
};

TEST_F(ViewLimits, PageAndLiveViewStayReachableUnderIdleWebSocketsAndUnfinishedRequests) {
  // Listening on every interface, as for a lab: the per-address limit applies (on loopback only the total does).
  const int port = start_view(test_domain(80), {"--bind", "0.0.0.0"});
  ASSERT_GT(port, 0) << tail(log_path("view"));
  const char* kAttacker = "127.0.0.2";
  const char* kBrowser = "127.0.0.1";

  // 64 WebSockets that never read or answer anything, then 70 requests that stop half-way through their headers.
  std::vector<std::unique_ptr<Connection>> websockets, unfinished;
  int accepted = 0;
  for (int i = 0; i < 64; ++i) {
    auto c = std::make_unique<Connection>(kAttacker, port);
    ASSERT_TRUE(c->ok());
    ASSERT_TRUE(c->send(websocket_request()));
    const std::string reply = c->receive(3s, "\r\n\r\n");
    if (status_of(reply) == 101) ++accepted;
    websockets.push_back(std::move(c));
  }
  for (int i = 0; i < 70; ++i) {
    auto c = std::make_unique<Connection>(kAttacker, port);
    ASSERT_TRUE(c->ok());
    ASSERT_TRUE(c->send("GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n"));
    unfinished.push_back(std::move(c));
  }
  EXPECT_LE(accepted, 8) << "WebSockets accepted from one address";

  // A browser elsewhere loads the page and opens its live view, each at once (not after a timeout).
  for (const char* path : {"/", "/view.js"}) {
    Connection page(kBrowser, port);
    ASSERT_TRUE(page.ok());
    const auto start = Clock::now();
    ASSERT_TRUE(page.send(get_request(path)));
    const std::string reply = page.receive(5s);
    EXPECT_EQ(status_of(reply), 200) << path << ": " << reply.substr(0, 200);
    EXPECT_LT(Clock::now() - start, 1s) << path << " took this long";
  }
  Connection live(kBrowser, port);
  ASSERT_TRUE(live.ok());
  ASSERT_TRUE(live.send(websocket_request()));
  EXPECT_EQ(status_of(live.receive(2s, "\r\n\r\n")), 101) << "the browser's WebSocket";

  // The idle WebSockets are closed by the server within seconds (pinged every second, closed after 6 unanswered).
  const auto deadline = Clock::now() + 15s;
  int closed = 0;
  for (auto& c : websockets) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
    c->receive(std::max(left, std::chrono::milliseconds(1)));
    if (c->closed()) ++closed;
  }
  EXPECT_EQ(closed, 64) << "idle WebSockets still open 15 s after they were made";
  EXPECT_TRUE(child("view").running());
}

TEST_F(ViewLimits, WithATokenNothingIsServedWithoutIt) {
  const std::string token = "s3cret-token-0123456789";
  const int port = start_view(test_domain(81), {"--token", token});
  ASSERT_GT(port, 0) << tail(log_path("view"));
  EXPECT_NE(read_file(log_path("view")).find("/?token=" + token), std::string::npos) << "the URL it prints";
  auto fetch = [&](const std::string& request) {
    Connection c("127.0.0.1", port);
    EXPECT_TRUE(c.ok());
    c.send(request);
    return c.receive(5s, request.find("Upgrade") != std::string::npos ? "\r\n\r\n" : "");
  };
  EXPECT_EQ(status_of(fetch(get_request("/"))), 401);
  EXPECT_EQ(status_of(fetch(get_request("/view.js"))), 401);
  EXPECT_EQ(status_of(fetch(get_request("/?token=wrong-token-0123456789"))), 401);
  EXPECT_EQ(status_of(fetch(websocket_request())), 401);
  EXPECT_EQ(status_of(fetch(websocket_request("Cookie: bsn_view_token=wrong-token-0123456789\r\n"))), 401);
  // The URL it printed serves the page and hands the token over as a cookie for the rest.
  const std::string page = fetch(get_request("/?token=" + token));
  EXPECT_EQ(status_of(page), 200);
  EXPECT_NE(page.find("Set-Cookie: bsn_view_token=" + token + "; Path=/; HttpOnly; SameSite=Strict"), std::string::npos)
      << page.substr(0, 400);
  const std::string cookie = "Cookie: bsn_view_token=" + token + "\r\n";
  EXPECT_EQ(status_of(fetch(get_request("/view.js", cookie))), 200);
  EXPECT_EQ(status_of(fetch(websocket_request(cookie))), 101);

  // A token too short to be safe is a usage error.
  spawn("short", {"view", "--port", "0", "--token", "short", "--domain", std::to_string(test_domain(81))});
  EXPECT_EQ(exit_code(child("short").wait_for(10s)), 2) << read_file(log_path("short"));
}

}  // namespace
}  // namespace bsn::integration
