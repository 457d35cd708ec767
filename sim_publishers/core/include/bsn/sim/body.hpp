// Kinematic chains of rigid segments with exact orientation, angular rate and acceleration from analytic
// signals (no numerical differentiation). A segment hangs from its parent at a joint centre and rotates
// relative to it through a sequence of revolute steps; the root is placed in the earth frame (ENU) by three
// translation signals and its own revolute steps.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "bsn/fusion/anatomy.hpp"
#include "bsn/fusion/rotation.hpp"
#include "bsn/sim/signal.hpp"

namespace bsn::sim {

using fusion::Quat;
using fusion::Vec3;

/// Rotation by angle(t) (rad) about a unit axis fixed in the frame before this step.
struct RevoluteStep {
  Vec3 axis = Vec3::UnitZ();
  Signal angle;
};

struct SegmentDef {
  std::string name;
  int parent = -1;                     ///< index of the parent segment (lower than this one); -1 = root
  Vec3 joint_offset = Vec3::Zero();    ///< joint centre in the parent's segment frame, m (root: unused)
  std::vector<RevoluteStep> rotation;  ///< parent frame -> segment frame (root: earth -> segment)
  std::array<Signal, 3> translation;   ///< root only: origin in the earth frame, m
  Vec3 sensor_offset = Vec3::Zero();   ///< sensor position in the segment frame, m
  /// The sensor's mounting: sensor coordinates into segment coordinates (q_sensor = q_segment * sensor_to_segment).
  Quat sensor_to_segment = Quat::Identity();
  std::string joint;  ///< name of the joint to the parent, e.g. "knee_l" (its anatomical convention comes from it)
};

/// Exact kinematics of one segment and its sensor at one instant.
struct SegmentState {
  // Segment frame, earth-referenced.
  Quat q_segment = Quat::Identity();        ///< segment-to-earth
  Vec3 omega_earth = Vec3::Zero();          ///< angular velocity, rad/s, earth frame
  Vec3 alpha_earth = Vec3::Zero();          ///< angular acceleration, rad/s^2, earth frame
  Vec3 origin = Vec3::Zero();               ///< m
  Vec3 origin_velocity = Vec3::Zero();      ///< m/s
  Vec3 origin_acceleration = Vec3::Zero();  ///< m/s^2
  // The sensor.
  Quat q_sensor = Quat::Identity();  ///< sensor-to-earth
  Vec3 gyr_sensor = Vec3::Zero();    ///< angular rate, rad/s, sensor frame
  Vec3 position = Vec3::Zero();      ///< sensor position, m, earth frame
  Vec3 velocity = Vec3::Zero();      ///< m/s, earth frame
  Vec3 acceleration = Vec3::Zero();  ///< linear acceleration of the sensor point, m/s^2, earth frame
  /// Specific force in the sensor frame: R^T (a + g z), m/s^2.
  Vec3 specific_force_sensor() const;
};

/// Segment-to-earth orientation of a segment's ISB anatomical frame (X anterior, Y superior, Z right). The
/// simulator's segment frames are x forward, y left, z up when standing: the default mounting of bsn's body model.
inline Quat anatomical_orientation(const SegmentState& s) {
  return fusion::segment_orientation(s.q_segment, fusion::default_sensor_to_segment());
}

/// The sensor-to-segment rotation into the ISB frame (what an alignment should find) of a segment's sensor.
inline Quat true_sensor_to_segment(const SegmentDef& def) {
  return fusion::default_sensor_to_segment() * def.sensor_to_segment;
}

class Body {
 public:
  Body() = default;
  /// Throws std::invalid_argument on a bad parent index, a duplicate name or a non-unit axis.
  explicit Body(std::vector<SegmentDef> segments);

  std::size_t size() const { return segments_.size(); }
  const SegmentDef& segment(std::size_t i) const { return segments_[i]; }
  SegmentDef& segment(std::size_t i) { return segments_[i]; }
  std::optional<std::size_t> find(const std::string& name) const;

  /// States of every segment at t seconds; `out` is resized once to size() (no allocation afterwards).
  void evaluate(double t_s, std::vector<SegmentState>& out) const;
  /// State of segment i and its ancestors only (the other entries of `out` are left as they were).
  void evaluate_chain(double t_s, std::size_t i, std::vector<SegmentState>& out) const;

 private:
  void evaluate_segment(double t_s, std::size_t i, std::vector<SegmentState>& out) const;

