// `bsn eval` as a user runs it: files and folders in, a table or the agreed JSON out, an SVG plot, clear errors.
#include <gtest/gtest.h>

#include <cmath>

#include "bsn/eval/tune_runner.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/sim/scenario.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

class EvalCommand : public ProcessTest {
 protected:
  // Readings of a known rotation with its truth as reference, written as BROAD HDF5.
  std::string write_trial(const std::string& name, std::uint64_t seed) {
    const io::Recording rec = eval::simulate_recording(sim::swing_scenario("imu", seed, 100.0, 15.0));
    const std::string path = (dir() / "trials" / (name + ".hdf5")).string();
    std::filesystem::create_directories(dir() / "trials");
    io::write_broad_hdf5(path, rec);
    return path;
  }

  // Runs `bsn eval ARGS` to completion; returns the exit status, output in <dir>/<name>.log.
  std::optional<int> run(const std::string& name, const std::vector<std::string>& args) {
    spawn(name, args);
    return child(name).wait_for(std::chrono::seconds(60));
  }
};

TEST_F(EvalCommand, FolderToJsonAndPlot) {
  write_trial("walk_a", 1);
  write_trial("walk_b", 2);
  const std::string svg = (dir() / "errors.svg").string();
  const auto st =
      run("eval", {"eval", (dir() / "trials").string(), "--filter", "complementary", "--json", "--plot", svg});
  ASSERT_EQ(exit_code(st), 0) << read_file(log_path("eval"));
  const std::string out = read_file(log_path("eval"));
  EXPECT_NE(out.find("{\"trials\": [{\"trial\": \"walk_a\", \"filter\": \"complementary\", \"total_rmse_deg\": "),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("{\"trial\": \"walk_b\""), std::string::npos) << out;
  EXPECT_NE(out.find("\"means\": [{\"filter\": \"complementary\", \"total_rmse_deg\": "), std::string::npos) << out;
  const std::string image = read_file(svg);
  EXPECT_EQ(image.rfind("<svg", 0), 0u);
  EXPECT_NE(image.find("walk_b"), std::string::npos);
}

TEST_F(EvalCommand, TableWithEveryFilterByDefault) {
  const std::string trial = write_trial("one", 3);
  const auto st = run("eval", {"eval", trial});
  ASSERT_EQ(exit_code(st), 0) << read_file(log_path("eval"));
  const std::string out = read_file(log_path("eval"));
  EXPECT_NE(out.find("total"), std::string::npos);
  for (const auto& name : fusion::filter_names()) EXPECT_NE(out.find(name), std::string::npos) << name << "\n" << out;
}

TEST_F(EvalCommand, ClearErrors) {
  const std::string trial = write_trial("one", 4);
  EXPECT_EQ(exit_code(run("unknown_filter", {"eval", trial, "--filter", "nonesuch"})), 2);
  EXPECT_NE(read_file(log_path("unknown_filter")).find("unknown filter 'nonesuch'"), std::string::npos);
  EXPECT_EQ(exit_code(run("bad_param", {"eval", trial, "--filter", "complementary:tau=abc"})), 2);
  EXPECT_NE(read_file(log_path("bad_param")).find("is not a number"), std::string::npos);
  EXPECT_EQ(exit_code(run("missing", {"eval", (dir() / "nope.hdf5").string()})), 2);
  EXPECT_NE(read_file(log_path("missing")).find("nope.hdf5: no such file"), std::string::npos);
  write_file(dir() / "broken.hdf5", "not an hdf5 file");
  EXPECT_EQ(exit_code(run("broken", {"eval", (dir() / "broken.hdf5").string(), "--filter", "complementary"})), 2);
  EXPECT_NE(read_file(log_path("broken")).find("broken.hdf5: cannot open as HDF5"), std::string::npos);
  // A file in the BROAD layout with no samples, and a real trial cut short: bad input, not an empty score.
  {
    io::Recording empty;
    empty.sampling_rate_hz = 100;
    io::write_broad_hdf5((dir() / "empty.hdf5").string(), empty);
  }
  EXPECT_EQ(exit_code(run("empty", {"eval", (dir() / "empty.hdf5").string(), "--filter", "complementary"})), 2);
  EXPECT_NE(read_file(log_path("empty")).find("empty.hdf5: fewer than two samples"), std::string::npos)
      << read_file(log_path("empty"));
  const std::string cut = write_trial("cut", 5);
  std::filesystem::resize_file(cut, std::filesystem::file_size(cut) / 2);
  EXPECT_EQ(exit_code(run("cut", {"eval", cut, "--filter", "complementary"})), 2) << read_file(log_path("cut"));
}

}  // namespace
}  // namespace bsn::integration
