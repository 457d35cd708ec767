// `bsn eval` as a user runs it: files and folders in, a table or the agreed JSON out, an SVG plot, clear errors.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <sstream>

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

// The manual's accuracy table is this output: every filter once, sorted by its mean total error, with the same
// figures the JSON gives (the table rounds to 0.01 deg), and its worst trial over its mean.
TEST_F(EvalCommand, MarkdownTableIsTheJsonMeansSortedWithTheWorstTrial) {
  write_trial("walk_a", 5);
  write_trial("walk_b", 6);
  const std::string trials = (dir() / "trials").string();
  ASSERT_EQ(exit_code(run("json", {"eval", trials, "--json"})), 0) << read_file(log_path("json"));
  ASSERT_EQ(exit_code(run("markdown", {"eval", trials, "--markdown"})), 0) << read_file(log_path("markdown"));
  const std::string json = read_file(log_path("json")), markdown = read_file(log_path("markdown"));
  double previous_total = 0.0;
  std::size_t rows = 0;
  std::istringstream lines(markdown);
  for (std::string line; std::getline(lines, line) && !line.empty();) {
    if (line.rfind("| `", 0) != 0) continue;
    const std::string filter = line.substr(3, line.find('`', 3) - 3);
    double total = 0, heading = 0, inclination = 0, worst = 0, ratio = 0;
    char worst_trial[64] = {};
    const std::string cells = line.substr(line.find('`', 3) + 1);
    ASSERT_EQ(std::sscanf(cells.c_str(), " | %lf° | %lf° | %lf° | %63s (%lf°) | %lf× |", &total, &heading, &inclination,
                          worst_trial, &worst, &ratio),
              6)
        << line;
    const std::string key = "{\"filter\": \"" + filter + "\", \"total_rmse_deg\": ";
    const std::size_t at = json.find(key, json.find("\"means\""));
    ASSERT_NE(at, std::string::npos) << filter << "\n" << json;
    EXPECT_NEAR(total, std::stod(json.substr(at + key.size())), 0.005 + 1e-9) << filter;
    EXPECT_GE(total, previous_total) << "sorted by mean total error: " << filter;
    EXPECT_NEAR(ratio, worst / total, 0.01 + 0.01 / total) << line;  // both rounded to 0.01
    EXPECT_GE(worst, total - 0.005) << "the worst trial is not below the mean: " << line;
    previous_total = total;
    ++rows;
  }
  EXPECT_EQ(rows, fusion::filter_names().size()) << markdown;
  EXPECT_NE(markdown.find("| walk_b |"), std::string::npos) << "a row per trial\n" << markdown;
  EXPECT_EQ(exit_code(run("both", {"eval", trials, "--markdown", "--json"})), 2);
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
