#include "bsn/sim/scenario_file.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <numbers>
#include <sstream>
#include <string_view>

#include "bsn/config/yaml_reader.hpp"

namespace bsn::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

class Parser : public config::YamlReader<ScenarioError> {
 public:
  using YamlReader::YamlReader;
  double positive(const YAML::Node& n, const std::string& what) const {
    const double v = number(n, what);
    if (!(v > 0.0)) fail(n, what + " must be > 0");
    return v;
  }
  double non_negative(const YAML::Node& n, const std::string& what) const {
    const double v = number(n, what);
    if (!(v >= 0.0)) fail(n, what + " must be >= 0");
    return v;
  }

  Vec3 vec3(const YAML::Node& n, const std::string& what) const {
    if (!n.IsSequence() || n.size() != 3) fail(n, what + " must be a list of three numbers [x, y, z]");
    return Vec3(number(n[0], what), number(n[1], what), number(n[2], what));
  }

  Mat3 mat3(const YAML::Node& n, const std::string& what) const {
    if (!n.IsSequence() || n.size() != 3) fail(n, what + " must be three rows of three numbers");
    Mat3 m;
    for (int r = 0; r < 3; ++r) m.row(r) = vec3(n[r], what + " row").transpose();
    return m;
  }

  std::vector<Window> windows(const YAML::Node& n, const std::string& what, double default_ramp) const {
    if (!n.IsSequence()) fail(n, what + " must be a list of {from_s, to_s[, ramp_s]}");
    std::vector<Window> out;
    for (const YAML::Node& w : n) {
      check_keys(w, {"from_s", "to_s", "ramp_s"}, what + " window");
      if (!w["from_s"] || !w["to_s"]) fail(w, what + " window needs from_s and to_s");
      Window win{number(w["from_s"], "from_s"), number(w["to_s"], "to_s"), default_ramp};
      if (w["ramp_s"]) win.ramp_s = non_negative(w["ramp_s"], "ramp_s");
      if (!(win.end_s >= win.start_s + win.ramp_s)) fail(w, what + " window: to_s must be >= from_s + ramp_s");
      out.push_back(win);
    }
    return out;
  }

  ChannelErrors channel(const YAML::Node& n, ChannelErrors e, const std::string& name, bool magnetometer) const {
    if (magnetometer) {
      check_keys(n,
                 {"white_density", "bias", "bias_random_walk", "bias_instability", "bias_correlation_s", "scale",
                  "nonorthogonality", "mounting_deg", "soft_iron", "hard_iron", "bias_steps", "range", "lsb"},
                 "sensors." + name);
    } else {
      check_keys(n,
                 {"white_density", "bias", "bias_random_walk", "bias_instability", "bias_correlation_s", "scale",
                  "nonorthogonality", "mounting_deg", "bias_steps", "range", "lsb"},
                 "sensors." + name);
    }
    if (n["white_density"]) e.white_density = non_negative(n["white_density"], "white_density");
    if (n["bias"]) e.bias = vec3(n["bias"], "bias");
    if (n["bias_random_walk"]) e.bias_random_walk = non_negative(n["bias_random_walk"], "bias_random_walk");
    if (n["bias_instability"]) e.bias_instability = non_negative(n["bias_instability"], "bias_instability");
    if (n["bias_correlation_s"]) e.bias_correlation_s = positive(n["bias_correlation_s"], "bias_correlation_s");
    if (n["scale"]) e.scale = vec3(n["scale"], "scale");
    if (n["nonorthogonality"]) e.nonorthogonality = vec3(n["nonorthogonality"], "nonorthogonality");
    if (n["mounting_deg"]) e.mounting_rad = vec3(n["mounting_deg"], "mounting_deg") * kDeg;
    if (n["soft_iron"]) e.soft_iron = mat3(n["soft_iron"], "soft_iron");
    if (n["hard_iron"]) e.hard_iron = vec3(n["hard_iron"], "hard_iron");
    if (n["range"]) e.range = positive(n["range"], "range");
    if (n["lsb"]) e.lsb = non_negative(n["lsb"], "lsb");
    if (const YAML::Node steps = n["bias_steps"]) {
      if (!steps.IsSequence()) fail(steps, "bias_steps must be a list of {at_s, value}");
      e.bias_steps.clear();
      for (const YAML::Node& s : steps) {
        check_keys(s, {"at_s", "value"}, "a bias step");
        if (!s["at_s"] || !s["value"]) fail(s, "a bias step needs at_s and value");
        e.bias_steps.push_back({number(s["at_s"], "at_s"), vec3(s["value"], "value")});
      }
    }
    if (!(std::abs(e.physical_from_reading().determinant()) > 1e-9)) {
      fail(n, "sensors." + name + ": scale, non-orthogonality and soft iron give a singular transformation");
    }
    return e;
  }

