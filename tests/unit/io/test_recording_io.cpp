// Recordings round-trip through BROAD-layout HDF5, and CSV files are read by their documented columns.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <thread>
#include <utility>
#include <vector>

#include "bsn/io/recording.hpp"

namespace bsn::io {
namespace {

class TempDir {
 public:
  TempDir() {
    char tmpl[] = "/tmp/bsn-io-test-XXXXXX";
    path_ = mkdtemp(tmpl);
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

Recording small_recording() {
  Recording r;
  r.sampling_rate_hz = 100.0;
  r.gyr = RowsX3::Random(5, 3);
  r.acc = RowsX3::Random(5, 3);
  r.mag = RowsX3::Random(5, 3);
  r.mag.row(2).setConstant(std::nan(""));
  r.opt_quat = RowsX4::Random(5, 4);
  r.movement = {0, 1, 1, 1, 0};
  return r;
}

TEST(BroadHdf5, RoundTripIsExact) {
  TempDir dir;
  const Recording r = small_recording();
  write_broad_hdf5(dir.file("a.hdf5"), r);
  const Recording back = read_broad_hdf5(dir.file("a.hdf5"));
  EXPECT_EQ(back.sampling_rate_hz, 100.0);
  EXPECT_EQ(back.gyr, r.gyr);
  EXPECT_EQ(back.acc, r.acc);
  EXPECT_TRUE(back.mag.row(2).array().isNaN().all());
  EXPECT_EQ(back.mag.row(3), r.mag.row(3));
  EXPECT_EQ(back.opt_quat, r.opt_quat);
  EXPECT_EQ(back.movement, r.movement);
  EXPECT_EQ(back.opt_pos.rows(), 0);
}

// A session with a gap and a rate change exports with each sample's time, and eval then takes dt from it.
TEST(BroadHdf5, EachSampleTimeRoundTripsWhenGiven) {
  TempDir dir;
  Recording r = small_recording();
  r.timestamp_ns = {1'000'000'000u, 1'010'000'000u, 1'020'000'000u, 1'520'000'000u, 1'521'000'000u};
  write_broad_hdf5(dir.file("t.hdf5"), r);
  const Recording back = read_broad_hdf5(dir.file("t.hdf5"));
  EXPECT_EQ(back.timestamp_ns, r.timestamp_ns);
  EXPECT_EQ(back.sample(3).timestamp_ns, 1'520'000'000u);
  // Without times the file has no such dataset and reads back uniform.
  write_broad_hdf5(dir.file("u.hdf5"), small_recording());
  EXPECT_TRUE(read_broad_hdf5(dir.file("u.hdf5")).timestamp_ns.empty());
}

// The same recording written twice gives the same bytes (no modification times in the file), so simulator and
// recorder outputs can be compared with cmp. HDF5 stores times in whole seconds: the writes are > 1 s apart.
TEST(BroadHdf5, SameRecordingSameBytes) {
  TempDir dir;
  const Recording r = small_recording();
  write_broad_hdf5(dir.file("first.hdf5"), r);
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  write_broad_hdf5(dir.file("second.hdf5"), r);
  const auto bytes = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const std::string first = bytes(dir.file("first.hdf5"));
  ASSERT_FALSE(first.empty());
  EXPECT_TRUE(first == bytes(dir.file("second.hdf5")));
}

TEST(BroadHdf5, SamplesCarryUniformTimeAndMissingMagnetometer) {
  const Recording r = small_recording();
  EXPECT_EQ(r.sample(3).timestamp_ns, 30'000'000u);
  EXPECT_FALSE(r.sample(2).has_mag);
  EXPECT_TRUE(r.sample(1).has_mag);
}

TEST(BroadHdf5, ErrorsNameTheFileAndTheProblem) {
  TempDir dir;
  try {
    read_broad_hdf5(dir.file("missing.hdf5"));
    FAIL();
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.hdf5"), std::string::npos);
  }
  std::ofstream(dir.file("text.hdf5")) << "not hdf5";
  EXPECT_THROW(read_broad_hdf5(dir.file("text.hdf5")), IoError);
  Recording bad = small_recording();
  bad.acc = RowsX3::Zero(4, 3);
  try {
    write_broad_hdf5(dir.file("bad.hdf5"), bad);
    FAIL();
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("different lengths"), std::string::npos) << e.what();
  }
}

TEST(Csv, ReadsColumnsInAnyOrder) {
  TempDir dir;
  std::ofstream(dir.file("r.csv")) << "# a comment\n"
                                      "t_s,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z,movement\n"
                                      "0.00,0.1,0.2,0.3,0,0,9.81,20,0,-40,1\n"
                                      "0.02,0.1,0.2,0.3,0,0,9.81,,,,1\n"
                                      "0.04,0.1,0.2,0.3,0,0,9.81,21,0,-40,0\n";
  const Recording r = read_csv(dir.file("r.csv"));
  ASSERT_EQ(r.size(), 3u);
  EXPECT_NEAR(r.sampling_rate_hz, 50.0, 1e-9);
  EXPECT_EQ(r.sample(1).timestamp_ns, 20'000'000u);
  EXPECT_EQ(r.sample(0).gyr, fusion::Vec3(0.1, 0.2, 0.3));
  EXPECT_FALSE(r.sample(1).has_mag);
  EXPECT_EQ(r.sample(2).mag.x(), 21.0);
  EXPECT_EQ(r.movement, (std::vector<std::uint8_t>{1, 1, 0}));
}

TEST(Csv, ErrorsNameFileLineAndProblem) {
  TempDir dir;
  std::ofstream(dir.file("m.csv")) << "t_s,acc_x,acc_y,acc_z\n0,0,0,9.8\n";
  try {
    read_csv(dir.file("m.csv"));
    FAIL();
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("gyr_x"), std::string::npos) << e.what();
  }
  std::ofstream(dir.file("n.csv"))
      << "t_s,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,9.8,0,0,0\n0.01,0,abc,9.8,0,0,0\n";
  try {
    read_csv(dir.file("n.csv"));
    FAIL();
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("n.csv:3: 'abc' is not a number"), std::string::npos) << e.what();
  }
}

TEST(Csv, ATimeBeyondIntegerNanosecondsIsAnErrorNotUndefinedBehaviour) {
  // Found by the csv fuzz target: 1e82 ns (or 1e300 s) was converted to uint64, which is undefined behaviour.
  TempDir dir;
  const std::vector<std::pair<std::string, std::string>> cases = {{"t_ns", "1e82"}, {"t_s", "1e300"}, {"t_s", "inf"}};
  for (const auto& [column, value] : cases) {
    std::ofstream(dir.file("t.csv")) << column << ",acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n0,0,0,9.8,0,0,0\n"
                                     << value << ",0,0,9.8,0,0,0\n";
    try {
      read_csv(dir.file("t.csv"));
      ADD_FAILURE() << "accepted " << column << " = " << value;
    } catch (const IoError& e) {
      EXPECT_NE(std::string(e.what()).find("t.csv:3: time must be >= 0 and below 9e18 ns"), std::string::npos)
          << e.what();
    }
  }
}

}  // namespace
}  // namespace bsn::io
