// The simulator's motion interface: any source of exact segment kinematics. The full body simulator
// (gait, reaching, scenarios) plugs in here.
#pragma once

#include <cstdint>

#include "bsn/fusion/rotation.hpp"

namespace bsn::sim {

using fusion::Quat;
using fusion::Vec3;

/// Exact kinematics of one sensor at one instant.
struct MotionState {
  Quat q_sensor_to_earth = Quat::Identity();
  Vec3 angular_rate_sensor = Vec3::Zero();  ///< rad/s, sensor frame
  Vec3 linear_acc_earth = Vec3::Zero();     ///< acceleration of the sensor point, m/s^2, earth frame (ENU)
};

class MotionModel {
 public:
  virtual ~MotionModel() = default;
  /// State at t seconds after the start.
  virtual MotionState at(double t_s) const = 0;
};

/// Rotation about the sensor's own origin (no translation) with yaw, pitch and roll (z-y'-x'') each a sum of
/// a constant and one sinusoid. Angular rate comes from the analytic derivatives.
class SinusoidalRotation final : public MotionModel {
 public:
  struct Axis {
    double offset_rad = 0.0;
    double amplitude_rad = 0.0;
    double frequency_hz = 0.0;
    double phase_rad = 0.0;
  };
  struct Params {
    Axis yaw, pitch, roll;
  };

  explicit SinusoidalRotation(const Params& params) : params_(params) {}

  /// A varied but bounded motion picked from a seed: yaw swings up to +-60 deg, pitch and roll up to +-30 deg,
  /// at 0.1-0.4 Hz. Pitch stays far from +-90 deg.
  static SinusoidalRotation from_seed(std::uint64_t seed);

  MotionState at(double t_s) const override;
  const Params& params() const { return params_; }

 private:
  Params params_;
};

}  // namespace bsn::sim
