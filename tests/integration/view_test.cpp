// `bsn view` as a process: a clear error for a port in use, and the page in a real browser (headless Chromium,
// driven over the DevTools protocol) on a running simulated body.
#include <civetweb.h>
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <map>
#include <mutex>
#include <numbers>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bsn/dds/participant.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/fusion/rotation.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;
using SampleInfo = eprosima::fastdds::dds::SampleInfo;

/// The port `bsn view` printed in its first line ("bsn view: http://HOST:PORT/ ..."), or 0 until it has.
int printed_port(const std::filesystem::path& log) {
  std::smatch m;
  const std::string text = read_file(log);
  static const std::regex url("bsn view: http://[^:/]+:([0-9]+)/");
  return std::regex_search(text, m, url) ? std::stoi(m[1]) : 0;
}

TEST_F(ProcessTest, ViewPortInUseIsAClearErrorNamingThePort) {
  auto& first = spawn("first", {"view", "--port", "0", "--domain", std::to_string(test_domain(65))});
  int port = 0;
  ASSERT_TRUE(wait_until([&] { return (port = printed_port(log_path("first"))) > 0; }, 20s)) << tail(log_path("first"));
  auto& second = spawn("second", {"view", "--port", std::to_string(port), "--domain", std::to_string(test_domain(65))});
  const auto status = second.wait_for(20s);
  ASSERT_TRUE(status.has_value()) << "bsn view on a port in use did not exit";
  EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 2) << describe_status(status);
  const std::string out = read_file(log_path("second"));
  EXPECT_NE(out.find("port " + std::to_string(port) + " in use"), std::string::npos) << out;
  EXPECT_TRUE(first.running());
}

// ---- a small DevTools-protocol client (civetweb's WebSocket client) -------------------------------------------

/// One HTTP GET on loopback, the whole response ("" on failure).
std::string http_get(int port, const std::string& path) {
  mg_init_library(0);  // counted: once per call is fine
  char error[256] = "";
  mg_connection* conn = mg_download("127.0.0.1", port, 0, error, sizeof error,
                                    "GET %s HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n", path.c_str());
  if (conn == nullptr) {
    return "";
  }
  std::string body;
  char buf[4096];
  for (int n; (n = mg_read(conn, buf, sizeof buf)) > 0;) body.append(buf, static_cast<std::size_t>(n));
  mg_close_connection(conn);
  return body;
}

/// The first JSON string value of `key` in `json`, unescaped ("" if absent).
std::string json_string_value(const std::string& json, const std::string& key) {
  const std::string name = "\"" + key + "\":";
  auto at = json.find(name);
  if (at == std::string::npos) return "";
  at = json.find_first_not_of(' ', at + name.size());
  if (at == std::string::npos || json[at] != '"') return "";
  std::string out;
  for (std::size_t i = at + 1; i < json.size(); ++i) {
    char c = json[i];
    if (c == '"') break;
    if (c == '\\' && i + 1 < json.size()) {
      c = json[++i];
      if (c == 'n')
        c = '\n';
      else if (c == 't')
        c = '\t';
      else if (c == 'u' && i + 4 < json.size()) {
        c = static_cast<char>(std::stoi(json.substr(i + 1, 4), nullptr, 16));
        i += 4;
      }
    }
    out += c;
  }
  return out;
}

