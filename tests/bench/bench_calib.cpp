// Fit times of the Zhang-Yang calibration: 30 static poses (the paper's simulation), and 10 000 raw samples
// (a hand-turned recording of 100 s at 100 Hz: ellipsoid over every sample, H over its poses).
#include <benchmark/benchmark.h>

#include "bsn/calib/field_calibration.hpp"
#include "bsn/calib/pose_segmentation.hpp"
#include "calib_test_helpers.hpp"

namespace {

using namespace bsn::calib;
using testing::Quat;

void BM_Fit30Poses(benchmark::State& state) {
  const testing::PaperSensor sensor = testing::paper_sensor();
  std::mt19937_64 rng(1);
  const Vec3 m_earth = testing::earth_field(500.0, 1.15);
  Points3 poses(3, 30);
  std::vector<Mat3> rotations;
  Quat q0;
  for (int j = 0; j < 30; ++j) {
    const Quat q = testing::random_orientation(rng);
    if (j == 0) q0 = q;
    poses.col(j) = testing::raw_reading(sensor, q, m_earth, 0.316, rng);
    rotations.push_back((q0.conjugate() * q).toRotationMatrix());
  }
  for (auto _ : state) {
    FieldCalibration c = calibrate_field(poses, rotations, 500.0);
    benchmark::DoNotOptimize(c);
    if (!c.ok()) state.SkipWithError(c.message.c_str());
  }
}
BENCHMARK(BM_Fit30Poses)->Unit(benchmark::kMicrosecond);

testing::HandRecording hand_recording() {
  std::mt19937_64 rng(2);
  std::vector<Quat> orientations;
  for (int j = 0; j < 20; ++j) orientations.push_back(testing::random_orientation(rng));
  // 20 rests of 3.1 s and 19 turns of 2 s = 100 s at 100 Hz = 10 000 samples.
  return testing::hand_turned_recording(orientations, 3.1, 2.0, testing::ConsumerGyro{}, Mat3::Identity(),
                                        Vec3(0.01, 0.0, -0.01), testing::paper_sensor(),
                                        testing::earth_field(500.0, 1.15), 0.316, rng);
}

void BM_Fit10000RawSamples(benchmark::State& state) {
  const testing::HandRecording r = hand_recording();
  state.counters["samples"] = static_cast<double>(r.mag.cols());
  for (auto _ : state) {
    FieldCalibration c = calibrate_field_from_recording(r.rates, r.mag, 100.0, 500.0);
    benchmark::DoNotOptimize(c);
    if (!c.ok()) state.SkipWithError(c.message.c_str());
  }
}
BENCHMARK(BM_Fit10000RawSamples)->Unit(benchmark::kMillisecond);

void BM_Ellipsoid10000RawSamples(benchmark::State& state) {
  const testing::HandRecording r = hand_recording();
  for (auto _ : state) {
    EllipsoidFit e = fit_ellipsoid(r.mag);
    benchmark::DoNotOptimize(e);
  }
}
BENCHMARK(BM_Ellipsoid10000RawSamples)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
