#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <numbers>
#include <optional>
#include <set>

#include "bsn/dds/topics.hpp"
#include "bsn/fusion/anatomy.hpp"
#include "bsn/fusion/rotation.hpp"
#include "export_formats.hpp"
#include "session_streams.hpp"

namespace bsn::services {
namespace {

namespace fs = std::filesystem;

// Rajagopal et al. 2016's body names, as OpenSense's IMU placer finds "<body>_imu" columns: the segments of bsn's
// default lower and upper bodies.
const std::map<std::string, std::string>& default_opensim_bodies() {
  static const std::map<std::string, std::string> m{
      {"pelvis", "pelvis"},         {"thigh_l", "femur_l"},       {"thigh_r", "femur_r"},    {"shank_l", "tibia_l"},
      {"shank_r", "tibia_r"},       {"foot_l", "calcn_l"},        {"foot_r", "calcn_r"},     {"trunk", "torso"},
      {"upper_arm_l", "humerus_l"}, {"upper_arm_r", "humerus_r"}, {"forearm_l", "radius_l"}, {"forearm_r", "radius_r"},
      {"hand_l", "hand_l"},         {"hand_r", "hand_r"}};
  return m;
}

// One alignment result of a node, as recorded.
struct Alignment {
  std::uint64_t arrival_ns = 0;
  std::string request_id;
  fusion::Quat sensor_to_segment = fusion::Quat::Identity();
};

// Every successful sensor-to-segment alignment of the session, per node, in the order they arrived.
std::map<std::string, std::vector<Alignment>> recorded_alignments(const io::SessionReader& r) {
  std::map<std::string, std::vector<Alignment>> out;
  for (const auto& s : r.streams_of(dds::kCalibrationResultTopic.name)) {
    const auto arrival = r.read_u64(s, "arrival_ns");
    const auto results = read_stream_samples<bsn::CalibrationResultPubSubType>(r, s);
    for (std::size_t i = 0; i < results.size(); ++i) {
      const auto& c = results[i];
      if (c.kind() != bsn::CALIBRATION_SEGMENT_ALIGNMENT || !c.success()) continue;
      const auto& w = c.sensor_to_segment();
      const fusion::Quat q(w[0], w[1], w[2], w[3]);
      if (!std::isfinite(q.norm()) || std::abs(q.norm() - 1.0) > 1e-6) continue;
      out[c.node_id()].push_back({i < arrival.size() ? arrival[i] : 0, c.request_id(), q.normalized()});
    }
  }
  for (auto& [node, list] : out)
    std::stable_sort(list.begin(), list.end(),
                     [](const auto& a, const auto& b) { return a.arrival_ns < b.arrival_ns; });
  return out;
}

// The alignment of a sample that arrived at `arrival_ns`: the latest before it, or (a sample recorded before the
// first alignment) the first one: a mounting does not change while the sensor stays strapped on.
const Alignment* alignment_at(const std::vector<Alignment>* list, std::uint64_t arrival_ns) {
  if (list == nullptr || list->empty()) return nullptr;
  const Alignment* best = &list->front();
  for (const Alignment& a : *list)
    if (a.arrival_ns <= arrival_ns) best = &a;
  return best;
}

// A column of an OpenSim table: its sensor times and values.
struct Track {
  std::vector<std::uint64_t> ts;
  std::vector<std::vector<double>> values;
};

// The rows of a table of tracks: they follow the track with the most samples; the others are held at their latest
// sample at or before each row's time, and rows before every track has one are left out. Per row: its time and the
// sample index of every track.
// `clock`, when given, sets the row times instead (the truth's files take the estimates' rows, so that the two line
// up row by row, with the samples of the same instants).
std::vector<std::pair<std::uint64_t, std::vector<std::size_t>>> table_rows(
    const std::vector<const Track*>& tracks, const std::vector<std::uint64_t>* clock = nullptr) {
  std::vector<std::pair<std::uint64_t, std::vector<std::size_t>>> out;
  if (tracks.empty()) return out;
  if (clock == nullptr) {
    clock = &(*std::max_element(tracks.begin(), tracks.end(), [](const Track* a, const Track* b) {
               return a->ts.size() < b->ts.size();
             }))->ts;
  }
  std::vector<std::size_t> at(tracks.size(), 0);
  for (const std::uint64_t t : *clock) {
    bool complete = true;
    for (std::size_t c = 0; c < tracks.size(); ++c) {
      const Track& track = *tracks[c];
      std::size_t& k = at[c];
      while (k + 1 < track.ts.size() && track.ts[k + 1] <= t) ++k;
      if (track.ts.empty() || track.ts[k] > t) complete = false;
    }
    if (complete) out.emplace_back(t, at);
  }
  return out;
}

struct Window {
  std::uint64_t t0 = 0;  ///< sensor time of time 0: the session's first complete row of estimates
  double from_s = 0.0, to_s = 1e300;
  bool keeps(std::uint64_t t) const {
    const double s = seconds(t);
    return s >= from_s - 1e-9 && s <= to_s + 1e-9;
  }
  double seconds(std::uint64_t t) const {
    return t >= t0 ? static_cast<double>(t - t0) * 1e-9 : -static_cast<double>(t0 - t) * 1e-9;
  }
};

// Orientation tracks of one topic in the export's frames, and what the header says of each column.
struct OrientationTable {
  std::map<std::string, Track> tracks;          ///< by segment
  std::map<std::string, std::string> mounting;  ///< by segment: how its samples got into the file's frames
};

// The orientations of `topic` in the file's frames (segment or sensor). Segment frames: a sample in its sensor frame
// is turned by its node's recorded alignment (the latest before it, else the first: also samples recorded before
// the alignment arrived), or by the default mounting where the node was never aligned. Sensor frames: a sample in
// its segment frame is turned back by the alignment in effect. Throws if a sample cannot be brought into the frame.
OrientationTable orientation_table(const io::SessionReader& r, const std::string& topic, bool segment_frames,
                                   const std::map<std::string, std::vector<Alignment>>& alignments) {
  OrientationTable out;
  for (const auto& s : r.streams_of(topic)) {
    const auto arrival = r.read_u64(s, "arrival_ns");
    const auto samples = read_stream_samples<bsn::OrientationPubSubType>(r, s);
    Track& t = out.tracks[s.key];
    std::set<std::string> how;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const auto& o = samples[i];
      const auto& w = o.quat();
      fusion::Quat q(w[0], w[1], w[2], w[3]);
      if (!std::isfinite(q.norm()) || q.norm() < 0.5) continue;  // never a NaN into a file
      q.normalize();
      const bool in_segment_frame = (o.flags() & bsn::FLAG_SEGMENT_FRAME) != 0;
      const auto list = alignments.find(o.node_id());
      const Alignment* a =
          alignment_at(list == alignments.end() ? nullptr : &list->second, i < arrival.size() ? arrival[i] : 0);
      if (segment_frames && !in_segment_frame) {
        if (a != nullptr) {
          q = fusion::segment_orientation(q, a->sensor_to_segment);
          how.insert("aligned " + a->request_id);
        } else {
          q = fusion::segment_orientation(q, fusion::default_sensor_to_segment());
          how.insert("default mounting");
        }
      } else if (!segment_frames && in_segment_frame) {
        if (a == nullptr) {
          throw io::IoError(r.path() + ": segment '" + s.key +
                            "' is in its segment frame by a mounting the session holds no alignment result of (the "
                            "body file's sensor_axes or sensor_to_segment?): --frames sensor cannot undo it");
        }
        q = q * a->sensor_to_segment;
        how.insert("aligned " + a->request_id);
      } else if (in_segment_frame) {
        how.insert(a != nullptr ? "aligned " + a->request_id : "segment frame as recorded");
      } else {
        how.insert(a != nullptr ? "aligned " + a->request_id : "sensor frame as recorded");
      }
      q = fusion::canonical(q);
      t.ts.push_back(o.timestamp_ns());
      t.values.push_back({q.w(), q.x(), q.y(), q.z()});
    }
    std::string text;
    for (const auto& h : how) text += (text.empty() ? "" : "; ") + h;
    out.mounting[s.key] = text;
  }
  return out;
}

// `name` of a segment in OpenSim: an override, else Rajagopal's body name, else the segment's own name.
std::string opensim_body(const std::string& segment, const std::map<std::string, std::string>& overrides) {
  if (auto it = overrides.find(segment); it != overrides.end()) return it->second;
  if (auto it = default_opensim_bodies().find(segment); it != default_opensim_bodies().end()) return it->second;
  return segment;
}

// Writes an OpenSense orientation file: OpenSim's header (DataRate, DataType=Quaternion, version=3,
// OpenSimVersion, bsn's own keys, endheader), then a time column and per segment "<body>_imu" with "w,x,y,z".
// `only_row` >= 0 writes that one row (the IMU placer's calibration input). Returns the rows written.
std::size_t write_orientation_sto(const fs::path& path, const OrientationTable& table, const Window& window,
                                  bool opensim_frame, const std::string& frames,
                                  const std::map<std::string, std::string>& names, double only_row_s,
                                  const std::vector<std::uint64_t>* clock,
                                  std::vector<std::uint64_t>* row_times = nullptr) {
  std::vector<const Track*> tracks;
  for (const auto& [segment, track] : table.tracks) tracks.push_back(&track);
  auto rows = table_rows(tracks, clock);
  std::erase_if(rows, [&](const auto& row) { return !window.keeps(row.first); });
  if (only_row_s >= 0.0 && !rows.empty()) {
    auto it = std::find_if(rows.begin(), rows.end(),
                           [&](const auto& row) { return window.seconds(row.first) >= only_row_s - 1e-9; });
    if (it == rows.end()) --it;
    rows = {*it};
  }
  if (row_times != nullptr)
    for (const auto& row : rows) row_times->push_back(row.first);
  if (rows.empty()) return 0;
  // ENU (z up) to OpenSim's ground (y up): -90 degrees about x, so up -> +Y, east -> +X, north -> -Z.
  const fusion::Quat to_opensim(std::cos(-std::numbers::pi / 4), std::sin(-std::numbers::pi / 4), 0.0, 0.0);
  const double duration = window.seconds(rows.back().first) - window.seconds(rows.front().first);
  const double rate = rows.size() > 1 && duration > 0 ? static_cast<double>(rows.size() - 1) / duration : 0.0;
  std::ofstream f(path);
  f << "DataRate=" << std::to_string(rate) << "\nDataType=Quaternion\nversion=3\nOpenSimVersion=4.5\n";
  // bsn's keys (OpenSim keeps unknown header keys as metadata): which frames the whole file is in, and per column
  // how its samples got there.
  f << "bsn_frames=" << frames << "\nbsn_ground=" << (opensim_frame ? "opensim_y_up" : "enu_z_up")
    << "\nbsn_time_zero_ns=" << window.t0 << "\n";
  for (const auto& [segment, how] : table.mounting)
    if (table.tracks.count(segment)) f << "bsn_mounting_" << segment << "=" << how << "\n";
  f << "endheader\ntime";
  for (const auto& [segment, track] : table.tracks) f << "\t" << opensim_body(segment, names) << "_imu";
  f << "\n";
  for (const auto& [t, at] : rows) {
    char cell[128];
    std::snprintf(cell, sizeof cell, "%.6f", window.seconds(t));
    f << cell;
    for (std::size_t c = 0; c < tracks.size(); ++c) {
      const auto& v = tracks[c]->values[at[c]];
      fusion::Quat q(v[0], v[1], v[2], v[3]);
      if (opensim_frame) q = to_opensim * q;
      std::snprintf(cell, sizeof cell, "\t%.12f,%.12f,%.12f,%.12f", q.w(), q.x(), q.y(), q.z());
      f << cell;
    }
    f << "\n";
  }
  if (!f) throw io::IoError(path.string() + ": cannot write");
  return rows.size();
}

// The latest sample of `track` at or before `t` (nullptr if none).
const std::vector<double>* sample_at(const Track& track, std::uint64_t t) {
  const auto it = std::upper_bound(track.ts.begin(), track.ts.end(), t);
  if (it == track.ts.begin()) return nullptr;
  return &track.values[static_cast<std::size_t>(it - track.ts.begin() - 1)];
}

// Writes the named anatomical angles of `topic` as an OpenSim motion file (.mot, degrees): per joint with an
// anatomy, one column "<joint>_<angle name>" per angle. A sample that fusion computed on the default mounting (no
// FLAG_SEGMENT_FRAME: before the alignment arrived) is computed again from `segments`, the segment-frame
// orientations of the export (the alignment applied to them), so the whole file is of aligned segment frames.
// Returns the rows written.
std::size_t write_joint_mot(const io::SessionReader& r, const std::string& topic, const fs::path& path,
                            const Window& window, const OrientationTable* segments,
                            const std::vector<std::uint64_t>* clock, std::vector<std::uint64_t>* row_times) {
  std::map<std::string, Track> tracks;
  std::map<std::string, std::array<std::string, 3>> names;
  std::size_t recomputed = 0;
  for (const auto& s : r.streams_of(topic)) {
    const auto samples = read_stream_samples<bsn::JointAnglesPubSubType>(r, s);
    for (const auto& j : samples) {
      if (j.anatomy().empty() || j.anatomical_names().size() != 3) continue;
      std::array<double, 3> a = j.anatomical();
      if (segments != nullptr && (j.flags() & bsn::FLAG_SEGMENT_FRAME) == 0) {
        const auto parent = segments->tracks.find(j.parent());
        const auto child = segments->tracks.find(j.child());
        const auto type = fusion::parse_joint_type(j.anatomy());
        const auto side =
            j.side().empty() ? std::optional(fusion::BodySide::kMidline) : fusion::parse_body_side(j.side());
        if (parent == segments->tracks.end() || child == segments->tracks.end() || !type || !side) continue;
        const auto* qp = sample_at(parent->second, j.timestamp_ns());
        const auto* qc = sample_at(child->second, j.timestamp_ns());
        if (qp == nullptr || qc == nullptr) continue;
        const fusion::Quat p((*qp)[0], (*qp)[1], (*qp)[2], (*qp)[3]), c((*qc)[0], (*qc)[1], (*qc)[2], (*qc)[3]);
        const fusion::Vec3 v = fusion::anatomical_angles(p.conjugate() * c, fusion::JointConvention{*type, *side});
        a = {v.x(), v.y(), v.z()};
        ++recomputed;
      }
      if (!std::all_of(a.begin(), a.end(), [](double v) { return std::isfinite(v); })) continue;
      Track& t = tracks[s.key];
      if (t.ts.empty()) names[s.key] = {j.anatomical_names()[0], j.anatomical_names()[1], j.anatomical_names()[2]};
      constexpr double kDeg = 180.0 / std::numbers::pi;
      t.ts.push_back(j.timestamp_ns());
      t.values.push_back({a[0] * kDeg, a[1] * kDeg, a[2] * kDeg});
    }
  }
  std::vector<const Track*> list;
  for (const auto& [joint, track] : tracks) list.push_back(&track);
  auto rows = table_rows(list, clock);
  std::erase_if(rows, [&](const auto& row) { return !window.keeps(row.first); });
  if (row_times != nullptr)
    for (const auto& row : rows) row_times->push_back(row.first);
  if (rows.empty()) return 0;
  std::ofstream f(path);
  // OpenSim's motion-file header (Storage version 1): name, version, rows, columns, degrees, then bsn's keys.
  f << path.stem().string() << "\nversion=1\nnRows=" << rows.size() << "\nnColumns=" << 1 + 3 * list.size()
    << "\ninDegrees=yes\nbsn_frames=segment\nbsn_time_zero_ns=" << window.t0
    << "\nbsn_recomputed_samples=" << recomputed << "\nendheader\ntime";
  for (const auto& [joint, track] : tracks)
    for (const auto& n : names[joint]) f << "\t" << joint << "_" << n;
  f << "\n";
  for (const auto& [t, at] : rows) {
    char cell[64];
    std::snprintf(cell, sizeof cell, "%.6f", window.seconds(t));
    f << cell;
    for (std::size_t c = 0; c < list.size(); ++c)
      for (const double v : list[c]->values[at[c]]) {
        std::snprintf(cell, sizeof cell, "\t%.9f", v);
        f << cell;
      }
    f << "\n";
  }
  if (!f) throw io::IoError(path.string() + ": cannot write");
  return rows.size();
}

// The alignment results the sensor-frame files go with: one line per segment.
void write_alignment_csv(const fs::path& path, const OrientationTable& table, const io::SessionReader& r,
                         const std::map<std::string, std::vector<Alignment>>& alignments) {
  std::map<std::string, std::string> node_of;
  for (const auto& s : r.streams_of(dds::kOrientationTopic.name)) {
    const auto samples = read_stream_samples<bsn::OrientationPubSubType>(r, s);
    if (!samples.empty()) node_of[s.key] = samples.back().node_id();
  }
  std::ofstream f(path);
  f << "segment,node_id,request_id,sensor_to_segment_w,sensor_to_segment_x,sensor_to_segment_y,sensor_to_segment_z\n";
  for (const auto& [segment, track] : table.tracks) {
    const auto node = node_of.count(segment) ? node_of.at(segment) : segment;
    const auto list = alignments.find(node);
    if (list == alignments.end() || list->second.empty()) continue;
    const Alignment& a = list->second.back();
    char q[160];
    std::snprintf(q, sizeof q, "%.12f,%.12f,%.12f,%.12f", a.sensor_to_segment.w(), a.sensor_to_segment.x(),
                  a.sensor_to_segment.y(), a.sensor_to_segment.z());
    f << segment << "," << node << "," << a.request_id << "," << q << "\n";
  }
  if (!f) throw io::IoError(path.string() + ": cannot write");
}

}  // namespace

