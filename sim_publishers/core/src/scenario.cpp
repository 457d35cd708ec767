#include "bsn/sim/scenario.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

namespace bsn::sim {

namespace {

// Each segment's sensor rotated and displaced by its own random stream.
void mount_sensors(const Mounting& m, std::uint64_t seed, Body& body) {
  const double max_rotation = std::clamp(m.max_rotation_deg, 0.0, 180.0) * std::numbers::pi / 180.0;
  for (std::size_t i = 0; i < body.size(); ++i) {
    std::mt19937_64 rng(mix_seed(seed, 5000 + i));
    std::normal_distribution<double> normal(0.0, 1.0);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    Quat r;
    if (max_rotation >= std::numbers::pi) {
      // Four normal deviates, normalised: uniform on the rotations.
      r = Quat(normal(rng), normal(rng), normal(rng), normal(rng)).normalized();
    } else {
      const Vec3 axis = Vec3(normal(rng), normal(rng), normal(rng)).normalized();
      r = Quat(Eigen::AngleAxisd(unit(rng) * max_rotation, axis));
    }
    const Vec3 direction = Vec3(normal(rng), normal(rng), normal(rng)).normalized();
    SegmentDef& def = body.segment(i);
    def.sensor_to_segment = (def.sensor_to_segment * r).normalized();
    def.sensor_offset += direction * (unit(rng) * std::max(0.0, m.max_offset_m));
  }
}

}  // namespace

Body build_body(const ScenarioSpec& spec) {
  Body body;
  switch (spec.body) {
    case BodyKind::kLowerBody:
      body = lower_body(spec.gait, spec.pose);
      break;
    case BodyKind::kUpperBody:
      body = upper_body(spec.reaching, spec.pose);
      break;
    case BodyKind::kHingeChain:
      body = hinge_chain(spec.pose);
      break;
    case BodyKind::kFree:
      return free_body(spec.free_motion, spec.free_body_name);
  }
  if (spec.mounting.max_rotation_deg > 0.0 || spec.mounting.max_offset_m > 0.0)
    mount_sensors(spec.mounting, spec.seed, body);
  return body;
}

ScenarioSpec swing_scenario(const std::string& segment, std::uint64_t seed, double rate_hz, double duration_s) {
  ScenarioSpec spec;
  spec.name = "swing";
  spec.duration_s = duration_s > 0.0 ? duration_s : std::numeric_limits<double>::infinity();
  spec.rate_hz = rate_hz;
  spec.seed = seed;
  spec.free_body_name = segment;
  spec.free_motion = random_swing(seed);
  // Densities: per-sample SD / sqrt(100 Hz).
  spec.sensors.gyr.white_density = 0.0005;
  spec.sensors.acc.white_density = 0.002;
  spec.sensors.mag.white_density = 0.03;
  return spec;
}

ScenarioRunner::ScenarioRunner(const ScenarioSpec& spec, const std::vector<std::string>& segments, bool ideal)
    : spec_(spec), body_(build_body(spec)) {
  if (!(spec.rate_hz > 0.0 && spec.rate_hz <= 10000.0)) throw std::invalid_argument("rate_hz must be in (0, 10000]");
  if (!(spec.duration_s > 0.0)) throw std::invalid_argument("duration_s must be > 0");
  if (ideal) spec_.sensors = SensorErrors::ideal();
  for (const AttachedMagnet& m : spec_.magnetic.attached_magnets) {
    if (m.segment >= body_.size()) throw std::invalid_argument("an attached magnet refers to a missing segment");
  }
  if (segments.empty()) {
    for (std::size_t i = 0; i < body_.size(); ++i) selected_.push_back(i);
  } else {
    for (const std::string& name : segments) {
      const auto i = body_.find(name);
      if (!i) {
        std::string known;
        for (std::size_t j = 0; j < body_.size(); ++j) known += (j ? ", " : "") + body_.segment(j).name;
        throw std::invalid_argument("scenario '" + spec.name + "' has no segment '" + name + "' (it has: " + known +
                                    ")");
      }
      selected_.push_back(*i);
    }
  }
  for (std::size_t i : selected_) {
    names_.push_back(body_.segment(i).name);
    joints_.push_back(body_.segment(i).parent >= 0 ? fusion::infer_joint_convention(body_.segment(i).joint)
                                                   : fusion::JointConvention{});
    // Streams depend on the segment's index in the body, not on which segments were selected.
    sensors_.emplace_back(spec_.sensors, spec_.rate_hz, mix_seed(spec_.seed, 2 * i));
    timing_rng_.emplace_back(mix_seed(spec_.seed, 2 * i + 1));
  }
  count_ = std::isinf(spec_.duration_s)
               ? std::numeric_limits<std::uint64_t>::max()
               : static_cast<std::uint64_t>(std::floor(spec_.duration_s * spec_.rate_hz + 1e-9));
  states_.reserve(body_.size());
}

bool ScenarioRunner::next(std::vector<ScenarioSample>& out) {
  if (k_ >= count_) return false;
  out.resize(selected_.size());
  const double period = 1.0 / spec_.rate_hz;
  const double nominal = static_cast<double>(k_) * period;
  const SensorErrors& e = spec_.sensors;
  // A slower magnetometer delivers on the first IMU sample at or after each of its own ticks.
  bool has_mag = true;
  if (e.mag_rate_hz > 0.0 && e.mag_rate_hz < spec_.rate_hz && k_ > 0) {
    const double ratio = e.mag_rate_hz / spec_.rate_hz;
    has_mag =
        std::floor(static_cast<double>(k_) * ratio + 1e-9) > std::floor(static_cast<double>(k_ - 1) * ratio + 1e-9);
  }
  bool evaluated = false;
  for (std::size_t j = 0; j < selected_.size(); ++j) {
    double t = nominal;
    if (e.jitter_s > 0.0) {
      // Bounded to keep timestamps strictly increasing. Fresh distributions: a shared one would carry a cached
      // normal deviate from one sensor's stream to the next.
      t = std::max(0.0, t + std::clamp(std::normal_distribution<double>(0.0, 1.0)(timing_rng_[j]) * e.jitter_s,
                                       -0.4 * period, 0.4 * period));
    }
    const bool dropped = e.drop_probability > 0.0 &&
                         std::uniform_real_distribution<double>(0.0, 1.0)(timing_rng_[j]) < e.drop_probability;
    const std::size_t i = selected_[j];
    if (e.jitter_s > 0.0) {
      body_.evaluate_chain(t, i, states_);  // each sensor at its own instant: only its chain
    } else if (!evaluated) {
      body_.evaluate(t, states_);
      evaluated = true;
    }
    const SegmentState& s = states_[i];
    const Vec3 mag = spec_.magnetic.sensor_field(i, s.position, s.q_sensor, t);
    const auto t_ns = static_cast<std::uint64_t>(std::llround(t * 1e9));
    ScenarioSample& o = out[j];
    o.sample = sensors_[j].measure(s.gyr_sensor, s.specific_force_sensor(), mag, t, t_ns, has_mag);
    o.truth = s.q_sensor;
    o.segment_truth = anatomical_orientation(s);
    o.dropped = dropped;
    o.movement = spec_.movement.empty() || inside_any(spec_.movement, t);
    o.joint = joints_[j];
    if (const int parent = body_.segment(i).parent; parent >= 0) {
      // The parent's state is of the same instant: evaluate() and evaluate_chain() both computed it.
      o.joint_relative = fusion::canonical(fusion::relative_orientation(
          anatomical_orientation(states_[static_cast<std::size_t>(parent)]), anatomical_orientation(s)));
      o.joint_anatomical = fusion::anatomical_angles(*o.joint_relative, o.joint);
    }
  }
  ++k_;
  return true;
}

}  // namespace bsn::sim
