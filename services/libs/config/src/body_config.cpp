#include "bsn/config/body_config.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <initializer_list>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <vector>

#include "bsn/config/calibration_file.hpp"
#include "bsn/config/yaml_reader.hpp"

namespace bsn::config {
namespace {

using fusion::BodyModel;
using fusion::FilterSpec;
using fusion::SegmentSpec;

class Parser : public config::YamlReader<ConfigError> {
 public:
  using YamlReader::YamlReader;

  fusion::AxisSequence axes(const YAML::Node& n) const {
    const std::string name = text(n, "joint_axes");
    auto seq = fusion::parse_axis_sequence(name);
    if (!seq) fail(n, "joint_axes '" + name + "' is not a sequence of three distinct axes such as zyx or zxy");
    return *seq;
  }

  FilterSpec filter(const YAML::Node& n, const FilterSpec& base) const {
    require_map(n, "filter");
    FilterSpec spec = base;
    if (n["name"]) {
      const std::string name = text(n["name"], "filter name");
      if (name != base.name) spec.parameters.clear();  // another filter: the defaults' parameters do not apply
      spec.name = name;
    }
    for (const auto& kv : n) {
      const std::string key = kv.first.as<std::string>();
      if (key == "name") continue;
      double value = 0.0;
      try {
        value = kv.second.as<double>();
      } catch (const YAML::Exception&) {
        fail(kv.second, "filter parameter '" + key + "' must be a number");
      }
      std::erase_if(spec.parameters, [&](const auto& p) { return p.first == key; });
      spec.parameters.emplace_back(key, value);
    }
    // Let the filter factory judge names and values now, so a bad parameter is reported at its line.
    try {
      (void)fusion::make_filter(spec);
    } catch (const std::invalid_argument& e) {
      fail(n, e.what());
    }
    return spec;
  }

  // `anatomy: knee`, `side: left`: the joint's anatomical convention, when its name does not imply it.
  fusion::JointConvention anatomy(const YAML::Node& s, const std::string& joint) const {
    fusion::JointConvention c = fusion::infer_joint_convention(joint);
    if (const YAML::Node a = s["anatomy"]) {
      const std::string name = text(a, "anatomy");
      const auto type = fusion::parse_joint_type(name);
      if (!type)
        fail(a, "anatomy '" + name + "' is not one of hip, knee, ankle, trunk_pelvis, shoulder, elbow, wrist, none");
      c.type = *type;
    }
    if (const YAML::Node sd = s["side"]) {
      const std::string name = text(sd, "side");
      const auto side = fusion::parse_body_side(name);
      if (!side) fail(sd, "side '" + name + "' is not one of left, right, midline");
      c.side = *side;
    }
    return c;
  }

  // `sensor_axes: [anterior, left, up]`: where the sensor's x, y, z point in the standing pose; or
  // `sensor_to_segment: [w, x, y, z]`, the rotation itself (as an alignment writes it).
  fusion::Quat mounting(const YAML::Node& s) const {
    if (s["sensor_axes"] && s["sensor_to_segment"]) fail(s, "give either sensor_axes or sensor_to_segment, not both");
    if (const YAML::Node a = s["sensor_axes"]) {
      if (!a.IsSequence() || a.size() != 3)
        fail(a, "sensor_axes must be a list of three directions (of the sensor's x, y, z), e.g. [anterior, left, up]");
      std::array<fusion::Direction, 3> dirs{};
      for (std::size_t i = 0; i < 3; ++i) {
        const std::string name = text(a[i], "a sensor axis direction");
        const auto d = fusion::parse_direction(name);
        if (!d)
          fail(a[i], "sensor axis direction '" + name +
                         "' is not one of anterior, posterior, superior (up), inferior (down), left, right");
        dirs[i] = *d;
      }
      const auto q = fusion::sensor_to_segment_from_axes(dirs);
      if (!q) fail(a, "sensor_axes must be three perpendicular directions of a right-handed frame (x cross y = z)");
      return *q;
    }
    const YAML::Node q = s["sensor_to_segment"];
    if (!q.IsSequence() || q.size() != 4) fail(q, "sensor_to_segment must be a quaternion [w, x, y, z]");
    const fusion::Quat r(number(q[0], "w"), number(q[1], "x"), number(q[2], "y"), number(q[3], "z"));
    if (!(std::abs(r.norm() - 1.0) < 1e-3)) fail(q, "sensor_to_segment must be a unit quaternion [w, x, y, z]");
    return r.normalized();
  }

