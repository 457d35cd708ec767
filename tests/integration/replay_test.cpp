// `bsn replay`: a recorded demo session replays and records again bit-identical; bsn fusion on a replayed BROAD
// trial gives the orientations the filter gives offline (what bsn eval scores); loops and node maps; truncated
// files and missing datasets give errors naming them.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <mutex>
#include <thread>

#include "bsn/dds/participant.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/io/session_file.hpp"
#include "process_fixture.hpp"
#include "session_streams.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;
using SampleInfo = eprosima::fastdds::dds::SampleInfo;

std::map<std::string, services::RawColumns> read_raw(const std::string& path) {
  const io::SessionReader r(path);
  std::map<std::string, services::RawColumns> out;
  for (const auto& s : r.streams_of("bsn/raw")) out[s.key] = services::read_raw_columns(r, s);
  return out;
}

std::uint64_t first_timestamp(const std::map<std::string, services::RawColumns>& tracks) {
  std::uint64_t t0 = UINT64_MAX;
  for (const auto& [node, t] : tracks) t0 = std::min(t0, t.timestamp_ns.front());
  return t0;
}

// Rotation angle between two unit quaternions (w, x, y, z), accurate also for tiny angles (no acos near 1).
double angle_between(const std::array<double, 4>& a, const fusion::Quat& b) {
  const fusion::Quat d = fusion::Quat(a[0], a[1], a[2], a[3]).conjugate() * b;
  return 2.0 * std::atan2(d.vec().norm(), std::abs(d.w()));
}

class Replay : public ProcessTest {};

TEST_F(Replay, RecordReplayRecordIsBitIdentical) {
  const std::string domain = std::to_string(test_domain(16));
  const std::string first = (dir() / "first.h5").string(), second = (dir() / "second.h5").string();
  spawn("record1", {"record", "--out", first, "--domain", domain, "--topic", "bsn/raw", "--duration", "5"});
  std::this_thread::sleep_for(1s);
  spawn("demo", {"demo", "--domain", domain, "--duration", "3"});
  ASSERT_EQ(exit_code(child("record1").wait_for(20s)), 0) << read_file(log_path("record1"));
  child("demo").wait_for(10s);

  spawn("record2", {"record", "--out", second, "--domain", domain, "--topic", "bsn/raw"});
  spawn("replay", {"replay", first, "--domain", domain});
  ASSERT_EQ(exit_code(child("replay").wait_for(20s)), 0) << read_file(log_path("replay"));
  std::this_thread::sleep_for(500ms);
  ASSERT_EQ(exit_code(stop("record2")), 0) << read_file(log_path("record2"));

  const auto a = read_raw(first), b = read_raw(second);
  ASSERT_EQ(a.size(), 7u);  // the demo's seven nodes
  ASSERT_EQ(b.size(), a.size());
  const std::uint64_t t0a = first_timestamp(a), t0b = first_timestamp(b);
  for (const auto& [node, ta] : a) {
    ASSERT_TRUE(b.count(node)) << node;
    const services::RawColumns& tb = b.at(node);
    ASSERT_EQ(tb.seq.size(), ta.seq.size()) << node;
    for (std::size_t i = 0; i < ta.seq.size(); ++i) {
      ASSERT_EQ(tb.seq[i], ta.seq[i]) << node << " " << i;
      ASSERT_EQ(tb.timestamp_ns[i] - t0b, ta.timestamp_ns[i] - t0a) << node << " " << i;
      ASSERT_EQ(tb.channels[i], ta.channels[i]) << node << " " << i;
    }
    // Bit-identical values: compare the bytes, so even a NaN payload or a signed zero would count.
    ASSERT_EQ(std::memcmp(ta.acc.data(), tb.acc.data(), ta.acc.size() * sizeof(double)), 0) << node;
    ASSERT_EQ(std::memcmp(ta.gyr.data(), tb.gyr.data(), ta.gyr.size() * sizeof(double)), 0) << node;
    ASSERT_EQ(std::memcmp(ta.mag.data(), tb.mag.data(), ta.mag.size() * sizeof(double)), 0) << node;
  }
}

