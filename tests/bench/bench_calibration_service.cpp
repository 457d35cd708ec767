// Calibration service latency: from the last collected sample written on bsn/raw to the result's
// arrival on bsn/calibration/result, through a real `bsn calibration` process, for the 30-pose Table I session
// at 100 Hz (22 500 samples). Target <= 50 ms. Prints every run and the median.
//   ./build/tests/bench/bsn_bench_calibration_service [--runs N] [--domain D]
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <thread>

#include "bsn/dds/child_process.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/sim/scenario_file.hpp"

using Clock = std::chrono::steady_clock;

int main(int argc, char** argv) {
  CLI::App app{"calibration service latency: last sample -> result"};
  int runs = 7;
  int domain = 231;
  app.add_option("--runs", runs, "calibrations to time")->capture_default_str();
  app.add_option("--domain", domain, "DDS domain id")->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  // The session's samples, generated once.
  const bsn::sim::ScenarioSpec spec =
      bsn::sim::load_scenario(std::string(BSN_SCENARIO_DIR) + "/mag_calibration_session.yaml");
  bsn::sim::ScenarioRunner runner(spec, {}, false);
  std::vector<bsn::RawSample> samples;
  std::vector<bsn::sim::ScenarioSample> out;
  while (runner.next(out)) {
    bsn::RawSample raw;
    raw.node_id("bench");
    bsn::dds::fill_raw_sample(out[0].sample, raw);
    raw.seq(samples.size());
    samples.push_back(raw);
  }
  std::printf("%zu samples (%d poses at %g Hz)\n", samples.size(), 30, spec.rate_hz);

  char dir_template[] = "/tmp/bsn-bench-calib-XXXXXX";
  if (mkdtemp(dir_template) == nullptr) return 1;
  const std::string store = std::string(dir_template) + "/store";
  bsn::dds::ChildProcess service({BSN_EXECUTABLE, "calibration", "--store", store, "--domain", std::to_string(domain)},
                                 std::string(dir_template) + "/service.log");
  bsn::dds::Participant participant({domain, "bench calibration"});
  std::mutex mutex;
  std::condition_variable arrived;
  std::string last_id;
  Clock::time_point last_at;
  bool last_success = false;
  std::string last_message;
  auto results =
      participant.make_reader(bsn::dds::kCalibrationResultTopic, [&](const bsn::CalibrationResult& r, const auto&) {
        const auto now = Clock::now();
        std::lock_guard lock(mutex);
        last_id = r.request_id();
        last_at = now;
        last_success = r.success();
        last_message = r.message();
        arrived.notify_all();
      });
  auto requests = participant.make_writer(bsn::dds::kCalibrationRequestTopic);
  auto raw_writer = participant.make_writer(bsn::dds::kRawTopic);
  while (requests->matched() == 0 || results->matched() == 0 || raw_writer->matched() == 0)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));

  std::vector<double> latencies_ms;
  for (int run = 0; run < runs; ++run) {
    const std::string id = "bench-" + std::to_string(run);
    bsn::CalibrationRequest request;
    request.request_id(id);
    request.node_id("bench");
    request.kind(bsn::CALIBRATION_MAGNETOMETER);
    request.sample_count(static_cast<std::uint32_t>(samples.size()));
    request.field_magnitude(49.0);
    requests->write(request);
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    // Faster than real time (2000 samples/s in bursts of 20), so a run takes ~11 s; the service gets
    // the same samples, in order, as from a 100 Hz node.
    const std::uint64_t offset = static_cast<std::uint64_t>(run) * (samples.size() + 1000);
    Clock::time_point last_written;
    for (std::size_t k = 0; k < samples.size(); ++k) {
      bsn::RawSample s = samples[k];
      s.seq(s.seq() + offset);
      s.timestamp_ns(s.timestamp_ns() + offset * 10'000'000ull);
      if (k + 1 == samples.size()) last_written = Clock::now();
      raw_writer->write(s);
      if (k % 20 == 19) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    std::unique_lock lock(mutex);
    if (!arrived.wait_for(lock, std::chrono::seconds(10), [&] { return last_id == id; })) {
      std::printf("run %d: no result within 10 s\n", run);
      continue;
    }
    const double ms = std::chrono::duration<double, std::milli>(last_at - last_written).count();
    std::printf("run %d: %s, %.2f ms%s%s\n", run, last_success ? "ok" : "FAILED", ms, last_message.empty() ? "" : ": ",
                last_message.c_str());
    if (last_success) latencies_ms.push_back(ms);
  }
  service.stop();
  std::filesystem::remove_all(dir_template);
  if (latencies_ms.empty()) return 1;
  std::sort(latencies_ms.begin(), latencies_ms.end());
  std::printf("last sample -> result: median %.2f ms, min %.2f ms, max %.2f ms over %zu runs (target <= 50 ms)\n",
              latencies_ms[latencies_ms.size() / 2], latencies_ms.front(), latencies_ms.back(), latencies_ms.size());
  return 0;
}
