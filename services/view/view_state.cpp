#include "view_state.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string_view>

#include "bsn/io/json.hpp"

namespace bsn::services {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;
constexpr std::uint64_t kIntervalNs = static_cast<std::uint64_t>(1e9 / ViewState::kMaxRateHz);

std::string name_of(const std::string& s) { return json_string(s.substr(0, ViewState::kMaxNameChars)); }

std::string number(double v, int digits = 9) { return io::json_number(v, digits); }

std::string quat_json(const std::array<double, 4>& q) {
  return "[" + number(q[0]) + "," + number(q[1]) + "," + number(q[2]) + "," + number(q[3]) + "]";
}

bool finite(const std::array<double, 4>& q) {
  return std::all_of(q.begin(), q.end(), [](double v) { return std::isfinite(v); });
}

/// Inserts `key` if there is room (kMaxKeys); nullptr if the map is full.
template <class Map>
typename Map::mapped_type* slot_for(Map& map, const std::string& key) {
  if (auto it = map.find(key); it != map.end()) return &it->second;
  if (map.size() >= ViewState::kMaxKeys) return nullptr;
  return &map[key];
}

}  // namespace

std::string json_string(std::string_view text) { return io::json_string(text, /*ascii_only=*/true); }

double rotation_angle_deg(const std::array<double, 4>& a, const std::array<double, 4>& b) {
  // The rotation a^* b: its angle from atan2 (acos of the dot product loses digits near 0).
  const double w = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
  const double x = a[0] * b[1] - a[1] * b[0] - a[2] * b[3] + a[3] * b[2];
  const double y = a[0] * b[2] + a[1] * b[3] - a[2] * b[0] - a[3] * b[1];
  const double z = a[0] * b[3] - a[1] * b[2] + a[2] * b[1] - a[3] * b[0];
  return 2.0 * std::atan2(std::sqrt(x * x + y * y + z * z), std::abs(w)) * kDeg;
}

bool ViewState::due(Limited& slot, std::uint64_t now_ns) {
  if (now_ns < slot.next_due_ns) return false;
  // One grid for every segment and joint (multiples of 1/30 s): each passes its first sample after a grid point,
  // so a 100 Hz source is passed on at the full 30 Hz, and the messages of all segments come in bursts that the
  // server sends to a browser in one frame.
  slot.next_due_ns = (now_ns / kIntervalNs + 1) * kIntervalNs;
  return true;
}

std::optional<std::string> ViewState::on_truth(const bsn::Orientation& t, std::uint64_t now_ns) {
  const std::array<double, 4> q = t.quat();
  if (!finite(q)) {
    ++rejected_non_finite_;
    return std::nullopt;
  }
  const std::string seg = t.segment().substr(0, kMaxNameChars);
  const bool segment_frame = (t.flags() & bsn::FLAG_SEGMENT_FRAME) != 0;
  auto* history = slot_for(segment_frame ? segment_truth_ : truth_, seg);
  auto* slot = slot_for(truth_msg_, seg);
  if (history == nullptr || slot == nullptr) {
    ++rejected_too_many_names_;
    return std::nullopt;
  }
  history->emplace_back(t.timestamp_ns(), q);
  if (history->size() > kTruthHistory) history->pop_front();
  // The ghost shows the truth of the frame the estimate is drawn in (the sensor's until an estimate says otherwise).
  const auto estimate = estimate_in_segment_frame_.find(seg);
  const bool shown_frame = estimate != estimate_in_segment_frame_.end() && estimate->second;
  if (segment_frame != shown_frame) return std::nullopt;
  if (!due(*slot, now_ns)) return std::nullopt;
  slot->latest = "{\"k\":\"t\",\"seg\":" + json_string(seg) + ",\"ts\":" + std::to_string(t.timestamp_ns()) +
                 ",\"q\":" + quat_json(q) +
                 ",\"flags\":" + std::to_string(segment_frame ? bsn::FLAG_SEGMENT_FRAME : 0u) + "}";
  return slot->latest;
}

