#include "format.hpp"

#include <cstdio>
#include <numbers>

#include "bsn/logging/log.hpp"
#include "calibration_wire.hpp"

namespace bsn::services {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

std::string printf_string(const char* fmt, auto... args) {
  char buf[512];
  std::snprintf(buf, sizeof buf, fmt, args...);
  return buf;
}

std::string vec3(const std::array<double, 3>& v, double scale = 1.0) {
  return printf_string("[%8.3f %8.3f %8.3f]", v[0] * scale, v[1] * scale, v[2] * scale);
}

// Every string of a sample comes from the network: escaped, so that it cannot drive the terminal.
std::string text(const std::string& s) { return logging::printable(s); }

double seconds(std::uint64_t ns) { return static_cast<double>(ns) * 1e-9; }

// The calibration service's names (kind_name of calib_core), the spelling of --kind and of the store's files.
const char* kind_name(bsn::CalibrationKind k) {
  const std::optional<calib::CalibrationKind> kind = from_wire(k);
  return kind ? calib::kind_name(*kind) : "unknown";
}

}  // namespace

std::string format_flags(std::uint32_t f) {
  std::string out;
  auto add = [&](std::uint32_t bit, const char* name) {
    if (f & bit) out += (out.empty() ? "" : ",") + std::string(name);
  };
  add(bsn::FLAG_RESTING, "resting");
  add(bsn::FLAG_MAG_REJECTED, "mag_rejected");
  add(bsn::FLAG_STALE, "stale");
  add(bsn::FLAG_INITIALISING, "initialising");
  add(bsn::FLAG_REINITIALISED, "reinitialised");
  add(bsn::FLAG_SEGMENT_FRAME, "segment_frame");
  add(bsn::FLAG_HEADING_KINEMATIC, "heading_kinematic");
  return out.empty() ? "-" : out;
}

std::string format_sample(const bsn::RawSample& s) {
  std::string missing;
  if (!(s.channels() & bsn::CHANNEL_ACC)) missing += " no-acc";
  if (!(s.channels() & bsn::CHANNEL_GYR)) missing += " no-gyr";
  if (!(s.channels() & bsn::CHANNEL_MAG)) missing += " no-mag";
  return "raw " + text(s.node_id()) +
         printf_string(" seq=%llu t=%.6fs", static_cast<unsigned long long>(s.seq()), seconds(s.timestamp_ns())) +
         " acc=" + vec3(s.acc()) + " m/s2 gyr=" + vec3(s.gyr(), kDeg) + " deg/s mag=" + vec3(s.mag()) + " uT" + missing;
}

std::string format_sample(const bsn::Orientation& s, const char* prefix) {
  const auto& q = s.quat();
  return std::string(prefix) + " " + text(s.segment()) +
         printf_string(" t=%.6fs yaw=%8.2f pitch=%7.2f roll=%8.2f deg q=[%.4f %.4f %.4f %.4f]",
                       seconds(s.timestamp_ns()), s.yaw() * kDeg, s.pitch() * kDeg, s.roll() * kDeg, q[0], q[1], q[2],
                       q[3]) +
         " bias=" + vec3(s.gyro_bias(), kDeg) + " deg/s flags=" + format_flags(s.flags());
}

std::string format_sample(const bsn::JointAngles& s) {
  const auto& a = s.angles();
  std::string out = "joint " + text(s.joint()) + " (" + text(s.parent()) + " -> " + text(s.child()) + ")" +
                    printf_string(" t=%.6fs", seconds(s.timestamp_ns()));
  // The named anatomical angles first: what a gait lab reads; the axis-sequence angles after them.
  if (!s.anatomy().empty() && s.anatomical_names().size() == 3) {
    out += " " + text(s.anatomy()) + (s.side().empty() ? "" : " " + text(s.side()));
    for (std::size_t i = 0; i < 3; ++i)
      out += " " + text(s.anatomical_names()[i]) + printf_string("=%.2f", s.anatomical()[i] * kDeg);
    out += " deg;";
  }
  out += printf_string(" %s=[%8.2f %8.2f %8.2f] deg", text(s.axes()).c_str(), a[0] * kDeg, a[1] * kDeg, a[2] * kDeg);
  if (s.flags() & bsn::FLAG_HEADING_KINEMATIC)
    out += printf_string(" heading_offset=%.2f deg observability=%.2f", s.heading_offset() * kDeg,
                         s.heading_observability());
  return out + " flags=" + format_flags(s.flags());
}

std::string format_non_finite(const bsn::Orientation& s, const char* prefix) {
  return std::string(prefix) + " " + text(s.segment()) + printf_string(" t=%.6fs", seconds(s.timestamp_ns())) +
         " NON-FINITE (values not shown) flags=" + format_flags(s.flags());
}

std::string format_non_finite(const bsn::JointAngles& s) {
  return "joint " + text(s.joint()) + " (" + text(s.parent()) + " -> " + text(s.child()) + ")" +
         printf_string(" t=%.6fs", seconds(s.timestamp_ns())) +
         " NON-FINITE (values not shown) flags=" + format_flags(s.flags());
}

