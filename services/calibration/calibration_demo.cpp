// `bsn demo --calibrate`: one simulated node with a hard- and soft-iron magnetometer error turned through still
// poses, `bsn fusion` tracking it, `bsn calibration` calibrating it live; the terminal shows the heading error
// before and after the result, which fusion applies without a restart.
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <numbers>

#include "bsn/dds/child_process.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/dds/sample_source.hpp"
#include "bsn/dds/shutdown.hpp"
#include "bsn/fusion/orientation_error.hpp"
#include "bsn/logging/log.hpp"
#include "calibration_client.hpp"

namespace bsn::services {
namespace {

using Clock = std::chrono::steady_clock;
constexpr double kDeg = 180.0 / std::numbers::pi;

// 20 still poses of 3 s turned by hand, then the sensor keeps its last pose; the magnetometer reads the field
// plus a 31 uT hard-iron offset and a soft-iron distortion (everything else exact, small noise).
constexpr const char* kScenario = R"(name: calibration_demo
duration_s: 130
rate_hz: 100
seed: 5
sensors:
  preset: ideal
  mag: {hard_iron: [25, -15, 10], soft_iron: [[1.05, 0.03, 0], [0.03, 0.95, 0.02], [0, 0.02, 1.0]], white_density: 0.02}
body:
  kind: free
  segment: imu
  pose: {position_m: [0, 0, 1]}
  pose_sequence: {count: 20, hold_s: 3, turn_s: 1.5, start_s: 0}
magnetic: {magnitude_ut: 49, dip_deg: 64}
)";

struct HeadingWatch {
  std::mutex mutex;
  std::map<std::uint64_t, fusion::Quat> truth;              // by sensor timestamp
  std::deque<std::pair<Clock::time_point, double>> recent;  // |heading error|, deg, last second
  double before_sum_sq = 0.0, after_sum_sq = 0.0;
  std::size_t before_n = 0, after_n = 0;
  std::optional<Clock::time_point> calibrated_at;
  std::optional<bsn::CalibrationProgress> progress;
  std::optional<bsn::CalibrationResult> result;

  void on_truth(const bsn::Orientation& o) {
    if (!dds::finite_values(o)) return;  // never a number to compare with
    std::lock_guard lock(mutex);
    truth[o.timestamp_ns()] = dds::to_quat(o.quat());
  }

  /// Scores an estimate against the truth of its instant: before the calibration (from 5 s on, once the filter
  /// has settled) or from 1 s after it.
  void on_estimate(const bsn::Orientation& o) {
    if (!dds::finite_values(o)) return;
    std::lock_guard lock(mutex);
    const auto t = truth.find(o.timestamp_ns());
    if (t == truth.end()) return;
    const double e = std::abs(fusion::error_angles(dds::to_quat(o.quat()), t->second).heading) * kDeg;
    truth.erase(truth.begin(), t);
    const auto now = Clock::now();
    recent.emplace_back(now, e);
    while (!recent.empty() && now - recent.front().first > std::chrono::seconds(1)) recent.pop_front();
    if (!calibrated_at && o.timestamp_ns() > 5'000'000'000ull) {
      before_sum_sq += e * e;
      ++before_n;
    } else if (calibrated_at && now > *calibrated_at + std::chrono::seconds(1)) {
      after_sum_sq += e * e;
      ++after_n;
    }
  }

  /// The live line: the largest heading error of the last second and the calibration's progress or result.
  /// `calibrated` says whether the result has come.
  std::string line(const std::string& request_id, bool& calibrated) {
    std::lock_guard lock(mutex);
    double worst = 0.0;
    for (const auto& [at, e] : recent) worst = std::max(worst, e);
    char text[512];
    calibrated = calibrated_at.has_value();
    if (!calibrated) {
      const auto& p = progress;
      std::snprintf(text, sizeof text, "heading error %6.1f deg (uncalibrated) | calibrating: %3.0f%%, %u poses | %s",
                    worst, p ? 100.0 * p->fraction() : 0.0, p && !p->nodes().empty() ? p->nodes()[0].poses() : 0u,
                    p ? p->instruction().c_str() : "waiting for the service");
    } else {
      std::snprintf(text, sizeof text, "heading error %6.2f deg (calibrated by request %s, %s)", worst,
                    request_id.c_str(), result && result->success() ? "applied live" : "FAILED");
    }
    return text;
  }
};

/// Shows the heading error until --duration, the simulated node's end, or 4 s after the calibration.
void show_heading(HeadingWatch& watch, dds::ChildProcess& sim, Clock::time_point start, double duration_s,
                  const std::string& request_id) {
  const bool tty = isatty(STDOUT_FILENO) != 0;
  auto next_draw = Clock::now();
  std::optional<Clock::time_point> show_after_until;
  while (dds::sleep_unless_shutdown(std::chrono::milliseconds(20))) {
    const auto now = Clock::now();
    if (duration_s > 0.0 && now - start > std::chrono::duration<double>(duration_s)) break;
    if (!sim.running() || (show_after_until && now > *show_after_until)) break;
    if (now < next_draw) continue;
    next_draw = now + std::chrono::milliseconds(tty ? 250 : 1000);
    bool calibrated = false;
    const std::string line = watch.line(request_id, calibrated);
    if (calibrated && !show_after_until) show_after_until = now + std::chrono::seconds(4);
    std::printf(tty ? "\r\033[K%s" : "%s\n", line.c_str());
    std::fflush(stdout);
  }
  if (tty) std::printf("\n");
}

/// The heading error before and after the calibration; 0 when it fell below 2 deg RMS (the folder then removed).
int summarise(HeadingWatch& watch, const std::filesystem::path& dir) {
  std::lock_guard lock(watch.mutex);
  if (!watch.result || !watch.result->success()) {
    std::printf("no calibration result%s%s; logs in %s\n", watch.result ? ": " : "",
                watch.result ? watch.result->message().c_str() : "", dir.c_str());
    return 1;
  }
  const double before = watch.before_n ? std::sqrt(watch.before_sum_sq / static_cast<double>(watch.before_n)) : NAN;
  const double after = watch.after_n ? std::sqrt(watch.after_sum_sq / static_cast<double>(watch.after_n)) : NAN;
  std::printf("heading error RMS: %.1f deg before the calibration, %.2f deg from 1 s after it (%zu estimates)\n",
              before, after, watch.after_n);
  const int exit_code = after < 2.0 ? 0 : 1;
  if (exit_code == 0) {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  } else {
    std::printf("logs kept in %s\n", dir.c_str());
  }
  return exit_code;
}

}  // namespace

