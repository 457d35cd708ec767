// One-line human renderings of bsn samples: degrees, seconds, named flags.
#pragma once

#include <string>

#include "bsn_idl/bsn.h"

namespace bsn::services {

std::string format_flags(std::uint32_t flags);
std::string format_sample(const bsn::RawSample& s);
std::string format_sample(const bsn::Orientation& s, const char* prefix = "orientation");
std::string format_sample(const bsn::JointAngles& s);
std::string format_sample(const bsn::Status& s);
std::string format_sample(const bsn::CalibrationRequest& s);
std::string format_sample(const bsn::CalibrationResult& s);
std::string format_sample(const bsn::CalibrationProgress& s);
/// "waiting", "collecting", "fitting", "done", "refused".
const char* phase_name(bsn::CalibrationPhase phase);

}  // namespace bsn::services
