#include "bsn/fusion/anatomy.hpp"

#include <cctype>
#include <cmath>
#include <numbers>
#include <string>

namespace bsn::fusion {
namespace {

// Grood & Suntay in ISB frames: Z of the parent, the floating X', Y of the child.
const AxisSequence kJointCoordinateSystem{{2, 0, 1}};

struct TypeTable {
  JointType type;
  std::string_view name;
  std::array<std::string_view, 3> angles;
  // Sign of (a, b, c) that makes the named direction positive on the right side (and midline). The knee and the
  // trunk flex against the right-hand rule about Z: the shank's and the trunk's long axes tilt forward.
  std::array<double, 3> right_sign;
};

constexpr std::array<TypeTable, 7> kTypes{{
    {JointType::kHip, "hip", {"flexion_extension", "adduction_abduction", "internal_external_rotation"}, {1, 1, 1}},
    {JointType::kKnee, "knee", {"flexion_extension", "adduction_abduction", "internal_external_rotation"}, {-1, 1, 1}},
    {JointType::kAnkle,
     "ankle",
     {"dorsiflexion_plantarflexion", "inversion_eversion", "internal_external_rotation"},
     {1, 1, 1}},
    {JointType::kTrunkPelvis,
     "trunk_pelvis",
     {"flexion_extension", "right_left_lateral_bending", "left_right_axial_rotation"},
     {-1, 1, 1}},
    {JointType::kShoulder,
     "shoulder",
     {"flexion_extension", "adduction_abduction", "internal_external_rotation"},
     {1, 1, 1}},
    {JointType::kElbow, "elbow", {"flexion_extension", "adduction_abduction", "pronation_supination"}, {1, 1, 1}},
    {JointType::kWrist, "wrist", {"flexion_extension", "ulnar_radial_deviation", "pronation_supination"}, {1, 1, 1}},
}};

const TypeTable* find_type(JointType type) {
  for (const TypeTable& t : kTypes)
    if (t.type == type) return &t;
  return nullptr;
}

// Signs of (a, b, c) for a convention: the right side's, with b and c mirrored on the left.
Vec3 signs(const TypeTable& t, BodySide side) {
  const double m = side == BodySide::kLeft ? -1.0 : 1.0;
  return {t.right_sign[0], m * t.right_sign[1], m * t.right_sign[2]};
}

bool ends_with(std::string_view s, std::string_view tail) {
  return s.size() >= tail.size() && s.substr(s.size() - tail.size()) == tail;
}

}  // namespace

std::string_view joint_type_name(JointType type) {
  const TypeTable* t = find_type(type);
  return t ? t->name : std::string_view();
}

std::optional<JointType> parse_joint_type(std::string_view name) {
  for (const TypeTable& t : kTypes)
    if (t.name == name) return t.type;
  if (name == "none") return JointType::kNone;
  return std::nullopt;
}

std::string_view body_side_name(BodySide side) {
  switch (side) {
    case BodySide::kLeft:
      return "left";
    case BodySide::kRight:
      return "right";
    case BodySide::kMidline:
      break;
  }
  return "";
}

std::optional<BodySide> parse_body_side(std::string_view name) {
  if (name == "left") return BodySide::kLeft;
  if (name == "right") return BodySide::kRight;
  if (name == "midline") return BodySide::kMidline;
  return std::nullopt;
}

JointConvention infer_joint_convention(std::string_view joint_name) {
  std::string n(joint_name);
  for (char& c : n) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  JointConvention out;
  std::string_view rest = n;
  for (const auto& [tail, side] : {std::pair<std::string_view, BodySide>{"_left", BodySide::kLeft},
                                   {"_right", BodySide::kRight},
                                   {"_l", BodySide::kLeft},
                                   {"_r", BodySide::kRight}}) {
    if (ends_with(rest, tail)) {
      out.side = side;
      rest.remove_suffix(tail.size());
      break;
    }
  }
  if (out.side == BodySide::kMidline) {
    for (const auto& [head, side] : {std::pair<std::string_view, BodySide>{"left_", BodySide::kLeft},
                                     {"right_", BodySide::kRight},
                                     {"l_", BodySide::kLeft},
                                     {"r_", BodySide::kRight}}) {
      if (rest.starts_with(head)) {
        out.side = side;
        rest.remove_prefix(head.size());
        break;
      }
    }
  }
  if (rest == "trunk" || rest == "lumbar" || rest == "spine" || rest == "trunk_pelvis" || rest == "pelvis_trunk") {
    out.type = JointType::kTrunkPelvis;
    out.side = BodySide::kMidline;
    return out;
  }
  if (const auto type = parse_joint_type(rest); type && *type != JointType::kNone) {
    out.type = *type;
    return out;
  }
  return {};
}

std::array<std::string_view, 3> anatomical_angle_names(JointType type) {
  const TypeTable* t = find_type(type);
  return t ? t->angles : std::array<std::string_view, 3>{};
}

Vec3 anatomical_angles(const Quat& relative, const JointConvention& convention) {
  const TypeTable* t = find_type(convention.type);
  if (!t) return Vec3::Zero();
  return decompose(relative, kJointCoordinateSystem).cwiseProduct(signs(*t, convention.side));
}

Quat relative_from_anatomical(const Vec3& angles, const JointConvention& convention) {
  const TypeTable* t = find_type(convention.type);
  if (!t) return Quat::Identity();
  // The signs are +-1: multiplying again undoes them.
  return compose(angles.cwiseProduct(signs(*t, convention.side)), kJointCoordinateSystem);
}

Quat default_sensor_to_segment() { return Quat(Eigen::AngleAxisd(-0.5 * std::numbers::pi, Vec3::UnitX())); }

std::optional<Direction> parse_direction(std::string_view name) {
  if (name == "anterior" || name == "forward") return Direction::kAnterior;
  if (name == "posterior" || name == "backward") return Direction::kPosterior;
  if (name == "superior" || name == "up") return Direction::kSuperior;
  if (name == "inferior" || name == "down") return Direction::kInferior;
  if (name == "left") return Direction::kLeft;
  if (name == "right") return Direction::kRight;
  return std::nullopt;
}

std::optional<Quat> sensor_to_segment_from_axes(const std::array<Direction, 3>& sensor_axes) {
  // Column i of R (sensor -> segment) is sensor axis i in segment coordinates (X anterior, Y superior, Z right).
  Eigen::Matrix3d r;
  for (int i = 0; i < 3; ++i) {
    switch (sensor_axes[static_cast<std::size_t>(i)]) {
      case Direction::kAnterior:
        r.col(i) = Vec3::UnitX();
        break;
      case Direction::kPosterior:
        r.col(i) = -Vec3::UnitX();
        break;
      case Direction::kSuperior:
        r.col(i) = Vec3::UnitY();
        break;
      case Direction::kInferior:
        r.col(i) = -Vec3::UnitY();
        break;
      case Direction::kRight:
        r.col(i) = Vec3::UnitZ();
        break;
      case Direction::kLeft:
        r.col(i) = -Vec3::UnitZ();
        break;
    }
  }
  // A rotation has determinant +1: two axes along one line give 0, a mirror gives -1.
  if (!(std::abs(r.determinant() - 1.0) < 1e-9)) return std::nullopt;
  return canonical(Quat(r));
}

}  // namespace bsn::fusion
