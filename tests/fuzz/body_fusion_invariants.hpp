// What BodyFusion must keep for any sample it is fed, good or hostile; checked after every sample by the fuzz
// target (fuzz_body_fusion.cpp) and the seeded property test (tests/unit/fusion/test_body_fusion_property.cpp).
// Returns "" when everything holds, else what broke.
#pragma once

#include <cmath>
#include <numeric>
#include <string>

#include "bsn/fusion/body_fusion.hpp"

namespace bsn::fusion::invariants {

inline bool finite_unit(const Quat& q) { return q.coeffs().allFinite() && std::abs(q.norm() - 1.0) < 1e-6; }

/// After `result` of one process() call; `processed` counts every call so far.
inline std::string check(const BodyFusion& fusion, const SampleResult& result, std::uint64_t processed) {
  if (result.outcome == SampleOutcome::kEstimated) {
    if (!finite_unit(result.orientation)) return "an orientation that is not a finite unit quaternion";
    if (!result.gyro_bias.allFinite()) return "a non-finite gyro bias";
    if (result.joint) {
      if (!finite_unit(result.joint->relative)) return "a joint quaternion that is not a finite unit quaternion";
      if (!result.joint->angles.allFinite()) return "non-finite joint angles";
      if (!result.joint->anatomical.allFinite()) return "non-finite anatomical angles";
      if (const auto& h = result.joint->heading) {
        if (!(std::abs(h->offset_rad) <= 3.15)) return "a kinematic heading offset that is not an angle in (-pi, pi]";
        if (!(h->observability >= 0.0 && h->observability <= 1.0 + 1e-9))
          return "a kinematic heading observability outside 0..1";
      }
    }
  }
  std::uint64_t received = fusion.unknown_node_samples();
  for (std::size_t i = 0; i < fusion.body().segments.size(); ++i) {
    const SampleGate& gate = fusion.segment(i).gate;
    const auto& c = gate.counters();
    const std::uint64_t rejected = std::accumulate(c.rejected.begin(), c.rejected.end(), std::uint64_t{0});
    if (c.received != c.accepted + rejected) return "received != accepted + rejected by reason";
    if (fusion.segment(i).filter_rejected > c.accepted) return "more filter rejections than accepted samples";
    // Each accepted sample adds at most max_sequence_gap - 1 missing: no blow-up from one forged number.
    if (c.missing > c.accepted * gate.params().max_sequence_gap) return "missing beyond any sequence step seen";
    if (fusion.segment(i).q && !finite_unit(*fusion.segment(i).q)) return "a stored orientation is not finite unit";
    received += c.received;
  }
  if (received != processed) return "a sample was neither counted for a node nor as unknown";
  return {};
}

}  // namespace bsn::fusion::invariants