  SensorErrors sensors(const YAML::Node& n) const {
    if (n.IsScalar()) return preset(n);
    check_keys(n,
               {"preset", "gyr", "acc", "mag", "mag_rate_hz", "mag_delay_samples", "mag_bandwidth_hz", "jitter_s",
                "drop_probability"},
               "sensors");
    SensorErrors e = n["preset"] ? preset(n["preset"]) : SensorErrors::ideal();
    if (n["gyr"]) e.gyr = channel(n["gyr"], e.gyr, "gyr", false);
    if (n["acc"]) e.acc = channel(n["acc"], e.acc, "acc", false);
    if (n["mag"]) e.mag = channel(n["mag"], e.mag, "mag", true);
    if (n["mag_rate_hz"]) e.mag_rate_hz = non_negative(n["mag_rate_hz"], "mag_rate_hz");
    if (n["mag_delay_samples"]) {
      const double d = non_negative(n["mag_delay_samples"], "mag_delay_samples");
      if (d != std::floor(d) || d > 1000)
        fail(n["mag_delay_samples"], "mag_delay_samples must be a whole number <= 1000");
      e.mag_delay_samples = static_cast<int>(d);
    }
    if (n["mag_bandwidth_hz"]) e.mag_bandwidth_hz = non_negative(n["mag_bandwidth_hz"], "mag_bandwidth_hz");
    if (n["jitter_s"]) e.jitter_s = non_negative(n["jitter_s"], "jitter_s");
    if (n["drop_probability"]) {
      e.drop_probability = non_negative(n["drop_probability"], "drop_probability");
      if (e.drop_probability > 1.0) fail(n["drop_probability"], "drop_probability must be in [0, 1]");
    }
    return e;
  }

  SensorErrors preset(const YAML::Node& n) const {
    const std::string name = text(n, "sensor preset");
    if (auto e = sensor_preset(name)) return *e;
    std::string list;
    for (const auto& p : sensor_preset_names()) list += (list.empty() ? "" : ", ") + p;
    fail(n, "unknown sensor preset '" + name + "' (known: " + list + ")");
  }

  Pose pose(const YAML::Node& n) const {
    check_keys(n, {"position_m", "yaw_pitch_roll_deg"}, "body.pose");
    Pose p;
    if (n["position_m"]) p.position_m = vec3(n["position_m"], "position_m");
    if (n["yaw_pitch_roll_deg"]) {
      const Vec3 a = vec3(n["yaw_pitch_roll_deg"], "yaw_pitch_roll_deg") * kDeg;
      p.orientation = {a.x(), a.y(), a.z()};
    }
    return p;
  }

