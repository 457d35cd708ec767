#include "view_service.hpp"

#include <cctype>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <sstream>

#include "bsn/dds/participant.hpp"
#include "bsn/logging/log.hpp"
#include "view_server.hpp"
#include "view_state.hpp"
#include "view_web_assets.hpp"

namespace bsn::services {
namespace {

std::uint64_t monotonic_ns() {
  return static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
          .count());
}

bool read_whole(const std::string& path, std::string& out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::ostringstream s;
  s << in.rdbuf();
  out = s.str();
  return true;
}

std::map<std::string, ViewServer::Asset> view_assets() {
  std::map<std::string, ViewServer::Asset> assets;
  for (const auto& page : view_web_assets()) assets[page.path] = {page.content_type, page.body};
  // Debian's packages, served from where they install (works offline).
  const std::pair<const char*, const char*> libraries[] = {
      {"/lib/three.min.js", "/usr/share/javascript/three/three.min.js"},
      {"/lib/OrbitControls.js", "/usr/share/javascript/three/examples/js/controls/OrbitControls.js"},
      {"/lib/chart.min.js", "/usr/share/javascript/chart.js/chart.min.js"}};
  for (const auto& [url, path] : libraries) {
    ViewServer::Asset a{"text/javascript; charset=utf-8", ""};
    if (!read_whole(path, a.body)) {
      logging::log_warn("cannot read ", path,
                        " (install libjs-three and libjs-chart.js: deploy/setup.sh); the page "
                        "will say what is missing");
      continue;
    }
    assets[url] = std::move(a);
  }
  return assets;
}

// A token travels in a URL and a cookie: URL-safe characters only, and long enough not to be guessed.
std::string token_problem(const std::string& token) {
  if (token.size() < 16) return "the token must have at least 16 characters";
  for (const char c : token)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '_' && c != '~' && c != '-')
      return "the token may hold only A-Z a-z 0-9 . _ ~ -";
  return "";
}

