// The lab's alignment session in simulation, shared by the alignment tests: consumer MEMS (magnetometer calibrated
// before, as a lab does), sensors at any orientation and up to 2 cm off their place, the alignment moves (N-pose,
// flexions), then `walk_s` of walking on the spot.
#pragma once

#include <cstdint>

#include "bsn/sim/scenario.hpp"

namespace bsn::calib::testing {

inline sim::ScenarioSpec alignment_session_scenario(std::uint64_t seed, double walk_s) {
  sim::ScenarioSpec spec;
  spec.name = "alignment_session";
  spec.body = sim::BodyKind::kLowerBody;
  spec.seed = seed;
  sim::Gait gait;
  gait.alignment = sim::AlignmentMoves{};
  spec.gait = gait;
  spec.duration_s = gait.alignment->walk_start_s() + walk_s;
  spec.sensors = *sim::sensor_preset("consumer_mems");
  spec.sensors.mag.hard_iron = sim::Vec3::Zero();
  spec.sensors.mag.soft_iron = sim::Mat3::Identity();
  spec.mounting = sim::Mounting{180.0, 0.02};
  return spec;
}

}  // namespace bsn::calib::testing
