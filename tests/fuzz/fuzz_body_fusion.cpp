// The sample gate and BodyFusion fed arbitrary samples: three segments in a chain (so joints are computed) plus an
// unknown node, each sample's node, sequence number, timestamp, values and channels taken from the input, mostly
// near a plausible stream so that the filters run, with NaN, Inf, 1e300, wraps and jumps mixed in.
// Invariants (body_fusion_invariants.hpp): finite unit quaternions out, every sample counted once.
#include <fuzzer/FuzzedDataProvider.h>

#include <array>
#include <limits>

#include "body_fusion_invariants.hpp"
#include "bsn/fusion/body_fusion.hpp"
#include "fuzz_check.hpp"

namespace {

using namespace bsn::fusion;

constexpr std::array<const char*, 4> kNodes = {"a", "b", "c", "intruder"};

double value(FuzzedDataProvider& in, double typical) {
  switch (in.ConsumeIntegralInRange<int>(0, 7)) {
    case 0:
      return in.ConsumeFloatingPoint<double>();  // anything, NaN and Inf included
    case 1:
      return std::numeric_limits<double>::quiet_NaN();
    case 2:
      return 1e300;
    default:
      return typical + in.ConsumeFloatingPointInRange<double>(-1.0, 1.0) * typical * 0.2;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  FuzzedDataProvider in(data, size);
  const std::vector<std::string> filters = filter_names();
  BodyModel body;
  for (std::size_t i = 0; i < 3; ++i) {
    SegmentSpec s;
    s.name = std::string("seg_") + kNodes[i];
    s.node = kNodes[i];
    if (i > 0) s.parent = body.segments.back().name;
    if (i == 2) s.kinematic_heading = HingeHeadingEstimator::Params{};  // one joint plain, one kinematic
    s.filter.name = filters[in.ConsumeIntegralInRange<std::size_t>(0, filters.size() - 1)];
    body.segments.push_back(s);
  }
  BodyFusion fusion(body, {}, BodyFusion::Params{}, 0);

  std::array<std::uint64_t, kNodes.size()> seq{}, t{};
  for (auto& s : seq) s = in.ConsumeIntegral<std::uint64_t>();
  std::uint64_t arrival = 0, processed = 0;
  while (in.remaining_bytes() > 0) {
    const std::size_t node = in.ConsumeIntegralInRange<std::size_t>(0, kNodes.size() - 1);
    NodeSample s;
    s.node = kNodes[node];
    switch (in.ConsumeIntegralInRange<int>(0, 7)) {
      case 0:
        seq[node] = in.ConsumeIntegral<std::uint64_t>();  // forged
        break;
      case 1:
        break;  // repeated
      default:
        seq[node] += in.ConsumeIntegralInRange<std::uint64_t>(1, 3);  // next, or a few lost; wraps like the wire
    }
    s.seq = seq[node];
    switch (in.ConsumeIntegralInRange<int>(0, 7)) {
      case 0:
        t[node] = in.ConsumeIntegral<std::uint64_t>();  // anywhere, 0 and 2^64 - 1 included
        break;
      case 1:
        t[node] -= in.ConsumeIntegralInRange<std::uint64_t>(0, 2'000'000'000);  // back
        break;
      default:
        t[node] += in.ConsumeIntegralInRange<std::uint64_t>(100'000, 30'000'000);  // 33 Hz .. 10 kHz
    }
    s.imu.timestamp_ns = t[node];
    for (int k = 0; k < 3; ++k) {
      s.imu.acc[k] = value(in, k == 2 ? kGravity : 0.5);
      s.imu.gyr[k] = value(in, 0.3);
      s.imu.mag[k] = value(in, k == 1 ? 20.0 : -40.0);
    }
    const auto channels = in.ConsumeIntegralInRange<unsigned>(0, 15);
    s.imu.has_acc = (channels & 1u) || channels >= 8;
    s.imu.has_gyr = (channels & 2u) || channels >= 8;
    s.imu.has_mag = (channels & 4u) || channels >= 12;
    arrival += in.ConsumeIntegralInRange<std::uint64_t>(0, 50'000'000);
    const SampleResult& r = fusion.process(s, arrival);
    ++processed;
    const std::string broken = invariants::check(fusion, r, processed);
    BSN_FUZZ_CHECK(broken.empty(), broken.c_str());
    if (in.ConsumeBool()) fusion.check_stale(arrival);
  }
  return 0;
}
