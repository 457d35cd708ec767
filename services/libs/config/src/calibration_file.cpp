#include "bsn/config/calibration_file.hpp"

#include <yaml-cpp/yaml.h>

#include <Eigen/LU>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "bsn/config/yaml_reader.hpp"

namespace bsn::config {
namespace {

using Reader = config::YamlReader<ConfigError>;

calib::Vec3 vector3(const Reader& r, const YAML::Node& n, const std::string& what) {
  if (!n.IsSequence() || n.size() != 3) r.fail(n, what + " must be a list of 3 numbers");
  return {r.number(n[0], what), r.number(n[1], what), r.number(n[2], what)};
}

calib::ChannelCalibration channel(const Reader& r, const YAML::Node& n, const std::string& name) {
  r.check_keys(n, {"bias", "transform", "field_magnitude", "field_vector"}, name);
  calib::ChannelCalibration c;
  if (n["bias"]) c.bias = vector3(r, n["bias"], name + " bias");
  if (const YAML::Node t = n["transform"]) {
    if (!t.IsSequence() || t.size() != 3) r.fail(t, name + " transform must be a list of 3 rows of 3 numbers");
    for (std::size_t row = 0; row < 3; ++row) {
      c.transform.row(static_cast<Eigen::Index>(row)) = vector3(r, t[row], name + " transform row").transpose();
    }
    if (!(std::abs(c.transform.determinant()) > 1e-12 * std::pow(c.transform.norm(), 3))) {
      r.fail(t, name + " transform is singular");
    }
  }
  return c;
}

AlignmentRecord alignment(const Reader& r, const YAML::Node& n) {
  r.check_keys(n, {"segment", "sensor_to_segment", "source", "hinge_residual", "axis_observability", "samples"},
               "alignment");
  AlignmentRecord a;
  const YAML::Node segment = n["segment"];
  if (!segment || !segment.IsScalar() || segment.as<std::string>().empty())
    r.fail(n, "alignment needs segment: the segment it was fitted for");
  a.segment = segment.as<std::string>();
  const YAML::Node q = n["sensor_to_segment"];
  if (!q || !q.IsSequence() || q.size() != 4) r.fail(q ? q : n, "alignment needs sensor_to_segment: [w, x, y, z]");
  const Eigen::Vector4d v(r.number(q[0], "sensor_to_segment"), r.number(q[1], "sensor_to_segment"),
                          r.number(q[2], "sensor_to_segment"), r.number(q[3], "sensor_to_segment"));
  if (!(std::abs(v.norm() - 1.0) < 1e-3)) r.fail(q, "sensor_to_segment must be a unit quaternion [w, x, y, z]");
  a.sensor_to_segment = calib::Quat(v[0], v[1], v[2], v[3]).normalized();
  if (const YAML::Node x = n["source"]) a.source = x.as<std::string>();
  if (n["hinge_residual"]) a.hinge_residual = r.number(n["hinge_residual"], "hinge_residual");
  if (n["axis_observability"]) a.axis_observability = r.number(n["axis_observability"], "axis_observability");
  if (n["samples"]) a.samples = static_cast<std::size_t>(std::max(0.0, r.number(n["samples"], "samples")));
  return a;
}

}  // namespace

CalibrationDocument parse_calibration_document(const std::string& yaml_text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::ParserException& e) {
    throw ConfigError(source + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + e.msg);
  }
  const Reader reader(source);
  if (!root || root.IsNull()) reader.fail_at(1, "the calibration file is empty");
  CalibrationDocument doc;
  calib::SensorCalibration& out = doc.calibration;
  try {
    reader.check_keys(root,
                      {"node", "request_id", "magnetometer", "accelerometer", "gyroscope", "quality", "alignment"},
                      "the calibration file");
    if (const YAML::Node n = root["node"]) {
      if (!n.IsScalar()) reader.fail(n, "node must be a node id");
      doc.node = n.as<std::string>();
      doc.node_line = n.Mark().line + 1;
    }
    if (const YAML::Node n = root["request_id"]) {
      if (!n.IsScalar()) reader.fail(n, "request_id must be a string");
      doc.request_id = n.as<std::string>();
    }
    if (const YAML::Node m = root["magnetometer"]) {
      out.magnetometer = channel(reader, m, "magnetometer");
      if (m["field_magnitude"])
        doc.magnetometer_field_magnitude = reader.number(m["field_magnitude"], "field_magnitude");
      if (m["field_vector"]) doc.magnetometer_field_vector = vector3(reader, m["field_vector"], "field_vector");
    }
    if (const YAML::Node a = root["accelerometer"]) {
      out.accelerometer = channel(reader, a, "accelerometer");
      if (a["field_magnitude"])
        doc.accelerometer_field_magnitude = reader.number(a["field_magnitude"], "field_magnitude");
    }
    if (root["gyroscope"]) out.gyroscope = channel(reader, root["gyroscope"], "gyroscope");
    if (root["alignment"]) doc.alignment = alignment(reader, root["alignment"]);
  } catch (const YAML::Exception& e) {
    reader.fail_at(e.mark.line + 1, e.msg);
  }
  if (out.empty() && !doc.alignment)
    reader.fail(root, "the calibration file holds no magnetometer, accelerometer, gyroscope or alignment");
  return doc;
}

