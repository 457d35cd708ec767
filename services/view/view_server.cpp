#include "view_server.hpp"

#include <civetweb.h>

#include <condition_variable>
#include <cstring>
#include <deque>
#include <thread>

namespace bsn::services {

struct ViewServer::Client {
  mg_connection* conn = nullptr;
  std::mutex mutex;
  std::condition_variable wake;
  std::deque<std::shared_ptr<const std::string>> queue;
  bool closing = false;
  std::atomic<std::uint64_t> dropped{0};
  std::atomic<std::uint64_t> frames_sent{0};
  std::thread sender;
  std::chrono::nanoseconds gather{0};

  void push(std::shared_ptr<const std::string> message, std::size_t max_queue) {
    bool was_empty = false;
    {
      std::lock_guard lock(mutex);
      if (closing) return;
      was_empty = queue.empty();
      queue.push_back(std::move(message));
      while (queue.size() > max_queue) {
        queue.pop_front();
        ++dropped;
      }
    }
    // Only the first message of a frame wakes the sender (it then gathers the others): a wake-up per message costs
    // 20 browsers more than the writes themselves.
    if (was_empty) wake.notify_one();
  }

  // Sends everything queued as one frame (a JSON array), so a browser that is behind catches up in few writes.
  void run() {
    std::string frame;
    for (;;) {
      {
        std::unique_lock lock(mutex);
        wake.wait(lock, [this] { return closing || !queue.empty(); });
        if (wake.wait_for(lock, gather, [this] { return closing; })) return;
        frame = "[";
        for (const auto& m : queue) {
          if (frame.size() > 1) frame += ',';
          frame += *m;
        }
        frame += ']';
        queue.clear();
      }
      if (mg_websocket_write(conn, MG_WEBSOCKET_OPCODE_TEXT, frame.data(), frame.size()) <= 0) return;  // gone
      ++frames_sent;
    }
  }
};

namespace {

int send_error(mg_connection* conn, int code, const char* text) {
  mg_printf(conn,
            "HTTP/1.1 %d %s\r\nContent-Type: text/plain\r\nContent-Length: %zu\r\nConnection: close\r\n"
            "X-Content-Type-Options: nosniff\r\n\r\n%s",
            code, text, std::strlen(text), text);
  return code;
}

constexpr const char* kTokenCookie = "bsn_view_token";

// Compares without an early exit, so the time taken says nothing about how much of a guess was right.
bool same_secret(const std::string& a, const std::string& b) {
  unsigned char differ = a.size() == b.size() ? 0 : 1;
  for (std::size_t i = 0; i < a.size(); ++i) differ |= static_cast<unsigned char>(a[i] ^ (i < b.size() ? b[i] : 0));
  return differ == 0;
}

std::string remote_address(const mg_connection* conn) {
  const mg_request_info* info = mg_get_request_info(conn);
  return info != nullptr ? info->remote_addr : "";
}

ViewServer* server_of(const mg_connection* conn) {
  return static_cast<ViewServer*>(mg_get_user_data(mg_get_context(conn)));
}

}  // namespace

bool ViewServer::token_ok(const mg_connection* conn, bool& set_cookie) const {
  set_cookie = false;
  if (options_.token.empty()) return true;
  const mg_request_info* info = mg_get_request_info(conn);
  char given[256] = "";
  if (info->query_string != nullptr &&
      mg_get_var(info->query_string, std::strlen(info->query_string), "token", given, sizeof given) > 0) {
    set_cookie = same_secret(given, options_.token);
    return set_cookie;
  }
  const char* cookies = mg_get_header(conn, "Cookie");
  return cookies != nullptr && mg_get_cookie(cookies, kTokenCookie, given, sizeof given) > 0 &&
         same_secret(given, options_.token);
}

// Every connection ends here, also a WebSocket whose handshake failed after on_ws_connect accepted it.
void ViewServer::on_connection_close(const mg_connection* conn) {
  ViewServer* self = server_of(conn);
  if (self == nullptr) return;
  std::lock_guard lock(self->mutex_);
  const auto ws = self->websocket_peer_.find(conn);
  if (ws == self->websocket_peer_.end()) return;
  if (const auto peer = self->websockets_of_.find(ws->second);
      peer != self->websockets_of_.end() && --peer->second <= 0)
    self->websockets_of_.erase(peer);
  self->websocket_peer_.erase(ws);
}

ViewServer::ViewServer(Options options) : options_(std::move(options)) {
  const std::string listen = options_.bind + ":" + std::to_string(options_.port);
  const std::string threads = std::to_string(options_.max_connections);
  const std::string request_timeout = std::to_string(options_.request_timeout_ms);
  const std::string ping = std::to_string(options_.websocket_ping_ms);
  // Each connection, a WebSocket for its whole life and a page request until it is answered or times out, holds one
  // civetweb worker thread; the limits in Options keep some of them for page requests whatever one client does.
  const char* config[] = {"listening_ports", listen.c_str(), "num_threads", threads.c_str(), "request_timeout_ms",
                          request_timeout.c_str(),  // a client that sends half a request is cut off
                          "max_request_size",
                          "8192",  // request line + headers; larger gets 413
                          "enable_keep_alive", "no", "enable_directory_listing", "no",
                          // The page only listens; civetweb pings a silent WebSocket every websocket_timeout_ms and
                          // closes it after 6 unanswered pings (MG_MAX_UNANSWERED_PING), so one that does not even
                          // answer pings (not a browser) frees its worker within seconds.
                          "websocket_timeout_ms", ping.c_str(), "enable_websocket_ping_pong", "yes", nullptr};
  mg_callbacks callbacks{};
  callbacks.log_message = [](const mg_connection*, const char*) { return 1; };  // quiet: errors come from mg_start2
  callbacks.connection_close = &ViewServer::on_connection_close;
  mg_init_data init{};
  init.callbacks = &callbacks;
  init.user_data = this;
  init.configuration_options = config;
  char error_text[256] = "";
  unsigned error_code = 0;
  mg_error_data error{&error_code, error_text, sizeof error_text};
  ctx_ = mg_start2(&init, &error);
  if (ctx_ == nullptr) {
    throw ViewServerError("cannot listen on " + listen + " (port " + std::to_string(options_.port) +
                          " in use, or the address is not one of this machine's): " + error_text);
  }
  mg_server_port ports[4]{};
  port_ = mg_get_server_ports(ctx_, 4, ports) > 0 ? ports[0].port : options_.port;
  mg_set_websocket_handler(ctx_, "/ws", &ViewServer::on_ws_connect, &ViewServer::on_ws_ready, &ViewServer::on_ws_data,
                           &ViewServer::on_ws_close, this);
  mg_set_request_handler(ctx_, "/", &ViewServer::on_http, this);
}

ViewServer::~ViewServer() {
  if (ctx_ != nullptr) mg_stop(ctx_);  // calls on_ws_close for every browser, which stops its sender
}

int ViewServer::on_http(mg_connection* conn, void* self_ptr) {
  auto* self = static_cast<ViewServer*>(self_ptr);
  const mg_request_info* info = mg_get_request_info(conn);
  const std::string method = info->request_method ? info->request_method : "";
  if (method != "GET" && method != "HEAD") return send_error(conn, 405, "method not allowed");
  // The raw URI, before civetweb decodes or cleans it, is looked up as it is in a fixed table: "/../x",
  // "/%2e%2e/x" and any other spelling are simply not in it. No path ever reaches the file system.
  std::string path = info->request_uri ? info->request_uri : "";
  if (const auto q = path.find('?'); q != std::string::npos) path.resize(q);
  if (path == "/") path = "/index.html";
  bool set_cookie = false;
  if (!self->token_ok(conn, set_cookie)) {
    ++self->refused_token_;
    return send_error(conn, 401, "this view needs its token: open the URL bsn view printed, with ?token=...");
  }
  const auto it = self->options_.assets.find(path);
  if (it == self->options_.assets.end()) return send_error(conn, 404, "not found");
  const Asset& asset = it->second;
  // The token in the URL becomes a cookie for the page's scripts and its WebSocket (same origin only).
  const std::string cookie = set_cookie ? std::string("Set-Cookie: ") + kTokenCookie + "=" + self->options_.token +
                                              "; Path=/; HttpOnly; SameSite=Strict\r\n"
                                        : "";
  mg_printf(conn,
            "HTTP/1.1 200 OK\r\nContent-Type: %s\r\nContent-Length: %zu\r\nCache-Control: no-cache\r\n"
            "X-Content-Type-Options: nosniff\r\n%sConnection: close\r\n\r\n",
            asset.content_type.c_str(), asset.body.size(), cookie.c_str());
  if (method == "GET") mg_write(conn, asset.body.data(), asset.body.size());
  return 200;
}

int ViewServer::on_ws_connect(const mg_connection* conn, void* self_ptr) {
  auto* self = static_cast<ViewServer*>(self_ptr);
  // Refusals answer in plain HTTP (the handshake has not happened) and return non-zero: civetweb closes.
  auto* writable = const_cast<mg_connection*>(conn);
  bool set_cookie = false;
  if (!self->token_ok(conn, set_cookie)) {
    ++self->refused_token_;
    send_error(writable, 401, "this view needs its token");
    return 1;
  }
  const std::string address = remote_address(conn);
  {
    std::lock_guard lock(self->mutex_);
    int& of_address = self->websockets_of_[address];
    if (static_cast<int>(self->websocket_peer_.size()) < self->options_.max_websockets &&
        of_address < self->options_.max_websockets_per_client) {
      ++of_address;
      self->websocket_peer_[conn] = address;
      return 0;  // accept
    }
    if (of_address == 0) self->websockets_of_.erase(address);
  }
  ++self->refused_busy_;
  send_error(writable, 503, "too many live views open at once");
  return 1;
}

void ViewServer::on_ws_ready(mg_connection* conn, void* self_ptr) {
  auto* self = static_cast<ViewServer*>(self_ptr);
  auto client = std::make_shared<Client>();
  client->conn = conn;
  client->gather = std::chrono::nanoseconds(static_cast<std::int64_t>(self->options_.gather_ms * 1e6));
  // The snapshot is taken outside mutex_: its provider locks the state, whose owner broadcasts (taking mutex_)
  // under that lock, so taking it inside would invert the order. A message broadcast between the snapshot and the
  // registration is lost to this browser only; the next one of its segment comes within 1/30 s.
  if (self->options_.snapshot)
    for (auto& m : self->options_.snapshot())
      client->push(std::make_shared<const std::string>(std::move(m)), self->options_.max_queue);
  {
    std::lock_guard lock(self->mutex_);
    self->clients_[conn] = client;
  }
  client->sender = std::thread([c = client.get()] { c->run(); });
}

int ViewServer::on_ws_data(mg_connection*, int bits, char*, std::size_t, void* self_ptr) {
  // The page sends nothing; whatever a browser sends is counted and ignored. A close frame ends the connection.
  static_cast<ViewServer*>(self_ptr)->frames_received_++;
  return (bits & 0x0f) == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE ? 0 : 1;
}

void ViewServer::on_ws_close(const mg_connection* conn, void* self_ptr) {
  auto* self = static_cast<ViewServer*>(self_ptr);
  std::shared_ptr<Client> client;
  {
    std::lock_guard lock(self->mutex_);
    auto it = self->clients_.find(conn);
    if (it == self->clients_.end()) return;
    client = it->second;
    self->clients_.erase(it);
  }
  {
    std::lock_guard lock(client->mutex);
    client->closing = true;
  }
  client->wake.notify_one();
  if (client->sender.joinable()) client->sender.join();  // before civetweb frees the connection
  self->dropped_closed_ += client->dropped.load();
  self->frames_sent_closed_ += client->frames_sent.load();
}

void ViewServer::broadcast(const std::string& message) {
  auto shared = std::make_shared<const std::string>(message);
  std::lock_guard lock(mutex_);
  for (auto& [conn, client] : clients_) client->push(shared, options_.max_queue);
}

ViewServer::Stats ViewServer::stats() const {
  Stats s;
  std::lock_guard lock(mutex_);
  s.clients = clients_.size();
  s.dropped = dropped_closed_.load();
  s.frames_sent = frames_sent_closed_.load();
  for (const auto& [conn, client] : clients_) {
    s.dropped += client->dropped.load();
    s.frames_sent += client->frames_sent.load();
  }
  s.frames_received = frames_received_.load();
  s.refused_busy = refused_busy_.load();
  s.refused_token = refused_token_.load();
  return s;
}

}  // namespace bsn::services