  RandomMotion random(const YAML::Node& n, std::uint64_t seed) const {
    check_keys(
        n,
        {"intensity", "angular_rate_rms_deg_s", "acceleration_rms_m_s2", "frequency_hz", "harmonics", "active", "seed"},
        "body.random");
    RandomMotion r;
    r.seed = seed;
    if (n["intensity"]) {
      const std::string level = text(n["intensity"], "intensity");
      if (level == "slow")
        r = random_motion_for(Intensity::kSlow, seed);
      else if (level == "intermediate")
        r = random_motion_for(Intensity::kIntermediate, seed);
      else if (level == "fast")
        r = random_motion_for(Intensity::kFast, seed);
      else
        fail(n["intensity"], "intensity must be slow, intermediate or fast (Nez et al. 2018, Table 1)");
    }
    if (n["angular_rate_rms_deg_s"]) {
      r.angular_rate_rms_rad_s = non_negative(n["angular_rate_rms_deg_s"], "angular_rate_rms_deg_s") * kDeg;
    }
    if (n["acceleration_rms_m_s2"])
      r.acceleration_rms_m_s2 = non_negative(n["acceleration_rms_m_s2"], "acceleration_rms_m_s2");
    if (const YAML::Node f = n["frequency_hz"]) {
      if (!f.IsSequence() || f.size() != 2) fail(f, "frequency_hz must be [lowest, highest]");
      r.min_frequency_hz = positive(f[0], "frequency_hz");
      r.max_frequency_hz = positive(f[1], "frequency_hz");
      if (r.max_frequency_hz < r.min_frequency_hz) fail(f, "frequency_hz: highest below lowest");
    }
    if (n["harmonics"]) {
      const double h = positive(n["harmonics"], "harmonics");
      if (h != std::floor(h) || h > 32) fail(n["harmonics"], "harmonics must be a whole number 1..32");
      r.harmonics_per_axis = static_cast<int>(h);
    }
    if (n["active"]) r.active = windows(n["active"], "active", 1.0);
    if (n["seed"]) r.seed = static_cast<std::uint64_t>(non_negative(n["seed"], "seed"));
    return r;
  }

  // The lower body's gait; takes the moves parsed into spec.free_motion (a lower body's 'moves' carry the body).
  Gait gait_of(const YAML::Node& g, ScenarioSpec& spec) const {
    check_keys(g, {"cadence_steps_per_min", "speed_m_s", "heading_deg", "alignment", "active"}, "body.gait");
    Gait gait;
    if (g["cadence_steps_per_min"]) gait.cadence_steps_per_min = positive(g["cadence_steps_per_min"], "cadence");
    if (g["speed_m_s"]) gait.speed_m_s = non_negative(g["speed_m_s"], "speed_m_s");
    if (g["heading_deg"]) gait.heading_rad = number(g["heading_deg"], "heading_deg") * kDeg;
    if (const YAML::Node a = g["alignment"]) {
      check_keys(a, {"pose_s", "flexions_per_leg", "flexion_s"}, "body.gait.alignment");
      AlignmentMoves moves;
      if (a["pose_s"]) moves.pose_s = positive(a["pose_s"], "pose_s");
      if (a["flexion_s"]) moves.flexion_s = positive(a["flexion_s"], "flexion_s");
      if (a["flexions_per_leg"]) {
        const double count = positive(a["flexions_per_leg"], "flexions_per_leg");
        if (count != std::floor(count) || count > 20) fail(a["flexions_per_leg"], "flexions_per_leg must be 1..20");
        moves.flexions_per_leg = static_cast<int>(count);
      }
      gait.alignment = moves;
    }
    if (g["active"]) {
      if (g["alignment"]) fail(g["active"], "give either alignment or active windows, not both");
      if (gait.speed_m_s > 0.0)
        fail(g["active"], "active windows need speed_m_s: 0 (walking on the spot; 'moves' carries the body)");
      gait.active = windows(g["active"], "active", 1.0);
    }
    gait.moves = std::move(spec.free_motion.moves);  // the lower body's moves, parsed above
    spec.free_motion.moves.clear();
    return gait;
  }