calib::SensorCalibration parse_calibration(const std::string& yaml_text, const std::string& source) {
  return parse_calibration_document(yaml_text, source).calibration;
}

CalibrationDocument load_calibration_document(const std::string& path) {
  return parse_calibration_document(read_config_file<ConfigError>(path, "calibration"), path);
}

calib::SensorCalibration load_calibration_file(const std::string& path) {
  return load_calibration_document(path).calibration;
}

namespace {

void emit_vector(YAML::Emitter& out, const calib::Vec3& v) {
  out << YAML::Flow << YAML::BeginSeq << v.x() << v.y() << v.z() << YAML::EndSeq;
}

void emit_channel(YAML::Emitter& out, const calib::ChannelCalibration& c) {
  out << YAML::Key << "bias" << YAML::Value;
  emit_vector(out, c.bias);
  out << YAML::Key << "transform" << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (int r = 0; r < 3; ++r) emit_vector(out, c.transform.row(r).transpose());
  out << YAML::EndSeq;
}

void emit_field(YAML::Emitter& out, const std::string& name, const calib::FieldCalibration& f) {
  out << YAML::Key << name << YAML::Value << YAML::BeginMap;
  emit_channel(out, f.calibration);
  out << YAML::Key << "field_magnitude" << YAML::Value << f.field_magnitude;
  out << YAML::Key << "field_vector" << YAML::Value;
  emit_vector(out, f.field_vector);
  out << YAML::EndMap;
}

}  // namespace

