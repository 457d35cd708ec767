#include "calibration_client.hpp"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include "bsn/calib/calibration_session.hpp"
#include "bsn/config/body_config.hpp"
#include "bsn/dds/shutdown.hpp"
#include "calibration_service.hpp"
#include "command.hpp"

namespace bsn::services {
namespace {

using Clock = std::chrono::steady_clock;

std::string default_request_id() {
  char host[256] = {};
  gethostname(host, sizeof host - 1);
  const auto now = std::chrono::system_clock::now().time_since_epoch();
  return std::string(host) + "-" + std::to_string(getpid()) + "-" +
         std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(now).count());
}

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

std::string bar(double fraction) {
  const int width = 24;
  const int full = static_cast<int>(std::lround(std::clamp(fraction, 0.0, 1.0) * width));
  return "[" + std::string(static_cast<std::size_t>(full), '#') +
         std::string(static_cast<std::size_t>(width - full), '.') + "]";
}

std::string progress_line(const bsn::CalibrationProgress& p, bool alignment) {
  char head[96];
  if (p.seconds_left() >= 0.0)
    std::snprintf(head, sizeof head, "%s %3.0f%% %5.1f s left", bar(p.fraction()).c_str(), 100.0 * p.fraction(),
                  p.seconds_left());
  else
    std::snprintf(head, sizeof head, "%s %3.0f%%", bar(p.fraction()).c_str(), 100.0 * p.fraction());
  std::string line = head;
  if (alignment) {
    std::uint32_t least = p.nodes().empty() ? 0u : p.nodes()[0].samples();
    for (const auto& n : p.nodes()) least = std::min(least, n.samples());
    line += " | " + std::to_string(p.nodes().size()) + " nodes, >= " + std::to_string(least) + " samples each";
  } else if (p.nodes().size() == 1) {
    const auto& n = p.nodes()[0];
    char buf[128];
    std::snprintf(buf, sizeof buf, " | %u poses, %u/8 octants, coverage %.2f", n.poses(), n.octants(),
                  n.sphere_coverage());
    line += buf;
  } else {
    std::uint32_t least = p.nodes().empty() ? 0u : p.nodes()[0].poses();
    for (const auto& n : p.nodes()) least = std::min(least, n.poses());
    line += " | " + std::to_string(p.nodes().size()) + " nodes, >= " + std::to_string(least) + " poses each";
  }
  return line + " | " + p.instruction();
}

void print_result(const bsn::CalibrationResult& r) {
  const std::optional<calib::CalibrationKind> known = from_wire(r.kind());
  const char* kind = known ? calib::kind_name(*known) : "unknown kind";
  if (!r.success()) {
    std::printf("%s: %s FAILED: %s\n", r.node_id().c_str(), kind, r.message().c_str());
    return;
  }
  if (r.kind() == bsn::CALIBRATION_SEGMENT_ALIGNMENT) {
    const auto& q = r.sensor_to_segment();
    std::printf("%s: aligned to segment %s (request %s, %u samples, %s", r.node_id().c_str(), r.segment().c_str(),
                r.request_id().c_str(), r.sample_count(), r.alignment_source().c_str());
    if (r.axis_observability() > 0.0)
      std::printf(", hinge residual %.3f, axis observability %.3f", r.hinge_residual(), r.axis_observability());
    std::printf(")\n  sensor_to_segment = [%.6f, %.6f, %.6f, %.6f]\n", q[0], q[1], q[2], q[3]);
    return;
  }
  const auto& b = r.bias();
  const auto& h = r.transform();
  std::printf("%s: %s calibrated (request %s, %u samples", r.node_id().c_str(), kind, r.request_id().c_str(),
              r.sample_count());
  if (r.kind() != bsn::CALIBRATION_GYRO_BIAS)
    std::printf(", %u poses, %u/8 octants, coverage %.2f, | |u| - M | rms %.3g", r.pose_count(), r.octants_covered(),
                r.sphere_coverage(), r.residual_rms());
  std::printf(")\n  B = [%.6g, %.6g, %.6g]\n", b[0], b[1], b[2]);
  if (r.kind() != bsn::CALIBRATION_GYRO_BIAS)
    for (int row = 0; row < 3; ++row)
      std::printf("  %s [%.6g, %.6g, %.6g]\n", row == 0 ? "H =" : "   ", h[3 * row], h[3 * row + 1], h[3 * row + 2]);
  for (const auto& w : r.warnings()) std::printf("  warning: %s\n", w.c_str());
  if (!r.message().empty()) std::printf("  note: %s\n", r.message().c_str());
}

/// The request of `opt`, checked; 0, or 2 (said) when the options do not go together or the body is unreadable.
int live_request(const LiveCalibrationOptions& opt, bsn::CalibrationRequest& request) {
  const std::optional<calib::CalibrationKind> kind = calib::parse_kind(opt.kind);
  if (!kind) {
    std::fprintf(stderr, "bsn calibrate: unknown --kind '%s' (magnetometer, gyro-bias, accelerometer, alignment)\n",
                 opt.kind.c_str());
    return 2;
  }
  const bool alignment = *kind == calib::CalibrationKind::alignment;
  if (!opt.node.empty() && opt.all_nodes) {
    std::fprintf(stderr, "bsn calibrate: --live takes one of --node ID or --all-nodes, not both\n");
    return 2;
  }
  if (opt.node.empty() && !opt.all_nodes && !alignment) {
    std::fprintf(stderr, "bsn calibrate: --live needs exactly one of --node ID or --all-nodes\n");
    return 2;
  }
  if (!alignment && (!opt.body_path.empty() || opt.pose_s != 0.0)) {
    std::fprintf(stderr, "bsn calibrate: --body and --pose go with --kind alignment\n");
    return 2;
  }
  std::string body_text;
  if (!opt.body_path.empty()) {
    try {
      body_text = config::body_model_to_yaml(config::load_body_model(opt.body_path));
    } catch (const config::ConfigError& e) {
      std::fprintf(stderr, "bsn calibrate: error: %s\n", e.what());
      return 2;
    }
  }
  request.request_id(opt.request_id.empty() ? default_request_id() : opt.request_id);
  request.node_id(opt.all_nodes || opt.node.empty() ? "*" : opt.node);
  request.kind(to_wire(*kind));
  request.duration_s(opt.duration_s);
  request.sample_count(opt.sample_count);
  request.until_good(opt.until_good);
  request.field_magnitude(opt.field_magnitude);
  request.body(body_text);
  request.pose_s(opt.pose_s);
  return 0;
}

/// The service's replies to the request, written by the DDS readers.
struct LiveReplies {
  std::mutex mutex;
  std::optional<bsn::CalibrationProgress> progress;
  bool progress_changed = false;
  std::map<std::string, bsn::CalibrationResult> results;  // of this request, by node
};

/// Shows the progress until the service is done (then prints the results), refuses, or is gone, or Ctrl-C; the
/// exit code, or nullopt at Ctrl-C.
std::optional<int> follow_request(LiveReplies& replies, const dds::Reader<bsn::CalibrationProgress>& progress_reader,
                                  dds::Writer<bsn::CalibrationRequest>& request_writer,
                                  const bsn::CalibrationRequest& request, std::uint64_t lost_before) {
  const bool alignment = request.kind() == bsn::CALIBRATION_SEGMENT_ALIGNMENT;
  auto last_sent_at = Clock::now();
  constexpr double kResendAfterS = 0.5;
  std::mutex& mutex = replies.mutex;
  std::optional<bsn::CalibrationProgress>& progress = replies.progress;
  bool& progress_changed = replies.progress_changed;
  std::map<std::string, bsn::CalibrationResult>& results = replies.results;
  const bool tty = isatty(fileno(stderr)) != 0;
  auto last_progress_at = Clock::now();
  auto last_line_at = Clock::now() - std::chrono::seconds(10);
  std::string last_instruction;
  std::optional<Clock::time_point> done_at;
  auto end_line = [&] {
    if (tty) std::fputc('\n', stderr);
  };
  while (dds::sleep_unless_shutdown(std::chrono::milliseconds(50))) {
    std::lock_guard lock(mutex);
    if (progress_changed) {
      progress_changed = false;
      last_progress_at = Clock::now();
      const bsn::CalibrationProgress& p = *progress;
      if (p.phase() == bsn::CALIBRATION_PHASE_REFUSED) {
        end_line();
        std::fprintf(stderr, "bsn calibrate: refused: %s\n", p.message().c_str());
        return 1;
      }
      if (p.phase() == bsn::CALIBRATION_PHASE_DONE && !done_at) done_at = Clock::now();
      const std::string line = progress_line(p, alignment);
      if (tty) {
        std::fprintf(stderr, "\r\033[K%s", line.c_str());
      } else if (p.instruction() != last_instruction || since(last_line_at) >= 1.0) {
        std::fprintf(stderr, "%s\n", line.c_str());
        last_line_at = Clock::now();
      }
      last_instruction = p.instruction();
      std::fflush(stderr);
    }
    if (done_at) {
      // The results and the final progress travel on two topics: wait briefly for every node's result.
      const std::size_t expected = progress->nodes().size();
      if (results.size() >= expected || since(*done_at) > 2.0) {
        end_line();
        bool ok = results.size() >= expected;
        for (const auto& [node, r] : results) {
          print_result(r);
          ok = ok && r.success();
        }
        if (results.size() < expected)
          std::fprintf(stderr, "bsn calibrate: %zu of %zu results arrived\n", results.size(), expected);
        return ok ? 0 : 1;
      }
      continue;
    }
    // No answer yet: the service may have answered before its progress writer had matched our reader (discovery
    // runs each way on its own); it says a refusal again to the same request id (an accepted one is ignored, and its
    // progress comes every period anyway).
    if (!progress && since(last_sent_at) >= kResendAfterS) {
      request_writer.write(request);
      last_sent_at = Clock::now();
    }
    // Service death: its progress writer's liveliness (1 s lease) lapses, or it leaves (unmatched).
    if (progress_reader.writers_lost() > lost_before || progress_reader.matched() == 0 ||
        since(last_progress_at) > 3.0) {
      end_line();
      std::fprintf(stderr, "bsn calibrate: the calibration service is gone (%s) before the result of %s\n",
                   progress_reader.writers_lost() > lost_before ? "its DDS liveliness lapsed"
                   : progress_reader.matched() == 0             ? "it left the domain"
                                                                : "no progress for 3 s",
                   request.request_id().c_str());
      return 1;
    }
  }
  return std::nullopt;
}

}  // namespace

