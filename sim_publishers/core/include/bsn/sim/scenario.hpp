// A scenario: a body and its motion, a magnetic environment and sensor errors, for a duration at a rate.
// ScenarioRunner turns it into per-segment samples with exact truth. Plain data in, no I/O: the YAML loader
// lives in sim_publishers/scenario.
#pragma once

#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "bsn/fusion/imu_sample.hpp"
#include "bsn/sim/body.hpp"
#include "bsn/sim/magnetic_environment.hpp"
#include "bsn/sim/sensor_model.hpp"

namespace bsn::sim {

enum class BodyKind { kFree, kLowerBody, kUpperBody, kHingeChain };

/// How each sensor of a lower or upper body sits on its segment: rotated and displaced at random (own stream per
/// segment), as sensors strapped on by hand are. The default is realistic: any rotation, up to 2 cm off its place.
struct Mounting {
  double max_rotation_deg = 180.0;  ///< 180: any rotation (uniform); below: random axis, angle uniform up to this
  double max_offset_m = 0.02;       ///< displacement in a random direction, uniform up to this
};

struct ScenarioSpec {
  std::string name;
  std::string description;
  double duration_s = 60.0;  ///< infinity: until the caller stops
  double rate_hz = 100.0;
  std::uint64_t seed = 1;
  BodyKind body = BodyKind::kFree;
  std::string free_body_name = "body";  ///< segment name of the free body
  FreeMotion free_motion;               ///< free body
  std::optional<Gait> gait;             ///< lower body
  std::optional<Reaching> reaching;     ///< upper body
  Pose pose;                            ///< lower and upper body, hinge chain: where they stand
  Mounting mounting;                    ///< lower and upper body: the sensors' mounting errors
  MagneticEnvironment magnetic;         ///< attached magnets refer to segments of build_body() by index
  SensorErrors sensors;                 ///< the same error model (own random streams) on every segment
  std::vector<Window> movement;         ///< where errors count; empty = everywhere
};

Body build_body(const ScenarioSpec& spec);

/// What `bsn sim --node` runs without a scenario file: one free body `segment` on random_swing(seed) in the
/// default earth field, with white noise only (at 100 Hz 0.005 rad/s, 0.02 m/s^2 and 0.3 uT per sample).
/// duration_s 0 = until stopped.
ScenarioSpec swing_scenario(const std::string& segment, std::uint64_t seed, double rate_hz, double duration_s);

/// One segment's output at one sample.
struct ScenarioSample {
  fusion::ImuSample sample;               ///< timestamp in ns from the scenario start
  Quat truth = Quat::Identity();          ///< sensor-to-earth
  Quat segment_truth = Quat::Identity();  ///< the segment's ISB frame to earth (what an aligned estimate reads)
  bool dropped = false;  ///< the sensor lost this sample (sample is still filled with what it would have read)
  bool movement = true;  ///< inside the scenario's movement windows
  // The joint to the segment's parent (none for a root): its convention (from the joint's name), the relative
  // orientation of the two ISB segment frames and its anatomical angles, rad.
  fusion::JointConvention joint;
  std::optional<Quat> joint_relative;
  Vec3 joint_anatomical = Vec3::Zero();
};

class ScenarioRunner {
 public:
  /// `segments`: names to simulate (empty = every segment). `ideal` switches every sensor error off.
  /// Throws std::invalid_argument on an unknown segment or a bad spec.
  ScenarioRunner(const ScenarioSpec& spec, const std::vector<std::string>& segments, bool ideal);

  std::uint64_t sample_count() const { return count_; }
  std::uint64_t next_index() const { return k_; }
  const std::vector<std::string>& segment_names() const { return names_; }
  const Body& body() const { return body_; }
  const MagneticEnvironment& magnetic() const { return spec_.magnetic; }

  /// Fills `out` (one entry per selected segment) with the next sample; false when the scenario is over.
  bool next(std::vector<ScenarioSample>& out);

 private:
  ScenarioSpec spec_;
  Body body_;
  std::vector<std::size_t> selected_;
  std::vector<std::string> names_;
  std::vector<fusion::JointConvention> joints_;  ///< per selected segment
  std::vector<SensorSimulator> sensors_;
  std::vector<std::mt19937_64> timing_rng_;  ///< per sensor: jitter and drops
  std::vector<SegmentState> states_;
  std::uint64_t count_ = 0;
  std::uint64_t k_ = 0;
};

}  // namespace bsn::sim
