// The body model: segments, the node on each, the parent of each and the joint to it. Parsing a file is
// the services' job; the structure and its rules live here.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "bsn/fusion/anatomy.hpp"
#include "bsn/fusion/hinge_heading.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion {

/// A hinge joint's axis in the two ISB segment frames. In the reference pose (the N-pose, where every segment frame
/// is parallel to its parent's) the axis is one vector in both, so `child` is usually `parent`; a joint whose frames
/// are not parallel at zero (a test rig, a robot arm with its own link frames) gives each.
struct HingeAxis {
  Vec3 parent = Vec3::UnitZ();  ///< in the parent's segment frame; any length > 0 (used normalised)
  Vec3 child = Vec3::UnitZ();   ///< in the child's segment frame
};

/// The unit vector of a named segment-frame axis: "x", "y", "z" with an optional sign ("-x", "+z"), or an ISB
/// direction ("anterior" = +X, "posterior", "superior"/"up" = +Y, "inferior"/"down", "right" = +Z, "left").
std::optional<Vec3> parse_segment_axis(std::string_view name);

struct SegmentSpec {
  std::string name;         ///< unique segment name, e.g. "thigh_l"
  std::string node;         ///< node_id of the sensor on this segment; unique across segments
  std::string parent;       ///< parent segment name, "" for a root
  std::string joint;        ///< name of the joint parent -> this segment, e.g. "hip_l"; "" = "<parent>-<name>"
  AxisSequence joint_axes;  ///< rotation sequence the joint angles are decomposed in (default z-y'-x'')
  FilterSpec filter;        ///< filter for this segment
  /// Anatomical convention of the joint to the parent; nullopt = inferred from the joint's name.
  std::optional<JointConvention> anatomy;
  /// Rotation of the sensor's coordinates into the segment's ISB frame (a known mounting, or an alignment). nullopt:
  /// unknown; the anatomical angles assume default_sensor_to_segment() and orientations stay in the sensor frame.
  std::optional<Quat> sensor_to_segment;
  /// How the joint to the parent gets the child's heading relative to the parent's. nullopt (the default): from
  /// the two filters as they are (their magnetometers). Set (`heading: kinematic`, for a hinge-like joint): from
  /// the hinge constraint, estimated with these parameters (hinge_heading.hpp); the joint's angles then use the
  /// child's orientation turned about the vertical by the estimated offset.
  std::optional<HingeHeadingEstimator::Params> kinematic_heading;
  /// The joint's hinge axis, used by the kinematic heading (its parent_axis and child_axis). nullopt: Z in both
  /// frames, the ISB flexion axis of the knee, elbow and ankle.
  std::optional<HingeAxis> hinge_axis;
};

/// The kinematic heading parameters of a segment's joint with its hinge axis filled in; nullopt in the plain mode.
std::optional<HingeHeadingEstimator::Params> kinematic_heading_params(const SegmentSpec& segment);

struct BodyModel {
  std::string name;
  std::vector<SegmentSpec> segments;

  /// Index of a segment by name, or nullopt.
  std::optional<std::size_t> find_segment(const std::string& name) const;
};

/// What is wrong with a body model, and which segment entry shows it.
struct BodyModelProblem {
  std::size_t segment_index = 0;
  std::string message;
};

/// Checks the rules: at least one segment; names and nodes non-empty, at most 63 characters and unique;
/// every parent exists; no parent cycle; a kinematic heading and a hinge axis only on a joint (a segment with a
/// parent), with valid parameters and finite, non-zero axes. Returns the first problem found, or nullopt.
std::optional<BodyModelProblem> check_body_model(const BodyModel& body);

/// Joint name of a segment: its explicit name, or "<parent>-<child>".
std::string joint_name(const SegmentSpec& segment);

/// Anatomical convention of the joint parent -> segment: the explicit one, or the one its name implies.
JointConvention joint_convention(const SegmentSpec& segment);

/// The default 7-segment lower body: pelvis; left and right thigh, shank and foot. Node ids equal segment names.
BodyModel default_lower_body();

}  // namespace bsn::fusion
