#include "bsn/sim/body.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>
#include <tuple>

namespace bsn::sim {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

RevoluteStep constant_step(const Vec3& axis, double angle) { return {axis, Signal::constant_value(angle)}; }

RevoluteStep harmonic_step(const Vec3& axis, double constant, std::vector<Signal::Harmonic> harmonics) {
  RevoluteStep s{axis, Signal::constant_value(constant)};
  s.angle.harmonics = std::move(harmonics);
  return s;
}

// Rotation chain of a root placed at `pose`: intrinsic z-y'-x'' as three revolute steps.
void add_pose(SegmentDef& root, const Pose& pose) {
  root.rotation.push_back(constant_step(Vec3::UnitZ(), pose.orientation.yaw));
  root.rotation.push_back(constant_step(Vec3::UnitY(), pose.orientation.pitch));
  root.rotation.push_back(constant_step(Vec3::UnitX(), pose.orientation.roll));
  for (int i = 0; i < 3; ++i) root.translation[i] = Signal::constant_value(pose.position_m[i]);
}

// The alignment moves of one leg (side 0 = left, first), a few times: the hip flexes and the knee follows a little
// later, the toes come up and down while the knee bends, then all return. As a person does it, the three joints
// do not move in proportion, which is what lets the functional fit tell their axes apart.
void add_alignment_moves(const AlignmentMoves& m, int side, SegmentDef& thigh, SegmentDef& shank, SegmentDef& foot) {
  const double f = m.flexion_s;
  for (int k = 0; k < m.flexions_per_leg; ++k) {
    const double t = m.pose_s + (side * m.flexions_per_leg + k) * f;
    // (segment, amplitude, up at, up for, down at, down for), times as shares of one flexion.
    const std::array<std::tuple<SegmentDef*, double, double, double, double, double>, 3> moves{{
        {&thigh, m.hip_flexion_rad, 0.0, 0.4, 0.5, 0.4},
        {&shank, m.knee_flexion_rad, 0.1, 0.25, 0.6, 0.35},
        {&foot, m.ankle_flexion_rad, 0.05, 0.2, 0.3, 0.2},
    }};
    for (const auto& [seg, amplitude, up_at, up_for, down_at, down_for] : moves) {
      seg->rotation[0].angle.steps.push_back({amplitude, t + up_at * f, up_for * f});
      seg->rotation[0].angle.steps.push_back({-amplitude, t + down_at * f, down_for * f});
    }
  }
}

// The gait's harmonics fade in once the alignment moves are done, or in and out with the gait's active windows
// (each joint's mean angle stepping in and out with them, so the body stands upright between).
void fade_gait_in_and_out(std::vector<SegmentDef>& segs, const Gait* gait, const AlignmentMoves* moves) {
  if (moves) {
    // Walking starts after the alignment moves: the gait's harmonics fade in, its mean angles step in.
    const double start = moves->walk_start_s();
    for (SegmentDef& seg : segs) {
      for (RevoluteStep& step : seg.rotation) {
        if (step.angle.harmonics.empty()) continue;
        step.angle.envelope = {Window{start, 1e12, 1.0}};
        if (&seg != &segs[0] && step.angle.constant != 0.0) {
          step.angle.steps.push_back({step.angle.constant, start, 1.0});
          step.angle.constant = 0.0;
        }
      }
    }
  }
  if (gait && !moves && !gait->active.empty()) {
    for (SegmentDef& seg : segs) {
      for (RevoluteStep& step : seg.rotation) {
        if (step.angle.harmonics.empty()) continue;
        step.angle.envelope = gait->active;
        if (&seg == &segs[0] || step.angle.constant == 0.0) continue;
        for (const Window& w : gait->active) {
          const double ramp = std::max(w.ramp_s, 0.1);  // a step needs a duration
          step.angle.steps.push_back({step.angle.constant, w.start_s, ramp});
          step.angle.steps.push_back({-step.angle.constant, w.end_s, ramp});
        }
        step.angle.constant = 0.0;
      }
    }
    for (Signal& axis : segs[0].translation) {
      if (!axis.harmonics.empty()) axis.envelope = gait->active;
    }
  }
}

}  // namespace

Vec3 SegmentState::specific_force_sensor() const {
  return q_sensor.conjugate() * (acceleration + Vec3(0.0, 0.0, fusion::kGravity));
}