std::filesystem::path shortest_broad_trial() {
  const char* env = std::getenv("BSN_BROAD_DIR");
  const std::filesystem::path dir =
      env ? std::filesystem::path(env) : std::filesystem::path(BSN_SCENARIO_DIR) / "../../../shared/data/broad";
  std::filesystem::path best;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
    if (e.path().extension() == ".hdf5" && (best.empty() || e.file_size() < std::filesystem::file_size(best))) {
      best = e.path();
    }
  }
  return best;
}

TEST_F(Replay, FusionOnAReplayedBroadTrialEqualsTheOfflineFilter) {
  const std::filesystem::path trial = shortest_broad_trial();
  if (trial.empty()) GTEST_SKIP() << "BROAD recordings not found (set BSN_BROAD_DIR)";
  const int domain = test_domain(17);
  const std::string body = (dir() / "one.yaml").string();
  write_file(body, "segments:\n  - name: seg\n    node: trial\n");

  // What bsn eval computes: one fresh default filter from the first sample over the file.
  const io::Recording rec = io::read_broad_hdf5(trial.string());
  auto filter = fusion::make_filter(fusion::FilterSpec{});
  std::vector<fusion::Quat> offline(rec.size());
  for (std::size_t i = 0; i < rec.size(); ++i) {
    filter->update(rec.sample(i));
    offline[i] = filter->orientation();
  }

  std::mutex m;
  std::vector<std::pair<std::uint64_t, std::array<double, 4>>> live;
  std::uint64_t accepted = 0, missing = 0, rejected = 0;
  {
    dds::Participant participant({domain, "replay test"});
    auto orientations =
        participant.make_reader(dds::kOrientationTopic, [&](const bsn::Orientation& o, const SampleInfo&) {
          std::lock_guard lock(m);
          live.emplace_back(o.timestamp_ns(), o.quat());
        });
    auto status = participant.make_reader(dds::kStatusTopic, [&](const bsn::Status& s, const SampleInfo&) {
      std::lock_guard lock(m);
      for (const auto& n : s.nodes()) {
        if (n.node_id() != "trial") continue;
        accepted = n.accepted();
        missing = n.missing();
        rejected = 0;
        for (const auto& r : n.rejected()) rejected += r.count();
      }
    });
    spawn("fusion", {"fusion", "--body", body, "--domain", std::to_string(domain), "--status-period", "0.2"});
    spawn("replay", {"replay", trial.string(), "--node-map", trial.stem().string() + "=trial", "--speed", "20",
                     "--domain", std::to_string(domain)});
    ASSERT_EQ(exit_code(child("replay").wait_for(60s)), 0) << read_file(log_path("replay"));
    ASSERT_TRUE(wait_until(
        [&] {
          std::lock_guard lock(m);
          return accepted == rec.size();
        },
        5s))
        << "fusion accepted " << accepted << " of " << rec.size() << " samples (missing " << missing << ", rejected "
        << rejected << ")";
  }
  std::lock_guard lock(m);
  EXPECT_EQ(missing, 0u);
  EXPECT_EQ(rejected, 0u);
  // Orientations are RELIABLE KEEP_LAST 1 to any reader, so a subscriber may miss some; each one that arrives must
  // be the offline filter's estimate of the same sample. The replayed timestamps are the file's plus one offset.
  ASSERT_GT(live.size(), rec.size() / 2);
  std::map<std::uint64_t, std::size_t> index_of;
  for (std::size_t i = 0; i < rec.size(); ++i) index_of[rec.time_ns(i)] = i;
  double worst = 0.0;
  const std::size_t first_index = [&] {
    // The first estimate that arrived belongs to one of the first samples: the one it equals.
    std::size_t best = 0;
    double best_err = 1e9;
    for (std::size_t k = 0; k < std::min<std::size_t>(rec.size(), 50); ++k) {
      const double e = angle_between(live.front().second, offline[k]);
      if (e < best_err) {
        best_err = e;
        best = k;
      }
    }
    return best;
  }();
  const std::uint64_t replay_base = live.front().first - rec.time_ns(first_index);
  for (const auto& [ts, q] : live) {
    const auto it = index_of.find(ts - replay_base);
    ASSERT_NE(it, index_of.end()) << "an estimate at a timestamp the file does not have";
    worst = std::max(worst, angle_between(q, offline[it->second]));
  }
  EXPECT_LE(worst, 1e-9) << "largest difference to the offline filter, rad";
}

