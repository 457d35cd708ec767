// `bsn process` on real files and against real processes: a session recorded live (bsn replay -> bsn fusion, both
// recorded by bsn record) processed offline gives the joint angles the live fusion published; the same input gives
// the same bytes; a folder of per-node recordings gives the simulator's motion; bad inputs are usage errors.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <numbers>
#include <thread>
#include <tuple>

#include "bsn/fusion/body_fusion.hpp"
#include "bsn/io/session_file.hpp"
#include "bsn/sim/scenario.hpp"
#include "bsn/sim/scenario_file.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;

// A leg of the simulator's walking lower body, the knee with the kinematic heading (its estimator state counts too).
constexpr const char* kLegBody = R"(name: leg
segments:
  - name: pelvis
  - name: thigh_l
    parent: pelvis
    joint: hip_l
  - name: shank_l
    parent: thigh_l
    joint: knee_l
    heading: kinematic
)";

constexpr const char* kWalk = R"(name: walk
description: "12 s of walking, consumer MEMS with calibrated magnetometers"
duration_s: 12
rate_hz: 100
seed: 3
sensors:
  preset: consumer_mems
  mag: {hard_iron: [0, 0, 0], soft_iron: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}
body:
  kind: lower_body
  pose: {position_m: [0, 0, 0.95]}
  gait: {cadence_steps_per_min: 110, speed_m_s: 1.2, heading_deg: 90}
)";

// Every joint sample of a session: (joint, timestamp) -> quat, angles, anatomical angles, flags.
struct JointRow {
  std::array<double, 4> quat{};
  std::array<double, 3> angles{}, anatomical{};
  std::uint32_t flags = 0;
};
std::map<std::pair<std::string, std::uint64_t>, JointRow> joint_rows(const std::string& path) {
  const io::SessionReader r(path);
  std::map<std::pair<std::string, std::uint64_t>, JointRow> rows;
  for (const auto& s : r.streams_of("bsn/joint_angles")) {
    const auto ts = r.read_u64(s, "timestamp_ns");
    const auto q = r.read_f64(s, "quat", 4);
    const auto a = r.read_f64(s, "angles", 3);
    const auto flags = r.read_u32(s, "flags");
    std::array<std::vector<double>, 3> anat;
    for (int k = 0; k < 3; ++k) anat[k] = r.read_f64(s, "anatomical_" + std::to_string(k), 1);
    for (std::size_t i = 0; i < ts.size(); ++i) {
      JointRow row;
      for (int k = 0; k < 4; ++k) row.quat[k] = q[4 * i + k];
      for (int k = 0; k < 3; ++k) row.angles[k] = a[3 * i + k];
      for (int k = 0; k < 3; ++k) row.anatomical[k] = anat[k][i];
      row.flags = flags[i];
      rows[{s.key, ts[i]}] = row;
    }
  }
  return rows;
}

class Process : public ProcessTest {
 protected:
  int run(const std::string& name, const std::vector<std::string>& args) {
    const auto status = spawn(name, args).wait_for(60s);
    EXPECT_TRUE(status.has_value()) << "bsn " << name << " did not exit within 60 s";
    return exit_code(status);
  }
  std::string output(const std::string& name) { return read_file(log_path(name)); }

  /// The walk, simulated to <dir>/lab/<segment>.hdf5.
  void simulate() {
    write_file(dir() / "walk.yaml", kWalk);
    write_file(dir() / "leg.yaml", kLegBody);
    ASSERT_EQ(run("sim", {"sim", "--scenario", (dir() / "walk.yaml").string(), "--out", (dir() / "lab").string()}), 0)
        << output("sim");
  }
};

