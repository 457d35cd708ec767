// bsn view's server on loopback, without DDS: what a hostile or broken browser can do to it.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <string>
#include <thread>

#include "view_server.hpp"

namespace bsn::services {
namespace {

using Clock = std::chrono::steady_clock;

/// A TCP connection to 127.0.0.1:port (closed on destruction).
class Socket {
 public:
  explicit Socket(int port, int receive_buffer = 0) {
    fd_ = socket(AF_INET, SOCK_STREAM, 0);
    if (receive_buffer > 0) setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &receive_buffer, sizeof receive_buffer);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(static_cast<std::uint16_t>(port));
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = connect(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0;
  }
  ~Socket() { close(fd_); }
  bool connected() const { return connected_; }
  /// Sends all of `data` (false if the server closed the connection meanwhile).
  bool send_all(const std::string& data) {
    std::size_t done = 0;
    while (done < data.size()) {
      const ssize_t n = send(fd_, data.data() + done, data.size() - done, MSG_NOSIGNAL);
      if (n <= 0) return false;
      done += static_cast<std::size_t>(n);
    }
    return true;
  }
  /// Reads until the server closes, `until` appears, or `timeout` passes.
  std::string receive(std::chrono::milliseconds timeout = std::chrono::milliseconds(5000),
                      const std::string& until = "") {
    std::string out;
    const auto end = Clock::now() + timeout;
    char buf[65536];
    while (Clock::now() < end) {
      pollfd p{fd_, POLLIN, 0};
      if (poll(&p, 1, 50) <= 0) continue;
      const ssize_t n = recv(fd_, buf, sizeof buf, 0);
      if (n <= 0) break;
      out.append(buf, static_cast<std::size_t>(n));
      if (!until.empty() && out.find(until) != std::string::npos) break;
    }
    return out;
  }

 private:
  int fd_ = -1;
  bool connected_ = false;
};

std::string get(int port, const std::string& target) {
  Socket s(port);
  s.send_all("GET " + target + " HTTP/1.1\r\nHost: localhost\r\n\r\n");
  return s.receive();
}

int status_of(const std::string& response) {
  if (response.rfind("HTTP/1.", 0) != 0 || response.size() < 12) return 0;
  return std::stoi(response.substr(9, 3));
}

/// A WebSocket client frame (browsers mask theirs).
std::string ws_frame(int opcode, const std::string& payload, bool mask = true) {
  std::string f;
  f += static_cast<char>(0x80 | opcode);
  const char m = mask ? static_cast<char>(0x80) : 0;
  if (payload.size() < 126) {
    f += static_cast<char>(m | static_cast<char>(payload.size()));
  } else {
    f += static_cast<char>(m | 126);
    f += static_cast<char>(payload.size() >> 8);
    f += static_cast<char>(payload.size() & 0xff);
  }
  const char key[4] = {0x11, 0x22, 0x33, 0x44};
  if (mask) f.append(key, 4);
  for (std::size_t i = 0; i < payload.size(); ++i) f += mask ? static_cast<char>(payload[i] ^ key[i % 4]) : payload[i];
  return f;
}

const char* kUpgrade =
    "GET /ws HTTP/1.1\r\nHost: localhost\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n";

class ViewServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::signal(SIGPIPE, SIG_IGN);
    ViewServer::Options o;
    o.port = 0;
    o.max_queue = 16;
    o.assets["/index.html"] = {"text/html", "<html>the page</html>"};
    o.assets["/lib/three.min.js"] = {"text/javascript", "var THREE;"};
    o.snapshot = [] { return std::vector<std::string>{"{\"k\":\"hello\"}"}; };
    server = std::make_unique<ViewServer>(o);
    port = server->port();
    ASSERT_GT(port, 0);
  }
  /// True if a fresh browser still gets the page and a live message: the server is unharmed.
  bool still_serves() {
    if (get(port, "/").find("the page") == std::string::npos) return false;
    Socket ws(port);
    ws.send_all(kUpgrade);
    if (ws.receive(std::chrono::milliseconds(5000), "hello").find("hello") == std::string::npos) return false;
    return true;
  }
  std::unique_ptr<ViewServer> server;
  int port = 0;
};