/// A DevTools-protocol session with one page of a browser started with --remote-debugging-port.
class DevTools {
 public:
  bool connect(int port, const std::string& path) {
    mg_init_library(0);
    char error[256] = "";
    conn_ = mg_connect_websocket_client("127.0.0.1", port, 0, error, sizeof error, path.c_str(), nullptr,
                                        &DevTools::on_data, &DevTools::on_close, this);
    if (conn_ == nullptr) ADD_FAILURE() << "DevTools connection: " << error;
    return conn_ != nullptr;
  }
  ~DevTools() {
    if (conn_ != nullptr) mg_close_connection(conn_);
  }
  /// Sends a command and returns its reply ("" after `timeout`).
  std::string call(const std::string& method, const std::string& params_json, std::chrono::milliseconds timeout = 10s) {
    const int id = ++last_id_;
    const std::string msg =
        "{\"id\":" + std::to_string(id) + ",\"method\":\"" + method + "\",\"params\":" + params_json + "}";
    mg_websocket_client_write(conn_, MG_WEBSOCKET_OPCODE_TEXT, msg.data(), msg.size());
    const std::string prefix = "{\"id\":" + std::to_string(id) + ",";
    std::unique_lock lock(mutex_);
    std::string reply;
    wake_.wait_for(lock, timeout, [&] {
      for (auto it = messages_.begin(); it != messages_.end(); ++it) {
        if (it->rfind(prefix, 0) == 0) {
          reply = std::move(*it);
          messages_.erase(it);
          return true;
        }
      }
      return false;
    });
    return reply;
  }
  /// Evaluates a JavaScript expression in the page; its value as a string.
  std::string eval(const std::string& expression) {
    std::string quoted = "\"";
    for (char c : expression) {
      if (c == '"' || c == '\\') quoted += '\\';
      quoted += c == '\n' ? ' ' : c;
    }
    quoted += "\"";
    const std::string reply =
        call("Runtime.evaluate", "{\"expression\":" + quoted + ",\"returnByValue\":true,\"awaitPromise\":true}");
    const std::string v = json_string_value(reply, "value");
    if (!v.empty()) return v;
    const auto at = reply.find("\"value\":");  // a number or boolean
    if (at == std::string::npos) return "";
    return reply.substr(at + 8, reply.find_first_of(",}", at + 8) - at - 8);
  }

 private:
  static int on_data(mg_connection*, int bits, char* data, std::size_t len, void* self_ptr) {
    auto* self = static_cast<DevTools*>(self_ptr);
    std::lock_guard lock(self->mutex_);
    self->partial_.append(data, len);
    if (bits & 0x80) {  // FIN: a whole message
      self->messages_.push_back(std::move(self->partial_));
      self->partial_.clear();
      while (self->messages_.size() > 64) self->messages_.pop_front();  // events nobody asked for
      self->wake_.notify_all();
    }
    return 1;
  }
  static void on_close(const mg_connection*, void*) {}

  mg_connection* conn_ = nullptr;
  int last_id_ = 0;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::string partial_;
  std::deque<std::string> messages_;
};

std::string base64_decode(const std::string& in) {
  static const std::string alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  unsigned value = 0;
  int bits = 0;
  for (char c : in) {
    const auto p = alphabet.find(c);
    if (p == std::string::npos) continue;  // padding, line breaks
    value = (value << 6) | static_cast<unsigned>(p);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out += static_cast<char>((value >> bits) & 0xff);
    }
  }
  return out;
}

double angle_deg(const std::array<double, 4>& a, const std::array<double, 4>& b) {
  const double dot = std::abs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]);
  return 2.0 * std::acos(std::min(1.0, dot)) * 180.0 / std::numbers::pi;
}

// pelvis <- thigh_l <- shank_l: the page's layout knows these names.
constexpr const char* kBody = R"(name: view_test
segments:
  - name: pelvis
    node: pelvis
  - name: thigh_l
    node: thigh_l
    parent: pelvis
    joint: hip_l
  - name: shank_l
    node: shank_l
    parent: thigh_l
    joint: knee_l
)";

/// What the test itself reads of the same topics, by sensor time.
struct Seen {
  std::mutex mutex;
  std::map<std::string, std::map<std::uint64_t, std::array<double, 3>>> joints;  // joint -> ts -> degrees
  std::map<std::string, std::map<std::uint64_t, std::array<double, 4>>> truth;   // segment -> ts -> q
  std::map<std::string, std::map<std::uint64_t, std::array<double, 4>>> estimate;
};

/// The sample of `series` nearest `ts` (within 1 us: the page's numbers are doubles), or nullptr.
template <class V>
const V* at_time(const std::map<std::uint64_t, V>& series, double ts) {
  auto it = series.lower_bound(static_cast<std::uint64_t>(std::max(0.0, ts - 1000.0)));
  return it != series.end() && std::abs(static_cast<double>(it->first) - ts) <= 1000.0 ? &it->second : nullptr;
}