TEST_F(Process, OfflineGivesTheJointAnglesTheLiveFusionPublished) {
  // One code path (FusionPipeline): the same raw samples in the same order through the same body give the same
  // numbers. The live order is what one writer (bsn replay) sent, in order, to both the fusion and the recorder;
  // bsn/raw is RELIABLE and KEEP_ALL here (an XML profile for every process), so neither loses a sample, and
  // `bsn process --order arrival` runs the recorded samples in the order the recorder (and so the fusion) got them.
  simulate();
  write_file(dir() / "lossless.xml", R"(<?xml version="1.0" encoding="UTF-8"?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <data_writer profile_name="bsn/raw">
    <topic><historyQos><kind>KEEP_ALL</kind></historyQos></topic>
    <qos><reliability><kind>RELIABLE</kind></reliability></qos>
  </data_writer>
  <data_reader profile_name="bsn/raw">
    <topic><historyQos><kind>KEEP_ALL</kind></historyQos></topic>
    <qos><reliability><kind>RELIABLE</kind></reliability></qos>
  </data_reader>
</profiles>
)");
  const std::string domain = std::to_string(test_domain(88));
  const std::string profile = (dir() / "lossless.xml").string();
  const std::string live = (dir() / "live.h5").string(), offline = (dir() / "offline.h5").string();
  const std::string body = (dir() / "leg.yaml").string();
  spawn("record", {"record", "--out", live, "--domain", domain, "--profile", profile, "--topic", "bsn/raw", "--topic",
                   "bsn/joint_angles", "--body", body});
  spawn("fusion", {"fusion", "--body", body, "--domain", domain, "--profile", profile});
  std::vector<std::string> replay{"replay", "--domain", domain, "--profile", profile, "--speed", "3", "--readers", "2"};
  for (const char* n : {"pelvis", "thigh_l", "shank_l"})
    replay.push_back((dir() / "lab" / (std::string(n) + ".hdf5")).string());
  ASSERT_EQ(exit_code(spawn("replay", replay).wait_for(30s)), 0) << output("replay");
  // The fusion's last estimates are on their way to the recorder; what is compared is every estimate recorded.
  std::this_thread::sleep_for(500ms);
  ASSERT_EQ(exit_code(stop("record")), 0) << output("record");
  ASSERT_EQ(run("process", {"process", live, "--body", body, "--out", offline}), 0) << output("process");

  const auto a = joint_rows(live), b = joint_rows(offline);
  // 12 s at 100 Hz, two joints: the offline run has every one; the live recording nearly all.
  ASSERT_EQ(b.size(), 2u * 1200u) << output("process");
  ASSERT_GT(a.size(), 2u * 1100u);
  double worst = 0.0;
  for (const auto& [key, row] : a) {
    const auto it = b.find(key);
    ASSERT_NE(it, b.end()) << key.first << " at " << key.second << " was published live but not offline";
    for (int k = 0; k < 4; ++k) worst = std::max(worst, std::abs(row.quat[k] - it->second.quat[k]));
    for (int k = 0; k < 3; ++k) worst = std::max(worst, std::abs(row.angles[k] - it->second.angles[k]));
    for (int k = 0; k < 3; ++k) worst = std::max(worst, std::abs(row.anatomical[k] - it->second.anatomical[k]));
    // Staleness is the live service's clock (arrival gaps), which an offline run does not have.
    EXPECT_EQ(row.flags & ~4u, it->second.flags & ~4u) << key.first << " at " << key.second;
  }
  // Floating-point noise: the same operations in the same order give the same doubles; 1e-12 rad leaves room for
  // nothing else (a sample missed or taken in another order moves the angles by 1e-6 rad and more).
  EXPECT_LT(worst, 1e-12);
}