int run_calibration_demo(double speed, double duration_s, int domain) {
  dds::install_shutdown_handlers();
  char dir_template[] = "/tmp/bsn-demo-calibrate-XXXXXX";
  if (mkdtemp(dir_template) == nullptr) {
    std::perror("bsn demo: mkdtemp");
    return 1;
  }
  const std::filesystem::path dir = dir_template;
  std::ofstream(dir / "scenario.yaml") << kScenario;
  std::ofstream(dir / "body.yaml") << "segments:\n  - name: imu\n";
  const std::string self = dds::self_executable();
  const std::string d = std::to_string(domain);
  const std::string request_id = "demo-" + std::to_string(getpid());

  HeadingWatch watch;
  {
    dds::Participant participant({domain, "bsn demo --calibrate"});
    auto truth_reader = participant.make_reader(dds::kTruthOrientationTopic,
                                                [&](const bsn::Orientation& o, const auto&) { watch.on_truth(o); });
    auto estimate_reader = participant.make_reader(
        dds::kOrientationTopic, [&](const bsn::Orientation& o, const auto&) { watch.on_estimate(o); });
    auto progress_reader =
        participant.make_reader(dds::kCalibrationProgressTopic, [&](const bsn::CalibrationProgress& p, const auto&) {
          if (p.request_id() != request_id) return;
          std::lock_guard lock(watch.mutex);
          watch.progress = p;
        });
    auto result_reader =
        participant.make_reader(dds::kCalibrationResultTopic, [&](const bsn::CalibrationResult& r, const auto&) {
          if (r.request_id() != request_id) return;
          std::lock_guard lock(watch.mutex);
          watch.result = r;
          watch.calibrated_at = Clock::now();
        });
    auto request_writer = participant.make_writer(dds::kCalibrationRequestTopic);

    std::vector<std::unique_ptr<dds::ChildProcess>> children;
    try {
      children.push_back(std::make_unique<dds::ChildProcess>(
          std::vector<std::string>{self, "fusion", "--domain", d, "--body", (dir / "body.yaml").string()},
          (dir / "fusion.log").string()));
      children.push_back(std::make_unique<dds::ChildProcess>(
          std::vector<std::string>{self, "calibration", "--domain", d, "--store", (dir / "store").string()},
          (dir / "calibration.log").string()));
    } catch (const std::exception& e) {
      logging::log_error("cannot start the demo processes: ", e.what());
      return 1;
    }
    std::printf(
        "bsn demo --calibrate: a simulated node 'imu' whose magnetometer has a 31 uT hard-iron offset and\n"
        "soft iron, turned through 20 still poses at %gx real time; `bsn fusion` tracks it; `bsn calibration`\n"
        "calibrates it live and fusion applies the result without a restart.\n\n",
        speed);
    const auto start = Clock::now();
    while (request_writer->matched() == 0 || estimate_reader->matched() == 0) {
      if (!dds::sleep_unless_shutdown(std::chrono::milliseconds(20))) return 1;
      if (Clock::now() - start > std::chrono::seconds(15)) {
        logging::log_error("the demo's processes did not appear; logs in ", dir.string());
        return 1;
      }
    }
    bsn::CalibrationRequest request;
    request.request_id(request_id);
    request.node_id("imu");
    request.kind(bsn::CALIBRATION_MAGNETOMETER);
    request.duration_s(0.0);
    request.sample_count(20 * 450);  // the 20 poses
    request.field_magnitude(49.0);
    request_writer->write(request);
    children.push_back(std::make_unique<dds::ChildProcess>(
        std::vector<std::string>{self, "sim", "--domain", d, "--scenario", (dir / "scenario.yaml").string(), "--node",
                                 "imu", "--speed", std::to_string(speed)},
        (dir / "sim.log").string()));

    show_heading(watch, *children[2], start, duration_s, request_id);
    for (auto it = children.rbegin(); it != children.rend(); ++it) (*it)->stop();
  }
  return summarise(watch, dir);
}

}  // namespace bsn::services