Body::Body(std::vector<SegmentDef> segments) : segments_(std::move(segments)) {
  for (std::size_t i = 0; i < segments_.size(); ++i) {
    const SegmentDef& s = segments_[i];
    if (s.parent >= static_cast<int>(i) || s.parent < -1) {
      throw std::invalid_argument("segment '" + s.name + "': its parent must come before it");
    }
    for (std::size_t j = 0; j < i; ++j) {
      if (segments_[j].name == s.name) throw std::invalid_argument("duplicate segment '" + s.name + "'");
    }
    for (const RevoluteStep& r : s.rotation) {
      if (!(std::abs(r.axis.norm() - 1.0) < 1e-9)) {
        throw std::invalid_argument("segment '" + s.name + "': a rotation axis is not a unit vector");
      }
    }
  }
}

std::optional<std::size_t> Body::find(const std::string& name) const {
  for (std::size_t i = 0; i < segments_.size(); ++i) {
    if (segments_[i].name == name) return i;
  }
  return std::nullopt;
}

void Body::evaluate(double t, std::vector<SegmentState>& out) const {
  out.resize(segments_.size());
  for (std::size_t i = 0; i < segments_.size(); ++i) evaluate_segment(t, i, out);
}

void Body::evaluate_chain(double t, std::size_t i, std::vector<SegmentState>& out) const {
  out.resize(segments_.size());
  if (segments_[i].parent >= 0) evaluate_chain(t, static_cast<std::size_t>(segments_[i].parent), out);
  evaluate_segment(t, i, out);
}

void Body::evaluate_segment(double t, std::size_t i, std::vector<SegmentState>& out) const {
  const SegmentDef& def = segments_[i];
  SegmentState& s = out[i];
  Quat q = Quat::Identity();
  Vec3 w = Vec3::Zero(), alpha = Vec3::Zero();
  if (def.parent < 0) {
    for (int k = 0; k < 3; ++k) {
      const SignalValue v = def.translation[k].at(t);
      s.origin[k] = v.value;
      s.origin_velocity[k] = v.rate;
      s.origin_acceleration[k] = v.acceleration;
    }
  } else {
    // The joint centre is a point of the parent: rigid-body velocity and acceleration transfer.
    const SegmentState& p = out[static_cast<std::size_t>(def.parent)];
    const Vec3 d = p.q_segment * def.joint_offset;
    s.origin = p.origin + d;
    s.origin_velocity = p.origin_velocity + p.omega_earth.cross(d);
    s.origin_acceleration =
        p.origin_acceleration + p.alpha_earth.cross(d) + p.omega_earth.cross(p.omega_earth.cross(d));
    q = p.q_segment;
    w = p.omega_earth;
    alpha = p.alpha_earth;
  }
  // Each revolute step adds u*rate to the angular velocity, with u the step's axis in the earth frame;
  // u turns with the frame before the step, so it adds w x u * rate + u * acceleration to alpha.
  for (const RevoluteStep& step : def.rotation) {
    const SignalValue a = step.angle.at(t);
    const Vec3 u = q * step.axis;
    alpha += w.cross(u) * a.rate + u * a.acceleration;
    w += u * a.rate;
    q = q * Quat(Eigen::AngleAxisd(a.value, step.axis));
  }
  s.q_segment = q.normalized();
  s.omega_earth = w;
  s.alpha_earth = alpha;
  const Vec3 d = s.q_segment * def.sensor_offset;
  s.position = s.origin + d;
  s.velocity = s.origin_velocity + w.cross(d);
  s.acceleration = s.origin_acceleration + alpha.cross(d) + w.cross(w.cross(d));
  s.q_sensor = (s.q_segment * def.sensor_to_segment).normalized();
  s.gyr_sensor = s.q_sensor.conjugate() * w;
}

Body free_body(const std::string& name) { return free_body(FreeMotion{}, name); }

IntensityStats nez_table1(Intensity intensity) {
  switch (intensity) {
    case Intensity::kSlow:
      return {0.03, 0.02, 40.0, 20.0};
    case Intensity::kIntermediate:
      return {0.7, 0.5, 300.0, 150.0};
    case Intensity::kFast:
      break;
  }
  return {4.0, 2.0, 700.0, 400.0};
}