TEST_F(Process, AFolderOfRecordingsIsDeterministicAndExportable) {
  simulate();
  const std::string body = (dir() / "leg.yaml").string();
  const std::string a = (dir() / "a.h5").string(), b = (dir() / "b.h5").string();
  ASSERT_EQ(run("a", {"process", (dir() / "lab").string(), "--body", body, "--out", a}), 0) << output("a");
  ASSERT_EQ(run("b", {"process", (dir() / "lab").string(), "--body", body, "--out", b}), 0) << output("b");
  EXPECT_EQ(read_file(a), read_file(b)) << "the same input gave different bytes";
  // The four other segments' recordings are named as left out.
  EXPECT_NE(output("a").find("foot_l.hdf5 is the recording of no node or segment of the body"), std::string::npos)
      << output("a");
  const io::SessionReader r(a);
  EXPECT_EQ(r.attributes().at("format"), "bsn-session");
  EXPECT_EQ(r.streams_of("bsn/orientation").size(), 3u);
  EXPECT_EQ(r.streams_of("bsn/joint_angles").size(), 2u);
  EXPECT_EQ(r.streams_of("bsn/truth/orientation").size(), 3u);
  ASSERT_EQ(r.streams_of("bsn/status").size(), 1u);
  // bsn export reads it as it reads a live session.
  ASSERT_EQ(run("export", {"export", a, "--format", "csv", "--out", (dir() / "csv").string()}), 0) << output("export");
  // One CSV file per joint (its columns carry the joint's own angle names), each with all 1200 of its samples. The
  // joint angles are columns alone in the file (no serialised copy): their texts come from the stream's attributes.
  for (const auto& [joint, segments] :
       {std::pair<std::string, std::string>{"hip_l", ",pelvis,thigh_l,"}, {"knee_l", ",thigh_l,shank_l,"}}) {
    const std::string csv = read_file(dir() / "csv" / ("joint_angles_" + joint + ".csv"));
    EXPECT_NE(csv.find(joint + segments), std::string::npos) << joint;
    EXPECT_NE(csv.find("flexion_extension [rad]"), std::string::npos) << joint;
    EXPECT_GT(std::count(csv.begin(), csv.end(), '\n'), 1200) << joint;
  }
  for (const auto& s : r.streams_of("bsn/joint_angles")) EXPECT_FALSE(r.has(s, "cdr")) << s.key;
  // The other filter: different numbers, same layout.
  ASSERT_EQ(run("ekf", {"process", (dir() / "lab").string(), "--body", body, "--filter", "ekf", "--out",
                        (dir() / "ekf.h5").string()}),
            0)
      << output("ekf");
  EXPECT_NE(io::SessionReader((dir() / "ekf.h5").string()).attributes().at("filter_parameters").find("ekf"),
            std::string::npos);
}

// The first number after `key` at or after `from` in `text` (a JSON figure), NaN if none.
double number_after(const std::string& text, std::size_t from, const std::string& key) {
  const std::size_t at = text.find("\"" + key + "\": ", from);
  if (at == std::string::npos) return std::nan("");
  return std::strtod(text.c_str() + at + key.size() + 4, nullptr);
}