  // `heading: kinematic` (or `magnetometer`, the default), or `heading: {mode: kinematic, window_s: 1,
  // min_observability: 0.1, max_step_s: 1}`: where the joint's child gets its heading relative to the parent.
  std::optional<fusion::HingeHeadingEstimator::Params> heading(const YAML::Node& n) const {
    if (n.IsMap()) {
      check_keys(n, {"mode", "window_s", "min_observability", "max_step_s"}, "heading");
      if (!n["mode"]) fail(n, "heading needs a mode (kinematic or magnetometer)");
    } else if (!n.IsScalar()) {
      fail(n,
           "heading must be kinematic or magnetometer, or a map {mode: kinematic, window_s, min_observability, "
           "max_step_s}");
    }
    // Not assigned later: assigning to a yaml-cpp Node that refers to another would overwrite that one.
    const YAML::Node mode = n.IsMap() ? n["mode"] : n;
    const std::string name = text(mode, "heading mode");
    if (name == "magnetometer") {
      if (n.IsMap() && n.size() > 1) fail(n, "heading: the magnetometer mode has no parameters");
      return std::nullopt;
    }
    if (name != "kinematic") fail(mode, "heading mode '" + name + "' is not kinematic or magnetometer");
    fusion::HingeHeadingEstimator::Params p;
    if (n.IsMap()) {
      if (n["window_s"]) p.window_s = number(n["window_s"], "window_s");
      if (n["min_observability"]) p.min_observability = number(n["min_observability"], "min_observability");
      if (n["max_step_s"]) p.max_step_s = number(n["max_step_s"], "max_step_s");
    }
    try {
      p.check();
    } catch (const std::invalid_argument& e) {
      fail(n, e.what());
    }
    return p;
  }

  // One hinge axis in a segment frame: a named axis (x, -y, anterior, right, ...) or a vector [x, y, z].
  fusion::Vec3 segment_axis(const YAML::Node& n, const char* what) const {
    if (n.IsSequence()) {
      if (n.size() != 3)
        fail(n, std::string(what) +
                    " must be a named axis (x, y, z, -x, ..., anterior, right, ...) or "
                    "a vector [x, y, z]");
      const fusion::Vec3 v(number(n[0], "x"), number(n[1], "y"), number(n[2], "z"));
      if (!v.allFinite() || !(v.norm() > 1e-9)) fail(n, std::string(what) + " must not be the zero vector");
      return v.normalized();
    }
    const std::string name = text(n, what);
    const auto axis = fusion::parse_segment_axis(name);
    if (!axis)
      fail(n, std::string(what) + " '" + name +
                  "' is not x, y, z (optionally signed: -x), one of anterior, posterior, superior (up), inferior "
                  "(down), left, right, or a vector [x, y, z]");
    return *axis;
  }

  // `hinge_axis: z`, `hinge_axis: [0, 0.6, 0.8]` (the same in both segment frames: they are parallel in the reference
  // pose), or `hinge_axis: {parent: x, child: [0, 0, 1]}`.
  fusion::HingeAxis hinge_axis(const YAML::Node& n) const {
    if (n.IsMap()) {
      check_keys(n, {"parent", "child"}, "hinge_axis");
      if (!n["parent"] || !n["child"]) fail(n, "hinge_axis as a map needs both parent and child");
      return {segment_axis(n["parent"], "hinge_axis parent"), segment_axis(n["child"], "hinge_axis child")};
    }
    const fusion::Vec3 axis = segment_axis(n, "hinge_axis");
    return {axis, axis};
  }

  // `calibration: FILE` (relative to the body file): loaded here only to report a bad file at its line; the
  // fusion service reads it again with load_body_calibrations().
  void check_calibration(const YAML::Node& n) const {
    const std::string path = resolve_relative(text(n, "calibration"), source());
    try {
      (void)load_calibration_file(path);
    } catch (const ConfigError& e) {
      fail(n, std::string("calibration: ") + e.what());
    }
  }

