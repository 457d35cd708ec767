// Cost of the kinematic-constraint heading of a hinge joint: one estimator update plus the
// correction of the child (ns per joint sample), and a knee's whole BodyFusion step (the thigh's and the shank's
// samples through gate, filter and joint) in the plain and the kinematic mode.
// Run: ./build/tests/bench/bsn_bench_hinge_heading --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <vector>

#include "bsn/fusion/body_fusion.hpp"
#include "bsn/fusion/hinge_heading.hpp"
#include "bsn/sim/scenario.hpp"

namespace {

using bsn::fusion::Quat;

// 10 s of the simulator's walking lower body at 100 Hz (consumer MEMS), thigh_l and shank_l: their exact segment
// orientations and their raw samples, precomputed so that only the estimator or the fusion is timed.
struct Walk {
  std::vector<Quat> thigh, shank;                                    // ISB segment frames, segment-to-earth
  std::vector<bsn::fusion::ImuSample> thigh_samples, shank_samples;  // sensor frames (exact mounting)
};

Walk make_walk() {
  bsn::sim::ScenarioSpec spec;
  spec.body = bsn::sim::BodyKind::kLowerBody;
  spec.gait = bsn::sim::Gait{};
  spec.duration_s = 10.0;
  spec.mounting = {0.0, 0.0};
  spec.sensors = *bsn::sim::sensor_preset("consumer_mems");
  bsn::sim::ScenarioRunner runner(spec, {"thigh_l", "shank_l"}, false);
  Walk w;
  std::vector<bsn::sim::ScenarioSample> out;
  while (runner.next(out)) {
    const Quat m = bsn::fusion::default_sensor_to_segment();
    w.thigh.push_back(bsn::fusion::segment_orientation(out[0].truth, m));
    w.shank.push_back(bsn::fusion::segment_orientation(out[1].truth, m));
    w.thigh_samples.push_back(out[0].sample);
    w.shank_samples.push_back(out[1].sample);
  }
  return w;
}

void BM_HingeHeadingUpdate(benchmark::State& state) {
  const Walk w = make_walk();
  bsn::fusion::HingeHeadingEstimator estimator;
  std::size_t i = 0;
  std::uint64_t t = 0;
  Quat corrected;
  for (auto _ : state) {
    estimator.update(w.thigh[i], w.shank[i], t);
    corrected = estimator.correct(w.shank[i]);
    benchmark::DoNotOptimize(corrected);
    t += 10'000'000;  // 100 Hz, time keeps moving forward when the walk wraps
    if (++i == w.thigh.size()) i = 0;
  }
}
BENCHMARK(BM_HingeHeadingUpdate);

// A knee through BodyFusion: per iteration one thigh and one shank sample (two filter updates, one joint).
void BM_KneeFusion(benchmark::State& state) {
  const bool kinematic = state.range(0) != 0;
  const Walk w = make_walk();
  bsn::fusion::BodyModel body;
  body.segments.resize(2);
  body.segments[0].name = body.segments[0].node = "thigh_l";
  body.segments[1].name = body.segments[1].node = "shank_l";
  body.segments[1].parent = "thigh_l";
  body.segments[1].joint = "knee_l";
  if (kinematic) body.segments[1].kinematic_heading = bsn::fusion::HingeHeadingEstimator::Params{};
  bsn::fusion::BodyFusion fusion(body, {}, {}, 0);
  std::size_t i = 0;
  std::uint64_t seq = 0, offset = 0;
  for (auto _ : state) {
    bsn::fusion::ImuSample thigh = w.thigh_samples[i], shank = w.shank_samples[i];
    thigh.timestamp_ns += offset;
    shank.timestamp_ns += offset;
    fusion.process({"thigh_l", seq, thigh}, thigh.timestamp_ns);
    benchmark::DoNotOptimize(fusion.process({"shank_l", seq, shank}, shank.timestamp_ns).joint);
    ++seq;
    if (++i == w.thigh_samples.size()) {
      i = 0;
      offset += 10'000'000'000ull + 10'000'000;  // the walk again, one sample period after its end
    }
  }
  state.SetLabel(kinematic ? "heading: kinematic" : "plain");
}
BENCHMARK(BM_KneeFusion)->Arg(0)->Arg(1);

}  // namespace

BENCHMARK_MAIN();
