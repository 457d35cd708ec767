// The HTTP and WebSocket side of `bsn view` (civetweb): a fixed table of assets (nothing else on disk is ever
// served), and one WebSocket endpoint, /ws, that pushes JSON messages to every browser. Each browser has its own
// bounded queue and sender thread: a slow or stuck browser loses its own oldest messages (counted), never slows
// the others or the DDS threads that broadcast.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

struct mg_context;
struct mg_connection;

namespace bsn::services {

/// The server cannot start (the port is in use, the address is not local, ...); the message names the address.
struct ViewServerError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class ViewServer {
 public:
  struct Asset {
    std::string content_type;
    std::string body;
  };
  struct Options {
    std::string bind = "127.0.0.1";
    int port = 8080;  ///< 0: any free port (see port())
    /// Messages queued per browser; beyond it the oldest are dropped and counted. 256 is about 1 s of a 7-segment
    /// body's orientations, truth and joint angles at 30 Hz: a browser that falls further behind sees the present.
    std::size_t max_queue = 256;
    /// A message waits this long for others before its frame goes, ms: what arrives meanwhile goes in the same
    /// frame. A 7-segment body with truth gives ~600 messages/s per browser, in bursts (a sample's orientation,
    /// truth and joint angles); one frame per message costs 20 browsers about twice the writes.
    double gather_ms = 2.0;
    std::map<std::string, Asset> assets;  ///< URL path ("/index.html") -> what it serves; "/" serves "/index.html"
    /// Connections served at once (civetweb's worker threads; each WebSocket holds one for its life). More wait in
    /// the kernel's listen queue until one ends.
    int max_connections = 128;
    /// WebSockets at once, of all browsers: the rest of max_connections always serves page requests.
    int max_websockets = 64;
    /// WebSockets at once from one address (a lab's browsers come from their own machines).
    int max_websockets_per_client = 8;
    /// A request whose line and headers have not all come within this is cut off, ms.
    int request_timeout_ms = 3000;
    /// A WebSocket silent this long is pinged; one silent for 6 pings more (a browser answers every ping) is
    /// closed, ms.
    int websocket_ping_ms = 1000;
    /// When not empty, every request needs it: `?token=...` on the page's URL (which sets a cookie for the rest of
    /// the page's requests and its WebSocket) or that cookie.
    std::string token;
    /// The first messages of a new browser. Called without the server's lock, so it may take locks that are held
    /// around broadcast().
    std::function<std::vector<std::string>()> snapshot;
  };
  struct Stats {
    std::size_t clients = 0;
    std::uint64_t dropped = 0;          ///< messages dropped for slow browsers, all browsers since the start
    std::uint64_t frames_sent = 0;      ///< WebSocket frames written
    std::uint64_t frames_received = 0;  ///< frames browsers sent (ignored)
    std::uint64_t refused_busy = 0;     ///< WebSockets refused (503) for the per-address or total limit
    std::uint64_t refused_token = 0;    ///< requests refused (401) without the token
  };

  /// Starts listening; throws ViewServerError.
  explicit ViewServer(Options options);
  ~ViewServer();  ///< closes every connection
  ViewServer(const ViewServer&) = delete;
  ViewServer& operator=(const ViewServer&) = delete;

  /// The port it listens on (the chosen one if Options::port was 0).
  int port() const { return port_; }
  /// Queues `message` for every browser connected now.
  void broadcast(const std::string& message);
  Stats stats() const;

  struct Client;  // public for civetweb's C callbacks

 private:
  static int on_http(mg_connection* conn, void* self);
  static int on_ws_connect(const mg_connection* conn, void* self);
  static void on_ws_ready(mg_connection* conn, void* self);
  static int on_ws_data(mg_connection* conn, int bits, char* data, std::size_t len, void* self);
  static void on_ws_close(const mg_connection* conn, void* self);
  static void on_connection_close(const mg_connection* conn);
  /// True if the request carries the token (or none is needed); `set_cookie` then says whether it came in the URL.
  bool token_ok(const mg_connection* conn, bool& set_cookie) const;

  Options options_;
  mg_context* ctx_ = nullptr;
  int port_ = 0;
  mutable std::mutex mutex_;
  std::map<const mg_connection*, std::shared_ptr<Client>> clients_;
  std::map<std::string, int> websockets_of_;                    ///< WebSockets open, by remote address
  std::map<const mg_connection*, std::string> websocket_peer_;  ///< WebSockets accepted and not yet closed
  std::atomic<std::uint64_t> refused_busy_{0};
  std::atomic<std::uint64_t> refused_token_{0};
  std::atomic<std::uint64_t> dropped_closed_{0};  ///< drops of browsers that have gone
  std::atomic<std::uint64_t> frames_sent_closed_{0};
  std::atomic<std::uint64_t> frames_received_{0};
};

}  // namespace bsn::services
