// Cost of one filter update (ns per sample), 9D and 6D, for every registered filter: each benchmark runs five
// repetitions in the same process, and the summary at the end gives each one's median and its ratio to the fastest
// and to the reference filter (complementary, the project's plain reference) of the same kind (9D or 6D). The
// repetitions of all benchmarks run interleaved in random order.
// Run: ./build/tests/bench/bsn_bench_filters
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/sim/body.hpp"
#include "bsn/sim/magnetic_environment.hpp"
#include "bsn/sim/sensor_model.hpp"

namespace {

using bsn::fusion::ImuSample;
using bsn::fusion::Vec3;

// offset + amplitude sin(2 pi f t + phase), rad.
bsn::sim::Signal swing(double offset, double amplitude, double frequency_hz, double phase) {
  bsn::sim::Signal s = bsn::sim::Signal::constant_value(offset);
  s.harmonics.push_back({amplitude, frequency_hz, phase});
  return s;
}

// 10 s of a noisy 100 Hz rotation (yaw, pitch, roll swinging), precomputed so that only the filter is timed. Every
// frequency is a multiple of 0.1 Hz, so the motion is periodic in 10 s and the stream wraps around without a jump: a
// jump would time the filters' large-error paths (clipping, re-convergence) instead of their usual per-sample work.
std::vector<ImuSample> make_stream(bool with_mag) {
  bsn::sim::SegmentDef segment;
  segment.name = "body";
  segment.rotation = {{Vec3::UnitZ(), swing(0.3, 1.0, 0.2, 0.1)},
                      {Vec3::UnitY(), swing(0.1, 0.4, 0.3, 0.5)},
                      {Vec3::UnitX(), swing(-0.2, 0.5, 0.1, 1.0)}};
  const bsn::sim::Body body({segment});
  const bsn::sim::MagneticEnvironment field;
  bsn::sim::SensorErrors errors;  // white noise of a consumer MEMS sensor at 100 Hz, as density = SD / sqrt(rate)
  errors.gyr.white_density = 0.005 / 10.0;
  errors.acc.white_density = 0.02 / 10.0;
  errors.mag.white_density = 0.3 / 10.0;
  bsn::sim::SensorSimulator sensor(errors, 100.0, 4);
  std::vector<bsn::sim::SegmentState> states;
  std::vector<ImuSample> stream;
  for (std::uint64_t k = 0; k < 1000; ++k) {
    const double t = static_cast<double>(k) * 0.01;
    body.evaluate(t, states);
    const bsn::sim::SegmentState& s = states.front();
    stream.push_back(sensor.measure(s.gyr_sensor, s.specific_force_sensor(),
                                    field.sensor_field(0, s.position, s.q_sensor, t), t, k * 10'000'000ull, with_mag));
  }
  return stream;
}

void update_cost(benchmark::State& state, const std::string& name, bool with_mag) {
  const std::vector<ImuSample> stream = make_stream(with_mag);
  auto filter = bsn::fusion::make_filter({name, {}});
  std::uint64_t offset = 0;
  std::size_t i = 0;
  ImuSample s;
  for (auto _ : state) {
    s = stream[i];
    s.timestamp_ns += offset;  // time keeps moving forward when the stream wraps
    benchmark::DoNotOptimize(filter->update(s));
    if (++i == stream.size()) {
      i = 0;
      offset += stream.size() * 10'000'000ull;
    }
  }
  benchmark::DoNotOptimize(filter->orientation());
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()));
}

constexpr int kRepetitions = 5;
constexpr const char* kReference = "complementary";

// The console output as usual, and the median real time per update of every benchmark kept for the summary.
class MedianCollector : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    ConsoleReporter::ReportRuns(runs);
    for (const Run& run : runs) {
      if (run.run_type == Run::RT_Aggregate && run.aggregate_name == "median") {
        median_ns[run.run_name.function_name] = run.GetAdjustedRealTime();  // the time unit is ns
      }
    }
  }
  std::map<std::string, double> median_ns;  ///< "name/9D" -> ns per update
};

void print_summary(const std::map<std::string, double>& median_ns) {
  for (const char* kind : {"9D", "6D"}) {
    std::vector<std::pair<std::string, double>> rows;
    for (const auto& name : bsn::fusion::filter_names()) {
      const auto it = median_ns.find(name + "/" + kind);
      if (it != median_ns.end()) rows.emplace_back(name, it->second);
    }
    if (rows.empty()) continue;
    const double fastest = std::min_element(rows.begin(), rows.end(), [](const auto& a, const auto& b) {
                             return a.second < b.second;
                           })->second;
    const auto reference = median_ns.find(std::string(kReference) + "/" + kind);
    std::printf("\n%s, median of %d repetitions: filter, ns per update, x fastest, x %s\n", kind, kRepetitions,
                kReference);
    for (const auto& [name, ns] : rows) {
      std::printf("  %-14s %7.1f ns  %5.2fx  ", name.c_str(), ns, ns / fastest);
      if (reference != median_ns.end()) {
        std::printf("%5.2fx\n", ns / reference->second);
      } else {
        std::printf("    -\n");
      }
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  for (const auto& name : bsn::fusion::filter_names()) {
    for (const bool with_mag : {true, false}) {
      benchmark::RegisterBenchmark((name + (with_mag ? "/9D" : "/6D")).c_str(), update_cost, name, with_mag)
          ->Repetitions(kRepetitions)
          ->ReportAggregatesOnly(true);
    }
  }
  // The repetitions of all benchmarks in random order: on a shared machine the load changes within a run, and
  // consecutive repetitions of one filter would all catch the same moment.
  std::vector<char*> args(argv, argv + argc);
  char interleave[] = "--benchmark_enable_random_interleaving=true";
  args.insert(args.begin() + 1, interleave);
  int args_count = static_cast<int>(args.size());
  benchmark::Initialize(&args_count, args.data());
  if (benchmark::ReportUnrecognizedArguments(args_count, args.data())) return 1;
  MedianCollector reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  print_summary(reporter.median_ns);
  benchmark::Shutdown();
  return 0;
}