int run_live_calibration(const LiveCalibrationOptions& opt) {
  bsn::CalibrationRequest request;
  if (const int code = live_request(opt, request); code != 0) return code;

  DdsCommandFrame frame(opt.domain, "bsn calibrate --live");
  LiveReplies replies;
  auto progress_reader = frame.participant().make_reader(dds::kCalibrationProgressTopic,
                                                         [&](const bsn::CalibrationProgress& p, const auto&) {
                                                           if (p.request_id() != request.request_id()) return;
                                                           std::lock_guard lock(replies.mutex);
                                                           replies.progress = p;
                                                           replies.progress_changed = true;
                                                         });
  auto result_reader =
      frame.participant().make_reader(dds::kCalibrationResultTopic, [&](const bsn::CalibrationResult& r, const auto&) {
        if (r.request_id() != request.request_id()) return;
        std::lock_guard lock(replies.mutex);
        replies.results[r.node_id()] = r;
      });
  auto request_writer = frame.participant().make_writer(dds::kCalibrationRequestTopic);

  // The request is VOLATILE: a service must be matched (on all three topics) before it is sent.
  const auto start = Clock::now();
  while (request_writer->matched() == 0 || progress_reader->matched() == 0 || result_reader->matched() == 0) {
    if (!dds::sleep_unless_shutdown(std::chrono::milliseconds(20))) return 1;
    if (since(start) > opt.service_timeout_s) {
      std::fprintf(stderr,
                   "bsn calibrate: no calibration service answers in domain %d within %.0f s (is `bsn "
                   "calibration` running?)\n",
                   opt.domain, opt.service_timeout_s);
      return 1;
    }
  }
  const std::uint64_t lost_before = progress_reader->writers_lost();
  request_writer->write(request);
  std::fprintf(stderr, "request %s: %s of %s\n", request.request_id().c_str(),
               calib::kind_name(*calib::parse_kind(opt.kind)), request.node_id().c_str());

  if (const auto code = follow_request(replies, *progress_reader, *request_writer, request, lost_before)) return *code;
  // Ctrl-C (or SIGTERM): cancel the request on the service, and say what it answered.
  if (isatty(fileno(stderr))) std::fputc('\n', stderr);
  request.cancel(true);
  request_writer->write(request);
  std::fprintf(stderr, "bsn calibrate: cancelling request %s\n", request.request_id().c_str());
  const auto cancel_at = Clock::now();
  while (since(cancel_at) < 2.0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    std::lock_guard lock(replies.mutex);
    if (!replies.results.empty() && replies.progress && replies.results.size() >= replies.progress->nodes().size())
      break;
  }
  std::lock_guard lock(replies.mutex);
  for (const auto& [node, r] : replies.results) print_result(r);
  return 1;
}

}  // namespace bsn::services