TEST_F(ViewServerTest, ServesTheAssetsAndNothingElse) {
  const std::string page = get(port, "/");
  EXPECT_EQ(status_of(page), 200);
  EXPECT_NE(page.find("the page"), std::string::npos);
  EXPECT_EQ(status_of(get(port, "/lib/three.min.js")), 200);
  EXPECT_EQ(status_of(get(port, "/index.html?x=1")), 200);
  EXPECT_EQ(status_of(get(port, "/nothing.js")), 404);
}

TEST_F(ViewServerTest, PathTraversalGets404AndNeverAFile) {
  for (const std::string target :
       {"/../../etc/passwd", "/../../../../../../etc/passwd", "/%2e%2e/%2e%2e/etc/passwd",
        "/%2E%2E%2F%2E%2E%2Fetc%2Fpasswd", "/lib/../../../etc/passwd", "/lib/%2e%2e/%2e%2e/etc/passwd",
        "/..%2f..%2fetc/passwd", "/%252e%252e/etc/passwd", "/./index.html/../../etc/passwd", "/etc/passwd",
        "//etc/passwd", "/lib/..%5c..%5cetc%5cpasswd", "/%c0%ae%c0%ae/%c0%ae%c0%ae/etc/passwd", "/proc/self/environ"}) {
    const std::string r = get(port, target);
    EXPECT_EQ(status_of(r), 404) << target << ":\n" << r;
    EXPECT_EQ(r.find("root:"), std::string::npos) << target;
  }
  // civetweb decodes %00 and the path ends at the NUL: this is the page itself, an asset, never another file.
  const std::string nul = get(port, "/index.html%00.js");
  EXPECT_TRUE(status_of(nul) == 404 || nul.find("the page") != std::string::npos) << nul;
}

TEST_F(ViewServerTest, OtherMethodsAreRefused) {
  Socket s(port);
  s.send_all("POST /index.html HTTP/1.1\r\nHost: x\r\nContent-Length: 4\r\n\r\nabcd");
  EXPECT_EQ(status_of(s.receive()), 405);
  Socket d(port);
  d.send_all("DELETE / HTTP/1.1\r\nHost: x\r\n\r\n");
  EXPECT_EQ(status_of(d.receive()), 405);
}