  void body(const YAML::Node& n, ScenarioSpec& spec) const {
    check_keys(
        n, {"kind", "segment", "pose", "random", "rotations", "moves", "pose_sequence", "gait", "reaching", "mounting"},
        "body");
    const std::string kind = n["kind"] ? text(n["kind"], "body kind") : "free";
    if (kind == "free")
      spec.body = BodyKind::kFree;
    else if (kind == "lower_body")
      spec.body = BodyKind::kLowerBody;
    else if (kind == "upper_body")
      spec.body = BodyKind::kUpperBody;
    else if (kind == "hinge_chain")
      spec.body = BodyKind::kHingeChain;
    else
      fail(n["kind"], "body kind must be free, lower_body, upper_body or hinge_chain");
    auto only = [&](const char* key, BodyKind k, const char* kind_name) {
      if (n[key] && spec.body != k) fail(n[key], std::string("'") + key + "' needs body kind " + kind_name);
    };
    for (const char* key : {"segment", "random", "rotations", "pose_sequence"}) only(key, BodyKind::kFree, "free");
    if (n["moves"] && (spec.body == BodyKind::kUpperBody || spec.body == BodyKind::kHingeChain))
      fail(n["moves"], "'moves' needs body kind free or lower_body");
    if (n["moves"] && spec.body == BodyKind::kLowerBody && !n["gait"])
      fail(n["moves"], "'moves' of a lower body needs a gait (e.g. gait: {speed_m_s: 0} to walk on the spot)");
    only("gait", BodyKind::kLowerBody, "lower_body");
    only("reaching", BodyKind::kUpperBody, "upper_body");
    if (n["mounting"] && spec.body == BodyKind::kFree)
      fail(n["mounting"], "'mounting' needs body kind lower_body, upper_body or hinge_chain");
    if (n["segment"]) spec.free_body_name = text(n["segment"], "segment");
    if (n["pose"]) {
      spec.pose = pose(n["pose"]);
      spec.free_motion.pose = spec.pose;
    }
    const std::uint64_t motion_seed = mix_seed(spec.seed, 1000);
    if (n["random"]) spec.free_motion.random = random(n["random"], motion_seed);
    if (const YAML::Node rs = n["rotations"]) {
      if (!rs.IsSequence()) fail(rs, "rotations must be a list");
      for (const YAML::Node& r : rs) {
        check_keys(r, {"axis", "angle_deg", "start_s", "duration_s"}, "a rotation");
        if (!r["axis"] || !r["angle_deg"] || !r["start_s"]) fail(r, "a rotation needs axis, angle_deg and start_s");
        const Vec3 axis = vec3(r["axis"], "axis");
        if (!(axis.norm() > 1e-9)) fail(r["axis"], "axis must not be zero");
        spec.free_motion.rotations.push_back({axis.normalized(), number(r["angle_deg"], "angle_deg") * kDeg,
                                              number(r["start_s"], "start_s"),
                                              r["duration_s"] ? positive(r["duration_s"], "duration_s") : 1.0});
      }
    }
    if (const YAML::Node ms = n["moves"]) {
      if (!ms.IsSequence()) fail(ms, "moves must be a list");
      for (const YAML::Node& m : ms) {
        check_keys(m, {"by_m", "start_s", "duration_s"}, "a move");
        if (!m["by_m"] || !m["start_s"]) fail(m, "a move needs by_m and start_s");
        spec.free_motion.moves.push_back({vec3(m["by_m"], "by_m"), number(m["start_s"], "start_s"),
                                          m["duration_s"] ? positive(m["duration_s"], "duration_s") : 1.0});
      }
    }
    if (const YAML::Node ps = n["pose_sequence"]) {
      check_keys(ps, {"count", "hold_s", "turn_s", "start_s"}, "body.pose_sequence");
      if (!ps["count"]) fail(ps, "pose_sequence needs count");
      const double count = positive(ps["count"], "count");
      if (count != std::floor(count) || count > 1000) fail(ps["count"], "count must be a whole number 1..1000");
      const auto seq =
          random_pose_sequence(static_cast<int>(count), ps["hold_s"] ? positive(ps["hold_s"], "hold_s") : 6.0,
                               ps["turn_s"] ? positive(ps["turn_s"], "turn_s") : 1.5,
                               ps["start_s"] ? non_negative(ps["start_s"], "start_s") : 0.0, mix_seed(spec.seed, 1001));
      spec.free_motion.rotations.insert(spec.free_motion.rotations.end(), seq.begin(), seq.end());
    }
    if (const YAML::Node m = n["mounting"]) {
      check_keys(m, {"max_rotation_deg", "max_offset_m"}, "body.mounting");
      if (m["max_rotation_deg"]) {
        spec.mounting.max_rotation_deg = non_negative(m["max_rotation_deg"], "max_rotation_deg");
        if (spec.mounting.max_rotation_deg > 180.0) fail(m["max_rotation_deg"], "max_rotation_deg must be 0..180");
      }
      if (m["max_offset_m"]) {
        spec.mounting.max_offset_m = non_negative(m["max_offset_m"], "max_offset_m");
        if (spec.mounting.max_offset_m > 0.2) fail(m["max_offset_m"], "max_offset_m must be 0..0.2");
      }
    }
    if (const YAML::Node g = n["gait"]) spec.gait = gait_of(g, spec);
    if (const YAML::Node r = n["reaching"]) {
      check_keys(r, {"period_s", "shoulder_flexion_deg"}, "body.reaching");
      Reaching reaching;
      if (r["period_s"]) reaching.period_s = positive(r["period_s"], "period_s");
      if (r["shoulder_flexion_deg"])
        reaching.shoulder_flexion_rad = number(r["shoulder_flexion_deg"], "shoulder_flexion_deg") * kDeg;
      spec.reaching = reaching;
    }
  }