  std::vector<SegmentDef> segments_;
};

// ---- Bodies and their motions -------------------------------------------------------------------------

/// One rigid body named `name` whose sensor sits at the origin: the bench-test body.
Body free_body(const std::string& name = "body");

/// Base pose of a root: position and intrinsic z-y'-x'' angles.
struct Pose {
  Vec3 position_m = Vec3(0.0, 0.0, 1.0);
  fusion::YawPitchRoll orientation;
};

/// Random smooth motion of a free body: a sum of harmonics per rotation axis and per translation axis with
/// amplitudes scaled to the target RMS angular rate and RMS linear acceleration.
struct RandomMotion {
  double angular_rate_rms_rad_s = 0.0;
  double acceleration_rms_m_s2 = 0.0;
  double min_frequency_hz = 0.2;
  double max_frequency_hz = 1.5;
  int harmonics_per_axis = 4;
  std::vector<Window> active;  ///< when it moves; empty = always
  std::uint64_t seed = 1;
};

/// The three movement intensities of Nez et al. 2018, Table 1 (mean +- SD of |a| and |w|).
enum class Intensity { kSlow, kIntermediate, kFast };
struct IntensityStats {
  double acc_mean_g, acc_sd_g, rate_mean_deg_s, rate_sd_deg_s;
};
IntensityStats nez_table1(Intensity intensity);
/// A RandomMotion whose RMS |a| and |w| equal sqrt(mean^2 + SD^2) of the intensity's Table 1 row.
RandomMotion random_motion_for(Intensity intensity, std::uint64_t seed);

/// A rotation of angle_rad about `axis` (in the body frame at that moment) with a minimum-jerk profile.
struct ScriptedRotation {
  Vec3 axis = Vec3::UnitZ();
  double angle_rad = 0.0;
  double start_s = 0.0;
  double duration_s = 1.0;
};
/// A translation by `by_m` (earth frame) with a minimum-jerk profile.
struct ScriptedMove {
  Vec3 by_m = Vec3::Zero();
  double start_s = 0.0;
  double duration_s = 1.0;
};

/// `count` static poses of `hold_s` each with hand-like rotations of turn_s between them (random axes,
/// 40..120 deg), starting after start_s: the magnetometer calibration session of Zhang & Yang 2015.
std::vector<ScriptedRotation> random_pose_sequence(int count, double hold_s, double turn_s, double start_s,
                                                   std::uint64_t seed);

/// One sinusoid on each angle of the pose (yaw, pitch, roll, z-y'-x''), amplitudes in rad.
struct PoseSwing {
  Signal::Harmonic yaw, pitch, roll;
};

/// Free-body motion: base pose (+ its swing) + random motion + scripted rotations and moves, in that order.
struct FreeMotion {
  Pose pose;
  std::optional<PoseSwing> swing;
  std::optional<RandomMotion> random;
  std::vector<ScriptedRotation> rotations;
  std::vector<ScriptedMove> moves;
};
Body free_body(const FreeMotion& motion, const std::string& name = "body");

/// A varied but bounded rotation about the sensor picked from a seed (no translation): yaw swings up to
/// +-60 deg, pitch and roll up to +-30 deg, each around a random offset, at 0.1-0.4 Hz. Pitch stays below
/// 45 deg, far from gimbal lock. The motion of `bsn sim --node` without a scenario.
FreeMotion random_swing(std::uint64_t seed);

/// Gait of the lower body: joint angles as harmonics of the stride phase (left and right half a stride
/// apart), pelvis translation forward at `speed_m_s` with vertical and lateral oscillation.
/// What a lab asks of a subject before walking, for the sensor-to-segment alignment: stand still in the N-pose,
/// then flex each leg (hip, knee and ankle together) a few times, stand still again, then walk.
struct AlignmentMoves {
  double pose_s = 3.0;              ///< standing still in the N-pose at the start, and again before walking
  int flexions_per_leg = 3;         ///< left leg first
  double flexion_s = 2.0;           ///< one flexion, up and down
  double hip_flexion_rad = 0.8;     ///< 46 deg
  double knee_flexion_rad = 1.2;    ///< 69 deg
  double ankle_flexion_rad = 0.35;  ///< 20 deg dorsiflexion
  /// When walking starts, s.
  double walk_start_s() const { return 2.0 * pose_s + 2.0 * flexions_per_leg * flexion_s; }
};

struct Gait {
  double cadence_steps_per_min = 110.0;
  double speed_m_s = 1.2;
  double heading_rad = 0.0;  ///< walking direction, yaw of the pelvis (0 = east)
  /// First stand and flex, then walk on the spot (as on a treadmill: speed_m_s does not apply).
  std::optional<AlignmentMoves> alignment;
  /// When the body walks; it stands upright outside these windows (the gait's mean angles step in and out with
  /// the windows' ramps). Empty = always. Not with `alignment`.
  std::vector<Window> active;
  /// Moves of the whole body (the pelvis), earth frame, minimum-jerk: e.g. walking into a disturbed area and back
  /// with speed_m_s 0 (Fan et al. 2018 test E carries the sensor between its two places so).
  std::vector<ScriptedMove> moves;
};
/// Segments pelvis, thigh_l, shank_l, foot_l, thigh_r, shank_r, foot_r (segment x forward, y left, z up
/// when standing). Without gait: standing still at `pose`.
Body lower_body(const std::optional<Gait>& gait, const Pose& pose = {});

/// Arm reaching of the upper body: shoulder flexion and elbow extension out and back once per period.
struct Reaching {
  double period_s = 3.0;
  double shoulder_flexion_rad = 1.4;  ///< at full reach
};
/// Segments trunk, upper_arm_l, forearm_l, hand_l, upper_arm_r, forearm_r, hand_r.
Body upper_body(const std::optional<Reaching>& reaching, const Pose& pose = {});

/// A test rig of three links whose two hinges turn about different axes of the middle link: `base` (the root, fixed
/// at `pose`), `link_1` hinged on top of it about the base's
/// medio-lateral axis (ISB Z, the simulator's -y) and `link_2` hinged on top of link_1 about link_1's anterior axis
/// (ISB X, the simulator's x), as a robot arm's shoulder pitch and roll. Links 0.3 m long, pointing up at zero;
/// hinge_1 swings 10 +- 20 deg at 0.25 Hz, hinge_2 0 +- 30 deg at 0.35 Hz (a slow rig: accelerations below 0.5 m/s^2),
/// so both hinge axes stay within about 30 deg of horizontal, where they show the relative heading. The joints are
/// named hinge_1 and hinge_2 (no anatomy).
Body hinge_chain(const Pose& pose = {});

}  // namespace bsn::sim
