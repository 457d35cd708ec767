// A recorded session with a live alignment in the middle (`bsn demo`: the body's sensors strapped on at random, the
// N-pose and flexions, the calibration service's alignment, then walking), exported to OpenSim files: every file is
// in one frame from its first row to its last, estimate and truth agree before and after the alignment instant, and
// the CSV's named anatomical angle columns are those of bsn/joint_angles.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <numbers>
#include <sstream>

#include "bsn/fusion/rotation.hpp"
#include "bsn/io/session_file.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;
constexpr double kDeg = 180.0 / std::numbers::pi;

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string cell;
  std::istringstream in(s);
  while (std::getline(in, cell, sep)) out.push_back(cell);
  return out;
}

/// An OpenSim table (.sto or .mot): header keys, column labels, rows of cells after the time column.
struct Table {
  std::map<std::string, std::string> header;
  std::vector<std::string> labels;  ///< without "time"
  std::vector<double> time;
  std::vector<std::vector<std::string>> cells;
  std::size_t column(const std::string& label) const {
    const auto it = std::find(labels.begin(), labels.end(), label);
    return it == labels.end() ? labels.size() : static_cast<std::size_t>(it - labels.begin());
  }
};

Table read_table(const std::filesystem::path& path) {
  Table t;
  std::istringstream in(read_file(path));
  std::string line;
  while (std::getline(in, line) && line != "endheader") {
    const auto eq = line.find('=');
    if (eq != std::string::npos) t.header[line.substr(0, eq)] = line.substr(eq + 1);
  }
  if (std::getline(in, line)) {
    t.labels = split(line, '\t');
    if (!t.labels.empty()) t.labels.erase(t.labels.begin());
  }
  while (std::getline(in, line)) {
    auto c = split(line, '\t');
    if (c.size() != t.labels.size() + 1) continue;
    t.time.push_back(std::stod(c[0]));
    c.erase(c.begin());
    t.cells.push_back(std::move(c));
  }
  return t;
}

fusion::Quat quat_of(const std::string& cell) {
  const auto v = split(cell, ',');
  return v.size() == 4 ? fusion::Quat(std::stod(v[0]), std::stod(v[1]), std::stod(v[2]), std::stod(v[3]))
                       : fusion::Quat(std::nan(""), 0, 0, 0);
}

double angle_deg(const fusion::Quat& a, const fusion::Quat& b) {
  const fusion::Quat d = a.conjugate() * b;
  return 2.0 * std::atan2(d.vec().norm(), std::abs(d.w())) * kDeg;
}

// The default lower body's segments and their OpenSim (Rajagopal) bodies.
const std::map<std::string, std::string> kOpenSimBody{
    {"pelvis", "pelvis"},   {"thigh_l", "femur_l"}, {"shank_l", "tibia_l"}, {"foot_l", "calcn_l"},
    {"thigh_r", "femur_r"}, {"shank_r", "tibia_r"}, {"foot_r", "calcn_r"}};

class AlignedSession : public ProcessTest {
 protected:
  // Records the demo's aligned walking body for 27 s (the alignment arrives after about 18 s) into session.h5.
  std::string record_demo(int domain_offset) {
    const std::string domain = std::to_string(test_domain(domain_offset));
    const std::string out = (dir() / "session.h5").string();
    spawn("record", {"record", "--out", out, "--duration", "27", "--domain", domain});
    spawn("demo", {"demo", "--duration", "26", "--domain", domain});
    EXPECT_EQ(exit_code(child("record").wait_for(60s)), 0) << tail(log_path("record"));
    EXPECT_TRUE(exited_cleanly(child("demo").wait_for(60s))) << tail(log_path("demo"));
    return out;
  }
};