TEST_F(ProcessTest, DemoWithViewPrintsTheUrlOfALiveView) {
  auto& demo = spawn(
      "demo", {"demo", "--view", "--view-port", "0", "--duration", "6", "--domain", std::to_string(test_domain(67))});
  int port = 0;
  const std::regex url("live 3D view at http://127\\.0\\.0\\.1:([0-9]+)/");
  ASSERT_TRUE(wait_until(
      [&] {
        std::smatch m;
        const std::string text = read_file(log_path("demo"));
        if (std::regex_search(text, m, url)) port = std::stoi(m[1]);
        return port > 0;
      },
      20s))
      << tail(log_path("demo"));
  EXPECT_NE(http_get(port, "/").find("<title>bsn view</title>"), std::string::npos);
  const auto status = demo.wait_for(30s);
  EXPECT_TRUE(exited_cleanly(status)) << describe_status(status) << "\n" << tail(log_path("demo"));
}

class ViewBrowser : public ProcessTest {
 protected:
  /// Starts headless Chromium on the view at `port` and connects `devtools` to its page, once the page has connected
  /// to the view's WebSocket.
  void open_page(int port, DevTools& devtools) {
    const auto profile = dir() / "chromium";
    spawn_command("chromium", {"/usr/bin/chromium", "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                               "--no-first-run", "--disable-background-networking", "--disable-component-update",
                               "--disable-sync", "--user-data-dir=" + profile.string(), "--window-size=1280,900",
                               "--remote-debugging-port=0", "http://127.0.0.1:" + std::to_string(port) + "/"});
    // DevToolsActivePort: the port, then the browser's path.
    int devtools_port = 0;
    ASSERT_TRUE(wait_until(
        [&] {
          std::istringstream in(read_file(profile / "DevToolsActivePort"));
          return static_cast<bool>(in >> devtools_port) && devtools_port > 0;
        },
        30s))
        << tail(log_path("chromium"));
    std::string page_path;
    ASSERT_TRUE(wait_until(
        [&] {
          const std::string list = http_get(devtools_port, "/json/list");
          const auto url = json_string_value(list, "webSocketDebuggerUrl");
          const auto at = url.find("/devtools/page/");
          if (at != std::string::npos) page_path = url.substr(at);
          return !page_path.empty();
        },
        30s));
    ASSERT_TRUE(devtools.connect(devtools_port, page_path));
    // The page connects to the view's WebSocket.
    ASSERT_TRUE(wait_until([&] { return devtools.eval("window.bsnView && bsnView.connected") == "true"; }, 30s));
  }
};

