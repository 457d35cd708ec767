// Which nodes of a body an alignment collects, in which order: the calibration service's bookkeeping, without DDS.
#pragma once

#include <string>
#include <vector>

#include "bsn/calib/alignment_session.hpp"
#include "bsn/fusion/body_model.hpp"

namespace bsn::services {

/// The alignment's nodes of `body`: those named in `wanted` (every node of the body when empty), parents before
/// children; `flexion_sign` from the joint's type (knee -1, hip and ankle +1, others 0). On a node of no segment
/// `problem` says so and the result is empty.
std::vector<calib::AlignmentNode> alignment_nodes(const fusion::BodyModel& body, const std::vector<std::string>& wanted,
                                                  std::string& problem);

}  // namespace bsn::services
