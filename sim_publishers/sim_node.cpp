#include "sim_node.hpp"

#include <time.h>

#include <cerrno>
#include <cmath>
#include <functional>

#include "bsn/dds/conversions.hpp"
#include "bsn/dds/log.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/dds/shutdown.hpp"
#include "bsn/sim/mimu_synthesizer.hpp"
#include "bsn/sim/motion_model.hpp"

namespace bsn::sim {

int run_sim_node(const SimNodeOptions& opt) {
  if (opt.node.empty() || opt.node.size() > 63) {
    dds::log_error("--node must be 1 to 63 characters");
    return 2;
  }
  if (!(opt.rate_hz > 0.0 && opt.rate_hz <= 10000.0)) {
    dds::log_error("--rate must be in (0, 10000] Hz");
    return 2;
  }
  const std::string segment = opt.segment.empty() ? opt.node : opt.segment;
  const std::uint64_t seed = opt.seed != 0 ? opt.seed : std::hash<std::string>{}(opt.node);
  dds::install_shutdown_handlers();

  dds::Participant participant({opt.domain, "bsn sim " + opt.node});
  auto raw_writer = participant.make_writer<bsn::RawSample>(dds::kRawTopic, dds::TopicQos::kSensorData);
  auto truth_writer = participant.make_writer<bsn::Orientation>(dds::kTruthOrientationTopic, dds::TopicQos::kEstimate);

  const SinusoidalRotation motion = SinusoidalRotation::from_seed(seed);
  MimuSynthesizer synth(EarthField{}, opt.ideal ? WhiteNoise::none() : WhiteNoise{}, seed ^ 0x9e3779b97f4a7c15ull);

  const auto period_ns = static_cast<std::uint64_t>(std::llround(1e9 / opt.rate_hz));
  const std::uint64_t t0 = dds::monotonic_ns();
  const std::uint64_t samples = opt.duration_s > 0.0 ? static_cast<std::uint64_t>(opt.duration_s * opt.rate_hz) : 0;
  dds::log_info("publishing node '", opt.node, "' (segment '", segment, "') at ", opt.rate_hz, " Hz in domain ",
                opt.domain);

  bsn::RawSample raw;
  raw.node_id(opt.node);
  bsn::Orientation truth;
  truth.segment(segment);
  truth.node_id(opt.node);
  std::uint64_t write_failures = 0;
  for (std::uint64_t k = 0; (samples == 0 || k < samples) && !dds::shutdown_requested(); ++k) {
    const std::uint64_t t_ns = t0 + k * period_ns;
    const timespec target{static_cast<time_t>(t_ns / 1000000000ull), static_cast<long>(t_ns % 1000000000ull)};
    // Absolute sleeps keep the schedule exact; SIGINT/SIGTERM interrupt the sleep (EINTR) and end the loop.
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &target, nullptr) == EINTR && !dds::shutdown_requested()) {
    }
    if (dds::shutdown_requested()) break;
    const MotionState state = motion.at(static_cast<double>(k * period_ns) * 1e-9);
    dds::fill_raw_sample(synth.measure(state, t_ns), raw);
    raw.seq(k);
    if (!raw_writer->write(raw)) ++write_failures;
    truth.timestamp_ns(t_ns);
    dds::fill_orientation(state.q_sensor_to_earth, truth);
    truth_writer->write(truth);
  }
  if (write_failures > 0) dds::log_warn(write_failures, " raw samples could not be written");
  dds::log_info("node '", opt.node, "' stopped");
  return 0;
}

}  // namespace bsn::sim
