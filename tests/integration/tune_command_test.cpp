// `bsn tune` as a user runs it: recordings in, a `filter:` block with fit and held-out errors out, JSON, and a
// clear error naming the file or the parameter for bad input (exit 2). No DDS.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "bsn/eval/tune_runner.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/sim/scenario.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

class TuneCommand : public ProcessTest {
 protected:
  // Noisy readings of a known motion (the simulator's default sensor), the truth as reference.
  io::Recording trial(std::uint64_t seed) {
    return eval::simulate_recording(sim::swing_scenario("imu", seed, 100.0, 12.0));
  }
  std::string write(const std::string& name, const io::Recording& rec) {
    std::filesystem::create_directories(dir() / "trials");
    const std::string path = (dir() / "trials" / (name + ".hdf5")).string();
    io::write_broad_hdf5(path, rec);
    return path;
  }
  std::optional<int> run(const std::string& name, const std::vector<std::string>& args) {
    spawn(name, args);
    return child(name).wait_for(std::chrono::seconds(90));
  }
};

TEST_F(TuneCommand, FilterBlockFitAndHeldOut) {
  const std::string a = write("walk_a", trial(1)), b = write("walk_b", trial(2)), c = write("walk_c", trial(3));
  const std::string json = (dir() / "tune.json").string();
  const auto st = run(
      "tune", {"tune", "--filter", "mekf", a, b, c, "--param", "sigma_a=0.05:50:log", "--param", "sigma_g=1e-3:1:log",
               "--holdout", "1", "--max-evaluations", "30", "--global-points", "8", "--json", json});
  ASSERT_EQ(exit_code(st), 0) << read_file(log_path("tune"));
  const std::string out = read_file(log_path("tune"));
  EXPECT_NE(out.find("filter: {name: mekf, sigma_a: "), std::string::npos) << out;
  EXPECT_NE(out.find("walk_c"), std::string::npos) << out;
  EXPECT_NE(out.find("criterion nez"), std::string::npos) << out;
  EXPECT_NE(out.find("held-out"), std::string::npos) << out;
  const std::string j = read_file(json);
  EXPECT_NE(j.find("\"filter\": \"mekf\", \"criterion\": \"nez\", \"parameters\": {\"sigma_a\": "), std::string::npos)
      << j;
  EXPECT_NE(j.find("{\"recording\": \"walk_c\", \"set\": \"held_out\""), std::string::npos) << j;
  EXPECT_NE(j.find("\"held_out_criterion_deg\": "), std::string::npos) << j;
}

TEST_F(TuneCommand, BadInputNamesTheFileOrTheParameter) {
  const io::Recording good = trial(4);
  const std::string ok = write("ok", good);
  io::Recording no_ref = good;
  no_ref.opt_quat.resize(0, 4);
  const std::string no_ref_path = write("no_reference", no_ref);
  io::Recording nan_ref = good;
  nan_ref.opt_quat.setConstant(std::numeric_limits<double>::quiet_NaN());
  const std::string nan_path = write("nan_reference", nan_ref);

  struct Case {
    const char* name;
    std::vector<std::string> args;
    std::string expected;
  };
  const std::vector<Case> cases = {
      {"no_reference", {"tune", "--filter", "mekf", no_ref_path}, "no_reference.hdf5: no reference orientation"},
      {"nan_reference", {"tune", "--filter", "mekf", nan_path}, "nan_reference.hdf5: the reference orientation is NaN"},
      {"unknown_param",
       {"tune", "--filter", "mekf", ok, "--param", "nonesuch=1:2"},
       "filter 'mekf' has no parameter 'nonesuch'"},
      {"empty_range", {"tune", "--filter", "mekf", ok, "--param", "sigma_a=1:1"}, "--param sigma_a: empty or inverted"},
      {"nan_range", {"tune", "--filter", "mekf", ok, "--param", "sigma_a=nan:1"}, "--param sigma_a lower bound"},
      {"no_ranges", {"tune", "--filter", "complementary", ok}, "name what to identify with --param"},
      {"holdout_all", {"tune", "--filter", "mekf", ok, "--holdout", "1"}, "--holdout 1 leaves no recording"},
  };
  for (const Case& c : cases) {
    EXPECT_EQ(exit_code(run(c.name, c.args)), 2) << c.name << ": " << read_file(log_path(c.name));
    EXPECT_NE(read_file(log_path(c.name)).find(c.expected), std::string::npos)
        << c.name << ": " << read_file(log_path(c.name));
  }
}