  BodyModel body(const YAML::Node& root) {
    if (!root || root.IsNull()) fail_at(1, "the body model file is empty");
    require_map(root, "the body model");
    // `subject:` names the body's subject (DDS partition; subjects.hpp reads it).
    check_keys(root, {"name", "subject", "defaults", "segments"}, "the body model");
    BodyModel model;
    if (root["name"]) model.name = text(root["name"], "name");

    FilterSpec default_filter;
    fusion::AxisSequence default_axes;
    if (const YAML::Node d = root["defaults"]) {
      require_map(d, "defaults");
      check_keys(d, {"filter", "joint_axes"}, "defaults");
      if (d["filter"]) default_filter = filter(d["filter"], default_filter);
      if (d["joint_axes"]) default_axes = axes(d["joint_axes"]);
    }

    const YAML::Node segs = root["segments"];
    if (!segs) fail(root, "the body model has no 'segments' list");
    if (!segs.IsSequence()) fail(segs, "'segments' must be a list of segments");
    std::vector<int> lines;
    for (const YAML::Node& s : segs) {
      require_map(s, "a segment");
      check_keys(s,
                 {"name", "node", "parent", "joint", "joint_axes", "anatomy", "side", "sensor_axes",
                  "sensor_to_segment", "heading", "hinge_axis", "filter", "calibration"},
                 "segment");
      SegmentSpec spec;
      if (!s["name"]) fail(s, "segment without 'name'");
      spec.name = text(s["name"], "name");
      spec.node = s["node"] ? text(s["node"], "node") : spec.name;
      if (s["parent"] && !s["parent"].IsNull()) spec.parent = text(s["parent"], "parent");
      if (s["joint"]) spec.joint = text(s["joint"], "joint");
      spec.joint_axes = s["joint_axes"] ? axes(s["joint_axes"]) : default_axes;
      spec.filter = s["filter"] ? filter(s["filter"], default_filter) : default_filter;
      if (s["anatomy"] || s["side"]) spec.anatomy = anatomy(s, fusion::joint_name(spec));
      if (s["sensor_axes"] || s["sensor_to_segment"]) spec.sensor_to_segment = mounting(s);
      if (s["heading"]) {
        if (spec.parent.empty())
          fail(s["heading"], "heading applies to a joint: segment '" + spec.name + "' has no parent");
        spec.kinematic_heading = heading(s["heading"]);
      }
      if (s["hinge_axis"]) {
        if (spec.parent.empty())
          fail(s["hinge_axis"], "hinge_axis applies to a joint: segment '" + spec.name + "' has no parent");
        spec.hinge_axis = hinge_axis(s["hinge_axis"]);
      }
      if (s["calibration"]) check_calibration(s["calibration"]);
      model.segments.push_back(std::move(spec));
      lines.push_back(s.Mark().line + 1);
    }
    if (auto problem = fusion::check_body_model(model)) {
      fail_at(lines.empty() ? segs.Mark().line + 1 : lines[problem->segment_index], problem->message);
    }
    return model;
  }
};

// yaml-cpp reports an unclosed '[' or '{' where it gave up looking for the closing bracket: the next line or the
// end of the file, not where the mistake is. Returns the 1-based line of the innermost flow collection still open
// at offset `end` of `text`, or 0 if none is found. A heuristic (quotes and comments skipped; in block context a
// bracket counts only where a flow collection can start), used for that one message.
int unclosed_flow_line(const std::string& text, std::size_t end) {
  std::vector<int> open;
  int line = 1;
  char prev = '\0';  // last non-blank character on the current line
  end = std::min(end, text.size());
  for (std::size_t i = 0; i < end; ++i) {
    const char c = text[i];
    if (c == '\n') {
      ++line;
      prev = '\0';
      continue;
    }
    if (c == ' ' || c == '\t' || c == '\r') continue;
    const bool value_start = !open.empty() || prev == '\0' || prev == ':' || prev == '-' || prev == ',' ||
                             prev == '[' || prev == '{' || prev == '?';
    if (c == '#' && (i == 0 || text[i - 1] == ' ' || text[i - 1] == '\t' || text[i - 1] == '\n')) {
      while (i + 1 < end && text[i + 1] != '\n') ++i;
      continue;
    }
    if ((c == '\'' || c == '"') && value_start) {
      for (++i; i < end && text[i] != c; ++i) {
        if (text[i] == '\n') ++line;
        if (c == '"' && text[i] == '\\') ++i;
      }
    } else if ((c == '[' || c == '{') && value_start) {
      open.push_back(line);
    } else if ((c == ']' || c == '}') && !open.empty()) {
      open.pop_back();
    }
    prev = c;
  }
  return open.empty() ? 0 : open.back();
}

}  // namespace

BodyModel parse_body_model(const std::string& yaml_text, const std::string& source) {
  Parser parser(source);
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::ParserException& e) {
    const bool seq = e.msg == YAML::ErrorMsg::END_OF_SEQ_FLOW;
    if (seq || e.msg == YAML::ErrorMsg::END_OF_MAP_FLOW) {
      const int opened = unclosed_flow_line(yaml_text, e.mark.pos < 0 ? 0 : static_cast<std::size_t>(e.mark.pos));
      if (opened > 0) {
        parser.fail_at(opened, std::string("YAML syntax error: the '") + (seq ? '[' : '{') +
                                   "' opened on this line is never closed (" + e.msg + ", line " +
                                   std::to_string(e.mark.line + 1) + ")");
      }
    }
    parser.fail_at(e.mark.line + 1, "YAML syntax error: " + e.msg);
  }
  try {
    return parser.body(root);
  } catch (const YAML::Exception& e) {
    parser.fail_at(e.mark.line + 1, e.msg);
  }
}