  void magnetic(const YAML::Node& n, ScenarioSpec& spec, const Body& body) const {
    check_keys(n, {"magnitude_ut", "dip_deg", "heading_changes", "dipoles", "floor_regions", "attached_magnets"},
               "magnetic");
    MagneticEnvironment& m = spec.magnetic;
    if (n["magnitude_ut"]) m.magnitude_ut = positive(n["magnitude_ut"], "magnitude_ut");
    if (n["dip_deg"]) {
      m.dip_deg = number(n["dip_deg"], "dip_deg");
      if (std::abs(m.dip_deg) > 90.0) fail(n["dip_deg"], "dip_deg must be in [-90, 90]");
    }
    auto list = [&](const char* key) {
      const YAML::Node l = n[key];
      if (l && !l.IsSequence()) fail(l, std::string(key) + " must be a list");
      return l;
    };
    if (const YAML::Node hs = list("heading_changes")) {
      for (const YAML::Node& h : hs) {
        check_keys(h, {"at_s", "delta_deg", "ramp_s"}, "a heading change");
        if (!h["at_s"] || !h["delta_deg"]) fail(h, "a heading change needs at_s and delta_deg");
        m.heading_changes.push_back({number(h["at_s"], "at_s"), number(h["delta_deg"], "delta_deg") * kDeg,
                                     h["ramp_s"] ? non_negative(h["ramp_s"], "ramp_s") : 0.0});
      }
    }
    if (const YAML::Node ds = list("dipoles")) {
      for (const YAML::Node& d : ds) {
        check_keys(d, {"position_m", "moment_am2", "approach_from_m", "active"}, "a dipole");
        if (!d["position_m"] || !d["moment_am2"]) fail(d, "a dipole needs position_m and moment_am2");
        Dipole dip{vec3(d["position_m"], "position_m"), vec3(d["moment_am2"], "moment_am2"), Vec3::Zero(), {}};
        if (d["approach_from_m"]) dip.approach_from_m = vec3(d["approach_from_m"], "approach_from_m");
        if (d["active"]) dip.active = windows(d["active"], "active", 0.5);
        m.dipoles.push_back(dip);
      }
    }
    if (const YAML::Node rs = list("floor_regions")) {
      for (const YAML::Node& r : rs) {
        check_keys(r, {"min_m", "max_m", "field_ut", "edge_m", "active"}, "a floor region");
        if (!r["min_m"] || !r["max_m"] || !r["field_ut"]) fail(r, "a floor region needs min_m, max_m and field_ut");
        FloorRegion f{vec3(r["min_m"], "min_m"), vec3(r["max_m"], "max_m"), vec3(r["field_ut"], "field_ut"), 0.2, {}};
        if ((f.max_m - f.min_m).minCoeff() <= 0.0) fail(r, "a floor region needs max_m > min_m on every axis");
        if (r["edge_m"]) f.edge_m = non_negative(r["edge_m"], "edge_m");
        if (r["active"]) f.active = windows(r["active"], "active", 0.5);
        m.floor_regions.push_back(f);
      }
    }
    if (const YAML::Node as = list("attached_magnets")) {
      for (const YAML::Node& a : as) {
        check_keys(a, {"segment", "offset_m", "moment_am2"}, "an attached magnet");
        if (!a["moment_am2"] || !a["offset_m"]) fail(a, "an attached magnet needs offset_m and moment_am2");
        AttachedMagnet mag;
        const std::string seg = a["segment"] ? text(a["segment"], "segment") : body.segment(0).name;
        const auto i = body.find(seg);
        if (!i) fail(a["segment"], "no segment '" + seg + "' in this body");
        mag.segment = *i;
        mag.offset_m = vec3(a["offset_m"], "offset_m");
        if (!(mag.offset_m.norm() > 1e-3)) fail(a["offset_m"], "offset_m must be at least 1 mm from the sensor");
        mag.moment_am2 = vec3(a["moment_am2"], "moment_am2");
        m.attached_magnets.push_back(mag);
      }
    }
  }

