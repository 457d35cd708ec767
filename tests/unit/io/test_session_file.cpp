// Session files: columns appended in several writes read back exactly, keys that are not HDF5 names survive,
// an existing file is refused unless asked, and a file that is not a session says so.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "bsn/io/session_file.hpp"

namespace bsn::io {
namespace {

class SessionFile : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/bsn-session-test-XXXXXX";
    dir_ = mkdtemp(tmpl);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string file(const std::string& name) const { return (dir_ / name).string(); }
  std::filesystem::path dir_;
};

// The bulk layout (large chunks sized to a dataset's first block) is invisible to a reader; a stream's own
// attributes are read back with it.
TEST_F(SessionFile, BulkChunksAndStreamAttributesReadBackExactly) {
  const std::string path = file("bulk.h5");
  {
    SessionWriter w(path, false, {}, ChunkLayout::kBulk);
    const std::size_t a = w.add_stream("bsn/orientation", "thigh_l", "bsn::Orientation",
                                       {{"timestamp_ns", ColumnType::kU64, 1, "ns"}, {"quat", ColumnType::kF64, 4, ""}},
                                       {{"node_id", "imu3"}, {"empty", ""}});
    const std::size_t b = w.add_stream("bsn/status", "p", "bsn::Status", {{"wall_time_ns", ColumnType::kU64, 1, ""}});
    for (std::uint64_t i = 0; i < 10000; ++i) {
      const double q[4] = {1.0, static_cast<double>(i), -0.5, 1e-300};
      w.append(a, 0, &i, 1);
      w.append(a, 1, q, 1);
      if (i == 2999 || i == 7000) {  // blocks of unequal sizes: chunks filled partly, across writes
        w.stage();
        w.write_staged();
      }
    }
    const std::uint64_t one = 7;
    w.append(b, 0, &one, 1);
    w.close();
  }
  const SessionReader r(path);
  const auto s = r.streams_of("bsn/orientation");
  ASSERT_EQ(s.size(), 1u);
  EXPECT_EQ(s[0].attributes, (std::map<std::string, std::string>{{"node_id", "imu3"}, {"empty", ""}}));
  const auto ts = r.read_u64(s[0], "timestamp_ns");
  const auto q = r.read_f64(s[0], "quat", 4);
  ASSERT_EQ(ts.size(), 10000u);
  for (std::size_t i = 0; i < ts.size(); ++i) {
    ASSERT_EQ(ts[i], i);
    ASSERT_EQ(q[4 * i + 1], static_cast<double>(i));
    ASSERT_EQ(q[4 * i + 3], 1e-300);
  }
  EXPECT_EQ(r.read_u64(r.streams_of("bsn/status").at(0), "wall_time_ns"), std::vector<std::uint64_t>{7});
  EXPECT_TRUE(r.streams_of("bsn/status").at(0).attributes.empty());
}

TEST_F(SessionFile, ColumnsWrittenInSeveralFlushesReadBackExactly) {
  const std::string path = file("s.h5");
  {
    SessionWriter w(path, false, {{"host", "lab"}});
    const std::size_t a = w.add_stream("bsn/raw", "thigh/l", "bsn::RawSample",
                                       {{"seq", ColumnType::kU64, 1, ""}, {"acc", ColumnType::kF64, 3, "m/s^2"}});
    const std::size_t b = w.add_stream("bsn/raw", ".hidden", "bsn::RawSample", {{"seq", ColumnType::kU64, 1, ""}});
    for (std::uint64_t i = 0; i < 1500; ++i) {  // more than two chunks, over three writes
      const double acc[3] = {static_cast<double>(i), -0.5, 1e-300};
      w.append(a, 0, &i, 1);
      w.append(a, 1, acc, 1);
      if (i % 2 == 0) w.append(b, 0, &i, 1);
      if (i == 400 || i == 1100) {
        w.stage();
        w.write_staged();
      }
    }
    w.close();
  }
  const SessionReader r(path);
  EXPECT_EQ(r.attributes().at("host"), "lab");
  ASSERT_EQ(r.streams().size(), 2u);
  const auto raw = r.streams_of("bsn/raw");
  const auto& thigh = raw[0].key == "thigh/l" ? raw[0] : raw[1];
  const auto& hidden = raw[0].key == "thigh/l" ? raw[1] : raw[0];
  EXPECT_EQ(hidden.key, ".hidden");
  const auto seq = r.read_u64(thigh, "seq");
  const auto acc = r.read_f64(thigh, "acc", 3);
  ASSERT_EQ(seq.size(), 1500u);
  for (std::size_t i = 0; i < seq.size(); ++i) {
    ASSERT_EQ(seq[i], i);
    ASSERT_EQ(acc[3 * i], static_cast<double>(i));
    ASSERT_EQ(acc[3 * i + 2], 1e-300);
  }
  EXPECT_EQ(r.read_u64(hidden, "seq").size(), 750u);
  EXPECT_THROW(r.read_f64(thigh, "acc", 4), IoError);
  try {
    r.read_u64(thigh, "timestamp_ns");
    FAIL();
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("timestamp_ns"), std::string::npos) << e.what();
  }
}

TEST_F(SessionFile, ExistingFileRefusedUnlessOverwrite) {
  const std::string path = file("exists.h5");
  std::ofstream(path) << "keep";
  EXPECT_THROW(SessionWriter(path, false, {}), IoError);
  EXPECT_NO_THROW(SessionWriter(path, true, {}).close());
  EXPECT_TRUE(is_session_file(path));
}

TEST_F(SessionFile, NotASessionSaysSo) {
  const std::string path = file("text.h5");
  std::ofstream(path) << "not hdf5";
  try {
    SessionReader r(path);
    FAIL();
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos);
  }
  EXPECT_FALSE(is_session_file(path));
}

}  // namespace
}  // namespace bsn::io
