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
    reader.check_keys(root, {"node", "request_id", "magnetometer", "accelerometer", "gyroscope", "quality"},
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
  } catch (const YAML::Exception& e) {
    reader.fail_at(e.mark.line + 1, e.msg);
  }
  if (out.empty()) reader.fail(root, "the calibration file holds no magnetometer, accelerometer or gyroscope");
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

std::unordered_map<std::string, calib::SensorCalibration> load_body_calibrations(const std::string& body_path) {
  std::unordered_map<std::string, calib::SensorCalibration> out;
  if (body_path.empty()) return out;
  YAML::Node root;
  try {
    root = YAML::LoadFile(body_path);
  } catch (const YAML::Exception& e) {
    throw ConfigError(body_path + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg);
  }
  if (!root.IsMap() || !root["segments"] || !root["segments"].IsSequence()) return out;
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
    out[node] = std::move(doc.calibration);
  }
  return out;
}

std::string resolve_relative(const std::string& path, const std::string& relative_to) {
  const std::filesystem::path p(path);
  if (p.is_absolute() || relative_to.empty()) return path;
  return (std::filesystem::path(relative_to).parent_path() / p).lexically_normal().string();
}

}  // namespace bsn::config
