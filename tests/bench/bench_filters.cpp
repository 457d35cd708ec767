// Cost of one filter update (ns per sample), 9D and 6D, for every registered filter.
// Run: ./build/tests/bench/bsn_bench_filters --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <vector>

#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/sim/mimu_synthesizer.hpp"
#include "bsn/sim/motion_model.hpp"

namespace {

using bsn::fusion::ImuSample;

// 10 s of a noisy 100 Hz rotation, precomputed so that only the filter is timed. Every frequency is a multiple
// of 0.1 Hz, so the motion is periodic in 10 s and the stream wraps around without a jump: a jump would time
// the filters' large-error paths (clipping, re-convergence) instead of their usual per-sample work.
std::vector<ImuSample> make_stream(bool with_mag) {
  bsn::sim::SinusoidalRotation::Params p;
  p.yaw = {0.3, 1.0, 0.2, 0.1};  // offset rad, amplitude rad, frequency Hz, phase rad
  p.pitch = {0.1, 0.4, 0.3, 0.5};
  p.roll = {-0.2, 0.5, 0.1, 1.0};
  const bsn::sim::SinusoidalRotation motion(p);
  bsn::sim::MimuSynthesizer synth(bsn::sim::EarthField{}, bsn::sim::WhiteNoise{}, 4);
  std::vector<ImuSample> stream;
  for (std::uint64_t k = 0; k < 1000; ++k) {
    ImuSample s = synth.measure(motion.at(static_cast<double>(k) * 0.01), k * 10'000'000ull);
    s.has_mag = with_mag;
    stream.push_back(s);
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

}  // namespace

int main(int argc, char** argv) {
  for (const auto& name : bsn::fusion::filter_names()) {
    benchmark::RegisterBenchmark((name + "/9D").c_str(), update_cost, name, true);
    benchmark::RegisterBenchmark((name + "/6D").c_str(), update_cost, name, false);
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