TEST_F(Process, EvalBodyReproducesTheSimulatorsJointErrors) {
  // bsn eval --body scores a simulated walk's joints against the recordings' reference orientations. The test
  // computes the same figures directly: BodyFusion on the simulator's samples in the same order, against the
  // simulator's own joint truth (ScenarioSample::joint_anatomical and joint_relative, from its segment frames, not
  // from the files). The sensors sit along their segments (the default mounting, given as sensor_axes), no jitter.
  const std::string scenario = R"(name: walk0
description: "walking, sensors along their segments"
duration_s: 20
rate_hz: 100
seed: 4
sensors:
  preset: consumer_mems
  mag: {hard_iron: [0, 0, 0], soft_iron: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}
  jitter_s: 0
body:
  kind: lower_body
  pose: {position_m: [0, 0, 0.95]}
  mounting: {max_rotation_deg: 0, max_offset_m: 0}
  gait: {cadence_steps_per_min: 110, speed_m_s: 1.2, heading_deg: 90}
)";
  write_file(dir() / "walk0.yaml", scenario);
  std::string body_yaml = "segments:\n";
  const std::vector<std::array<std::string, 3>> segments{
      {"pelvis", "", ""}, {"thigh_l", "pelvis", "hip_l"}, {"shank_l", "thigh_l", "knee_l"}};
  for (const auto& [name, parent, joint] : segments) {
    body_yaml += "  - name: " + name + "\n    sensor_axes: [anterior, left, up]\n";
    if (!parent.empty()) body_yaml += "    parent: " + parent + "\n    joint: " + joint + "\n";
  }
  write_file(dir() / "leg0.yaml", body_yaml);
  ASSERT_EQ(run("sim", {"sim", "--scenario", (dir() / "walk0.yaml").string(), "--out", (dir() / "lab0").string()}), 0)
      << output("sim");
  ASSERT_EQ(run("eval", {"eval", "--body", (dir() / "leg0.yaml").string(), (dir() / "lab0").string(), "--json",
                         "--plot", (dir() / "joints.svg").string()}),
            0)
      << output("eval");
  const std::string json = output("eval");
  EXPECT_NE(read_file(dir() / "joints.svg").find("<polyline"), std::string::npos);

  // The direct computation.
  fusion::BodyModel body;
  for (const auto& [name, parent, joint] : segments) {
    fusion::SegmentSpec s;
    s.name = s.node = name;
    s.parent = parent;
    s.joint = joint;
    s.sensor_to_segment = fusion::default_sensor_to_segment();
    body.segments.push_back(s);
  }
  fusion::BodyFusion fusion(body, {}, {}, 0);
  sim::ScenarioRunner runner(sim::load_scenario((dir() / "walk0.yaml").string()), {"pelvis", "thigh_l", "shank_l"},
                             false);
  std::map<std::string, std::pair<double, std::array<double, 3>>> sq;  // per joint: relative, anatomical squared errors
  std::map<std::string, std::size_t> n;
  std::vector<sim::ScenarioSample> out;
  for (std::uint64_t k = 0; runner.next(out); ++k) {
    for (std::size_t i = 0; i < out.size(); ++i) {
      const fusion::SampleResult& r = fusion.process({segments[i][0], k, out[i].sample}, out[i].sample.timestamp_ns);
      if (r.outcome != fusion::SampleOutcome::kEstimated || !r.joint) continue;
      auto& [rel, anat] = sq[segments[i][2]];
      const double e = fusion::angle_between(r.joint->relative, *out[i].joint_relative);
      rel += e * e;
      for (int c = 0; c < 3; ++c) {
        const double d = std::remainder(r.joint->anatomical[c] - out[i].joint_anatomical[c], 2 * std::numbers::pi);
        anat[c] += d * d;
      }
      ++n[segments[i][2]];
    }
  }
  ASSERT_EQ(n.size(), 2u);
  const double deg = 180.0 / std::numbers::pi;
  for (const auto& [joint, count] : n) {
    SCOPED_TRACE(joint);
    ASSERT_EQ(count, 2000u);
    const std::size_t at = json.find("\"" + joint + "\": {\"samples\": ");
    ASSERT_NE(at, std::string::npos) << json;
    EXPECT_EQ(number_after(json, at, "samples"), 2000.0);
    const std::size_t unaligned = json.find("\"unaligned\"", at);
    const auto& [rel, anat] = sq[joint];
    EXPECT_NEAR(number_after(json, unaligned, "relative_deg"), std::sqrt(rel / 2000.0) * deg, 0.01) << json;
    const auto names = fusion::anatomical_angle_names(fusion::infer_joint_convention(joint).type);
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(number_after(json, unaligned, std::string(names[c])), std::sqrt(anat[c] / 2000.0) * deg, 0.01)
          << names[c] << "\n"
          << json;
  }
  // A bad window is a usage error naming the option.
  EXPECT_EQ(run("window",
                {"eval", "--body", (dir() / "leg0.yaml").string(), (dir() / "lab0").string(), "--align-window", "5:1"}),
            2);
  EXPECT_NE(output("window").find("--align-window"), std::string::npos) << output("window");
}