std::optional<std::string> ViewState::on_orientation(const bsn::Orientation& o, std::uint64_t now_ns) {
  const std::array<double, 4> q = o.quat();
  if (!finite(q)) {
    ++rejected_non_finite_;
    return std::nullopt;
  }
  const std::string seg = o.segment().substr(0, kMaxNameChars);
  auto* slot = slot_for(orientation_, seg);
  auto* frame = slot_for(estimate_in_segment_frame_, seg);
  if (slot == nullptr || frame == nullptr) {
    ++rejected_too_many_names_;
    return std::nullopt;
  }
  const bool segment_frame = (o.flags() & bsn::FLAG_SEGMENT_FRAME) != 0;
  *frame = segment_frame;
  if (!due(*slot, now_ns)) return std::nullopt;
  // The error to the truth of the same sample in the same frame: an aligned estimate against the true segment
  // frame, a sensor-frame one against the true sensor orientation.
  std::string err = "null";
  const auto& truths = segment_frame ? segment_truth_ : truth_;
  if (auto it = truths.find(seg); it != truths.end()) {
    for (const auto& [ts, tq] : it->second)
      if (ts == o.timestamp_ns()) err = number(rotation_angle_deg(q, tq), 6);
  }
  slot->latest = "{\"k\":\"o\",\"seg\":" + json_string(seg) + ",\"node\":" + name_of(o.node_id()) +
                 ",\"ts\":" + std::to_string(o.timestamp_ns()) + ",\"q\":" + quat_json(q) +
                 ",\"flags\":" + std::to_string(o.flags()) + ",\"err\":" + err + "}";
  return slot->latest;
}

std::optional<std::string> ViewState::on_joint(const bsn::JointAngles& j, std::uint64_t now_ns) {
  const auto& a = j.angles();
  const auto& n = j.anatomical();
  if (!std::all_of(a.begin(), a.end(), [](double v) { return std::isfinite(v); }) ||
      !std::all_of(n.begin(), n.end(), [](double v) { return std::isfinite(v); })) {
    ++rejected_non_finite_;
    return std::nullopt;
  }
  auto* slot = slot_for(joint_, j.joint().substr(0, kMaxNameChars));
  if (slot == nullptr) {
    ++rejected_too_many_names_;
    return std::nullopt;
  }
  if (!due(*slot, now_ns)) return std::nullopt;
  const bool named = !j.anatomy().empty() && j.anatomical_names().size() == 3;
  std::string names = ",\"anatomy\":" + name_of(named ? j.anatomy() : std::string()) +
                      ",\"side\":" + name_of(j.side()) + ",\"names\":[";
  if (named)
    names += name_of(j.anatomical_names()[0]) + "," + name_of(j.anatomical_names()[1]) + "," +
             name_of(j.anatomical_names()[2]);
  names += "]";
  const std::string head = "{\"k\":\"j\",\"joint\":" + name_of(j.joint()) + ",\"parent\":" + name_of(j.parent()) +
                           ",\"child\":" + name_of(j.child()) + ",\"axes\":" + name_of(j.axes()) +
                           ",\"ts\":" + std::to_string(j.timestamp_ns()) + ",\"deg\":[" + number(a[0] * kDeg) + "," +
                           number(a[1] * kDeg) + "," + number(a[2] * kDeg) + "],\"flags\":" + std::to_string(j.flags());
  const std::string tail =
      ",\"anat\":[" + number(n[0] * kDeg) + "," + number(n[1] * kDeg) + "," + number(n[2] * kDeg) + "]}";
  // The names go to the browsers when they change and once a second (a slow browser's queue may drop a message);
  // the snapshot (a new browser's first messages) always has them. They are most of a message's bytes, and 20
  // browsers get every message.
  slot->latest = head + names + tail;
  if (names == slot->names && now_ns < slot->names_due_ns) return head + tail;
  slot->names = std::move(names);
  slot->names_due_ns = now_ns + 1'000'000'000ull;
  return slot->latest;
}

std::optional<std::string> ViewState::on_status(const bsn::Status& s) {
  const std::string process = s.process_id().substr(0, kMaxNameChars);
  auto* slot = slot_for(status_, process);
  if (slot == nullptr) {
    ++rejected_too_many_names_;
    return std::nullopt;
  }
  std::string nodes;
  std::size_t listed = 0;
  for (const auto& n : s.nodes()) {
    if (++listed > kMaxKeys) break;
    const double rate = std::isfinite(n.rate_hz()) ? n.rate_hz() : -1.0;  // -1: the page shows "?"
    if (!nodes.empty()) nodes += ",";
    nodes += "{\"node\":" + name_of(n.node_id()) + ",\"seg\":" + name_of(n.segment()) + ",\"rate\":" + number(rate, 6) +
             ",\"stale\":" + (n.stale() ? "true" : "false") + ",\"calib\":" + name_of(n.last_calibration_id()) + "}";
  }
  *slot = "{\"k\":\"s\",\"process\":" + json_string(process) + ",\"nodes\":[" + nodes + "]}";
  return *slot;
}

std::vector<std::string> ViewState::snapshot() const {
  std::vector<std::string> out;
  for (const auto* map : {&truth_msg_, &orientation_, &joint_})
    for (const auto& [name, slot] : *map)
      if (!slot.latest.empty()) out.push_back(slot.latest);
  for (const auto& [name, msg] : status_) out.push_back(msg);
  return out;
}

}  // namespace bsn::services