BodyModel load_body_model(const std::string& path) {
  return parse_body_model(read_config_file<ConfigError>(path, "body model"), path);
}

std::string body_model_to_yaml(const BodyModel& body) {
  YAML::Emitter out;
  out << YAML::BeginMap;
  if (!body.name.empty()) out << YAML::Key << "name" << YAML::Value << body.name;
  out << YAML::Key << "segments" << YAML::Value << YAML::BeginSeq;
  for (const auto& s : body.segments) {
    out << YAML::BeginMap << YAML::Key << "name" << YAML::Value << s.name;
    out << YAML::Key << "node" << YAML::Value << s.node;
    if (!s.parent.empty()) {
      out << YAML::Key << "parent" << YAML::Value << s.parent;
      out << YAML::Key << "joint" << YAML::Value << fusion::joint_name(s);
      out << YAML::Key << "joint_axes" << YAML::Value << s.joint_axes.name();
      const fusion::JointConvention c = fusion::joint_convention(s);
      if (c.type != fusion::JointType::kNone) {
        out << YAML::Key << "anatomy" << YAML::Value << std::string(fusion::joint_type_name(c.type));
        if (c.side != fusion::BodySide::kMidline)
          out << YAML::Key << "side" << YAML::Value << std::string(fusion::body_side_name(c.side));
      }
    }
    if (s.sensor_to_segment) {
      const fusion::Quat& q = *s.sensor_to_segment;
      out << YAML::Key << "sensor_to_segment" << YAML::Value << YAML::Flow << YAML::BeginSeq << q.w() << q.x() << q.y()
          << q.z() << YAML::EndSeq;
    }
    if (const auto& h = s.kinematic_heading) {
      const fusion::HingeHeadingEstimator::Params d;
      out << YAML::Key << "heading" << YAML::Value;
      if (h->window_s == d.window_s && h->min_observability == d.min_observability && h->max_step_s == d.max_step_s) {
        out << "kinematic";
      } else {
        out << YAML::Flow << YAML::BeginMap << YAML::Key << "mode" << YAML::Value << "kinematic" << YAML::Key
            << "window_s" << YAML::Value << h->window_s << YAML::Key << "min_observability" << YAML::Value
            << h->min_observability << YAML::Key << "max_step_s" << YAML::Value << h->max_step_s << YAML::EndMap;
      }
    }
    if (const auto& a = s.hinge_axis) {
      auto vector = [&](const fusion::Vec3& v) {
        out << YAML::Flow << YAML::BeginSeq << v.x() << v.y() << v.z() << YAML::EndSeq;
      };
      out << YAML::Key << "hinge_axis" << YAML::Value;
      if (a->parent == a->child) {
        vector(a->parent);
      } else {
        out << YAML::Flow << YAML::BeginMap << YAML::Key << "parent" << YAML::Value;
        vector(a->parent);
        out << YAML::Key << "child" << YAML::Value;
        vector(a->child);
        out << YAML::EndMap;
      }
    }
    out << YAML::Key << "filter" << YAML::Value << YAML::Flow << YAML::BeginMap;
    out << YAML::Key << "name" << YAML::Value << s.filter.name;
    for (const auto& [k, v] : s.filter.parameters) out << YAML::Key << k << YAML::Value << v;
    out << YAML::EndMap << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

}  // namespace bsn::config
