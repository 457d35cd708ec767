// Between the IDL types and the cores' Eigen types.
#pragma once

#include "bsn/fusion/anatomy.hpp"
#include "bsn/fusion/imu_sample.hpp"
#include "bsn/fusion/rotation.hpp"
#include "bsn_idl/bsn.h"

namespace bsn::dds {

fusion::ImuSample to_imu_sample(const bsn::RawSample& raw);
/// The same from a raw sample's fields held elsewhere (acc, gyr, mag: three values each; channels: CHANNEL_* bits), as
/// `bsn process` keeps its input: the offline fusion takes its samples exactly as the live one does.
fusion::ImuSample to_imu_sample(std::uint64_t timestamp_ns, const double* acc, const double* gyr, const double* mag,
                                std::uint32_t channels);

/// Fills a raw sample from an ImuSample (channels from its has_* flags).
void fill_raw_sample(const fusion::ImuSample& s, bsn::RawSample& raw);

fusion::Quat to_quat(const std::array<double, 4>& wxyz);
std::array<double, 4> to_wxyz(const fusion::Quat& q);

/// Sets quat and yaw/pitch/roll of an Orientation from q.
void fill_orientation(const fusion::Quat& q, bsn::Orientation& out);

/// Sets the anatomical fields of a JointAngles (anatomy, side, names, angles in rad). Keeps the strings' buffers.
void fill_anatomical(const fusion::JointConvention& convention, const fusion::Vec3& angles, bsn::JointAngles& out);

/// Monotonic clock (CLOCK_MONOTONIC) in ns: the sensor clock of simulated nodes on one host.
std::uint64_t monotonic_ns();

}  // namespace bsn::dds
