// `bsn session`: one command runs a lab session on the simulated lower body (the shipped session file): the
// alignment, a 30 s trial recorded and exported to OpenSim files, and every process it started stopped.
#include <gtest/gtest.h>

#include <algorithm>
#include <sstream>

#include "bsn/io/session_file.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;

const std::filesystem::path kRepository = BSN_SOURCE_DIR;

TEST_F(ProcessTest, SessionAlignsRecordsExportsAndStopsEverything) {
  const int domain = test_domain(95);
  // The shipped session file, run from this test's folder (where it writes calib/ and trials/).
  auto& session = spawn_command("session", {"/bin/sh", "-c",
                                            "cd '" + dir().string() + "' && exec '" + bsn_executable() + "' session '" +
                                                (kRepository / "deploy/sessions/lower_body_sim.yaml").string() +
                                                "' --domain " + std::to_string(domain) + " < /dev/null"});
  const auto status = session.wait_for(150s);
  ASSERT_TRUE(exited_cleanly(status)) << describe_status(status) << "\n" << tail(log_path("session"), 60);
  const std::string log = read_file(log_path("session"));
  EXPECT_NE(log.find("alignment: stand still"), std::string::npos) << "the N-pose is asked for:\n" << log;
  for (const char* node : {"pelvis", "thigh_l", "shank_l", "foot_l", "thigh_r", "shank_r", "foot_r"})
    EXPECT_NE(log.find(std::string("alignment: ") + node + " aligned"), std::string::npos) << node << "\n" << log;
  // Nothing left running in the domain.
  EXPECT_TRUE(bsn_processes_in_domain(domain).empty());

  // 30 s recorded, after the alignment: every estimate in its segment frame.
  const io::SessionReader r((dir() / "trials" / "walk.h5").string());
  const auto streams = r.streams_of("bsn/orientation");
  ASSERT_EQ(streams.size(), 7u);
  // The trial starts once every segment's streams flow (at most 10 s after the first sample) and lasts 30 s; what
  // arrived before is kept. So each stream spans 30 s to 40 s, and all end together (within the 50 ms tick and a
  // sample period, plus delivery on a loaded machine).
  std::vector<std::uint64_t> ends;
  for (const auto& s : streams) {
    const auto ts = r.read_u64(s, "timestamp_ns");
    const auto flags = r.read_u32(s, "flags");
    ASSERT_GT(ts.size(), 2000u) << s.key << ": about 30 s at 100 Hz";
    const double span_s = static_cast<double>(ts.back() - ts.front()) * 1e-9;
    EXPECT_GE(span_s, 29.5) << s.key;
    EXPECT_LE(span_s, 40.5) << s.key;
    ends.push_back(ts.back());
    std::size_t aligned = 0;
    for (const auto f : flags) aligned += (f & 32u) != 0;  // FLAG_SEGMENT_FRAME
    EXPECT_EQ(aligned, flags.size()) << s.key << ": recorded after the alignment";
  }
  const auto [first_end, last_end] = std::minmax_element(ends.begin(), ends.end());
  EXPECT_LT(static_cast<double>(*last_end - *first_end) * 1e-9, 0.5) << "the streams end together";
  // Exported: the OpenSense files in segment frames, the joint angles as .mot, the (empty) event markers.
  const auto out = dir() / "trials" / "walk";
  for (const char* f :
       {"orientations.sto", "calibration.sto", "joint_angles.mot", "truth_orientations.sto", "events.csv"})
    EXPECT_TRUE(std::filesystem::exists(out / f)) << f;
  EXPECT_NE(read_file(out / "orientations.sto").find("bsn_frames=segment\n"), std::string::npos);
  EXPECT_NE(read_file(out / "joint_angles.mot").find("knee_l_flexion_extension"), std::string::npos);
  EXPECT_EQ(read_file(out / "events.csv"), "unix_ns,monotonic_ns,label\n");
  for (const char* node : {"pelvis", "thigh_l", "foot_r"})
    EXPECT_TRUE(std::filesystem::exists(dir() / "calib" / (std::string(node) + ".alignment.calib.yaml"))) << node;
}

TEST_F(ProcessTest, ABadSessionFileStopsBeforeAnythingRunsNamingItsLine) {
  const std::string body = (kRepository / "deploy/bodies/lower_body.yaml").string();
  const std::string scenario = (kRepository / "sim_publishers/scenarios/gait_alignment.yaml").string();
  const std::string good = "body: " + body + "\nnodes:\n  simulated: {scenario: " + scenario +
                           "}\nrecord: {out: " + (dir() / "trials").string() + ", duration_s: 5}\n";
  std::filesystem::create_directories(dir() / "trials");
  write_file(dir() / "trials" / "taken.h5", "");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {good + "colour: red\n", ":5: unknown key 'colour' in the session"},
      {"nodes:\n  simulated: {scenario: " + scenario + "}\nrecord: {duration_s: 5}\n", "the session needs body"},
      {good + "trials: [walk, ../up]\n", ":5: trial name '../up'"},
      {good + "export: [sto, mp4]\n", ":5: unknown format 'mp4'"},
      {"body: " + body + "\nnodes:\n  simulated: {scenario: " + scenario + "}\nrecord: {duration_s: -5}\n",
       ":4: record.duration_s must be in (0, 86400] s"},
      {good + "record_typo: 1\n", "unknown key 'record_typo'"},
      {good + "trials: [taken]\n", "taken.h5 exists"},
  };
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const auto file = dir() / ("s" + std::to_string(i) + ".yaml");
    write_file(file, cases[i].first);
    const std::string name = "bad" + std::to_string(i);
    auto& p = spawn(name, {"session", file.string(), "--domain", std::to_string(test_domain(96))});
    EXPECT_EQ(exit_code(p.wait_for(20s)), 2) << cases[i].first << read_file(log_path(name));
    EXPECT_NE(read_file(log_path(name)).find(cases[i].second), std::string::npos) << cases[i].first << "\n"
                                                                                  << read_file(log_path(name));
  }
  EXPECT_TRUE(bsn_processes_in_domain(test_domain(96)).empty());
}

}  // namespace
}  // namespace bsn::integration