TEST_F(Process, AlignmentFromASessionFileAppliedFromTheFirstSample) {
  // The lab procedure simulated to per-node files, made a session (bsn process --raw), aligned from the session file
  // (bsn calibrate --alignment SESSION.h5): the same rotations as from the folder. Then the session processed again
  // with the alignment files: every orientation is in the segment frame from the first sample on.
  const std::string scenario = std::string(BSN_SCENARIO_DIR) + "/gait_alignment.yaml";
  ASSERT_EQ(run("sim", {"sim", "--scenario", scenario, "--out", (dir() / "lab").string()}), 0) << output("sim");
  ASSERT_EQ(run("body", {"fusion", "--print-body"}), 0);
  write_file(dir() / "body.yaml", output("body"));
  const std::string body = (dir() / "body.yaml").string(), session = (dir() / "procedure.h5").string();
  ASSERT_EQ(run("raw", {"process", (dir() / "lab").string(), "--body", body, "--raw", "--out", session}), 0)
      << output("raw");
  ASSERT_EQ(run("folder", {"calibrate", "--alignment", (dir() / "lab").string(), "--output", (dir() / "a").string()}),
            0)
      << output("folder");
  ASSERT_EQ(run("session", {"calibrate", "--alignment", session, "--output", (dir() / "b").string()}), 0)
      << output("session");
  std::vector<std::string> files;
  for (const char* n : {"pelvis", "thigh_l", "shank_l", "foot_l", "thigh_r", "shank_r", "foot_r"}) {
    const std::string name = std::string(n) + ".alignment.calib.yaml";
    EXPECT_EQ(read_file(dir() / "a" / name), read_file(dir() / "b" / name)) << name;
    EXPECT_NE(read_file(dir() / "b" / name).find("sensor_to_segment"), std::string::npos) << name;
    files.push_back((dir() / "b" / name).string());
  }
  std::vector<std::string> args{"process", session, "--out", (dir() / "aligned.h5").string()};
  for (const std::string& f : files) args.insert(args.end(), {"--calibration", f});
  ASSERT_EQ(run("aligned", args), 0) << output("aligned");
  EXPECT_NE(output("aligned").find("7 calibrations applied from the first sample"), std::string::npos)
      << output("aligned");
  const io::SessionReader r((dir() / "aligned.h5").string());
  ASSERT_EQ(r.streams_of("bsn/orientation").size(), 7u);
  for (const auto& s : r.streams_of("bsn/orientation")) {
    const auto flags = r.read_u32(s, "flags");
    ASSERT_EQ(flags.size(), 6000u) << s.key;
    EXPECT_EQ(std::count_if(flags.begin(), flags.end(), [](std::uint32_t f) { return (f & 32u) == 0; }), 0)
        << s.key << ": an orientation not in the segment frame (FLAG_SEGMENT_FRAME)";
  }
}

TEST_F(Process, BadInputsAreUsageErrors) {
  write_file(dir() / "leg.yaml", kLegBody);
  const std::string body = (dir() / "leg.yaml").string(), out = (dir() / "o.h5").string();
  EXPECT_EQ(run("missing", {"process", (dir() / "nothing").string(), "--body", body, "--out", out}), 2);
  EXPECT_NE(output("missing").find("no such file or folder"), std::string::npos) << output("missing");
  write_file(dir() / "text.h5", "not hdf5\n");
  EXPECT_EQ(run("text", {"process", (dir() / "text.h5").string(), "--body", body, "--out", out}), 2);
  EXPECT_NE(output("text").find("not a bsn session file"), std::string::npos) << output("text");
  std::filesystem::create_directories(dir() / "empty");
  EXPECT_EQ(run("nobody", {"process", (dir() / "empty").string(), "--out", out}), 2);
  EXPECT_NE(output("nobody").find("--body is required"), std::string::npos) << output("nobody");
  EXPECT_EQ(
      run("filter", {"process", (dir() / "empty").string(), "--body", body, "--filter", "nofilter", "--out", out}), 2);
  EXPECT_NE(output("filter").find("--filter"), std::string::npos) << output("filter");
  write_file(dir() / "bad.yaml", "segments:\n  - name: a\n    hinge_axis: q\n");
  EXPECT_EQ(run("body", {"process", (dir() / "empty").string(), "--body", (dir() / "bad.yaml").string(), "--out", out}),
            2);
  EXPECT_NE(output("body").find("bad.yaml:3:"), std::string::npos) << output("body");
  EXPECT_EQ(run("order", {"process", (dir() / "empty").string(), "--body", body, "--order", "random", "--out", out}),
            2);
  EXPECT_NE(output("order").find("--order must be arrival or time"), std::string::npos) << output("order");
}