RandomMotion random_motion_for(Intensity intensity, std::uint64_t seed) {
  const IntensityStats st = nez_table1(intensity);
  RandomMotion m;
  // E|x|^2 = mean^2 + SD^2: the RMS of the magnitude.
  m.angular_rate_rms_rad_s = std::hypot(st.rate_mean_deg_s, st.rate_sd_deg_s) * kDeg;
  m.acceleration_rms_m_s2 = std::hypot(st.acc_mean_g, st.acc_sd_g) * fusion::kGravity;
  // Faster motion is also higher in frequency; this keeps hand displacements within about half a metre.
  const double band[3][2] = {{0.2, 1.0}, {0.5, 2.0}, {1.0, 3.0}};
  const int i = static_cast<int>(intensity);
  m.min_frequency_hz = band[i][0];
  m.max_frequency_hz = band[i][1];
  m.seed = seed;
  return m;
}

std::vector<ScriptedRotation> random_pose_sequence(int count, double hold_s, double turn_s, double start_s,
                                                   std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> angle(40.0 * kDeg, 120.0 * kDeg);
  std::vector<ScriptedRotation> out;
  double t = start_s + hold_s;  // the first pose is the start pose
  for (int k = 1; k < count; ++k) {
    // Sequenced draws (z, y, x, as GCC evaluated the arguments before): the same seed, the same poses, any compiler.
    const double z = normal(rng);
    const double y = normal(rng);
    const double x = normal(rng);
    Vec3 axis(x, y, z);
    axis.normalize();
    out.push_back({axis, angle(rng), t, turn_s});
    t += turn_s + hold_s;
  }
  return out;
}

Body free_body(const FreeMotion& motion, const std::string& name) {
  SegmentDef root;
  root.name = name;
  add_pose(root, motion.pose);
  if (motion.swing) {
    root.rotation[0].angle.harmonics = {motion.swing->yaw};
    root.rotation[1].angle.harmonics = {motion.swing->pitch};
    root.rotation[2].angle.harmonics = {motion.swing->roll};
  }
  if (motion.random) {
    const RandomMotion& r = *motion.random;
    std::mt19937_64 rng(r.seed);
    std::uniform_real_distribution<double> freq(r.min_frequency_hz, r.max_frequency_hz), phase(0.0, 2.0 * kPi);
    const int n = std::max(1, r.harmonics_per_axis);
    // Per axis, n harmonics of equal rate (or acceleration) amplitude: RMS^2 = n * (A w^p)^2 / 2 = target^2 / 3.
    const double rate_amp = r.angular_rate_rms_rad_s / std::sqrt(3.0) * std::sqrt(2.0 / n);
    const double acc_amp = r.acceleration_rms_m_s2 / std::sqrt(3.0) * std::sqrt(2.0 / n);
    for (int axis = 2; axis >= 0; --axis) {  // z, y', x'' like the pose
      RevoluteStep step{Vec3::Unit(axis), Signal{}};
      for (int k = 0; k < n; ++k) {
        const double w = 2.0 * kPi * freq(rng);
        step.angle.harmonics.push_back({rate_amp / w, w / (2.0 * kPi), phase(rng)});
      }
      step.angle.envelope = r.active;
      root.rotation.push_back(std::move(step));
    }
    for (int axis = 0; axis < 3; ++axis) {
      for (int k = 0; k < n; ++k) {
        const double w = 2.0 * kPi * freq(rng);
        root.translation[axis].harmonics.push_back({acc_amp / (w * w), w / (2.0 * kPi), phase(rng)});
      }
      root.translation[axis].envelope = r.active;
    }
  }
  for (const ScriptedRotation& s : motion.rotations) {
    RevoluteStep step{s.axis.normalized(), Signal{}};
    step.angle.steps.push_back({s.angle_rad, s.start_s, s.duration_s});
    root.rotation.push_back(std::move(step));
  }
  for (const ScriptedMove& m : motion.moves) {
    for (int axis = 0; axis < 3; ++axis) {
      if (m.by_m[axis] != 0.0) root.translation[axis].steps.push_back({m.by_m[axis], m.start_s, m.duration_s});
    }
  }
  return Body({std::move(root)});
}

FreeMotion random_swing(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  // Per angle: offset, amplitude, frequency, phase, drawn in that order (yaw, pitch, roll).
  auto angle = [&](double max_deg, double& offset) {
    offset = (u(rng) - 0.5) * max_deg * kDeg;
    const double amplitude = (0.3 + 0.7 * u(rng)) * max_deg * kDeg;
    const double frequency = 0.1 + 0.3 * u(rng);
    return Signal::Harmonic{amplitude, frequency, 2.0 * kPi * u(rng)};
  };
  FreeMotion m;
  fusion::YawPitchRoll& o = m.pose.orientation;
  m.swing = PoseSwing{};
  m.swing->yaw = angle(60.0, o.yaw);
  m.swing->pitch = angle(30.0, o.pitch);
  m.swing->roll = angle(30.0, o.roll);
  return m;
}

