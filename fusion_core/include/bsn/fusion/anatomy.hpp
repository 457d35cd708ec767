// Anatomical segment frames and joint angles, after the ISB recommendations (Wu et al. 2002 lower limb and spine,
// Wu et al. 2005 upper limb) and the joint coordinate system of Grood & Suntay 1983.
//
// Segment frame (ISB): X anterior, Y superior (along the segment, distal to proximal), Z to the right; standing
// upright, every segment's frame is parallel to the pelvis's. A segment's orientation is segment-to-earth:
// q_segment = q_sensor * conj(q_sensor_to_segment).
//
// Joint angles: the child's frame relative to the parent's, relative = conj(q_parent) * q_child, decomposed as the
// intrinsic sequence Z (parent's medio-lateral axis: flexion), X' (the floating axis: ab/adduction), Y'' (the
// child's long axis: axial rotation): relative = R_Z(a) R_X(b) R_Y(c). Each joint gives its three angles a name
// whose first word is the positive direction (flexion_extension: flexion positive), with signs chosen so that
// flexion, adduction and internal rotation are positive and the left side reads like the right one for the same
// motion (b and c change sign on the left).
#pragma once

#include <array>
#include <optional>
#include <string_view>

#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion {

/// Which anatomical convention a joint follows. kNone: no anatomical angles (only the relative quaternion).
enum class JointType { kNone, kHip, kKnee, kAnkle, kTrunkPelvis, kShoulder, kElbow, kWrist };

/// Body side of a joint. kMidline (trunk-pelvis, or a joint named without a side) reads with the right side's signs.
enum class BodySide { kMidline, kLeft, kRight };

struct JointConvention {
  JointType type = JointType::kNone;
  BodySide side = BodySide::kMidline;
  bool operator==(const JointConvention&) const = default;
};

/// "hip", "knee", "ankle", "trunk_pelvis", "shoulder", "elbow", "wrist" ("" for kNone).
std::string_view joint_type_name(JointType type);
std::optional<JointType> parse_joint_type(std::string_view name);
/// "left", "right", "" (midline).
std::string_view body_side_name(BodySide side);
std::optional<BodySide> parse_body_side(std::string_view name);

/// The convention of a joint from its name: a type word ("hip", "knee", "ankle", "shoulder", "elbow", "wrist",
/// "trunk", "lumbar", "spine") and a side ("_l", "_r", "_left", "_right" at the end, "left_"/"right_"/"l_"/"r_"
/// at the start). "knee_l" is a left knee; "j12" has none.
JointConvention infer_joint_convention(std::string_view joint_name);

/// Names of the three anatomical angles of a joint type, in order (Z, X', Y''); all "" for kNone.
std::array<std::string_view, 3> anatomical_angle_names(JointType type);

/// The three anatomical angles (rad) of the relative orientation of two ISB segment frames. Zero for kNone.
Vec3 anatomical_angles(const Quat& relative, const JointConvention& convention);

/// Inverse of anatomical_angles: the relative orientation of angles (rad) under a convention (kNone: identity).
Quat relative_from_anatomical(const Vec3& angles, const JointConvention& convention);

/// The sensor-to-segment rotation of a sensor whose x points anterior, y left and z up in the standing pose (the
/// simulator's mounting, and the default when nothing better is known): R_X(-90 deg).
Quat default_sensor_to_segment();

/// Anatomical direction of a sensor axis, in the standing pose.
enum class Direction { kAnterior, kPosterior, kSuperior, kInferior, kLeft, kRight };
std::optional<Direction> parse_direction(std::string_view name);  ///< "anterior", "posterior", "superior" ("up")...

/// The sensor-to-segment rotation of a sensor whose x, y, z point in the given directions. nullopt if the three
/// directions are not a right-handed set (two along one line, or a mirror).
std::optional<Quat> sensor_to_segment_from_axes(const std::array<Direction, 3>& sensor_axes);

/// Segment-to-earth orientation of the segment a sensor sits on.
inline Quat segment_orientation(const Quat& q_sensor, const Quat& sensor_to_segment) {
  return q_sensor * sensor_to_segment.conjugate();
}

}  // namespace bsn::fusion