// The importers' hand-made samples (deploy/samples/): segments at rest in known orientations, so the estimates and
// the joint must be those orientations; malformed files exit 2 naming file and line.
TEST_F(Process, RecordingsOfOtherSystemsGoThroughTheImporters) {
  const std::string samples = std::string(BSN_DEPLOY_DIR) + "/samples";
  // The relative orientation of a joint's last sample against its known value, degrees.
  auto joint_error_deg = [](const std::string& session, const std::string& joint, const Eigen::Quaterniond& want) {
    const io::SessionReader r(session);
    for (const auto& s : r.streams_of("bsn/joint_angles")) {
      if (s.key != joint) continue;
      const auto q = r.read_f64(s, "quat", 4);
      if (q.size() < 4) return 180.0;
      const std::size_t i = q.size() - 4;
      return Eigen::Quaterniond(q[i], q[i + 1], q[i + 2], q[i + 3]).angularDistance(want) * 180 / std::numbers::pi;
    }
    return 180.0;
  };
  ASSERT_EQ(run("diodem", {"process", samples + "/diodem", "--body", samples + "/diodem/chain.yaml", "--out",
                           (dir() / "d.h5").string()}),
            0)
      << output("diodem");
  EXPECT_LT(
      joint_error_deg((dir() / "d.h5").string(), "hinge",
                      Eigen::Quaterniond(Eigen::AngleAxisd(60 * std::numbers::pi / 180, Eigen::Vector3d::UnitX()))),
      0.1);
  ASSERT_EQ(run("eval", {"eval", "--body", samples + "/diodem/chain.yaml", samples + "/diodem"}), 0) << output("eval");
  {
    // The joint's line: "hinge  <relative RMS> ...", degrees.
    const std::string text = output("eval");
    const auto at = text.find("\nhinge ");
    ASSERT_NE(at, std::string::npos) << text;
    EXPECT_LT(std::stod(text.substr(at + 7, 20)), 0.01) << text;
  }
  ASSERT_EQ(run("dot", {"process", samples + "/xsens_dot", "--body", samples + "/xsens_dot/arm.yaml", "--out",
                        (dir() / "x.h5").string()}),
            0)
      << output("dot");
  EXPECT_LT(joint_error_deg((dir() / "x.h5").string(), "elbow",
                            Eigen::Quaterniond(Eigen::AngleAxisd(std::numbers::pi / 2, Eigen::Vector3d::UnitX()))),
            0.1);

  // Malformed: a DOT row cut short, a DIODEM file without its rate line, an unknown unit.
  std::filesystem::create_directories(dir() / "bad_dot");
  for (const char* f : {"upper_arm.csv", "forearm.csv"})
    std::filesystem::copy_file(samples + "/xsens_dot/" + f, dir() / "bad_dot" / f);
  {
    std::string text = read_file(dir() / "bad_dot" / "forearm.csv");
    std::size_t at = 0;
    for (int line = 1; line < 7; ++line) at = text.find('\n', at) + 1;
    text.replace(at, text.find('\n', at) - at, "6,12,zz");
    write_file(dir() / "bad_dot" / "forearm.csv", text);
  }
  const std::string arm = samples + "/xsens_dot/arm.yaml", out = (dir() / "o.h5").string();
  EXPECT_EQ(run("bad_dot", {"process", (dir() / "bad_dot").string(), "--body", arm, "--out", out}), 2);
  EXPECT_NE(output("bad_dot").find("forearm.csv:7: 3 cells, fewer than the header's columns"), std::string::npos)
      << output("bad_dot");
  std::filesystem::create_directories(dir() / "bad_diodem");
  write_file(dir() / "bad_diodem" / "exp01_motion01_imu_rigid.csv", "no rate\nx\nseg1_acc_x\n");
  EXPECT_EQ(run("bad_diodem",
                {"process", (dir() / "bad_diodem").string(), "--body", samples + "/diodem/chain.yaml", "--out", out}),
            2);
  EXPECT_NE(output("bad_diodem").find("exp01_motion01_imu_rigid.csv:1: expected the sampling rate"), std::string::npos)
      << output("bad_diodem");
  EXPECT_EQ(run("unit", {"process", samples + "/xsens_dot", "--body", arm, "--out", out, "--unit", "gyr=rpm"}), 2);
  EXPECT_NE(output("unit").find("'rpm' is not a unit of gyr"), std::string::npos) << output("unit");
  EXPECT_EQ(run("format", {"process", samples + "/xsens_dot", "--body", arm, "--out", out, "--format", "diodem"}), 2);
  EXPECT_NE(output("format").find("no *_imu_rigid.csv file"), std::string::npos) << output("format");
  // Recordings named after no node of the body: an error naming what was found, not an empty output.
  EXPECT_EQ(run("names", {"process", samples + "/xsens_dot", "--body", samples + "/diodem/chain.yaml", "--out", out}),
            2);
  EXPECT_NE(output("names").find("no recording of any node or segment of the body (found: "), std::string::npos)
      << output("names");
  EXPECT_FALSE(std::filesystem::exists(out));
}

}  // namespace
}  // namespace bsn::integration
