#include "bsn/fusion/body_model.hpp"

#include <stdexcept>
#include <unordered_map>

namespace bsn::fusion {
namespace {
constexpr std::size_t kMaxNameLength = 63;
}

std::optional<std::size_t> BodyModel::find_segment(const std::string& n) const {
  for (std::size_t i = 0; i < segments.size(); ++i)
    if (segments[i].name == n) return i;
  return std::nullopt;
}

std::optional<BodyModelProblem> check_body_model(const BodyModel& body) {
  if (body.segments.empty()) return BodyModelProblem{0, "the body model has no segments"};
  std::unordered_map<std::string, std::size_t> by_name, by_node;
  for (std::size_t i = 0; i < body.segments.size(); ++i) {
    const SegmentSpec& s = body.segments[i];
    if (s.name.empty()) return BodyModelProblem{i, "segment without a name"};
    if (s.node.empty()) return BodyModelProblem{i, "segment '" + s.name + "' has no node"};
    if (s.name.size() > kMaxNameLength || s.node.size() > kMaxNameLength || s.joint.size() > kMaxNameLength) {
      return BodyModelProblem{i, "segment '" + s.name + "': names are limited to 63 characters"};
    }
    if (auto [it, fresh] = by_name.emplace(s.name, i); !fresh) {
      return BodyModelProblem{
          i, "duplicate segment '" + s.name + "' (first defined in entry " + std::to_string(it->second + 1) + ")"};
    }
    if (auto [it, fresh] = by_node.emplace(s.node, i); !fresh) {
      return BodyModelProblem{i,
                              "node '" + s.node + "' is already on segment '" + body.segments[it->second].name + "'"};
    }
  }
  for (std::size_t i = 0; i < body.segments.size(); ++i) {
    const SegmentSpec& s = body.segments[i];
    if (!s.parent.empty() && !by_name.contains(s.parent)) {
      return BodyModelProblem{i, "segment '" + s.name + "' has unknown parent '" + s.parent + "'"};
    }
    if (s.hinge_axis && s.parent.empty()) {
      return BodyModelProblem{i, "segment '" + s.name + "': hinge_axis needs a joint (a parent segment)"};
    }
    if (s.kinematic_heading) {
      if (s.parent.empty()) {
        return BodyModelProblem{i, "segment '" + s.name + "': heading: kinematic needs a joint (a parent segment)"};
      }
      try {
        kinematic_heading_params(s)->check();
      } catch (const std::invalid_argument& e) {
        return BodyModelProblem{i, "segment '" + s.name + "': " + e.what()};
      }
    }
    if (s.hinge_axis) {
      for (const Vec3* axis : {&s.hinge_axis->parent, &s.hinge_axis->child}) {
        if (!axis->allFinite() || !(axis->norm() > 1e-9)) {
          return BodyModelProblem{i, "segment '" + s.name + "': hinge_axis must be a finite, non-zero vector"};
        }
      }
    }
  }
  // Walk up from every segment; more steps than segments means a cycle.
  for (std::size_t i = 0; i < body.segments.size(); ++i) {
    std::size_t current = i;
    std::string path = body.segments[i].name;
    for (std::size_t steps = 0; !body.segments[current].parent.empty(); ++steps) {
      current = by_name.at(body.segments[current].parent);
      path += " -> " + body.segments[current].name;
      if (current == i || steps > body.segments.size()) {
        return BodyModelProblem{i, "parent cycle: " + path};
      }
    }
  }
  return std::nullopt;
}

std::optional<Vec3> parse_segment_axis(std::string_view name) {
  if (name.size() == 1 || (name.size() == 2 && (name[0] == '-' || name[0] == '+'))) {
    const double sign = name[0] == '-' ? -1.0 : 1.0;
    switch (name.back()) {
      case 'x':
        return Vec3(sign, 0.0, 0.0);
      case 'y':
        return Vec3(0.0, sign, 0.0);
      case 'z':
        return Vec3(0.0, 0.0, sign);
      default:
        return std::nullopt;
    }
  }
  const auto direction = parse_direction(name);
  if (!direction) return std::nullopt;
  switch (*direction) {
    case Direction::kAnterior:
      return Vec3::UnitX();
    case Direction::kPosterior:
      return Vec3(-Vec3::UnitX());
    case Direction::kSuperior:
      return Vec3::UnitY();
    case Direction::kInferior:
      return Vec3(-Vec3::UnitY());
    case Direction::kRight:
      return Vec3::UnitZ();
    case Direction::kLeft:
      return Vec3(-Vec3::UnitZ());
  }
  return std::nullopt;
}

std::optional<HingeHeadingEstimator::Params> kinematic_heading_params(const SegmentSpec& segment) {
  if (!segment.kinematic_heading) return std::nullopt;
  HingeHeadingEstimator::Params p = *segment.kinematic_heading;
  if (segment.hinge_axis) {
    p.parent_axis = segment.hinge_axis->parent;
    p.child_axis = segment.hinge_axis->child;
  }
  return p;
}

std::string joint_name(const SegmentSpec& segment) {
  return segment.joint.empty() ? segment.parent + "-" + segment.name : segment.joint;
}

JointConvention joint_convention(const SegmentSpec& segment) {
  if (segment.parent.empty()) return {};
  return segment.anatomy ? *segment.anatomy : infer_joint_convention(joint_name(segment));
}

BodyModel default_lower_body() {
  BodyModel body;
  body.name = "lower_body";
  auto add = [&](const char* name, const char* parent, const char* joint) {
    SegmentSpec s;
    s.name = name;
    s.node = name;
    s.parent = parent;
    s.joint = joint;
    body.segments.push_back(s);
  };
  add("pelvis", "", "");
  for (const char* side : {"_l", "_r"}) {
    const std::string sd = side;
    add(("thigh" + sd).c_str(), "pelvis", ("hip" + sd).c_str());
    add(("shank" + sd).c_str(), ("thigh" + sd).c_str(), ("knee" + sd).c_str());
    add(("foot" + sd).c_str(), ("shank" + sd).c_str(), ("ankle" + sd).c_str());
  }
  return body;
}

}  // namespace bsn::fusion