std::string calibration_to_yaml(const std::string& node, const calib::FieldCalibration* magnetometer,
                                const calib::FieldCalibration* accelerometer,
                                const calib::ChannelCalibration* gyroscope, const std::string& request_id) {
  YAML::Emitter out;
  out.SetDoublePrecision(10);
  out << YAML::BeginMap;
  if (!node.empty()) out << YAML::Key << "node" << YAML::Value << node;
  if (!request_id.empty()) out << YAML::Key << "request_id" << YAML::Value << request_id;
  if (magnetometer != nullptr && magnetometer->ok()) emit_field(out, "magnetometer", *magnetometer);
  if (accelerometer != nullptr && accelerometer->ok()) emit_field(out, "accelerometer", *accelerometer);
  if (gyroscope != nullptr) {
    out << YAML::Key << "gyroscope" << YAML::Value << YAML::BeginMap;
    emit_channel(out, *gyroscope);
    out << YAML::EndMap;
  }
  if (magnetometer != nullptr && magnetometer->ok()) {
    const calib::FitQuality& q = magnetometer->quality;
    out << YAML::Key << "quality" << YAML::Value << YAML::BeginMap;
    out << YAML::Key << "pose_count" << YAML::Value << q.pose_count;
    out << YAML::Key << "sample_count" << YAML::Value << q.sample_count;
    out << YAML::Key << "residual_rms" << YAML::Value << q.residual_rms;
    out << YAML::Key << "sphere_coverage" << YAML::Value << q.sphere_coverage;
    out << YAML::Key << "octants_covered" << YAML::Value << q.octants_covered;
    out << YAML::Key << "transform_condition" << YAML::Value << q.transform_condition;
    out << YAML::Key << "warnings" << YAML::Value << YAML::Flow << q.warnings;
    out << YAML::EndMap;
  }
  out << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

std::string alignment_to_yaml(const std::string& node, const AlignmentRecord& a, const std::string& request_id) {
  YAML::Emitter out;
  out.SetDoublePrecision(12);
  out << YAML::BeginMap;
  if (!node.empty()) out << YAML::Key << "node" << YAML::Value << node;
  if (!request_id.empty()) out << YAML::Key << "request_id" << YAML::Value << request_id;
  out << YAML::Key << "alignment" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "segment" << YAML::Value << a.segment;
  const calib::Quat& q = a.sensor_to_segment;
  out << YAML::Key << "sensor_to_segment" << YAML::Value << YAML::Flow << YAML::BeginSeq << q.w() << q.x() << q.y()
      << q.z() << YAML::EndSeq;
  out << YAML::Key << "source" << YAML::Value << a.source;
  out << YAML::Key << "hinge_residual" << YAML::Value << a.hinge_residual;
  out << YAML::Key << "axis_observability" << YAML::Value << a.axis_observability;
  out << YAML::Key << "samples" << YAML::Value << a.samples;
  out << YAML::EndMap << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

namespace {

/// Every segment of a body file that names a calibration file: the segment's YAML entry, its node and the file.
template <class Visit>
void for_each_body_calibration(const std::string& body_path, Visit visit) {
  if (body_path.empty()) return;
  YAML::Node root;
  try {
    root = YAML::LoadFile(body_path);
  } catch (const YAML::Exception& e) {
    throw ConfigError(body_path + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg);
  }
  if (!root.IsMap() || !root["segments"] || !root["segments"].IsSequence()) return;
  for (const YAML::Node& s : root["segments"]) {
    if (!s.IsMap() || !s["calibration"] || !s["name"]) continue;
    const std::string node = s["node"] ? s["node"].as<std::string>() : s["name"].as<std::string>();
    const std::string file = resolve_relative(s["calibration"].as<std::string>(), body_path);
    CalibrationDocument doc = load_calibration_document(file);
    // A file made for another sensor would silently spoil this one's estimates.
    if (!doc.node.empty() && doc.node != node) {
      throw ConfigError(file + ":" + std::to_string(doc.node_line) + ": this calibration is for node '" + doc.node +
                        "', but segment '" + s["name"].as<std::string>() + "' (" + body_path + ":" +
                        std::to_string(s["calibration"].Mark().line + 1) + ") is on node '" + node + "'");
    }
    visit(s, node, file, doc);
  }
}

}  // namespace

std::unordered_map<std::string, calib::SensorCalibration> load_body_calibrations(const std::string& body_path) {
  std::unordered_map<std::string, calib::SensorCalibration> out;
  for_each_body_calibration(body_path, [&out](const YAML::Node&, const std::string& node, const std::string&,
                                              CalibrationDocument& doc) { out[node] = std::move(doc.calibration); });
  return out;
}

void apply_body_alignments(const std::string& body_path, fusion::BodyModel& body) {
  for_each_body_calibration(
      body_path, [&](const YAML::Node& s, const std::string&, const std::string& file, const CalibrationDocument& doc) {
        if (!doc.alignment) return;
        const std::string name = s["name"].as<std::string>();
        const std::string where = body_path + ":" + std::to_string(s["calibration"].Mark().line + 1);
        if (doc.alignment->segment != name)
          throw ConfigError(file + ": this alignment was fitted for segment '" + doc.alignment->segment +
                            "', but it is named by segment '" + name + "' (" + where + ")");
        if (s["sensor_axes"] || s["sensor_to_segment"])
          throw ConfigError(where + ": segment '" + name +
                            "' gives its mounting twice: sensor_axes or sensor_to_segment, and an alignment in " +
                            file + "; keep one");
        if (const auto i = body.find_segment(name))
          body.segments[*i].sensor_to_segment = doc.alignment->sensor_to_segment;
      });
}

std::string resolve_relative(const std::string& path, const std::string& relative_to) {
  const std::filesystem::path p(path);
  if (p.is_absolute() || relative_to.empty()) return path;
  return (std::filesystem::path(relative_to).parent_path() / p).lexically_normal().string();
}

}  // namespace bsn::config