TEST_F(Replay, CsvWithNodeMapAndLoopKeepsIntervalsAndContinuesSequence) {
  const std::string csv = (dir() / "walk.csv").string();
  std::string text = "t_s,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n";
  for (int i = 0; i < 20; ++i) text += std::to_string(i * 0.01) + ",0,0,9.81,0.1,0,0\n";
  write_file(csv, text);
  const std::string domain = std::to_string(test_domain(18));
  const std::string out = (dir() / "looped.h5").string();
  spawn("record", {"record", "--out", out, "--domain", domain, "--topic", "bsn/raw"});
  spawn("replay", {"replay", csv, "--node-map", "walk=thigh_l", "--loop", "--domain", domain});
  std::this_thread::sleep_for(2s);
  EXPECT_EQ(exit_code(stop("replay")), 0) << read_file(log_path("replay"));
  std::this_thread::sleep_for(300ms);
  ASSERT_EQ(exit_code(stop("record")), 0) << read_file(log_path("record"));
  const auto tracks = read_raw(out);
  ASSERT_EQ(tracks.size(), 1u);
  ASSERT_TRUE(tracks.count("thigh_l"));
  const services::RawColumns& t = tracks.at("thigh_l");
  ASSERT_GT(t.seq.size(), 60u);  // more than three passes of 20 samples in about 1.7 s
  for (std::size_t i = 1; i < t.seq.size(); ++i) {
    ASSERT_EQ(t.seq[i], t.seq[i - 1] + 1) << i;
    ASSERT_EQ(t.timestamp_ns[i] - t.timestamp_ns[i - 1], 10000000u) << i;  // 10 ms, across the loop's seam too
  }
}

TEST_F(Replay, TruncatedFileAndMissingDatasetGiveClearErrors) {
  // A session file without the raw stream's seq column.
  const std::string missing = (dir() / "missing.h5").string();
  {
    io::SessionWriter w(missing, false, {});
    const std::size_t s =
        w.add_stream("bsn/raw", "imu", "bsn::RawSample", {{"timestamp_ns", io::ColumnType::kU64, 1, "ns"}});
    const std::uint64_t ts = 5;
    w.append(s, 0, &ts, 1);
    w.close();
  }
  spawn("missing", {"replay", missing, "--readers", "0"});
  EXPECT_EQ(exit_code(child("missing").wait_for(10s)), 2);
  const std::string log = read_file(log_path("missing"));
  EXPECT_NE(log.find(missing), std::string::npos) << log;
  EXPECT_NE(log.find("/bsn/raw/imu/seq"), std::string::npos) << log;

  // A real trial cut in half.
  const std::string cut = (dir() / "cut.hdf5").string();
  {
    io::Recording rec;
    rec.sampling_rate_hz = 100;
    rec.gyr = io::RowsX3::Zero(5000, 3);
    rec.acc = io::RowsX3::Constant(5000, 3, 1.0);
    rec.mag = io::RowsX3::Constant(5000, 3, 2.0);
    io::write_broad_hdf5(cut, rec);
    std::filesystem::resize_file(cut, std::filesystem::file_size(cut) / 2);
  }
  spawn("cut", {"replay", cut, "--readers", "0"});
  EXPECT_EQ(exit_code(child("cut").wait_for(10s)), 2);
  const std::string cut_log = read_file(log_path("cut"));
  EXPECT_NE(cut_log.find(cut), std::string::npos) << cut_log;
  EXPECT_EQ(cut_log.find("terminate"), std::string::npos) << cut_log;
}

}  // namespace
}  // namespace bsn::integration