Body lower_body(const std::optional<Gait>& gait, const Pose& pose) {
  const double f = gait ? gait->cadence_steps_per_min / 120.0 : 0.0;  // stride frequency, Hz
  const double g = gait ? 1.0 : 0.0;                                  // 0 = standing still
  auto hz = [&](double amp_deg, double mult, double phase) {
    return Signal::Harmonic{g * amp_deg * kDeg, mult * f, phase};
  };
  SegmentDef pelvis;
  pelvis.name = "pelvis";
  Pose p = pose;
  p.position_m.z() = pose.position_m.z() > 0.5 ? pose.position_m.z() : 0.95;
  if (gait) p.orientation.yaw = gait->heading_rad;
  add_pose(pelvis, p);
  pelvis.rotation[0].angle.harmonics = {hz(4.0, 1.0, 0.0)};        // pelvic rotation
  pelvis.rotation[1].angle.harmonics = {hz(2.0, 2.0, 0.0)};        // anterior tilt
  pelvis.rotation[2].angle.harmonics = {hz(3.0, 1.0, 0.5 * kPi)};  // obliquity
  pelvis.sensor_offset = Vec3(-0.10, 0.0, 0.0);                    // on the sacrum
  const AlignmentMoves* moves = gait && gait->alignment ? &*gait->alignment : nullptr;
  if (gait && !moves) {
    const double c = std::cos(gait->heading_rad), s = std::sin(gait->heading_rad);
    pelvis.translation[0].rate = gait->speed_m_s * c;
    pelvis.translation[1].rate = gait->speed_m_s * s;
    // Lateral sway once per stride, vertical bounce twice per stride.
    pelvis.translation[0].harmonics = {{-0.02 * s, f, 0.0}};
    pelvis.translation[1].harmonics = {{0.02 * c, f, 0.0}};
    pelvis.translation[2].harmonics = {{0.02, 2.0 * f, 0.0}};
  }
  if (gait) {
    for (const ScriptedMove& m : gait->moves) {
      for (int axis = 0; axis < 3; ++axis) {
        if (m.by_m[axis] != 0.0) pelvis.translation[axis].steps.push_back({m.by_m[axis], m.start_s, m.duration_s});
      }
    }
  }
  std::vector<SegmentDef> segs{pelvis};
  const Vec3 flex_axis(0.0, -1.0, 0.0);  // hip flexion and ankle dorsiflexion swing +x forward / toes up
  for (int side = 0; side < 2; ++side) {
    const double ph = side == 0 ? 0.0 : kPi;  // right leg half a stride later
    const double lr = side == 0 ? 1.0 : -1.0;
    const std::string suffix = side == 0 ? "_l" : "_r";
    SegmentDef thigh, shank, foot;
    thigh.name = "thigh" + suffix;
    thigh.parent = 0;
    thigh.joint_offset = Vec3(0.0, lr * 0.09, -0.08);
    thigh.rotation = {harmonic_step(flex_axis, g * 10.0 * kDeg, {hz(22.0, 1.0, ph + 0.5 * kPi), hz(2.0, 2.0, 2 * ph)}),
                      harmonic_step(Vec3::UnitX(), 0.0, {hz(lr * 3.0, 1.0, ph)})};
    thigh.sensor_offset = Vec3(0.0, lr * 0.08, -0.20);
    thigh.joint = "hip" + suffix;
    shank.name = "shank" + suffix;
    shank.parent = static_cast<int>(segs.size());
    shank.joint_offset = Vec3(0.0, 0.0, -0.42);
    shank.rotation = {
        harmonic_step(Vec3::UnitY(), g * 28.0 * kDeg, {hz(8.0, 1.0, ph), hz(22.0, 2.0, 2 * ph - 0.5 * kPi + 0.6)})};
    shank.sensor_offset = Vec3(0.0, lr * 0.05, -0.20);
    shank.joint = "knee" + suffix;
    foot.name = "foot" + suffix;
    foot.parent = shank.parent + 1;
    foot.joint_offset = Vec3(0.0, 0.0, -0.41);
    foot.rotation = {harmonic_step(flex_axis, g * 2.0 * kDeg, {hz(5.0, 1.0, ph + 0.5 * kPi), hz(8.0, 2.0, 2 * ph)})};
    foot.sensor_offset = Vec3(0.08, 0.0, 0.03);
    foot.joint = "ankle" + suffix;
    if (moves) add_alignment_moves(*moves, side, thigh, shank, foot);
    segs.push_back(thigh);
    segs.push_back(shank);
    segs.push_back(foot);
  }
  fade_gait_in_and_out(segs, gait ? &*gait : nullptr, moves);
  return Body(std::move(segs));
}

