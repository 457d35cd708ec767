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
    if (s.kinematic_heading) {
      if (s.parent.empty()) {
        return BodyModelProblem{i, "segment '" + s.name + "': heading: kinematic needs a joint (a parent segment)"};
      }
      try {
        s.kinematic_heading->check();
      } catch (const std::invalid_argument& e) {
        return BodyModelProblem{i, "segment '" + s.name + "': " + e.what()};
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
