// `bsn export` of a recorded simulated session: the OpenSim .sto has OpenSense's header and reads back as the
// simulator's truth; the CSV files carry units; the BROAD files are scored by bsn eval. And `bsn echo --format`.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>
#include <tuple>

#include "bsn/fusion/rotation.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/io/session_file.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string cell;
  std::istringstream in(s);
  while (std::getline(in, cell, sep)) out.push_back(cell);
  return out;
}

class Export : public ProcessTest {
 protected:
  // A recorded session of one simulated node "imu" (raw + truth), 2 s, in domain test_domain(domain_offset).
  std::string record_session(int domain_offset) {
    const std::string domain = std::to_string(test_domain(domain_offset));
    const std::string out = (dir() / "sim.h5").string();
    spawn("record", {"record", "--out", out, "--domain", domain, "--duration", "3"});
    spawn("sim", {"sim", "--node", "imu", "--domain", domain, "--duration", "2"});
    EXPECT_EQ(exit_code(child("record").wait_for(20s)), 0) << read_file(log_path("record"));
    return out;
  }
};

TEST_F(Export, StoHasOpenSenseLayoutAndReadsBackAsTheTruth) {
  const std::string session = record_session(19);
  const io::SessionReader r(session);
  // Each frame's file reads back as the truth the simulator published in that frame: the segment frames (the
  // default) as bsn/truth/segment_orientation, the sensor frames as bsn/truth/orientation.
  for (const auto& [frames, topic] : {std::pair<std::string, std::string>{"segment", "bsn/truth/segment_orientation"},
                                      {"sensor", "bsn/truth/orientation"}}) {
    const std::string out = (dir() / ("sto-" + frames)).string();
    spawn("export-" + frames, {"export", session, "--format", "sto", "--out", out, "--frames", frames});
    ASSERT_EQ(exit_code(child("export-" + frames).wait_for(30s)), 0) << read_file(log_path("export-" + frames));

    const auto lines = lines_of(read_file(std::filesystem::path(out) / "truth_orientations.sto"));
    ASSERT_GT(lines.size(), 150u);
    // OpenSense's header: DataRate, DataType=Quaternion, version=3, OpenSimVersion, bsn's keys, endheader; then the
    // labels.
    EXPECT_EQ(lines[0].rfind("DataRate=", 0), 0u);
    EXPECT_NEAR(std::stod(lines[0].substr(9)), 100.0, 1.0);
    EXPECT_EQ(lines[1], "DataType=Quaternion");
    EXPECT_EQ(lines[2], "version=3");
    EXPECT_EQ(lines[3].rfind("OpenSimVersion=", 0), 0u);
    const auto end = std::find(lines.begin(), lines.end(), "endheader");
    ASSERT_NE(end, lines.end());
    EXPECT_NE(std::find(lines.begin(), end, "bsn_frames=" + frames), end) << "the header names the file's frames";
    const std::size_t first = static_cast<std::size_t>(end - lines.begin()) + 2;
    EXPECT_EQ(lines[first - 1], "time\timu_imu");

    // The recorded truth, as the simulator published it.
    const auto truth = r.streams_of(topic);
    ASSERT_EQ(truth.size(), 1u) << topic;
    const auto q = r.read_f64(truth[0], "quat", 4);
    ASSERT_EQ(q.size() / 4, lines.size() - first);
    // Undo the ground-frame change (ENU z up -> OpenSim y up: -90 degrees about x) and compare every row.
    const fusion::Quat to_opensim(std::cos(-std::numbers::pi / 4), std::sin(-std::numbers::pi / 4), 0.0, 0.0);
    double worst = 0.0;
    for (std::size_t i = first; i < lines.size(); ++i) {
      const auto cols = split(lines[i], '\t');
      ASSERT_EQ(cols.size(), 2u) << lines[i];
      const auto wxyz = split(cols[1], ',');  // scalar first, as OpenSense reads it
      ASSERT_EQ(wxyz.size(), 4u) << lines[i];
      const fusion::Quat read(std::stod(wxyz[0]), std::stod(wxyz[1]), std::stod(wxyz[2]), std::stod(wxyz[3]));
      const std::size_t k = i - first;
      const fusion::Quat sim(q[4 * k], q[4 * k + 1], q[4 * k + 2], q[4 * k + 3]);
      const fusion::Quat d = (to_opensim.conjugate() * read).conjugate() * sim;
      worst = std::max(worst, 2.0 * std::atan2(d.vec().norm(), std::abs(d.w())));
    }
    EXPECT_LE(worst, 1e-6) << "rad";
    // The ground frame is OpenSim's: the first sample's up axis (ENU z) is along OpenSim's +Y.
    const auto first_row = split(split(lines[first], '\t')[1], ',');
    const fusion::Quat q0(std::stod(first_row[0]), std::stod(first_row[1]), std::stod(first_row[2]),
                          std::stod(first_row[3]));
    const fusion::Quat sim0(q[0], q[1], q[2], q[3]);
    const fusion::Vec3 up_local = sim0.conjugate() * fusion::Vec3::UnitZ();
    EXPECT_NEAR((q0 * up_local - fusion::Vec3::UnitY()).norm(), 0.0, 1e-9);
  }
}