// --by-intensity: 15 s at rest, then the swing; the rest is Nez's static class, which gets its own set.
TEST_F(TuneCommand, ByIntensityIdentifiesTheStaticClassOnItsOwn) {
  const io::Recording swing = trial(5);
  const Eigen::Index rest = 1500, n = rest + swing.gyr.rows();
  io::Recording rec;
  rec.sampling_rate_hz = 100.0;
  rec.gyr.resize(n, 3);
  rec.acc.resize(n, 3);
  rec.mag.resize(n, 3);
  rec.opt_quat.resize(n, 4);
  const fusion::Quat q0(swing.opt_quat(0, 0), swing.opt_quat(0, 1), swing.opt_quat(0, 2), swing.opt_quat(0, 3));
  for (Eigen::Index i = 0; i < rest; ++i) {  // exact readings at the swing's first orientation
    rec.gyr.row(i).setZero();
    rec.acc.row(i) = (q0.conjugate() * fusion::Vec3(0, 0, fusion::kGravity)).transpose();
    rec.mag.row(i) = swing.mag.row(0);
    rec.opt_quat.row(i) = swing.opt_quat.row(0);
  }
  rec.gyr.bottomRows(swing.gyr.rows()) = swing.gyr;
  rec.acc.bottomRows(swing.gyr.rows()) = swing.acc;
  rec.mag.bottomRows(swing.gyr.rows()) = swing.mag;
  rec.opt_quat.bottomRows(swing.gyr.rows()) = swing.opt_quat;
  const std::string path = write("rest_then_swing", rec);
  const std::string json = (dir() / "classes.json").string();
  const auto st = run("classes", {"tune", "--filter", "mekf", path, "--by-intensity", "--param", "sigma_g=1e-3:1:log",
                                  "--max-evaluations", "12", "--global-points", "4", "--json", json});
  ASSERT_EQ(exit_code(st), 0) << read_file(log_path("classes"));
  const std::string out = read_file(log_path("classes"));
  EXPECT_NE(out.find("intensity static:\nfilter: {name: mekf, sigma_g: "), std::string::npos) << out;
  EXPECT_NE(read_file(json).find("{\"intensity\": \"static\", \"filter\": \"mekf\""), std::string::npos);
  // The per-class sets end as mekf_adaptive's table, at the recording's rate.
  EXPECT_NE(out.find("filter: {name: mekf_adaptive, table_rate_hz: 100, sigma_g_static: "), std::string::npos) << out;
  EXPECT_NE(read_file(json).find("\"mekf_adaptive\": {\"name\": \"mekf_adaptive\", \"parameters\": {"),
            std::string::npos);
}

// tune's starting point: `bsn calibrate --allan` on the simulator's 30-minute static recording with a 50 Hz
// magnetometer analyses the magnetometer at its own rate (it was "skipped" and recommended sigma_m = 0 before).
TEST_F(TuneCommand, AllanAnalysesA50HzMagnetometerAndNeverRecommendsZero) {
  const std::string out_dir = (dir() / "still").string();
  ASSERT_EQ(exit_code(run("sim", {"sim", "--scenario", std::string(BSN_SCENARIO_DIR) + "/allan_static_30min.yaml",
                                  "--out", out_dir})),
            0)
      << read_file(log_path("sim"));
  const std::string svg = (dir() / "allan.svg").string();
  ASSERT_EQ(exit_code(run("allan", {"calibrate", "--allan", out_dir + "/imu.hdf5", "--plot", svg})), 0)
      << read_file(log_path("allan"));
  const std::string out = read_file(log_path("allan"));
  EXPECT_NE(out.find("mag_x  uT              50"), std::string::npos) << out;
  EXPECT_EQ(out.find("skipped"), std::string::npos) << out;
  EXPECT_EQ(out.find("sigma_m 0 "), std::string::npos) << out;
  EXPECT_NE(out.find("sigma_m 0."), std::string::npos) << out;  // a positive figure below 1 uT
  const std::string image = read_file(svg);
  EXPECT_NE(image.find("Allan deviation (uT)"), std::string::npos);
  EXPECT_NE(image.find("Allan deviation (rad/s)"), std::string::npos);
  EXPECT_NE(image.find("<circle"), std::string::npos);  // where N was read
}

}  // namespace
}  // namespace bsn::integration
