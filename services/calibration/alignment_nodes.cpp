#include "alignment_nodes.hpp"

#include <algorithm>

#include "bsn/logging/log.hpp"

namespace bsn::services {

std::vector<calib::AlignmentNode> alignment_nodes(const fusion::BodyModel& body, const std::vector<std::string>& wanted,
                                                  std::string& problem) {
  std::vector<calib::AlignmentNode> out;
  for (const std::string& node : wanted) {
    const bool known = std::any_of(body.segments.begin(), body.segments.end(),
                                   [&node](const fusion::SegmentSpec& s) { return s.node == node; });
    if (!known) {
      std::string nodes;
      for (const auto& s : body.segments) nodes += (nodes.empty() ? "" : ", ") + s.node;
      problem = "node '" + logging::printable(node, 64) + "' is on no segment of the body (its nodes: " + nodes + ")";
      return {};
    }
  }
  // Parents first: a segment is added once its parent is (or its parent is not aligned).
  std::vector<bool> added(body.segments.size(), false);
  std::vector<int> index_of(body.segments.size(), -1);
  auto included = [&](std::size_t i) {
    return wanted.empty() || std::find(wanted.begin(), wanted.end(), body.segments[i].node) != wanted.end();
  };
  for (bool progress = true; progress;) {
    progress = false;
    for (std::size_t i = 0; i < body.segments.size(); ++i) {
      if (added[i] || !included(i)) continue;
      const fusion::SegmentSpec& s = body.segments[i];
      const auto parent = body.find_segment(s.parent);
      if (parent && included(*parent) && !added[*parent]) continue;  // later, after its parent
      calib::AlignmentNode n;
      n.node = s.node;
      n.segment = s.name;
      n.joint = s.parent.empty() ? "" : fusion::joint_name(s);
      n.parent = parent && included(*parent) ? index_of[*parent] : -1;
      const fusion::JointType type = fusion::joint_convention(s).type;
      n.flexion_sign = s.parent.empty()                                                       ? 0
                       : type == fusion::JointType::kKnee                                     ? -1
                       : type == fusion::JointType::kHip || type == fusion::JointType::kAnkle ? 1
                                                                                              : 0;
      index_of[i] = static_cast<int>(out.size());
      added[i] = true;
      out.push_back(std::move(n));
      progress = true;
    }
  }
  return out;
}

}  // namespace bsn::services
