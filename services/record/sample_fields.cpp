#include "sample_fields.hpp"

#include <cinttypes>
#include <cstdio>

#include "bsn/io/json.hpp"

namespace bsn::services {

namespace {
// Primitive fields come by value from a const sample; one double is an array of one.
void scalar(FieldVisitor& v, const char* name, const char* unit, double value) { v.f64(name, unit, &value, 1); }
}  // namespace

void visit_fields(const bsn::RawSample& s, FieldVisitor& v) {
  v.key("node_id", s.node_id());
  v.u64("timestamp_ns", "ns", s.timestamp_ns());
  v.u64("seq", "", s.seq());
  v.f64("acc", "m/s^2", s.acc().data(), 3);
  v.f64("gyr", "rad/s", s.gyr().data(), 3);
  v.f64("mag", "uT", s.mag().data(), 3);
  v.u32("channels", "bits", s.channels());
}

void visit_fields(const bsn::Orientation& s, FieldVisitor& v) {
  v.key("segment", s.segment());
  v.text("node_id", s.node_id());
  v.u64("timestamp_ns", "ns", s.timestamp_ns());
  v.f64("quat", "wxyz", s.quat().data(), 4);
  scalar(v, "yaw", "rad", s.yaw());
  scalar(v, "pitch", "rad", s.pitch());
  scalar(v, "roll", "rad", s.roll());
  v.f64("gyro_bias", "rad/s", s.gyro_bias().data(), 3);
  v.u32("flags", "bits", s.flags());
}

void visit_fields(const bsn::JointAngles& s, FieldVisitor& v) {
  v.key("joint", s.joint());
  v.text("parent", s.parent());
  v.text("child", s.child());
  v.u64("timestamp_ns", "ns", s.timestamp_ns());
  v.f64("quat", "wxyz", s.quat().data(), 4);
  v.text("axes", s.axes());
  // The axis-sequence angles by their place in the sequence and their axis: angle_1_z is the first rotation, about z.
  // Labels from fixed tables and the sample's own strings: the recorder visits every sample, so nothing is allocated.
  static const std::string kSequence[3][4] = {{"angle_1_x", "angle_1_y", "angle_1_z", "angle_1"},
                                              {"angle_2_x", "angle_2_y", "angle_2_z", "angle_2"},
                                              {"angle_3_x", "angle_3_y", "angle_3_z", "angle_3"}};
  const std::string* sequence_labels[3];
  for (std::size_t i = 0; i < 3; ++i) {
    const char axis = i < s.axes().size() ? s.axes()[i] : '?';
    sequence_labels[i] = &kSequence[i][axis == 'x' ? 0 : axis == 'y' ? 1 : axis == 'z' ? 2 : 3];
  }
  v.named_f64("angles", "rad", s.angles().data(), 3, sequence_labels);
  v.u32("flags", "bits", s.flags());
  v.text("anatomy", s.anatomy());
  v.text("side", s.side());
  // Each named angle as its name and its value: fixed columns whatever the joint (in a file of one joint the value
  // columns carry the angle's name).
  static constexpr const char* kNames[3] = {"anatomical_name_0", "anatomical_name_1", "anatomical_name_2"};
  static const std::string kValues[3] = {"anatomical_0", "anatomical_1", "anatomical_2"};
  static const std::string kEmpty;
  for (std::size_t i = 0; i < 3; ++i) {
    const std::string& name = i < s.anatomical_names().size() ? s.anatomical_names()[i] : kEmpty;
    v.text(kNames[i], name);
    const std::string* label = name.empty() ? &kValues[i] : &name;
    v.named_f64(kValues[i].c_str(), "rad", &s.anatomical()[i], 1, &label);
  }
  scalar(v, "heading_offset", "rad", s.heading_offset());
  scalar(v, "heading_observability", "1", s.heading_observability());
}

void visit_fields(const bsn::Status& s, FieldVisitor& v) {
  v.key("process_id", s.process_id());
  v.u64("wall_time_ns", "ns", s.wall_time_ns());
  scalar(v, "period_s", "s", s.period_s());
  // Per node: "node:rate_hz:received:accepted:missing:stale" joined by ';' (the full record is in bsn/status).
  std::string nodes;
  for (const auto& n : s.nodes()) {
    char buf[200];
    std::snprintf(buf, sizeof buf, "%s:%.2f:%" PRIu64 ":%" PRIu64 ":%" PRIu64 ":%d", n.node_id().c_str(), n.rate_hz(),
                  static_cast<std::uint64_t>(n.received()), static_cast<std::uint64_t>(n.accepted()),
                  static_cast<std::uint64_t>(n.missing()), n.stale() ? 1 : 0);
    nodes += (nodes.empty() ? "" : ";") + std::string(buf);
  }
  v.text("nodes", nodes);
  v.u64("unknown_node_samples", "", s.unknown_node_samples());
  v.u64("qos_mismatches", "", s.qos_mismatches());
  v.u64("write_failures", "", s.write_failures());
  v.text("last_calibration_id", s.last_calibration_id());
  v.u64("participant_rejoins", "", s.participant_rejoins());
}

void visit_fields(const bsn::CalibrationRequest& s, FieldVisitor& v) {
  v.key("request_id", s.request_id());
  v.text("node_id", s.node_id());
  v.u32("kind", "enum", static_cast<std::uint32_t>(s.kind()));
  scalar(v, "duration_s", "s", s.duration_s());
  v.u32("sample_count", "", s.sample_count());
  v.text("body", s.body());
  scalar(v, "pose_s", "s", s.pose_s());
}

void visit_fields(const bsn::CalibrationResult& s, FieldVisitor& v) {
  v.key("node_id", s.node_id());
  v.text("request_id", s.request_id());
  v.u32("kind", "enum", static_cast<std::uint32_t>(s.kind()));
  v.u32("success", "bool", s.success() ? 1u : 0u);
  v.f64("bias", "", s.bias().data(), 3);
  v.f64("transform", "", s.transform().data(), 9);
  scalar(v, "field_magnitude", "", s.field_magnitude());
  v.f64("field_vector", "", s.field_vector().data(), 3);
  scalar(v, "residual_rms", "", s.residual_rms());
  scalar(v, "condition_number", "", s.condition_number());
  v.u32("pose_count", "", s.pose_count());
  v.text("message", s.message());
  v.text("segment", s.segment());
  v.f64("sensor_to_segment", "", s.sensor_to_segment().data(), 4);
  v.text("alignment_source", s.alignment_source());
  scalar(v, "hinge_residual", "", s.hinge_residual());
  scalar(v, "axis_observability", "", s.axis_observability());
}

std::string component_name(const char* name, int n, int i) {
  if (n == 1) return name;
  if (n == 4) return std::string(name) + "_" + "wxyz"[i];
  if (n == 3) return std::string(name) + "_" + "xyz"[i];
  return std::string(name) + "_" + std::to_string(i);
}

namespace {
std::string number(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);  // round-trips every double exactly
  return buf;
}
}  // namespace

