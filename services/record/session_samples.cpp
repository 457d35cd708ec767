#include "session_samples.hpp"

#include <array>

namespace bsn::services {
namespace {

/// The columns of one stream, read once, each checked against the stream's length.
class StreamColumns {
 public:
  StreamColumns(const io::SessionReader& r, const io::SessionStream& s)
      : r_(r), s_(s), timestamp_ns(r.read_u64(s, "timestamp_ns")) {}
  std::vector<double> f64(const char* name, int width) const {
    std::vector<double> v = r_.read_f64(s_, name, width);
    check(v.size(), static_cast<std::size_t>(width), name);
    return v;
  }
  std::vector<std::uint32_t> u32(const char* name) const {
    std::vector<std::uint32_t> v = r_.read_u32(s_, name);
    check(v.size(), 1, name);
    return v;
  }
  const std::string& text(const char* name) const {
    const auto it = s_.attributes.find(name);
    if (it == s_.attributes.end())
      throw io::IoError(r_.path() + ": '" + s_.group + "' has neither serialised samples nor the attribute '" + name +
                        "'");
    return it->second;
  }
  std::size_t size() const { return timestamp_ns.size(); }

 private:
  void check(std::size_t values, std::size_t width, const char* name) const {
    if (values != width * size())
      throw io::IoError(r_.path() + ": datasets '" + s_.group + "/timestamp_ns' and '" + s_.group + "/" + name +
                        "' differ in length");
  }
  const io::SessionReader& r_;
  const io::SessionStream& s_;

 public:
  const std::vector<std::uint64_t> timestamp_ns;
};

template <std::size_t N>
std::array<double, N> row(const std::vector<double>& v, std::size_t i) {
  std::array<double, N> a{};
  for (std::size_t k = 0; k < N; ++k) a[k] = v[N * i + k];
  return a;
}

}  // namespace

std::vector<bsn::Orientation> orientations_from_columns(const io::SessionReader& r, const io::SessionStream& s) {
  const StreamColumns c(r, s);
  const auto quat = c.f64("quat", 4), yaw = c.f64("yaw", 1), pitch = c.f64("pitch", 1), roll = c.f64("roll", 1),
             bias = c.f64("gyro_bias", 3);
  const auto flags = c.u32("flags");
  const std::string& node = c.text("node_id");
  std::vector<bsn::Orientation> out(c.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    bsn::Orientation& o = out[i];
    o.segment(s.key);
    o.node_id(node);
    o.timestamp_ns(c.timestamp_ns[i]);
    o.quat(row<4>(quat, i));
    o.yaw(yaw[i]);
    o.pitch(pitch[i]);
    o.roll(roll[i]);
    o.gyro_bias(row<3>(bias, i));
    o.flags(flags[i]);
  }
  return out;
}

std::vector<bsn::JointAngles> joint_angles_from_columns(const io::SessionReader& r, const io::SessionStream& s) {
  const StreamColumns c(r, s);
  const auto quat = c.f64("quat", 4), angles = c.f64("angles", 3), heading_offset = c.f64("heading_offset", 1),
             heading_observability = c.f64("heading_observability", 1);
  std::array<std::vector<double>, 3> anatomical;
  for (std::size_t k = 0; k < 3; ++k) anatomical[k] = c.f64(("anatomical_" + std::to_string(k)).c_str(), 1);
  const auto flags = c.u32("flags");
  // visit_fields writes an empty name for each angle of a joint without anatomical angles (an empty sequence).
  std::vector<std::string> names;
  for (std::size_t k = 0; k < 3; ++k) names.push_back(c.text(("anatomical_name_" + std::to_string(k)).c_str()));
  if (names[0].empty() && names[1].empty() && names[2].empty()) names.clear();
  std::vector<bsn::JointAngles> out(c.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    bsn::JointAngles& j = out[i];
    j.joint(s.key);
    j.parent(c.text("parent"));
    j.child(c.text("child"));
    j.timestamp_ns(c.timestamp_ns[i]);
    j.quat(row<4>(quat, i));
    j.axes(c.text("axes"));
    j.angles(row<3>(angles, i));
    j.flags(flags[i]);
    j.anatomy(c.text("anatomy"));
    j.side(c.text("side"));
    j.anatomical_names(names);
    j.anatomical({anatomical[0][i], anatomical[1][i], anatomical[2][i]});
    j.heading_offset(heading_offset[i]);
    j.heading_observability(heading_observability[i]);
  }
  return out;
}

}  // namespace bsn::services