TEST_F(ViewServerTest, OversizedAndMalformedRequestsAreRefused) {
  {  // a header far beyond max_request_size (8 kB): refused, or the connection cut, never served
    Socket s(port);
    s.send_all("GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + std::string(64 * 1024, 'a') + "\r\n\r\n");
    const std::string r = s.receive();
    EXPECT_TRUE(r.empty() || status_of(r) >= 400) << r.substr(0, 200);
    EXPECT_EQ(r.find("the page"), std::string::npos);
  }
  {  // a target of 20 kB
    Socket s(port);
    s.send_all("GET /" + std::string(20 * 1024, 'x') + " HTTP/1.1\r\nHost: x\r\n\r\n");
    const std::string r = s.receive();
    EXPECT_TRUE(r.empty() || status_of(r) >= 400) << r.substr(0, 200);
  }
  for (const std::string& bad :
       {std::string("\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03", 11),  // a TLS hello
        std::string("GARBAGE\r\n\r\n"), std::string("GET\r\n\r\n"), std::string("GET / HTTP/9.9\r\n\r\n"),
        std::string("GET / HTTP/1.1\r\nBad header\r\n\r\n"), std::string("\0\0\0\0\r\n\r\n", 8)}) {
    Socket s(port);
    s.send_all(bad);
    const std::string r = s.receive(std::chrono::milliseconds(3000));
    EXPECT_EQ(r.find("the page"), std::string::npos) << "served a page to: " << bad;
  }
  {  // half a request, then silence: the request timeout frees the worker; others are served meanwhile
    Socket s(port);
    s.send_all("GET / HTTP/1.1\r\nHost: x\r\n");
    EXPECT_TRUE(still_serves());
  }
  EXPECT_TRUE(still_serves());
}

TEST_F(ViewServerTest, FramesFromABrowserAreIgnoredNeverACrash) {
  Socket ws(port);
  ws.send_all(kUpgrade);
  ASSERT_NE(ws.receive(std::chrono::milliseconds(5000), "hello").find("101"), std::string::npos);
  ws.send_all(ws_frame(0x1, "{\"k\":\"o\",\"seg\":\"x\"}"));  // text, as if it were a message
  ws.send_all(ws_frame(0x2, std::string(1000, '\xff')));      // binary
  ws.send_all(ws_frame(0x1, std::string(60000, 'a')));        // large text
  ws.send_all(ws_frame(0x9, "ping"));                         // ping
  ws.send_all(ws_frame(0x3, "reserved opcode"));
  ws.send_all(ws_frame(0x1, "not masked", false));
  ws.send_all(std::string("\x81\xff\x7f\xff\xff\xff\xff\xff\xff\xff", 10));  // claims an 2^63-byte payload
  ws.send_all(std::string(5000, '\0'));
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_TRUE(still_serves());
  server->broadcast("{\"k\":\"after\"}");
  EXPECT_TRUE(still_serves());
}

// Reads one client's frames from a second socket and counts those holding `needle`.
TEST_F(ViewServerTest, AStuckBrowserNeverSlowsTheOthersAndItsDropsAreCounted) {
  // The stuck browser: handshake, then it never reads again (a small receive buffer fills at once).
  Socket stuck(port, 4096);
  stuck.send_all(kUpgrade);
  ASSERT_NE(stuck.receive(std::chrono::milliseconds(5000), "hello").find("101"), std::string::npos);
  Socket live(port);
  live.send_all(kUpgrade);
  ASSERT_NE(live.receive(std::chrono::milliseconds(5000), "hello").find("101"), std::string::npos);
  ASSERT_TRUE([&] {
    const auto end = Clock::now() + std::chrono::seconds(5);
    while (server->stats().clients < 2 && Clock::now() < end)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    return server->stats().clients == 2;
  }());

  // 2000 messages of 1 kB (2 MB: far more than the stuck socket's buffers hold), each broadcast timed: the call
  // only queues, so no broadcast may wait on the stuck browser.
  const std::string pad(1000, 'p');
  double slowest_ms = 0.0;
  std::string seen;
  for (int i = 0; i < 2000; ++i) {
    const auto t = Clock::now();
    server->broadcast("{\"k\":\"n\",\"i\":" + std::to_string(i) + ",\"pad\":\"" + pad + "\"}");
    slowest_ms = std::max(slowest_ms, std::chrono::duration<double, std::milli>(Clock::now() - t).count());
    if (i % 100 == 99) seen += live.receive(std::chrono::milliseconds(20));
  }
  if (seen.find("\"i\":1999,") == std::string::npos)
    seen += live.receive(std::chrono::milliseconds(5000), "\"i\":1999,");
  // The live browser got the last message; broadcasting took no socket time. 50 ms: a scheduling hiccup on a loaded
  // 2-core machine, while one blocking write to the stuck socket would wait for civetweb's timeout (seconds).
  EXPECT_NE(seen.find("\"i\":1999,"), std::string::npos);
  EXPECT_LT(slowest_ms, 50.0);
  // The stuck browser's queue (16) overflowed: most of its 2000 messages were dropped, and counted.
  EXPECT_GT(server->stats().dropped, 1000u);
}

TEST(ViewServer, PortInUseIsAClearErrorNamingThePort) {
  ViewServer::Options o;
  o.port = 0;
  ViewServer first(o);
  o.port = first.port();
  try {
    ViewServer second(o);
    FAIL() << "a second server on the same port started";
  } catch (const ViewServerError& e) {
    EXPECT_NE(std::string(e.what()).find("port " + std::to_string(o.port)), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace bsn::services
