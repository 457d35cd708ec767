// The calibration kinds and samples between the wire (IDL) and calib_core: one place, without DDS.
#pragma once

#include <cstdint>
#include <optional>

#include "bsn/calib/calibration_session.hpp"
#include "bsn/fusion/imu_sample.hpp"
#include "bsn_idl/bsn.h"

namespace bsn::services {

/// A sample of the calibration sessions from a fusion-core sample (live from bsn/raw, or from a recording).
calib::SessionSample session_sample(const fusion::ImuSample& imu, std::uint64_t seq);

/// The wire kind of a core kind and back (nullopt for a value outside the enum, e.g. from another vendor).
bsn::CalibrationKind to_wire(calib::CalibrationKind kind);
std::optional<calib::CalibrationKind> from_wire(bsn::CalibrationKind kind);

}  // namespace bsn::services