int export_sto(const io::SessionReader& r, const fs::path& out, const ExportOptions& opt) {
  const bool opensim_frame = opt.frame == "opensim";
  const bool segment_frames = opt.frames == "segment";
  std::map<std::string, std::string> names;
  for (const auto& m : opt.opensim_names) {
    const auto eq = m.find('=');
    names[m.substr(0, eq)] = m.substr(eq + 1);
  }
  const auto alignments = recorded_alignments(r);
  const OrientationTable estimates = orientation_table(r, dds::kOrientationTopic.name, segment_frames, alignments);
  // The truth of the same frames: the true segment frames, or the sensors'.
  const OrientationTable truth =
      orientation_table(r, segment_frames ? dds::kTruthSegmentOrientationTopic.name : dds::kTruthOrientationTopic.name,
                        segment_frames, {});
  if (segment_frames && truth.tracks.empty() && !r.streams_of(dds::kTruthOrientationTopic.name).empty()) {
    std::fprintf(stderr,
                 "bsn export: the session has the truth in sensor frames only (no %s): no truth_orientations.sto in "
                 "segment frames; --frames sensor exports it\n",
                 dds::kTruthSegmentOrientationTopic.name);
  }
  // Time 0 of every file: the first complete row of the estimates (else of the truth), so the files line up.
  Window window{0, opt.from_s, opt.to_s};
  for (const OrientationTable* t : {&estimates, &truth}) {
    std::vector<const Track*> tracks;
    for (const auto& [segment, track] : t->tracks) tracks.push_back(&track);
    const auto rows = table_rows(tracks);
    if (!rows.empty()) {
      window.t0 = rows.front().first;
      break;
    }
  }
  int files = 0;
  const double calibration_at = opt.calibration_at_s >= 0.0 ? opt.calibration_at_s : opt.from_s;
  // The truth's files take the estimates' row times (when there are estimates): row k of both is one instant.
  std::vector<std::uint64_t> rows;
  if (write_orientation_sto(out / "orientations.sto", estimates, window, opensim_frame, opt.frames, names, -1.0,
                            nullptr, &rows) > 0) {
    ++files;
    write_orientation_sto(out / "calibration.sto", estimates, window, opensim_frame, opt.frames, names, calibration_at,
                          nullptr);
    ++files;
    if (!segment_frames) {
      write_alignment_csv(out / "alignment.csv", estimates, r, alignments);
      ++files;
    }
  }
  const std::vector<std::uint64_t>* clock = rows.empty() ? nullptr : &rows;
  if (write_orientation_sto(out / "truth_orientations.sto", truth, window, opensim_frame, opt.frames, names, -1.0,
                            clock) > 0) {
    ++files;
    write_orientation_sto(out / "truth_calibration.sto", truth, window, opensim_frame, opt.frames, names,
                          calibration_at, clock);
    ++files;
  }
  // Joint angles are of segment frames whatever --frames says (they are anatomical angles).
  const OrientationTable segment_table =
      segment_frames ? OrientationTable{} : orientation_table(r, dds::kOrientationTopic.name, true, alignments);
  std::vector<std::uint64_t> joint_rows;
  if (write_joint_mot(r, dds::kJointAnglesTopic.name, out / "joint_angles.mot", window,
                      segment_frames ? &estimates : &segment_table, nullptr, &joint_rows) > 0)
    ++files;
  if (write_joint_mot(r, dds::kTruthJointAnglesTopic.name, out / "truth_joint_angles.mot", window, nullptr,
                      joint_rows.empty() ? nullptr : &joint_rows, nullptr) > 0)
    ++files;
  return files;
}

}  // namespace bsn::services