TEST_F(ViewBrowser, PageShowsTheLiveBodyJointAnglesAndTruth) {
  if (!std::filesystem::exists("/usr/bin/chromium"))
    GTEST_SKIP() << "Chromium is not installed (apt install chromium; deploy/setup.sh installs it)";
  const std::string domain = std::to_string(test_domain(66));
  write_file(dir() / "body.yaml", kBody);

  Seen seen;
  dds::Participant participant({test_domain(66), "view test"});
  auto joints = participant.make_reader(dds::kJointAnglesTopic, [&](const bsn::JointAngles& j, const SampleInfo&) {
    std::lock_guard lock(seen.mutex);
    auto& a = seen.joints[j.joint()][j.timestamp_ns()];
    for (int i = 0; i < 3; ++i) a[i] = j.anatomical()[i] * 180.0 / std::numbers::pi;  // the page's default
  });
  auto truth = participant.make_reader(dds::kTruthOrientationTopic, [&](const bsn::Orientation& o, const SampleInfo&) {
    std::lock_guard lock(seen.mutex);
    seen.truth[o.segment()][o.timestamp_ns()] = o.quat();
  });

  spawn("fusion", {"fusion", "--domain", domain, "--body", (dir() / "body.yaml").string()});
  for (const char* seg : {"pelvis", "thigh_l", "shank_l"}) spawn(seg, {"sim", "--domain", domain, "--node", seg});
  spawn("view", {"view", "--port", "0", "--domain", domain});
  int port = 0;
  ASSERT_TRUE(wait_until([&] { return (port = printed_port(log_path("view"))) > 0; }, 20s)) << tail(log_path("view"));

  DevTools devtools;
  open_page(port, devtools);
  if (HasFatalFailure()) return;

  // Reads the page's summary once every joint and segment (and its truth ghost) is on it.
  auto summary = [&] {
    std::string s;
    wait_until(
        [&] {
          s = devtools.eval("bsnView.summary()");
          int j = 0, g = 0;
          std::istringstream in(s);
          for (std::string line; std::getline(in, line);) {
            j += line.rfind("J ", 0) == 0;
            g += line.rfind("S ", 0) == 0 && line.find("| none |") == std::string::npos;
          }
          return j == 2 && g == 3;
        },
        30s);
    return s;
  };

  std::map<std::string, std::array<double, 4>> truth_shown_first;
  for (int reading = 0; reading < 2; ++reading) {
    if (reading == 1) std::this_thread::sleep_for(1500ms);
    const std::string text = summary();
    std::lock_guard lock(seen.mutex);
    std::istringstream in(text);
    int joint_lines = 0, segment_lines = 0;
    for (std::string line; std::getline(in, line);) {
      std::istringstream l(line);
      std::string kind, name;
      l >> kind >> name;
      if (kind == "J") {
        // The joint-angle values in the DOM are the named anatomical angles of bsn/joint_angles for the same sample:
        // within 0.1 degree (the table shows two decimals).
        double ts = 0;
        std::array<double, 3> shown{};
        l >> ts >> shown[0] >> shown[1] >> shown[2];
        const auto* dds_value = at_time(seen.joints[name], ts);
        ASSERT_NE(dds_value, nullptr) << "joint " << name << " at " << ts << " never on bsn/joint_angles: " << line;
        for (int i = 0; i < 3; ++i) EXPECT_NEAR(shown[i], (*dds_value)[i], 0.1) << line;
        ++joint_lines;
      } else if (kind == "S") {
        // The solid's orientation as drawn follows the truth of the same sample: within 5 degrees, Fan et al.'s
        // "acceptable" grade (the filter's own accuracy on this simulated motion is well below it). The truth
        // ghost as drawn is the simulator's truth of its sample (sent with 9 significant digits: 1e-6).
        double ts = 0, truth_ts = 0;
        std::array<double, 4> solid{}, ghost{};
        std::string bar;
        l >> ts >> solid[0] >> solid[1] >> solid[2] >> solid[3] >> bar >> truth_ts >> ghost[0] >> ghost[1] >>
            ghost[2] >> ghost[3];
        const auto* t = at_time(seen.truth[name], ts);
        const auto* g = at_time(seen.truth[name], truth_ts);
        ASSERT_TRUE(t != nullptr && g != nullptr) << "truth of " << name << " not seen: " << line;
        EXPECT_LT(angle_deg(solid, *t), 5.0) << line;
        for (int k = 0; k < 4; ++k) EXPECT_NEAR(ghost[k], (*g)[k], 1e-6) << line;  // sent with 9 digits
        if (reading == 0) {
          truth_shown_first[name] = ghost;
        } else {
          // Between the two readings the simulated body moved: the page shows a new pose, not a frozen one.
          EXPECT_GT(angle_deg(ghost, truth_shown_first[name]), 0.5) << name << " did not move in 1.5 s";
        }
        ++segment_lines;
      }
    }
    EXPECT_EQ(joint_lines, 2) << text;
    EXPECT_EQ(segment_lines, 3) << text;
  }

  // A screenshot is not blank: the body's solids (coloured; the floor, grid and background are grey) cover many
  // pixels of the 3D view. The browser decodes its own PNG and counts.
  const std::string shot = devtools.call("Page.captureScreenshot", "{\"format\":\"png\"}", 20s);
  const std::string png64 = json_string_value(shot, "data");
  ASSERT_GT(png64.size(), 1000u) << shot.substr(0, 300);
  write_file(dir() / "view.png", base64_decode(png64));
  const std::string coloured =
      devtools.eval("(async () => { const img = new Image(); img.src = 'data:image/png;base64," + png64 +
                    "'; await img.decode(); const c = document.createElement('canvas'); c.width = img.width; "
                    "c.height = img.height; const x = c.getContext('2d'); x.drawImage(img, 0, 0); "
                    "const r = document.getElementById('scene').getBoundingClientRect(); "
                    "const d = x.getImageData(r.left, r.top, r.width, r.height).data; let n = 0; "
                    "for (let i = 0; i < d.length; i += 4) { const hi = Math.max(d[i], d[i+1], d[i+2]), "
                    "lo = Math.min(d[i], d[i+1], d[i+2]); if (hi - lo > 40) n++; } return n; })()");
  // Three solids of 0.1-0.4 m at about 3.5 m cover thousands of pixels; 500 is far above noise and far below that.
  EXPECT_GT(std::atoi(coloured.c_str()), 500) << "coloured pixels in the 3D view: " << coloured;
}

