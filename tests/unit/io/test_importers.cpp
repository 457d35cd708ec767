// The importers read hand-made files of each format with known values into bsn's units, and name file:line for
// malformed input.
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "bsn/io/importers.hpp"

namespace bsn::io {
namespace {

class TempDir {
 public:
  TempDir() {
    char tmpl[] = "/tmp/bsn-import-test-XXXXXX";
    path_ = mkdtemp(tmpl);
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  std::string file(const std::string& name) const { return (path_ / name).string(); }
  std::string write(const std::string& name, const std::string& text) const {
    std::ofstream(file(name)) << text;
    return file(name);
  }
  std::string path() const { return path_.string(); }

 private:
  std::filesystem::path path_;
};

/// Runs `f`, which must throw FormatError whose message contains `expected`.
template <class F>
void expect_format_error(F f, const std::string& expected) {
  try {
    f();
    ADD_FAILURE() << "no error; expected one containing: " << expected;
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
  }
}

constexpr double kDeg = std::numbers::pi / 180.0;

// ---- bsn CSV with units ------------------------------------------------------------------------------------------

TEST(CsvImport, UnitsInTheHeaderAreConverted) {
  TempDir dir;
  const std::string p = dir.write("thigh.csv",
                                  "t [ms],acc_x [g],acc_y [g],acc_z [g],gyr_x [deg/s],gyr_y [deg/s],gyr_z [deg/s],"
                                  "mag_x [nT],mag_y [nT],mag_z [nT]\n"
                                  "0,0,0,1,90,0,0,20000,0,-40000\n"
                                  "10,0,0.5,1,0,-180,0,,,\n"
                                  "20,0,0,1,0,0,45,21000,0,-40000\n");
  const auto nodes = recording_importer("bsn-csv").read(p, {});
  ASSERT_EQ(nodes.size(), 1u);
  EXPECT_EQ(nodes[0].name, "thigh");
  const Recording& r = nodes[0].rec;
  ASSERT_EQ(r.size(), 3u);
  EXPECT_NEAR(r.sampling_rate_hz, 100.0, 1e-9);
  EXPECT_EQ(r.time_ns(1), 10'000'000u);
  EXPECT_DOUBLE_EQ(r.acc(0, 2), 9.80665);
  EXPECT_DOUBLE_EQ(r.acc(1, 1), 0.5 * 9.80665);
  EXPECT_DOUBLE_EQ(r.gyr(0, 0), std::numbers::pi / 2);
  EXPECT_DOUBLE_EQ(r.gyr(1, 1), -std::numbers::pi);
  EXPECT_DOUBLE_EQ(r.mag(0, 0), 20.0);
  EXPECT_DOUBLE_EQ(r.mag(0, 2), -40.0);
  EXPECT_FALSE(r.sample(1).has_mag);
}

TEST(CsvImport, AUnitOptionAppliesToColumnsWithoutOneAndConflictsAreErrors) {
  TempDir dir;
  const std::string body = "0,0,0,9.8,57.29577951308232,0,0\n0.01,0,0,9.8,0,0,0\n";
  const std::string p = dir.write("a.csv", "t_s,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n" + body);
  ImportOptions deg;
  deg.units["gyr"] = "deg/s";
  EXPECT_NEAR(recording_importer("bsn-csv").read(p, deg)[0].rec.gyr(0, 0), 1.0, 1e-15);
  EXPECT_DOUBLE_EQ(recording_importer("bsn-csv").read(p, {})[0].rec.gyr(0, 0), 57.29577951308232);

  const std::string q = dir.write("b.csv", "t_s,acc_x,acc_y,acc_z,gyr_x [rad/s],gyr_y,gyr_z\n" + body);
  expect_format_error([&] { recording_importer("bsn-csv").read(q, deg); },
                      "b.csv:1: column 'gyr_x' is in rad/s, but --unit gyr=deg/s was given");
  const std::string t = dir.write("c.csv", "t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n" + body);
  expect_format_error([&] { recording_importer("bsn-csv").read(t, {}); }, "c.csv:1: column 't' needs its unit");
  ImportOptions ms;
  ms.units["time"] = "ms";
  EXPECT_EQ(recording_importer("bsn-csv").read(t, ms)[0].rec.time_ns(1), 10'000u);  // 0.01 ms
  const std::string u = dir.write("d.csv", "t_s,acc_x [furlong],acc_y,acc_z,gyr_x,gyr_y,gyr_z\n" + body);
  expect_format_error([&] { recording_importer("bsn-csv").read(u, {}); },
                      "d.csv:1: column 'acc_x': 'furlong' is not a unit of acc (g, m/s2, m/s^2, mg)");
  const std::string s = dir.write("e.csv", "t_s [ms],acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n" + body);
  expect_format_error([&] { recording_importer("bsn-csv").read(s, {}); }, "e.csv:1: column 't_s' is in s by its name");
}

TEST(Units, FactorsAndTheOption) {
  EXPECT_DOUBLE_EQ(unit_factor("mag", "au"), 40.0);
  EXPECT_DOUBLE_EQ(unit_factor("mag", "au:48.5"), 48.5);
  EXPECT_DOUBLE_EQ(unit_factor("mag", "G"), 100.0);
  EXPECT_DOUBLE_EQ(unit_factor("time", "us"), 1000.0);
  EXPECT_THROW(unit_factor("mag", "au:-1"), std::invalid_argument);
  EXPECT_THROW(unit_factor("speed", "m/s"), std::invalid_argument);
  UnitOptions u;
  add_unit_option(u, "gyr=dps");
  EXPECT_EQ(u.at("gyr"), "dps");
  EXPECT_THROW(add_unit_option(u, "gyr"), std::invalid_argument);
  EXPECT_THROW(add_unit_option(u, "gyr=rpm"), std::invalid_argument);
}

// ---- DIODEM ------------------------------------------------------------------------------------------------------

/// A rotation by `deg` degrees about z, as (w, x, y, z) cells.
std::string quat_z(double deg) {
  const Eigen::Quaterniond q(Eigen::AngleAxisd(deg * kDeg, Eigen::Vector3d::UnitZ()));
  char buf[128];
  std::snprintf(buf, sizeof buf, "%.17g,%.17g,%.17g,%.17g", q.w(), q.x(), q.y(), q.z());
  return buf;
}

double yaw_deg(const Recording& r, Eigen::Index i) {
  const Eigen::Quaterniond q(r.opt_quat(i, 0), r.opt_quat(i, 1), r.opt_quat(i, 2), r.opt_quat(i, 3));
  return 2.0 * std::atan2(q.z(), q.w()) / kDeg;
}

/// A trial at 40 Hz (IMU) and 100 Hz (optical): seg1 turns about z at 10 deg per optical sample (1000 deg/s).
void write_diodem_trial(const TempDir& dir, const std::string& omc_row7 = "") {
  std::string imu =
      "sampling frequency: 40\nunits: acc m/s^2, gyr rad/s, mag a.u.\n"
      "seg1_acc_x,seg1_acc_y,seg1_acc_z,seg1_gyr_x,seg1_gyr_y,seg1_gyr_z,seg1_mag_x,seg1_mag_y,"
      "seg1_mag_z,seg2_acc_x,seg2_acc_y,seg2_acc_z,seg2_gyr_x,seg2_gyr_y,seg2_gyr_z\n";
  for (int i = 0; i < 4; ++i)
    imu += "0,0,9.81,0,0,17.453292519943295," + std::to_string(0.5 + i) + ",0,-1,1,2,3,4,5,6\n";
  dir.write("exp01_motion01_imu_rigid.csv", imu);
  dir.write("exp01_motion01_imu_nonrigid.csv",
            "hz: 40\nx\nseg1_acc_x,seg1_acc_y,seg1_acc_z,seg1_gyr_x,seg1_gyr_y,"
            "seg1_gyr_z\n7,7,7,0,0,0\n8,8,8,0,0,0\n");
  std::string omc =
      "sampling frequency: 100\nunits\nseg1_quat_w,seg1_quat_x,seg1_quat_y,seg1_quat_z,seg1_marker1_x,"
      "seg1_marker1_y,seg1_marker1_z\n";
  for (int k = 0; k < 10; ++k) omc += (k == 7 && !omc_row7.empty() ? omc_row7 : quat_z(10.0 * k)) + ",0.1,0.2,0.3\n";
  dir.write("exp01_motion01_omc.csv", omc);
}

TEST(DiodemImport, ATrialFolderGivesEachSegmentWithTheOpticalReferenceAtTheImuTimes) {
  TempDir dir;
  write_diodem_trial(dir);
  EXPECT_EQ(detect_format(dir.path()), "diodem");
  const auto nodes = import_recordings(dir.path(), "auto", {});
  ASSERT_EQ(nodes.size(), 2u);
  EXPECT_EQ(nodes[0].name, "seg1");
  EXPECT_EQ(nodes[1].name, "seg2");
  const Recording& r = nodes[0].rec;
  ASSERT_EQ(r.size(), 4u);
  EXPECT_EQ(r.sampling_rate_hz, 40.0);
  EXPECT_EQ(r.time_ns(3), 75'000'000u);
  EXPECT_DOUBLE_EQ(r.acc(2, 2), 9.81);
  EXPECT_DOUBLE_EQ(r.gyr(1, 2), 17.453292519943295);  // rad/s as recorded
  EXPECT_DOUBLE_EQ(r.mag(2, 0), 2.5 * 40.0);          // a.u. -> uT
  EXPECT_DOUBLE_EQ(r.mag(2, 2), -40.0);
  // IMU sample i is at optical sample 2.5 i: 0, 25, 50, 75 deg (slerp halfway between 20 and 30 deg for i = 1).
  ASSERT_EQ(r.opt_quat.rows(), 4);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(yaw_deg(r, i), 25.0 * i, 1e-9) << i;
  // seg2 has no magnetometer columns and no reference.
  EXPECT_FALSE(nodes[1].rec.sample(0).has_mag);
  EXPECT_EQ(nodes[1].rec.opt_quat.rows(), 0);
  EXPECT_DOUBLE_EQ(nodes[1].rec.gyr(1, 2), 6.0);
  // The non-rigid IMU on request.
  ImportOptions nonrigid;
  nonrigid.imu = "nonrigid";
  const auto nr = import_recordings(dir.path(), "diodem", nonrigid);
  ASSERT_EQ(nr.size(), 1u);
  EXPECT_DOUBLE_EQ(nr[0].rec.acc(1, 0), 8.0);
}

TEST(DiodemImport, AnOccludedOpticalSampleLeavesTheNeighbouringReferencesOut) {
  TempDir dir;
  write_diodem_trial(dir, ",,,");
  const Recording r = import_recordings(dir.file("exp01_motion01_imu_rigid.csv"), "auto", {})[0].rec;
  // IMU sample 3 is at optical 7.5 (between 7, occluded, and 8): no reference; the others are kept.
  EXPECT_TRUE(r.opt_quat.row(3).array().isNaN().all());
  EXPECT_NEAR(yaw_deg(r, 2), 50.0, 1e-9);
}

TEST(DiodemImport, OneFileWithImuAndQuaternionColumnsUsesThemAtItsRate) {
  const std::string text =
      "hz: 100\n-\nhip_acc_x,hip_acc_y,hip_acc_z,hip_gyr_x,hip_gyr_y,hip_gyr_z,hip_quat_w,"
      "hip_quat_x,hip_quat_y,hip_quat_z\n0,0,9.8,0,0,0,1,0,0,0\n0,0,9.8,0,0,0,nan,nan,nan,nan\n";
  const auto nodes = recording_importer("diodem").parse(text, "trial.csv", {});
  ASSERT_EQ(nodes.size(), 1u);
  EXPECT_EQ(nodes[0].name, "hip");
  EXPECT_EQ(nodes[0].rec.opt_quat(0, 0), 1.0);
  EXPECT_TRUE(std::isnan(nodes[0].rec.opt_quat(1, 0)));
}

TEST(DiodemImport, MalformedFilesNameFileAndLine) {
  const RecordingImporter& d = recording_importer("diodem");
  const std::string header = "seg1_acc_x,seg1_acc_y,seg1_acc_z,seg1_gyr_x,seg1_gyr_y,seg1_gyr_z\n";
  expect_format_error([&] { d.parse("no rate here\nx\n" + header, "t.csv", {}); },
                      "t.csv:1: expected the sampling rate as '<label>: <Hz>'");
  expect_format_error([&] { d.parse("hz: -40\nx\n" + header, "t.csv", {}); }, "t.csv:1:");
  expect_format_error([&] { d.parse("hz: 40\n", "t.csv", {}); }, "t.csv: ends after line 1");
  expect_format_error([&] { d.parse("hz: 40\nx\n" + header + "1,2,3,4,5,6\n1,2,3,4,5\n", "t.csv", {}); },
                      "t.csv:5: 5 cells, but the header names 6 columns");
  expect_format_error([&] { d.parse("hz: 40\nx\n" + header + "1,2,3,4,abc,6\n", "t.csv", {}); },
                      "t.csv:4: 'abc' in column 'seg1_gyr_y' is not a finite number");
  expect_format_error([&] { d.parse("hz: 40\nx\n" + header + "1,2,3,4,inf,6\n", "t.csv", {}); }, "t.csv:4: 'inf'");
  expect_format_error(
      [&] { d.parse("hz: 40\nx\nseg1_acc_x,seg1_acc_y,seg1_acc_z,seg1_gyr_x\n1,2,3,4\n", "t.csv", {}); },
      "t.csv:3: segment 'seg1' has no column 'seg1_gyr_y'");
  expect_format_error([&] { d.parse("hz: 40\nx\nseg1_quat_w,a\n1,2\n", "t.csv", {}); },
                      "t.csv:3: no '<segment>_acc_x' column");
  expect_format_error([&] { d.parse("hz: 40\nx\n" + header + "1,2,3,4,5,6\n", "t.csv", {}); },
                      "t.csv: fewer than two samples");
  TempDir dir;
  expect_format_error([&] { import_recordings(dir.path(), "diodem", {}); }, "no *_imu_rigid.csv file");
}

/// Writes `segs` (each with a reference) as a DIODEM trial: IMU and optical files at the same rate, 17 digits.
void write_diodem(const TempDir& dir, const std::vector<std::pair<std::string, Recording>>& segs) {
  std::ostringstream imu, omc;
  imu << "sampling frequency: " << segs[0].second.sampling_rate_hz << "\nunits\n";
  omc << "sampling frequency: " << segs[0].second.sampling_rate_hz << "\nunits\n";
  std::string ih, oh;
  for (const auto& [name, r] : segs) {
    for (const char* q : {"acc", "gyr", "mag"})
      for (const char* a : {"x", "y", "z"}) ih += (ih.empty() ? "" : ",") + name + "_" + q + "_" + a;
    for (const char* a : {"w", "x", "y", "z"}) oh += (oh.empty() ? "" : ",") + name + "_quat_" + a;
  }
  imu << ih << "\n";
  omc << oh << "\n";
  imu.precision(17);
  omc.precision(17);
  for (Eigen::Index i = 0; i < segs[0].second.gyr.rows(); ++i) {
    bool first = true;
    for (const auto& [name, r] : segs) {
      for (int a = 0; a < 3; ++a) imu << (first ? "" : ",") << r.acc(i, a), first = false;
      for (int a = 0; a < 3; ++a) imu << "," << r.gyr(i, a);
      for (int a = 0; a < 3; ++a) imu << "," << r.mag(i, a) / 40.0;
    }
    imu << "\n";
    first = true;
    for (const auto& [name, r] : segs) {
      for (int a = 0; a < 4; ++a) omc << (first ? "" : ",") << r.opt_quat(i, a), first = false;
    }
    omc << "\n";
  }
  dir.write("exp02_motion03_imu_rigid.csv", imu.str());
  dir.write("exp02_motion03_omc.csv", omc.str());
}

TEST(DiodemImport, ARecordingWrittenInTheLayoutReadsBack) {
  std::srand(7);
  std::vector<std::pair<std::string, Recording>> segs;
  for (const char* name : {"seg1", "seg4"}) {
    Recording r;
    r.sampling_rate_hz = 100.0;
    r.acc = RowsX3::Random(50, 3) * 20.0;
    r.gyr = RowsX3::Random(50, 3) * 10.0;
    r.mag = RowsX3::Random(50, 3) * 60.0;
    r.opt_quat.resize(50, 4);
    for (Eigen::Index i = 0; i < 50; ++i) {
      const Eigen::Quaterniond q = Eigen::Quaterniond::UnitRandom();
      r.opt_quat.row(i) << q.w(), q.x(), q.y(), q.z();
    }
    segs.emplace_back(name, r);
  }
  TempDir dir;
  write_diodem(dir, segs);
  const auto nodes = import_recordings(dir.path(), "auto", {});
  ASSERT_EQ(nodes.size(), 2u);
  for (std::size_t k = 0; k < 2; ++k) {
    const Recording& want = segs[k].second;
    const Recording& got = nodes[k].rec;
    EXPECT_EQ(nodes[k].name, segs[k].first);
    EXPECT_EQ(got.sampling_rate_hz, 100.0);
    EXPECT_EQ(got.acc, want.acc);  // 17 significant digits: exact
    EXPECT_EQ(got.gyr, want.gyr);
    EXPECT_LT((got.mag - want.mag).cwiseAbs().maxCoeff(), 1e-12);  // through a.u. and back
    EXPECT_LT((got.opt_quat - want.opt_quat).cwiseAbs().maxCoeff(), 1e-15);
    EXPECT_EQ(got.time_ns(49), 490'000'000u);
  }
}

TEST(XsensDotImport, ARecordingWrittenAsAnExportReadsBack) {
  std::srand(11);
  const RowsX3 acc = RowsX3::Random(30, 3) * 20.0, gyr = RowsX3::Random(30, 3) * 10.0,
               mag = RowsX3::Random(30, 3) * 60.0;
  std::ostringstream text;
  text.precision(17);
  text << "PacketCounter,SampleTimeFine,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z,Mag_X,Mag_Y,Mag_Z\n";
  for (Eigen::Index i = 0; i < 30; ++i) {
    text << i << "," << 1000 + 10000 * i;
    for (int a = 0; a < 3; ++a) text << "," << acc(i, a);
    for (int a = 0; a < 3; ++a) text << "," << gyr(i, a) / kDeg;
    for (int a = 0; a < 3; ++a) text << "," << mag(i, a) / 40.0;
    text << "\n";
  }
  const Recording r = recording_importer("xsens-dot").parse(text.str(), "n.csv", {})[0].rec;
  EXPECT_EQ(r.acc, acc);
  EXPECT_LT((r.gyr - gyr).cwiseAbs().maxCoeff(), 1e-13);
  EXPECT_LT((r.mag - mag).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_NEAR(r.sampling_rate_hz, 100.0, 1e-9);
  EXPECT_EQ(r.time_ns(29), (1000u + 10000u * 29) * 1000);
}

// ---- Xsens DOT ---------------------------------------------------------------------------------------------------

TEST(XsensDotImport, AnExportIsReadInBsnUnitsAcrossTheClockWrap) {
  // The 32-bit microsecond clock wraps between the second and third rows (60 Hz: 16667 us apart).
  const std::string text =
      "DOT Version: 2.0\nFirmware Version: 2.4.0\n"
      "PacketCounter,SampleTimeFine,Quat_W,Quat_X,Quat_Y,Quat_Z,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z,Mag_X,Mag_Y,Mag_Z\n"
      "1,4294950000,1,0,0,0,0.1,0.2,9.81,90,0,-45,0.5,0,-1\n"
      "2,4294966667,1,0,0,0,0.1,0.2,9.81,0,180,0,0.5,0,-1\n"
      "3,16038,1,0,0,0,0.1,0.2,9.81,0,0,0,0.5,0,-1\n";
  const auto nodes = recording_importer("xsens-dot").parse(text, "/data/shank_l.csv", {});
  ASSERT_EQ(nodes.size(), 1u);
  EXPECT_EQ(nodes[0].name, "shank_l");
  const Recording& r = nodes[0].rec;
  ASSERT_EQ(r.size(), 3u);
  EXPECT_EQ(r.time_ns(0), 4294950000ull * 1000);
  EXPECT_EQ(r.time_ns(1) - r.time_ns(0), 16'667'000u);
  EXPECT_EQ(r.time_ns(2) - r.time_ns(1), 16'667'000u);  // 2^32 - 4294966667 + 16038 = 16667 us
  EXPECT_NEAR(r.sampling_rate_hz, 1e6 / 16667, 1e-9);
  EXPECT_DOUBLE_EQ(r.acc(0, 2), 9.81);
  EXPECT_DOUBLE_EQ(r.gyr(0, 0), std::numbers::pi / 2);
  EXPECT_DOUBLE_EQ(r.gyr(0, 2), -std::numbers::pi / 4);
  EXPECT_DOUBLE_EQ(r.gyr(1, 1), std::numbers::pi);
  EXPECT_DOUBLE_EQ(r.mag(0, 0), 20.0);
  EXPECT_DOUBLE_EQ(r.mag(0, 2), -40.0);
  EXPECT_EQ(r.opt_quat.rows(), 0);  // the sensor's own estimate is not a reference
  ImportOptions mag50;
  mag50.units["mag"] = "au:50";
  EXPECT_DOUBLE_EQ(recording_importer("xsens-dot").parse(text, "s.csv", mag50)[0].rec.mag(0, 2), -50.0);
}

TEST(XsensDotImport, MalformedExportsNameFileAndLine) {
  const RecordingImporter& x = recording_importer("xsens-dot");
  const std::string header = "PacketCounter,SampleTimeFine,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z\n";
  expect_format_error([&] { x.parse("a,b\n1,2\n", "d.csv", {}); }, "d.csv: no header line naming SampleTimeFine");
  expect_format_error([&] { x.parse("PacketCounter,SampleTimeFine,Acc_X,Acc_Y,Acc_Z\n", "d.csv", {}); },
                      "d.csv:1: no column 'Gyr_X'");
  expect_format_error([&] { x.parse(header + "1,1000,0,0,9.8,0,0,0\n2,900,0,0,9.8,0,0,0\n", "d.csv", {}); },
                      "d.csv:3: SampleTimeFine goes from 1000 to 900 us");
  expect_format_error([&] { x.parse(header + "1,1000,0,0,9.8,0,0,0\n2,1000,0,0,9.8,0,0,0\n", "d.csv", {}); },
                      "d.csv:3: SampleTimeFine goes from 1000 to 1000 us");
  expect_format_error([&] { x.parse(header + "1,-5,0,0,9.8,0,0,0\n", "d.csv", {}); },
                      "d.csv:2: SampleTimeFine '-5' is not an integer");
  expect_format_error([&] { x.parse(header + "1,4294967296,0,0,9.8,0,0,0\n", "d.csv", {}); }, "d.csv:2:");
  expect_format_error([&] { x.parse(header + "1,1000,0,0,9.8,0,zero,0\n", "d.csv", {}); },
                      "d.csv:2: 'zero' in column 7 is not a finite number");
  expect_format_error([&] { x.parse(header + "1,1000,0,0\n", "d.csv", {}); },
                      "d.csv:2: 4 cells, fewer than the header's columns");
  expect_format_error([&] { x.parse(header + "1,1000,0,0,9.8,0,0,0\n", "d.csv", {}); },
                      "d.csv: fewer than two samples");
}

// ---- A folder of per-node files in mixed formats ------------------------------------------------------------------

TEST(FolderImport, EachFileInItsOwnFormatNamedByItsStem) {
  TempDir dir;
  dir.write("thigh_l.csv", "t_s,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,9.8,1,0,0\n0.01,0,0,9.8,1,0,0\n");
  dir.write("shank_l.csv",
            "PacketCounter,SampleTimeFine,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z\n1,0,0,0,9.8,180,0,0\n"
            "2,16667,0,0,9.8,180,0,0\n");
  dir.write("notes.txt", "not a recording");
  EXPECT_EQ(detect_format(dir.path()), "folder");
  EXPECT_EQ(detect_format(dir.file("shank_l.csv")), "xsens-dot");
  EXPECT_EQ(detect_format(dir.file("thigh_l.csv")), "bsn-csv");
  const auto nodes = import_recordings(dir.path(), "auto", {});
  ASSERT_EQ(nodes.size(), 2u);
  EXPECT_EQ(nodes[0].name, "shank_l");
  EXPECT_DOUBLE_EQ(nodes[0].rec.gyr(0, 0), std::numbers::pi);  // deg/s by the DOT format
  EXPECT_EQ(nodes[1].name, "thigh_l");
  EXPECT_DOUBLE_EQ(nodes[1].rec.gyr(0, 0), 1.0);
  // Forced to one format, a file of another is a named error, not a silent guess.
  expect_format_error([&] { import_recordings(dir.path(), "bsn-csv", {}); }, "shank_l.csv:1: missing column");
  EXPECT_THROW(import_recordings(dir.path(), "vicon", {}), std::invalid_argument);
}

}  // namespace
}  // namespace bsn::io
