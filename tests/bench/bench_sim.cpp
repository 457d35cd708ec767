// Simulator speed: a 7-segment lower body walking at 100 Hz, with the consumer MEMS error model and a
// disturbed magnetic environment. The counter `realtime_x` is simulated seconds per wall-clock second
// (the target is >= 1000 on one core).
#include <benchmark/benchmark.h>

#include "bsn/sim/scenario.hpp"

namespace {

using namespace bsn::sim;

ScenarioSpec walking_body() {
  ScenarioSpec spec;
  spec.body = BodyKind::kLowerBody;
  spec.gait = Gait{};
  spec.rate_hz = 100.0;
  spec.duration_s = 1e6;
  spec.sensors = *sensor_preset("consumer_mems");
  spec.magnetic.dipoles.push_back({Vec3(3.0, 0.5, 0.2), Vec3(0.0, 0.0, 1.0), Vec3::Zero(), {}});
  spec.magnetic.floor_regions.push_back({Vec3(5, -2, -1), Vec3(10, 2, 0.3), Vec3(10, -15, 20), 0.2, {}});
  return spec;
}

// One iteration = one simulated second (100 samples of all 7 segments).
void BM_LowerBody7Segments100Hz(benchmark::State& state) {
  ScenarioRunner runner(walking_body(), {}, /*ideal=*/false);
  std::vector<ScenarioSample> out;
  double checksum = 0.0;
  for (auto _ : state) {
    for (int k = 0; k < 100; ++k) {
      runner.next(out);
      checksum += out[3].sample.gyr.x();
    }
    benchmark::DoNotOptimize(checksum);
  }
  state.counters["realtime_x"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.SetItemsProcessed(state.iterations() * 700);  // segment samples
}
BENCHMARK(BM_LowerBody7Segments100Hz)->Unit(benchmark::kMicrosecond);

// The exact kinematics alone (7 segments, one instant).
void BM_LowerBodyKinematics(benchmark::State& state) {
  const Body body = lower_body(Gait{});
  std::vector<SegmentState> states;
  double t = 0.0;
  for (auto _ : state) {
    body.evaluate(t, states);
    benchmark::DoNotOptimize(states.data());
    t += 0.01;
  }
}
BENCHMARK(BM_LowerBodyKinematics)->Unit(benchmark::kNanosecond);

}  // namespace

BENCHMARK_MAIN();
