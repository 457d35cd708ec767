// One-line human renderings of bsn samples: degrees, seconds, named flags.
#pragma once

#include <string>

#include "bsn_idl/bsn.h"

namespace bsn::services {

std::string format_flags(std::uint32_t flags);
std::string format_sample(const bsn::RawSample& s);
std::string format_sample(const bsn::Orientation& s, const char* prefix = "orientation");
std::string format_sample(const bsn::JointAngles& s);
/// An estimate whose numbers are not all finite: its key, time and flags, and NON-FINITE in place of every number,
/// so that nothing prints a NaN as if it were an angle.
std::string format_non_finite(const bsn::Orientation& s, const char* prefix = "orientation");
std::string format_non_finite(const bsn::JointAngles& s);
std::string format_sample(const bsn::Status& s);
std::string format_sample(const bsn::CalibrationRequest& s);
std::string format_sample(const bsn::CalibrationResult& s);
std::string format_sample(const bsn::CalibrationProgress& s);
/// "waiting", "collecting", "fitting", "done", "refused".
const char* phase_name(bsn::CalibrationPhase phase);

}  // namespace bsn::services