// The demo's walking body, strapped on at random and aligned live by the calibration service: once aligned, every
// segment is drawn as the segment (its ISB frame, the long axis Y along the limb) and compared with the truth of
// its segment frame, the plots carry the named anatomical angles of bsn/joint_angles, and every node says "aligned".
TEST_F(ViewBrowser, AnAlignedDemoBodyIsDrawnAsSegmentsAndFollowsItsTruth) {
  if (!std::filesystem::exists("/usr/bin/chromium"))
    GTEST_SKIP() << "Chromium is not installed (apt install chromium; deploy/setup.sh installs it)";
  const int domain = test_domain(94);
  Seen seen;
  std::map<std::string, std::map<std::uint64_t, std::array<double, 4>>> segment_truth;
  dds::Participant participant({domain, "view test"});
  auto joints = participant.make_reader(dds::kJointAnglesTopic, [&](const bsn::JointAngles& j, const SampleInfo&) {
    std::lock_guard lock(seen.mutex);
    auto& a = seen.joints[j.joint()][j.timestamp_ns()];
    for (int i = 0; i < 3; ++i) a[i] = j.anatomical()[i] * 180.0 / std::numbers::pi;
  });
  auto truth =
      participant.make_reader(dds::kTruthSegmentOrientationTopic, [&](const bsn::Orientation& o, const SampleInfo&) {
        std::lock_guard lock(seen.mutex);
        segment_truth[o.segment()][o.timestamp_ns()] = o.quat();
      });
  spawn("demo", {"demo", "--view", "--view-port", "0", "--duration", "60", "--domain", std::to_string(domain)});
  int port = 0;
  const std::regex url("live 3D view at http://127\\.0\\.0\\.1:([0-9]+)/");
  ASSERT_TRUE(wait_until(
      [&] {
        std::smatch m;
        const std::string text = read_file(log_path("demo"));
        if (std::regex_search(text, m, url)) port = std::stoi(m[1]);
        return port > 0;
      },
      20s))
      << tail(log_path("demo"));
  DevTools devtools;
  open_page(port, devtools);
  if (HasFatalFailure()) return;

  // The alignment arrives about 18 s after the demo's start (the N-pose and the flexions come first).
  std::string text;
  ASSERT_TRUE(wait_until(
      [&] {
        text = devtools.eval("bsnView.summary()");
        int aligned = 0;
        std::istringstream in(text);
        for (std::string line; std::getline(in, line);)
          aligned += line.rfind("S ", 0) == 0 && line.find("| frame segment |") != std::string::npos &&
                     line.find("| truth_up none") == std::string::npos;
        return aligned == 7;
      },
      60s))
      << text << "\n"
      << tail(log_path("demo"));
  std::this_thread::sleep_for(2s);  // the ghosts and plots of the aligned frames, not the first samples after it

  const auto y_axis = [](const std::array<double, 4>& q) {
    return fusion::Quat(q[0], q[1], q[2], q[3]) * fusion::Vec3::UnitY();
  };
  for (int reading = 0; reading < 3; ++reading) {
    if (reading > 0) std::this_thread::sleep_for(1s);
    text = devtools.eval("bsnView.summary()");
    std::lock_guard lock(seen.mutex);
    std::istringstream in(text);
    int segments = 0, joint_lines = 0;
    for (std::string line; std::getline(in, line);) {
      std::istringstream l(line);
      std::string kind, name, bar;
      l >> kind >> name;
      if (kind == "S") {
        // "S name ts w x y z | ts w x y z | err | frame F | up x y z | truth_up x y z"
        double ts = 0, truth_ts = 0;
        std::array<double, 4> solid{}, ghost{};
        std::string err, frame_word, frame, up_word, truth_up_word;
        fusion::Vec3 up, truth_up;
        l >> ts >> solid[0] >> solid[1] >> solid[2] >> solid[3] >> bar >> truth_ts >> ghost[0] >> ghost[1] >>
            ghost[2] >> ghost[3] >> bar >> err >> bar >> frame_word >> frame >> bar >> up_word >> up.x() >> up.y() >>
            up.z() >> bar >> truth_up_word >> truth_up.x() >> truth_up.y() >> truth_up.z();
        ASSERT_EQ(frame, "segment") << line;
        // The error to the truth of its segment frame, as the page shows it: below 5 degrees (the alignment's bound
        // per segment, SegmentAlignment.GaitAnglesFollowTheTruthAfterTheAlignmentOnly).
        ASSERT_NE(err, "none") << line;
        EXPECT_LT(std::stod(err), 5.0) << line;
        // The drawn long axis is the segment's true long axis (ISB Y) at the sample drawn: within 5 degrees. A
        // segment frame drawn as a sensor frame (the long axis along z) errs by 90.
        const auto* t = at_time(segment_truth[name], ts);
        ASSERT_NE(t, nullptr) << "truth of " << name << " at " << ts << " not seen: " << line;
        EXPECT_LT(std::acos(std::clamp(up.normalized().dot(y_axis(*t)), -1.0, 1.0)) * 180.0 / std::numbers::pi, 5.0)
            << line;
        // The legs hang down from the pelvis: a thigh's or shank's long axis (proximal up) is within 60 degrees of
        // the vertical while walking (hip flexion and knee flexion in swing stay below it), not horizontal.
        if (name.rfind("thigh", 0) == 0 || name.rfind("shank", 0) == 0) {
          EXPECT_GT(up.normalized().z(), 0.5) << line;
        }
        ++segments;
      } else if (kind == "J") {
        // "J name ts a b c | names n1 n2 n3 | plot ts p1 p2 p3": the plotted series are the named anatomical
        // angles of bsn/joint_angles of the same sample, within 0.01 degree.
        double ts = 0, plot_ts = 0;
        std::array<double, 3> shown{}, plotted{};
        std::string names_word, n1, n2, n3, plot_word;
        l >> ts >> shown[0] >> shown[1] >> shown[2] >> bar >> names_word >> n1 >> n2 >> n3 >> bar >> plot_word >>
            plot_ts >> plotted[0] >> plotted[1] >> plotted[2];
        if (name.rfind("knee", 0) == 0) {
          EXPECT_EQ(n1 + " " + n2 + " " + n3, "flexion_extension adduction_abduction internal_external_rotation")
              << line;
        }
        const auto* a = at_time(seen.joints[name], plot_ts);
        ASSERT_NE(a, nullptr) << "joint " << name << " at " << plot_ts << " never on bsn/joint_angles: " << line;
        for (int i = 0; i < 3; ++i) EXPECT_NEAR(plotted[i], (*a)[i], 0.01) << line;
        ++joint_lines;
      }
    }
    EXPECT_EQ(segments, 7) << text;
    EXPECT_EQ(joint_lines, 6) << text;
  }
  // Every node's mounting, by its name: aligned.
  const std::string nodes = devtools.eval(
      "Array.from(document.querySelectorAll('#nodes tbody tr')).map(tr => tr.cells[0].textContent.split(' ')[0] + "
      "'=' + tr.cells[5].textContent).sort().join(';')");
  EXPECT_EQ(nodes,
            "foot_l=aligned;foot_r=aligned;pelvis=aligned;shank_l=aligned;shank_r=aligned;thigh_l=aligned;"
            "thigh_r=aligned");
  const std::string shot = devtools.call("Page.captureScreenshot", "{\"format\":\"png\"}", 20s);
  write_file(dir() / "aligned_view.png", base64_decode(json_string_value(shot, "data")));
}

}  // namespace
}  // namespace bsn::integration