Body upper_body(const std::optional<Reaching>& reaching, const Pose& pose) {
  SegmentDef trunk;
  trunk.name = "trunk";
  Pose p = pose;
  p.position_m.z() = pose.position_m.z() > 0.5 ? pose.position_m.z() : 1.2;
  add_pose(trunk, p);
  trunk.sensor_offset = Vec3(-0.12, 0.0, 0.25);  // between the shoulder blades
  const double f = reaching ? 1.0 / reaching->period_s : 0.0;
  const double amp = reaching ? reaching->shoulder_flexion_rad : 0.0;
  std::vector<SegmentDef> segs{trunk};
  const Vec3 flex_axis(0.0, -1.0, 0.0);
  for (int side = 0; side < 2; ++side) {
    const double ph = side == 0 ? kPi : 0.0;  // the arms reach in turn
    const double lr = side == 0 ? 1.0 : -1.0;
    const std::string suffix = side == 0 ? "_l" : "_r";
    SegmentDef upper, fore, hand;
    upper.name = "upper_arm" + suffix;
    upper.parent = 0;
    upper.joint_offset = Vec3(0.0, lr * 0.18, 0.45);
    // Shoulder flexion 0 -> amp -> 0 once per period: amp/2 (1 - cos).
    upper.rotation = {harmonic_step(flex_axis, 0.5 * amp, {{0.5 * amp, f, ph - 0.5 * kPi}}),
                      harmonic_step(Vec3::UnitX(), lr * 8.0 * kDeg, {{lr * 0.1 * amp, f, ph}})};
    upper.sensor_offset = Vec3(0.0, lr * 0.05, -0.15);
    upper.joint = "shoulder" + suffix;
    fore.name = "forearm" + suffix;
    fore.parent = static_cast<int>(segs.size());
    fore.joint_offset = Vec3(0.0, 0.0, -0.30);
    // Elbow flexed 70 deg at rest, extending to 20 deg at full reach.
    fore.rotation = {harmonic_step(flex_axis, 45.0 * kDeg, {{reaching ? 25.0 * kDeg : 0.0, f, ph + 0.5 * kPi}})};
    fore.sensor_offset = Vec3(0.0, lr * 0.03, -0.20);
    fore.joint = "elbow" + suffix;
    hand.name = "hand" + suffix;
    hand.parent = fore.parent + 1;
    hand.joint_offset = Vec3(0.0, 0.0, -0.26);
    hand.rotation = {harmonic_step(Vec3::UnitZ(), 0.0, {{reaching ? 15.0 * kDeg : 0.0, f, ph}})};
    hand.sensor_offset = Vec3(0.0, 0.0, -0.06);
    hand.joint = "wrist" + suffix;
    segs.push_back(upper);
    segs.push_back(fore);
    segs.push_back(hand);
  }
  return Body(std::move(segs));
}

Body hinge_chain(const Pose& pose) {
  SegmentDef base;
  base.name = "base";
  add_pose(base, pose);
  base.sensor_offset = Vec3(0.05, 0.0, 0.15);
  SegmentDef link_1;
  link_1.name = "link_1";
  link_1.parent = 0;
  link_1.joint_offset = Vec3(0.0, 0.0, 0.3);
  // ISB Z (right) is the simulator's -y: a positive angle about it tips the link forward.
  link_1.rotation = {harmonic_step(Vec3(0.0, -1.0, 0.0), 10.0 * kDeg, {{20.0 * kDeg, 0.25, 0.0}})};
  link_1.sensor_offset = Vec3(0.05, 0.0, 0.15);
  link_1.joint = "hinge_1";
  SegmentDef link_2;
  link_2.name = "link_2";
  link_2.parent = 1;
  link_2.joint_offset = Vec3(0.0, 0.0, 0.3);
  link_2.rotation = {harmonic_step(Vec3::UnitX(), 0.0, {{30.0 * kDeg, 0.35, 1.0}})};
  link_2.sensor_offset = Vec3(0.05, 0.0, 0.15);
  link_2.joint = "hinge_2";
  return Body({base, link_1, link_2});
}

}  // namespace bsn::sim
