// Sensor-to-segment alignment: the rotation of each sensor's coordinates into its segment's anatomical frame (ISB:
// X anterior, Y superior along the segment, Z to the right), from what a lab asks of a subject:
//  - a static N-pose (standing upright, arms down, feet parallel): every segment's Y is up, so the mean specific
//    force gives Y in each sensor's coordinates, and every segment's frame is parallel to every other's;
//  - a functional movement (a few hip-knee-ankle flexions, or walking): the flexion axis of a hinge-like joint in
//    both sensors' coordinates from the two gyroscopes alone (Seel, Raisch & Schauer 2014, "IMU-based joint angle
//    measurement for gait analysis", section 3.1: |g1 x j1| = |g2 x j2| at every instant).
// The flexion axes give each segment's Z; their signs (the fit cannot tell j from -j) come from one joint's known
// flexion direction and from the N-pose, where all Z point the same way on earth (the magnetometers only need to
// agree within 90 deg for this). A segment in no fitted joint takes the body's right direction from the N-pose.
#pragma once

#include <Eigen/Geometry>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "bsn/calib/sensor_calibration.hpp"

namespace bsn::calib {

using Quat = Eigen::Quaterniond;

struct HingeAxisParams {
  /// Samples where both rates are below this are skipped, rad/s: at rest they constrain nothing and their noise
  /// only biases the fit. Default 0.2 rad/s (11 deg/s), far above consumer gyro noise (~0.005 rad/s per sample).
  double min_rate_rad_s = 0.2;
  /// At most this many samples enter the fit (evenly picked), bounding its cost. Default 4000 (40 s at 100 Hz).
  std::size_t max_samples = 4000;
  /// Gauss-Newton iterations per start. Default 60: it converges in 5-15 from a start in the right basin.
  int max_iterations = 60;
  /// At least this many moving samples, or no fit. Default 200 (2 s of motion at 100 Hz).
  std::size_t min_samples = 200;
};

/// The hinge axis in both sensors' coordinates (unit vectors, each up to its sign).
struct HingeAxisFit {
  Vec3 parent_axis = Vec3::UnitZ();
  Vec3 child_axis = Vec3::UnitZ();
  double rms_residual_rad_s = 0.0;  ///< RMS of |g1 x j1| - |g2 x j2| over the samples used
  double rms_rate_rad_s = 0.0;      ///< RMS rate of the samples used: the residual's scale
  std::size_t samples = 0;          ///< moving samples used
  /// How well the data pin each axis down: the smallest curvature of the cost about the axis (smallest eigenvalue
  /// of its 2x2 block of J^T J) over n * rms_rate^2. Near 0: the axis is free, e.g. the parent's while the parent
  /// stands still (|0 x j| = 0 for any j) — a zero residual then says nothing about it.
  double parent_observability = 0.0;
  double child_observability = 0.0;
};

/// Seel et al. 2014's axis identification: minimises sum (|g1 x j1| - |g2 x j2|)^2 over unit j1, j2 by Gauss-Newton
/// from nine starts. gyr_parent[k] and gyr_child[k] are the two sensors' rates (rad/s, their own frames) at the same
/// instant. nullopt with fewer than min_samples moving samples or different lengths.
std::optional<HingeAxisFit> fit_hinge_axis(std::span<const Vec3> gyr_parent, std::span<const Vec3> gyr_child,
                                           const HingeAxisParams& params = {});

/// The sensor-to-segment rotation (v_segment = q * v_sensor) of a segment whose superior axis is `up_in_sensor`
/// (the mean specific force in the N-pose) and whose right axis is about `right_in_sensor` (made perpendicular to
/// up). nullopt if either is zero or they are within 10 deg of parallel.
std::optional<Quat> alignment_from_up_and_right(const Vec3& up_in_sensor, const Vec3& right_in_sensor);

/// Earth axes (ENU) in sensor coordinates from a still sensor's mean specific force and magnetic field (TRIAD):
/// rows east, north, up. nullopt if the two are parallel or zero.
std::optional<Mat3> earth_axes_in_sensor(const Vec3& acc, const Vec3& mag);

/// One segment of the body to align.
struct AlignmentSegment {
  std::string name;
  int parent = -1;  ///< index of the parent segment (lower than this one), -1 for a root
  /// Sign of the rotation about the segment's right (Z) axis, relative to its parent, that the functional moves
  /// flex it in: -1 knee (the shank swings back), +1 hip and ankle (thigh forward, toes up), 0 unknown (the joint
  /// is fitted but does not vote on the sign).
  int flexion_sign = 0;
  Vec3 acc_pose = Vec3::Zero();  ///< mean specific force in the N-pose, sensor frame
  Vec3 mag_pose = Vec3::Zero();  ///< mean magnetic field in the N-pose, sensor frame
  std::vector<Vec3> gyr;         ///< rates of the functional moves, sensor frame; sample k at the same instant for all
};

struct AlignmentParams {
  HingeAxisParams hinge;
  /// A joint's axis is used when its RMS residual is below this share of the RMS rate: a hinge. Default 0.15: the
  /// knee in gait and flexions fits to a few per cent; a ball joint in free motion does not.
  double max_relative_residual = 0.15;
  /// An axis is used for its segment only when its observability (HingeAxisFit) is at least this. Default 0.005:
  /// well-fitted axes of flexions and gait show 0.02 and more; a parent standing still shows ~0.
  double min_observability = 0.005;
};

struct SegmentAlignmentResult {
  std::optional<Quat> sensor_to_segment;  ///< nullopt: not aligned (see problem)
  std::string source;                     ///< "hinge <parent>-<child>" or "pose heading"
  double relative_residual = 0.0;         ///< of the hinge used (0 for the pose heading)
  double axis_observability = 0.0;        ///< of the hinge axis used, in this segment's sensor (0: pose heading)
  std::string problem;
};

struct BodyAlignment {
  std::vector<SegmentAlignmentResult> segments;  ///< in the input's order
  std::string problem;                           ///< why nothing could be aligned ("" = at least one segment is)
};

/// Aligns every segment. The functional gyro samples and the N-pose means come from the same session.
BodyAlignment align_body(std::span<const AlignmentSegment> segments, const AlignmentParams& params = {});

}  // namespace bsn::calib