void CsvHeaderVisitor::add(const char* name, const char* unit) {
  if (!out.empty()) out += ',';
  out += name;
  if (unit[0] != '\0') out += std::string(" [") + unit + "]";
}

void CsvRowVisitor::add_text(const std::string& value) {
  sep();
  // Quoted only when needed (RFC 4180): a comma, a quote or a line break.
  if (value.find_first_of(",\"\n\r") == std::string::npos) {
    out += value;
    return;
  }
  out += '"';
  for (const char c : value) {
    if (c == '"') out += '"';
    out += c;
  }
  out += '"';
}

void CsvRowVisitor::u64(const char*, const char*, std::uint64_t value) {
  sep();
  out += std::to_string(value);
}
void CsvRowVisitor::u32(const char*, const char*, std::uint32_t value) {
  sep();
  out += std::to_string(value);
}
void CsvRowVisitor::f64(const char*, const char*, const double* values, int n) {
  for (int i = 0; i < n; ++i) {
    sep();
    out += number(values[i]);
  }
}

void JsonVisitor::name(const char* n) {
  if (!out.empty()) out += ", ";
  out += io::json_string(n) + ": ";
}
void JsonVisitor::text(const char* n, const std::string& value) {
  name(n);
  out += io::json_string(value);
}
void JsonVisitor::u64(const char* n, const char*, std::uint64_t value) {
  name(n);
  out += std::to_string(value);
}
void JsonVisitor::u32(const char* n, const char*, std::uint32_t value) {
  name(n);
  out += std::to_string(value);
}
void JsonVisitor::f64(const char* n, const char*, const double* values, int count) {
  name(n);
  if (count > 1) out += '[';
  for (int i = 0; i < count; ++i) out += (i ? ", " : "") + io::json_number(values[i], 17);
  if (count > 1) out += ']';
}

}  // namespace bsn::services