  ScenarioSpec scenario(const YAML::Node& root) const {
    if (!root || root.IsNull()) fail_at(1, "the scenario file is empty");
    check_keys(root,
               {"name", "description", "duration_s", "rate_hz", "seed", "sensors", "body", "magnetic", "movement"},
               "the scenario");
    ScenarioSpec spec;
    spec.name = root["name"] ? text(root["name"], "name") : std::filesystem::path(source()).stem().string();
    if (root["description"]) spec.description = text(root["description"], "description");
    if (!root["duration_s"]) fail(root, "the scenario needs duration_s");
    spec.duration_s = positive(root["duration_s"], "duration_s");
    if (spec.duration_s > 24 * 3600.0) fail(root["duration_s"], "duration_s must be at most a day");
    if (root["rate_hz"]) {
      spec.rate_hz = positive(root["rate_hz"], "rate_hz");
      if (spec.rate_hz > 10000.0) fail(root["rate_hz"], "rate_hz must be at most 10000");
    }
    if (root["seed"]) spec.seed = static_cast<std::uint64_t>(non_negative(root["seed"], "seed"));
    if (root["sensors"]) spec.sensors = sensors(root["sensors"]);
    if (root["body"]) body(root["body"], spec);
    Body b;
    try {
      b = build_body(spec);
    } catch (const std::invalid_argument& e) {
      fail(root["body"], e.what());
    }
    if (root["magnetic"]) magnetic(root["magnetic"], spec, b);
    if (root["movement"]) spec.movement = windows(root["movement"], "movement", 0.0);
    return spec;
  }
};

}  // namespace

ScenarioSpec parse_scenario(const std::string& yaml_text, const std::string& source) {
  Parser parser(source);
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::ParserException& e) {
    parser.fail_at(e.mark.line + 1, "YAML syntax error: " + e.msg);
  }
  try {
    return parser.scenario(root);
  } catch (const YAML::Exception& e) {
    parser.fail_at(e.mark.line + 1, e.msg);
  }
}

ScenarioSpec load_scenario(const std::string& path) {
  return parse_scenario(config::read_config_file<ScenarioError>(path, "scenario"), path);
}

}  // namespace bsn::sim
