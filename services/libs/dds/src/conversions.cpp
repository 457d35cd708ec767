#include "bsn/dds/conversions.hpp"

#include <time.h>

namespace bsn::dds {
namespace {
std::array<double, 3> arr(const fusion::Vec3& v) { return {v.x(), v.y(), v.z()}; }
}  // namespace

fusion::ImuSample to_imu_sample(const bsn::RawSample& raw) {
  return to_imu_sample(raw.timestamp_ns(), raw.acc().data(), raw.gyr().data(), raw.mag().data(), raw.channels());
}

fusion::ImuSample to_imu_sample(std::uint64_t timestamp_ns, const double* acc, const double* gyr, const double* mag,
                                std::uint32_t channels) {
  fusion::ImuSample s;
  s.timestamp_ns = timestamp_ns;
  s.acc = fusion::Vec3(acc[0], acc[1], acc[2]);
  s.gyr = fusion::Vec3(gyr[0], gyr[1], gyr[2]);
  s.mag = fusion::Vec3(mag[0], mag[1], mag[2]);
  s.has_acc = (channels & bsn::CHANNEL_ACC) != 0;
  s.has_gyr = (channels & bsn::CHANNEL_GYR) != 0;
  s.has_mag = (channels & bsn::CHANNEL_MAG) != 0;
  return s;
}

void fill_raw_sample(const fusion::ImuSample& s, bsn::RawSample& raw) {
  raw.timestamp_ns(s.timestamp_ns);
  raw.acc(arr(s.acc));
  raw.gyr(arr(s.gyr));
  raw.mag(arr(s.mag));
  raw.channels((s.has_acc ? bsn::CHANNEL_ACC : 0u) | (s.has_gyr ? bsn::CHANNEL_GYR : 0u) |
               (s.has_mag ? bsn::CHANNEL_MAG : 0u));
}

fusion::Quat to_quat(const std::array<double, 4>& q) { return fusion::Quat(q[0], q[1], q[2], q[3]); }

std::array<double, 4> to_wxyz(const fusion::Quat& q) { return {q.w(), q.x(), q.y(), q.z()}; }

void fill_orientation(const fusion::Quat& q, bsn::Orientation& out) {
  const fusion::Quat c = fusion::canonical(q);
  out.quat(to_wxyz(c));
  const fusion::YawPitchRoll ypr = fusion::to_yaw_pitch_roll(c);
  out.yaw(ypr.yaw);
  out.pitch(ypr.pitch);
  out.roll(ypr.roll);
}

std::uint64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::uint64_t>(ts.tv_sec) * 1000000000ull + static_cast<std::uint64_t>(ts.tv_nsec);
}

void fill_anatomical(const fusion::JointConvention& convention, const fusion::Vec3& angles, bsn::JointAngles& out) {
  out.anatomy().assign(fusion::joint_type_name(convention.type));
  out.side().assign(fusion::body_side_name(convention.side));
  auto& names = out.anatomical_names();
  if (convention.type == fusion::JointType::kNone) {
    names.clear();
  } else {
    const auto wanted = fusion::anatomical_angle_names(convention.type);
    names.resize(3);
    for (std::size_t i = 0; i < 3; ++i) names[i].assign(wanted[i]);
  }
  out.anatomical({angles.x(), angles.y(), angles.z()});
}

}  // namespace bsn::dds
