#include "echo_command.hpp"

#include <atomic>
#include <chrono>
#include <cstdio>
#include <mutex>

#include "bsn/dds/log.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/dds/shutdown.hpp"
#include "format.hpp"

namespace bsn::services {
namespace {

using Clock = std::chrono::steady_clock;

struct Printer {
  explicit Printer(const EchoOptions& o) : opt(o) {}
  const EchoOptions& opt;
  std::mutex mutex;
  std::atomic<long> printed{0};
  Clock::time_point last_print{};

  void print(const std::string& line) {
    std::lock_guard lock(mutex);
    if (opt.count > 0 && printed.load() >= opt.count) return;
    const auto now = Clock::now();
    if (opt.rate_hz > 0.0 && printed.load() > 0 &&
        now - last_print < std::chrono::duration<double>(1.0 / opt.rate_hz)) {
      return;
    }
    last_print = now;
    std::fputs(line.c_str(), stdout);
    std::fputc('\n', stdout);
    std::fflush(stdout);
    if (++printed == opt.count) dds::request_shutdown();
  }
};

template <class T>
std::unique_ptr<dds::Reader<T>> subscribe(dds::Participant& p, const char* topic, dds::TopicQos qos, Printer& printer,
                                          const char* prefix = nullptr) {
  return p.make_reader<T>(topic, qos, [&printer, prefix](const T& s, const eprosima::fastdds::dds::SampleInfo&) {
    if constexpr (std::is_same_v<T, bsn::Orientation>) {
      printer.print(format_sample(s, prefix));
    } else {
      printer.print(format_sample(s));
    }
  });
}

}  // namespace

std::string echo_topic_list() {
  return std::string(dds::kRawTopic) + ", " + dds::kOrientationTopic + ", " + dds::kJointAnglesTopic + ", " +
         dds::kStatusTopic + ", " + dds::kTruthOrientationTopic + ", " + dds::kCalibrationRequestTopic + ", " +
         dds::kCalibrationResultTopic;
}

int run_echo(const EchoOptions& opt) {
  dds::install_shutdown_handlers();
  Printer printer(opt);
  dds::Participant participant({opt.domain, "bsn echo"});
  // Keep the reader alive for the loop; the variant per topic holds it.
  std::shared_ptr<void> reader;
  const std::string& t = opt.topic;
  if (t == dds::kRawTopic) {
    reader = subscribe<bsn::RawSample>(participant, dds::kRawTopic, dds::TopicQos::kSensorData, printer);
  } else if (t == dds::kOrientationTopic) {
    reader = subscribe<bsn::Orientation>(participant, dds::kOrientationTopic, dds::TopicQos::kEstimate, printer,
                                         "orientation");
  } else if (t == dds::kTruthOrientationTopic) {
    reader = subscribe<bsn::Orientation>(participant, dds::kTruthOrientationTopic, dds::TopicQos::kEstimate, printer,
                                         "truth");
  } else if (t == dds::kJointAnglesTopic) {
    reader = subscribe<bsn::JointAngles>(participant, dds::kJointAnglesTopic, dds::TopicQos::kEstimate, printer);
  } else if (t == dds::kStatusTopic) {
    reader = subscribe<bsn::Status>(participant, dds::kStatusTopic, dds::TopicQos::kLatched, printer);
  } else if (t == dds::kCalibrationRequestTopic) {
    reader = subscribe<bsn::CalibrationRequest>(participant, dds::kCalibrationRequestTopic, dds::TopicQos::kCommand,
                                                printer);
  } else if (t == dds::kCalibrationResultTopic) {
    reader =
        subscribe<bsn::CalibrationResult>(participant, dds::kCalibrationResultTopic, dds::TopicQos::kLatched, printer);
  } else {
    std::fprintf(stderr, "bsn echo: error: unknown topic '%s' (known: %s)\n", t.c_str(), echo_topic_list().c_str());
    return 2;
  }
  const auto start = Clock::now();
  while (dds::sleep_unless_shutdown(std::chrono::milliseconds(20))) {
    if (opt.timeout_s > 0.0 && Clock::now() - start > std::chrono::duration<double>(opt.timeout_s)) {
      std::fprintf(stderr, "bsn echo: timeout: %ld of %ld samples on %s within %.1f s\n", printer.printed.load(),
                   opt.count, t.c_str(), opt.timeout_s);
      return 1;
    }
  }
  reader.reset();
  return 0;
}

}  // namespace bsn::services
