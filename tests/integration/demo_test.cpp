// `bsn demo`: starts fusion and seven sims itself, prints joint angles, stops everything and leaves nothing behind.
#include <gtest/gtest.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <map>
#include <regex>
#include <string>
#include <thread>

#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;

class DemoCommand : public ProcessTest {};

/// True for a Fast DDS shared-memory port file or port semaphore ("fastrtps_port14160", "sem.fastrtps_port14160_mutex")
/// of a port outside `domain`'s range (7400 + 250 * domain + [0, 250)): another domain's, so not ours.
bool foreign_domain_port_entry(const std::string& name, int domain) {
  std::smatch m;
  static const std::regex port(R"(fastrtps_port(\d+))");
  if (!std::regex_search(name, m, port)) return false;
  const long p = std::stol(m[1].str());
  const long base = 7400 + 250L * domain;
  return p < base || p >= base + 250;
}

TEST_F(DemoCommand, Demo) {
  const int kDomain = test_domain(7);
  const std::set<std::string> shm_before = directory_entries("/dev/shm");

  auto& demo = spawn("demo", {"demo", "--duration", "26", "--domain", std::to_string(kDomain)});
  // While it runs, neither the demo nor its children (fusion, seven sims) may map or open anything in /dev/shm.
  std::set<std::string> shm_used;
  std::size_t most_children = 0;
  const auto deadline = Clock::now() + 70s;  // 26 s of demo plus start-up and shutdown
  while (demo.running() && Clock::now() < deadline) {
    const std::vector<int> children = children_of(demo.pid());
    most_children = std::max(most_children, children.size());
    shm_used.merge(shm_entries_used_by(demo.pid()));
    for (int c : children) shm_used.merge(shm_entries_used_by(c));
    std::this_thread::sleep_for(250ms);
  }
  const auto st = demo.wait_for(1s);
  ASSERT_TRUE(st.has_value()) << "bsn demo --duration 26 still runs after 70 s";
  EXPECT_TRUE(exited_cleanly(st)) << "bsn demo " << describe_status(st);
  EXPECT_EQ(most_children, 9u) << "child processes of the demo seen at once (fusion, calibration + 7 sims)";
  EXPECT_TRUE(shm_used.empty()) << "the demo's processes used shared memory: " << ::testing::PrintToString(shm_used);

  const std::string out = read_file(log_path("demo"));
  std::smatch m;
  const std::regex summary(R"(bsn demo: (\d+) joint-angle samples from (\d+) of (\d+) joints)");
  ASSERT_TRUE(std::regex_search(out, m, summary)) << "no summary line in the demo's output";
  EXPECT_GT(std::stoull(m[1].str()), 0u);
  EXPECT_EQ(m[2].str(), "6");
  EXPECT_EQ(m[3].str(), "6");
  // Joint-angle rows of the live view: named anatomical angles, e.g. "knee_l     flexion_extension     41.20 ...".
  EXPECT_TRUE(std::regex_search(
      out, std::regex(R"(\n(hip|knee|ankle)_[lr] +(flexion_extension|dorsiflexion_plantarflexion) +-?\d+\.\d\d)")))
      << "no joint-angle line in the demo's output";
  // The live alignment through the calibration service: every node aligned, the joints then in the segment frames.
  EXPECT_TRUE(std::regex_search(out, std::regex(R"(bsn demo: alignment: 7 of 7 nodes aligned)")))
      << "no successful alignment in the demo's output";
  EXPECT_TRUE(std::regex_search(out, std::regex(R"(\n(hip|knee|ankle)_[lr] .* aligned )")))
      << "no joint shown with the aligned mounting";
  // After the alignment, while walking, the walking body's first angles in the ranges of normal gait (knee 0..65, hip
  // -20..35, ankle -20..15 deg), with 5 deg for the filters' largest momentary errors, and within 3 deg rms of the
  // simulator's truth (what a lab accepts; the filters reach 1-2 deg on this motion).
  const std::map<std::string, std::pair<double, double>> ranges{
      {"hip", {-20, 35}}, {"knee", {0, 65}}, {"ankle", {-20, 15}}};
  // The error column (the largest of the three angles' errors at each instant) is within 3 deg rms too: a lab asks
  // it of the live column, and the knees' and ankles' axial rotation, the hardest angle, follows the heading
  // difference of two filters, which the demo's kinematic heading takes from the hinge.
  const std::regex joint_summary(
      R"(bsn demo: ((hip|knee|ankle)_[lr]) \S+ (-?[\d.]+) \.\. (-?[\d.]+) deg, error against the truth ([\d.]+) deg rms)"
      R"( over \d+ samples \(error column, the largest of the three angles: ([\d.]+) deg rms\))");
  int joints = 0;
  for (auto it = std::sregex_iterator(out.begin(), out.end(), joint_summary); it != std::sregex_iterator(); ++it) {
    const std::smatch& j = *it;
    SCOPED_TRACE(j[1].str());
    ++joints;
    const auto [lo, hi] = ranges.at(j[2].str());
    EXPECT_GE(std::stod(j[3].str()), lo - 5.0);
    EXPECT_LE(std::stod(j[4].str()), hi + 5.0);
    EXPECT_GT(std::stod(j[4].str()) - std::stod(j[3].str()), 10.0) << "the joint hardly moves";
    EXPECT_LT(std::stod(j[5].str()), 3.0);
    EXPECT_LT(std::stod(j[6].str()), 3.0) << "error column";
  }
  EXPECT_EQ(joints, 6) << "joints with a range and an error against the truth";

  // Nothing the demo started is left: no bsn process of this domain (its children were reparented if alive).
  std::vector<std::pair<int, std::string>> left;
  wait_until([&] { return (left = bsn_processes_in_domain(kDomain)).empty(); }, 2s);
  for (const auto& [pid, cmd] : left) {
    ADD_FAILURE() << "process " << pid << " left behind: " << cmd;
    ::kill(pid, SIGKILL);  // ours (this domain); do not leave it running
  }

  // UDP only: no new entry in /dev/shm. Other users of this host may run Fast DDS with shared memory at the same
  // time; a new entry that a running process still uses, or a port file of another domain, is theirs (all of
  // ours have ended).
  std::vector<std::string> new_shm, foreign;
  const std::set<std::string> in_use = shm_entries_in_use();
  for (const auto& e : directory_entries("/dev/shm")) {
    if (shm_before.contains(e)) continue;
    (in_use.contains(e) || foreign_domain_port_entry(e, kDomain) ? foreign : new_shm).push_back(e);
  }
  EXPECT_TRUE(new_shm.empty()) << "new entries in /dev/shm: " << ::testing::PrintToString(new_shm);
  if (!foreign.empty())
    std::printf("[ note     ] new /dev/shm entries of other processes: %s\n",
                ::testing::PrintToString(foreign).c_str());
}

}  // namespace
}  // namespace bsn::integration