std::string format_sample(const bsn::Status& s) {
  std::string out = "status " + text(s.process_id()) +
                    printf_string(" period=%.2fs unknown_node_samples=%llu qos_mismatches=%llu write_failures=%llu",
                                  s.period_s(), static_cast<unsigned long long>(s.unknown_node_samples()),
                                  static_cast<unsigned long long>(s.qos_mismatches()),
                                  static_cast<unsigned long long>(s.write_failures()));
  if (s.undecodable_samples() || s.dds_lost_samples())
    out += printf_string(" undecodable=%llu dds_lost=%llu", static_cast<unsigned long long>(s.undecodable_samples()),
                         static_cast<unsigned long long>(s.dds_lost_samples()));
  if (!s.unknown_nodes().empty()) {
    out += " unknown_nodes=";
    for (std::size_t i = 0; i < s.unknown_nodes().size(); ++i) out += (i ? "," : "") + text(s.unknown_nodes()[i]);
  }
  if (s.participant_rejoins())
    out += printf_string(" participant_rejoins=%llu", static_cast<unsigned long long>(s.participant_rejoins()));
  for (const std::string& other : s.other_fusion_processes()) out += " OTHER_FUSION=" + text(other);
  for (const auto& n : s.nodes()) {
    out +=
        "\n  " + text(n.node_id()) + " (" + text(n.segment()) + ")" +
        printf_string(" %6.1f Hz received=%llu accepted=%llu missing=%llu clock_resets=%llu%s rejected:", n.rate_hz(),
                      static_cast<unsigned long long>(n.received()), static_cast<unsigned long long>(n.accepted()),
                      static_cast<unsigned long long>(n.missing()), static_cast<unsigned long long>(n.clock_resets()),
                      n.stale() ? " STALE" : "");
    for (const auto& r : n.rejected()) out += " " + text(r.reason()) + "=" + std::to_string(r.count());
    if (n.source_handovers()) out += " source_handovers=" + std::to_string(n.source_handovers());
    if (!n.conflicting_writer().empty())
      out += " CONFLICT writer=" + text(n.source_writer()) + " other=" + text(n.conflicting_writer());
  }
  return out;
}

std::string format_sample(const bsn::CalibrationRequest& s) {
  return "calibration_request " + text(s.request_id()) + " node=" + text(s.node_id()) + " kind=" + kind_name(s.kind()) +
         printf_string(" duration=%.1fs samples=%u", s.duration_s(), s.sample_count()) +
         (s.kind() == bsn::CALIBRATION_SEGMENT_ALIGNMENT
              ? printf_string(" pose=%.1fs body=%s", s.pose_s(),
                              s.body().empty() ? "default" : printf_string("%zu-bytes", s.body().size()).c_str())
              : std::string());
}

std::string format_sample(const bsn::CalibrationResult& s) {
  if (s.kind() == bsn::CALIBRATION_SEGMENT_ALIGNMENT) {
    const auto& q = s.sensor_to_segment();
    return "calibration_result " + text(s.node_id()) + " request=" + text(s.request_id()) + " kind=alignment" +
           (s.success() ? " ok" : " FAILED") + " segment=" + text(s.segment()) +
           printf_string(" sensor_to_segment=[%.5f %.5f %.5f %.5f]", q[0], q[1], q[2], q[3]) + " source=\"" +
           text(s.alignment_source()) + "\"" +
           printf_string(" hinge_residual=%.4f observability=%.4f samples=%u", s.hinge_residual(),
                         s.axis_observability(), s.sample_count()) +
           (s.message().empty() ? "" : " message=\"" + logging::printable(s.message(), 400) + "\"");
  }
  const auto& h = s.transform();
  return "calibration_result " + text(s.node_id()) + " request=" + text(s.request_id()) +
         " kind=" + kind_name(s.kind()) + (s.success() ? " ok" : " FAILED") + " bias=" + vec3(s.bias()) +
         printf_string(" H=[%.4f %.4f %.4f; %.4f %.4f %.4f; %.4f %.4f %.4f] M=%.3f residual=%.4f cond=%.1f poses=%u",
                       h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8], s.field_magnitude(), s.residual_rms(),
                       s.condition_number(), s.pose_count()) +
         (s.message().empty() ? "" : " message=\"" + logging::printable(s.message(), 400) + "\"");
}

const char* phase_name(bsn::CalibrationPhase phase) {
  switch (phase) {
    case bsn::CALIBRATION_PHASE_WAITING:
      return "waiting";
    case bsn::CALIBRATION_PHASE_COLLECTING:
      return "collecting";
    case bsn::CALIBRATION_PHASE_FITTING:
      return "fitting";
    case bsn::CALIBRATION_PHASE_DONE:
      return "done";
    case bsn::CALIBRATION_PHASE_REFUSED:
      return "refused";
  }
  return "unknown";
}

std::string format_sample(const bsn::CalibrationProgress& s) {
  std::string out =
      "calibration_progress " + s.request_id() + " " + phase_name(s.phase()) +
      printf_string(" elapsed=%.1fs left=%.1fs done=%.0f%%", s.elapsed_s(), s.seconds_left(), 100.0 * s.fraction()) +
      " \"" + (s.phase() == bsn::CALIBRATION_PHASE_REFUSED ? s.message() : s.instruction()) + "\"";
  for (const auto& n : s.nodes())
    out += "\n  " + n.node_id() +
           printf_string(" samples=%u poses=%u octants=%u coverage=%.2f", n.samples(), n.poses(), n.octants(),
                         n.sphere_coverage()) +
           " \"" + n.instruction() + "\"";
  return out;
}

}  // namespace bsn::services
