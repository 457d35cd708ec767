// The body model: segments, the node on each, the parent of each and the joint to it. Parsing a file is
// the services' job; the structure and its rules live here.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "bsn/fusion/anatomy.hpp"
#include "bsn/fusion/hinge_heading.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion {

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
};

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
/// every parent exists; no parent cycle; a kinematic heading only on a joint (a segment with a parent) and with valid
/// parameters. Returns the first problem found, or nullopt.
std::optional<BodyModelProblem> check_body_model(const BodyModel& body);

/// Joint name of a segment: its explicit name, or "<parent>-<child>".
std::string joint_name(const SegmentSpec& segment);

/// Anatomical convention of the joint parent -> segment: the explicit one, or the one its name implies.
JointConvention joint_convention(const SegmentSpec& segment);

/// The default 7-segment lower body: pelvis; left and right thigh, shank and foot. Node ids equal segment names.
BodyModel default_lower_body();

}  // namespace bsn::fusion