TEST_F(AlignedSession, StoAndMotAreInSegmentFramesBeforeAndAfterTheLiveAlignment) {
  const std::string session = record_demo(93);
  const auto out = dir() / "sto";
  spawn("export", {"export", session, "--format", "sto", "--out", out.string()});
  ASSERT_EQ(exit_code(child("export").wait_for(60s)), 0) << read_file(log_path("export"));

  const Table est = read_table(out / "orientations.sto");
  const Table truth = read_table(out / "truth_orientations.sto");
  EXPECT_EQ(est.header.at("bsn_frames"), "segment");
  EXPECT_EQ(truth.header.at("bsn_frames"), "segment");
  ASSERT_EQ(est.header.at("bsn_time_zero_ns"), truth.header.at("bsn_time_zero_ns"));
  const auto t0_ns = std::stoull(est.header.at("bsn_time_zero_ns"));
  for (const auto& [segment, body] : kOpenSimBody) {
    EXPECT_LT(est.column(body + "_imu"), est.labels.size()) << body;
    EXPECT_LT(truth.column(body + "_imu"), truth.labels.size()) << body;
  }
  const Table calibration = read_table(out / "calibration.sto");
  EXPECT_EQ(calibration.time.size(), 1u) << "the IMU placer's input is one row";
  EXPECT_EQ(calibration.labels, est.labels);

  // The session's own record: when each segment's estimates turned to the segment frame (the alignment instant) and
  // the gyro rates of its node.
  const io::SessionReader r(session);
  std::map<std::string, double> aligned_at_s;
  for (const auto& s : r.streams_of("bsn/orientation")) {
    const auto ts = r.read_u64(s, "timestamp_ns");
    const auto flags = r.read_u32(s, "flags");
    for (std::size_t i = 0; i < std::min(ts.size(), flags.size()); ++i)
      if (flags[i] & 32u) {  // FLAG_SEGMENT_FRAME
        aligned_at_s[s.key] = (static_cast<double>(ts[i]) - static_cast<double>(t0_ns)) * 1e-9;
        break;
      }
  }
  std::map<std::string, std::vector<std::pair<double, double>>> rate_of;  // node -> (s, |gyr| rad/s)
  for (const auto& s : r.streams_of("bsn/raw")) {
    const auto ts = r.read_u64(s, "timestamp_ns");
    const auto g = r.read_f64(s, "gyr", 3);
    for (std::size_t i = 0; i < std::min(ts.size(), g.size() / 3); ++i)
      rate_of[s.key].emplace_back((static_cast<double>(ts[i]) - static_cast<double>(t0_ns)) * 1e-9,
                                  std::hypot(g[3 * i], g[3 * i + 1], g[3 * i + 2]));
  }
  ASSERT_EQ(aligned_at_s.size(), kOpenSimBody.size()) << "every segment aligned live during the recording";
  ASSERT_FALSE(est.time.empty());
  for (const auto& [segment, at] : aligned_at_s) {
    EXPECT_GT(at - est.time.front(), 10.0) << segment << ": the file holds the time before the alignment";
    EXPECT_GT(est.time.back() - at, 4.0) << segment << ": and after it";
  }

  // No row-to-row jump beyond what the motion explains: the turn between two rows is at most the largest recorded
  // angular rate of the node around them times the rows' interval plus one sample period (a row holds a segment's
  // latest sample), plus 1 degree for the filter's own correction in that step (its gain is about ts / 1.4 tau:
  // 0.4 % of an error of a few degrees per sample).
  for (const auto& [segment, body] : kOpenSimBody) {
    const std::size_t c = est.column(body + "_imu");
    const auto& rates = rate_of[segment];
    ASSERT_FALSE(rates.empty()) << segment;
    double worst_excess = -1e9;
    std::string worst;
    for (std::size_t k = 1; k < est.time.size(); ++k) {
      const double a = est.time[k - 1], b = est.time[k];
      double w = 0.0;
      for (const auto& [t, rate] : rates)
        if (t >= a - 0.05 && t <= b + 0.05) w = std::max(w, rate);
      const double jump = angle_deg(quat_of(est.cells[k - 1][c]), quat_of(est.cells[k][c]));
      const double bound = w * kDeg * (b - a + 0.01) + 1.0;
      if (jump - bound > worst_excess) {
        worst_excess = jump - bound;
        worst = "at " + std::to_string(b) + " s: " + std::to_string(jump) + " deg against " + std::to_string(bound);
      }
    }
    EXPECT_LE(worst_excess, 0.0) << segment << " " << worst << " (aligned at " << aligned_at_s[segment] << " s)";
  }

  // Estimate against truth, row by row of the same time, before and after the alignment instant: within 5 degrees
  // RMS, the alignment's own bound per segment (SegmentAlignment.GaitAnglesFollowTheTruthAfterTheAlignmentOnly).
  // The first 3 s are the filters' start (FLAG_INITIALISING).
  std::map<std::string, std::size_t> truth_row;
  for (std::size_t k = 0; k < truth.time.size(); ++k) truth_row[std::to_string(truth.time[k])] = k;
  for (const auto& [segment, body] : kOpenSimBody) {
    const std::size_t ce = est.column(body + "_imu"), ct = truth.column(body + "_imu");
    double sum[2] = {0, 0};
    int n[2] = {0, 0};
    for (std::size_t k = 0; k < est.time.size(); ++k) {
      if (est.time[k] < 3.0) continue;
      const auto it = truth_row.find(std::to_string(est.time[k]));
      if (it == truth_row.end()) continue;
      const double e = angle_deg(quat_of(est.cells[k][ce]), quat_of(truth.cells[it->second][ct]));
      const int after = est.time[k] >= aligned_at_s[segment] ? 1 : 0;
      sum[after] += e * e;
      ++n[after];
    }
    ASSERT_GT(n[0], 500) << segment << ": rows before the alignment";
    ASSERT_GT(n[1], 300) << segment << ": rows after the alignment";
    EXPECT_LT(std::sqrt(sum[0] / n[0]), 5.0) << segment << " before the alignment";
    EXPECT_LT(std::sqrt(sum[1] / n[1]), 5.0) << segment << " after the alignment";
  }

  // Joint angles (.mot, named anatomical angles in degrees) against the truth's, before and after: the bounds of
  // the alignment's joint-angle test (knee flexion 2 deg, hip flexion and adduction 3 deg, ankle dorsiflexion 3 deg
  // RMS).
  const Table mot = read_table(out / "joint_angles.mot");
  const Table truth_mot = read_table(out / "truth_joint_angles.mot");
  EXPECT_EQ(mot.header.at("inDegrees"), "yes");
  std::map<std::string, std::size_t> truth_mot_row;
  for (std::size_t k = 0; k < truth_mot.time.size(); ++k) truth_mot_row[std::to_string(truth_mot.time[k])] = k;
  const std::map<std::string, double> bounds{{"knee_l_flexion_extension", 2.0},
                                             {"knee_r_flexion_extension", 2.0},
                                             {"hip_l_flexion_extension", 3.0},
                                             {"hip_r_flexion_extension", 3.0},
                                             {"hip_l_adduction_abduction", 3.0},
                                             {"hip_r_adduction_abduction", 3.0},
                                             {"ankle_l_dorsiflexion_plantarflexion", 3.0},
                                             {"ankle_r_dorsiflexion_plantarflexion", 3.0}};
  for (const auto& [label, bound] : bounds) {
    const std::size_t ce = mot.column(label), ct = truth_mot.column(label);
    ASSERT_LT(ce, mot.labels.size()) << label;
    ASSERT_LT(ct, truth_mot.labels.size()) << label;
    const std::string segment = label.rfind("knee", 0) == 0  ? "shank_"
                                : label.rfind("hip", 0) == 0 ? "thigh_"
                                                             : "foot_";
    const double at = aligned_at_s[segment + label.substr(label.find('_') + 1, 1)];
    double sum[2] = {0, 0};
    int n[2] = {0, 0};
    for (std::size_t k = 0; k < mot.time.size(); ++k) {
      if (mot.time[k] < 3.0) continue;
      const auto it = truth_mot_row.find(std::to_string(mot.time[k]));
      if (it == truth_mot_row.end()) continue;
      const double e = std::stod(mot.cells[k][ce]) - std::stod(truth_mot.cells[it->second][ct]);
      const int after = mot.time[k] >= at ? 1 : 0;
      sum[after] += e * e;
      ++n[after];
    }
    ASSERT_GT(n[0], 500) << label;
    ASSERT_GT(n[1], 300) << label;
    EXPECT_LT(std::sqrt(sum[0] / n[0]), bound) << label << " before the alignment";
    EXPECT_LT(std::sqrt(sum[1] / n[1]), bound) << label << " after the alignment";
  }

  // CSV: one file per joint, its columns named by the joint's anatomical angles and the axis-sequence angles by
  // their axes in rotation order; the values those of bsn/joint_angles as recorded (within 0.01 degree).
  const auto csv_dir = dir() / "csv";
  spawn("csv", {"export", session, "--format", "csv", "--out", csv_dir.string()});
  ASSERT_EQ(exit_code(child("csv").wait_for(60s)), 0) << read_file(log_path("csv"));
  std::istringstream csv(read_file(csv_dir / "joint_angles_knee_l.csv"));
  std::string line;
  ASSERT_TRUE(std::getline(csv, line));
  const auto header = split(line, ',');
  const auto column = [&](const std::string& name) {
    return static_cast<std::size_t>(std::find(header.begin(), header.end(), name) - header.begin());
  };
  const std::size_t flexion = column("flexion_extension [rad]"), adduction = column("adduction_abduction [rad]"),
                    rotation = column("internal_external_rotation [rad]"), first = column("angle_1_z [rad]");
  ASSERT_LT(std::max({flexion, adduction, rotation, first}), header.size()) << line;
  const auto streams = r.streams_of("bsn/joint_angles");
  const auto knee = std::find_if(streams.begin(), streams.end(), [](const auto& s) { return s.key == "knee_l"; });
  ASSERT_NE(knee, streams.end());
  const auto recorded = r.read_f64(*knee, "anatomical_0", 1);
  std::size_t rows = 0;
  for (; std::getline(csv, line); ++rows) {
    const auto cells = split(line, ',');
    ASSERT_EQ(cells.size(), header.size()) << line;
    ASSERT_LT(rows, recorded.size());
    EXPECT_NEAR(std::stod(cells[flexion]) * kDeg, recorded[rows] * kDeg, 0.01) << "row " << rows;
  }
  EXPECT_EQ(rows, recorded.size());
}

}  // namespace
}  // namespace bsn::integration