int run_view(const ViewOptions& opt) {
  logging::set_log_identity("view");
  std::signal(SIGPIPE, SIG_IGN);  // a browser that goes mid-write is an error return, not the end of the process
  ViewState state;
  std::mutex state_mutex;
  ViewServer::Options server_options;
  server_options.bind = opt.bind;
  server_options.port = opt.port;
  server_options.assets = view_assets();
  server_options.token = opt.token;
  const bool loopback = opt.bind.rfind("127.", 0) == 0 || opt.bind == "::1" || opt.bind == "localhost";
  // On loopback every browser has the same address: only the total limit applies.
  if (loopback) server_options.max_websockets_per_client = server_options.max_websockets;
  if (opt.token.empty() && !loopback)
    logging::log_warn("listening on ", opt.bind, " without --token: anyone who reaches this address sees the body ",
                      "live (health data); give --token (or BSN_VIEW_TOKEN) to require one");
  server_options.snapshot = [&] {
    std::lock_guard lock(state_mutex);
    return state.snapshot();
  };
  std::unique_ptr<ViewServer> server;
  try {
    server = std::make_unique<ViewServer>(server_options);
  } catch (const ViewServerError& e) {
    std::fprintf(stderr, "bsn view: error: %s\n", e.what());
    return 2;
  }
  DdsCommandFrame frame(opt.domain, "bsn view", opt.subject);
  // Under one lock: the state decides, then the message is queued to every browser (in order, as decided).
  auto pass_on = [&](auto&& decide) {
    std::lock_guard lock(state_mutex);
    if (auto message = decide()) server->broadcast(*message);
  };
  using eprosima::fastdds::dds::SampleInfo;
  auto orientation_reader =
      frame.participant().make_reader(dds::kOrientationTopic, [&](const bsn::Orientation& o, const SampleInfo&) {
        pass_on([&] { return state.on_orientation(o, monotonic_ns()); });
      });
  auto truth_reader =
      frame.participant().make_reader(dds::kTruthOrientationTopic, [&](const bsn::Orientation& t, const SampleInfo&) {
        pass_on([&] { return state.on_truth(t, monotonic_ns()); });
      });
  auto segment_truth_reader = frame.participant().make_reader(
      dds::kTruthSegmentOrientationTopic, [&](const bsn::Orientation& t, const SampleInfo&) {
        pass_on([&] { return state.on_truth(t, monotonic_ns()); });
      });
  auto joint_reader =
      frame.participant().make_reader(dds::kJointAnglesTopic, [&](const bsn::JointAngles& j, const SampleInfo&) {
        pass_on([&] { return state.on_joint(j, monotonic_ns()); });
      });
  auto status_reader = frame.participant().make_reader(
      dds::kStatusTopic, [&](const bsn::Status& s, const SampleInfo&) { pass_on([&] { return state.on_status(s); }); });
  frame.participant().expect_peer(*orientation_reader, "writer of bsn/orientation or bsn/status (fusion)");
  frame.participant().expect_peer(*status_reader, "writer of bsn/orientation or bsn/status (fusion)");

  const std::string host = opt.bind == "0.0.0.0" ? "localhost" : opt.bind;
  const std::string query = opt.token.empty() ? "" : "?token=" + opt.token;
  std::printf("bsn view: http://%s:%d/%s (domain %d; Ctrl-C stops)\n", host.c_str(), server->port(), query.c_str(),
              opt.domain);
  std::fflush(stdout);

  // Every 5 s: browsers, and the messages dropped for slow ones (if any).
  auto next_report = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  std::uint64_t reported_drops = 0;
  std::uint64_t reported_refusals = 0;
  const int code = frame.run_ticks(std::chrono::milliseconds(100), [&]() -> std::optional<int> {
    if (std::chrono::steady_clock::now() < next_report) return std::nullopt;
    next_report += std::chrono::seconds(5);
    const auto s = server->stats();
    if (s.dropped != reported_drops) {
      logging::log_warn(s.clients, " browsers; ", s.dropped - reported_drops,
                        " messages dropped for slow browsers in the last 5 s (", s.dropped, " in all)");
      reported_drops = s.dropped;
    }
    if (s.refused_busy + s.refused_token != reported_refusals) {
      logging::log_warn("connections refused since the start: ", s.refused_busy,
                        " over a limit (per address or in all), ", s.refused_token, " without the token");
      reported_refusals = s.refused_busy + s.refused_token;
    }
    return std::nullopt;
  });
  // Readers first (their callbacks broadcast), then the browsers.
  orientation_reader.reset();
  truth_reader.reset();
  segment_truth_reader.reset();
  joint_reader.reset();
  status_reader.reset();
  server.reset();
  const auto s = [&] {
    std::lock_guard lock(state_mutex);
    return std::pair(state.rejected_non_finite(), state.rejected_too_many_names());
  }();
  if (s.first + s.second > 0)
    logging::log_warn("samples not shown: ", s.first, " with non-finite values, ", s.second, " beyond ",
                      ViewState::kMaxKeys, " names");
  return code;
}

}  // namespace

Command view_command() {
  return {
      "view", "Live 3D view of the body and joint-angle plots in the browser", [](CLI::App* cmd) {
        auto opt = std::make_shared<ViewOptions>();
        cmd->add_option("--port", opt->port, "HTTP port (0: any free port, printed)")
            ->capture_default_str()
            ->check(number_in(0, 65535));
        cmd->add_option("--bind", opt->bind, "address to listen on (0.0.0.0: every interface)")->capture_default_str();
        cmd->add_option("--token", opt->token,
                        "require this token on every request (at least 16 of A-Z a-z 0-9 . _ ~ -); the page's "
                        "URL carries it once (default: $BSN_VIEW_TOKEN)")
            ->check(token_problem);
        add_domain_option(cmd, opt->domain);
        add_subject_option(cmd, opt->subject);
        return [opt] {
          if (const char* env = std::getenv("BSN_VIEW_TOKEN"); opt->token.empty() && env != nullptr && *env) {
            if (const std::string why = token_problem(env); !why.empty()) {
              std::fprintf(stderr, "bsn view: error: BSN_VIEW_TOKEN: %s\n", why.c_str());
              return 2;
            }
            opt->token = env;
          }
          return run_view(*opt);
        };
      }};
}

}  // namespace bsn::services