TEST_F(Export, CsvAndBroadFromOneSessionAndExit2OnBadInput) {
  const std::string session = record_session(29);
  const std::string csv = (dir() / "csv").string(), broad = (dir() / "broad").string();
  spawn("csv", {"export", session, "--format", "csv", "--out", csv});
  ASSERT_EQ(exit_code(child("csv").wait_for(30s)), 0) << read_file(log_path("csv"));
  const auto raw = lines_of(read_file(std::filesystem::path(csv) / "raw.csv"));
  ASSERT_GT(raw.size(), 150u);
  EXPECT_EQ(raw[0],
            "arrival_ns [ns since 1970],node_id,timestamp_ns [ns],seq,acc_x [m/s^2],acc_y [m/s^2],acc_z [m/s^2],"
            "gyr_x [rad/s],gyr_y [rad/s],gyr_z [rad/s],mag_x [uT],mag_y [uT],mag_z [uT],channels [bits]");
  EXPECT_EQ(split(raw[1], ',').size(), 14u);
  EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(csv) / "truth_orientation.csv"));

  spawn("broad", {"export", session, "--format", "broad", "--out", broad});
  ASSERT_EQ(exit_code(child("broad").wait_for(30s)), 0) << read_file(log_path("broad"));
  const io::Recording rec = io::read_broad_hdf5((std::filesystem::path(broad) / "imu.hdf5").string());
  EXPECT_EQ(rec.size(), raw.size() - 1);
  EXPECT_EQ(static_cast<std::size_t>(rec.opt_quat.rows()), rec.size());
  EXPECT_NEAR(rec.sampling_rate_hz, 100.0, 0.5);
  // Each sample keeps its own time: the CSV's timestamp column, row for row.
  ASSERT_EQ(rec.timestamp_ns.size(), rec.size());
  for (std::size_t i = 1; i < raw.size(); ++i) {
    ASSERT_EQ(std::to_string(rec.timestamp_ns[i - 1]), split(raw[i], ',')[2]) << "row " << i;
  }
  spawn("eval", {"eval", broad, "--filter", "seel_ruppin", "--json"});
  ASSERT_EQ(exit_code(child("eval").wait_for(60s)), 0) << read_file(log_path("eval"));
  EXPECT_NE(read_file(log_path("eval")).find("\"trial\": \"imu\""), std::string::npos) << read_file(log_path("eval"));

  // Bad input is a usage error (exit 2) naming the file: missing, empty, cut short.
  const auto cut = dir() / "cut.h5";
  std::filesystem::copy_file(session, cut);
  std::filesystem::resize_file(cut, std::filesystem::file_size(cut) / 2);
  write_file(dir() / "empty.h5", "");
  for (const auto& [name, file, says] : std::vector<std::tuple<std::string, std::string, std::string>>{
           {"missing", (dir() / "nope.h5").string(), "nope.h5: no such file"},
           {"empty", (dir() / "empty.h5").string(), "empty.h5: not an HDF5 file"},
           {"cut", cut.string(), "cut.h5: "}}) {
    spawn(name, {"export", file, "--format", "csv", "--out", (dir() / ("out-" + name)).string()});
    EXPECT_EQ(exit_code(child(name).wait_for(30s)), 2) << read_file(log_path(name));
    EXPECT_NE(read_file(log_path(name)).find(says), std::string::npos) << read_file(log_path(name));
  }
}

TEST_F(Export, EchoPrintsCsvAndJson) {
  const std::string domain = std::to_string(test_domain(21));
  spawn("sim", {"sim", "--node", "imu", "--domain", domain});
  spawn("csv", {"echo", "bsn/raw", "--format", "csv", "--count", "3", "--timeout", "15", "--domain", domain});
  spawn("json",
        {"echo", "bsn/truth/orientation", "--format", "json", "--count", "2", "--timeout", "15", "--domain", domain});
  ASSERT_EQ(exit_code(child("csv").wait_for(20s)), 0) << read_file(log_path("csv"));
  ASSERT_EQ(exit_code(child("json").wait_for(20s)), 0) << read_file(log_path("json"));
  std::vector<std::string> csv;
  for (const auto& l : lines_of(read_file(log_path("csv"))))
    if (l.rfind("node_id", 0) == 0 || l.rfind("imu,", 0) == 0) csv.push_back(l);
  ASSERT_EQ(csv.size(), 4u) << read_file(log_path("csv"));
  EXPECT_EQ(csv[0].rfind("node_id,timestamp_ns [ns],seq,acc_x [m/s^2]", 0), 0u) << csv[0];
  EXPECT_EQ(split(csv[1], ',').size(), 13u);
  std::vector<std::string> json;
  for (const auto& l : lines_of(read_file(log_path("json"))))
    if (l.rfind("{", 0) == 0) json.push_back(l);
  ASSERT_EQ(json.size(), 2u) << read_file(log_path("json"));
  EXPECT_EQ(json[0].rfind("{\"topic\": \"bsn/truth/orientation\", \"segment\": \"imu\", \"node_id\": \"imu\", ", 0), 0u)
      << json[0];
  EXPECT_NE(json[0].find("\"quat\": ["), std::string::npos);
}

}  // namespace
}  // namespace bsn::integration
