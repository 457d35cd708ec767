// The real `bsn` on mistyped command lines: a usage error exits 2 before any DDS set-up, and a typo of a command
// or option is answered with the nearest name.
#include <gtest/gtest.h>

#include <string>

#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;

class CliUsage : public ProcessTest {
 protected:
  /// Runs `bsn <args>` to its end and returns its exit code; its output is in log_path(name).
  int run(const std::string& name, const std::vector<std::string>& args) {
    const auto status = spawn(name, args).wait_for(20s);
    EXPECT_TRUE(status.has_value()) << "bsn " << name << " did not exit within 20 s";
    return status && WIFEXITED(*status) ? WEXITSTATUS(*status) : -1;
  }
  std::string output(const std::string& name) { return read_file(log_path(name)); }
};

TEST_F(CliUsage, MistypedCommandGetsTheNearestCommand) {
  EXPECT_EQ(run("command", {"fuson", "--domain", std::to_string(test_domain(26))}), 2);
  EXPECT_NE(output("command").find("unknown command 'fuson'; did you mean 'fusion'?"), std::string::npos)
      << output("command");

  EXPECT_EQ(run("swapped", {"ehco", "bsn/raw"}), 2);  // two letters swapped count as one edit
  EXPECT_NE(output("swapped").find("did you mean 'echo'?"), std::string::npos) << output("swapped");
}

TEST_F(CliUsage, MistypedOptionGetsTheNearestOptionOfItsCommand) {
  EXPECT_EQ(run("option", {"fusion", "--best-efort", "--domain", std::to_string(test_domain(26))}), 2);
  EXPECT_NE(output("option").find("--best-efort"), std::string::npos) << output("option");
  EXPECT_NE(output("option").find("did you mean '--best-effort'?"), std::string::npos) << output("option");
}

TEST_F(CliUsage, NoGuessForAWordFarFromEveryName) {
  EXPECT_EQ(run("far", {"xyzzy"}), 2);
  EXPECT_NE(output("far").find("unknown command 'xyzzy'"), std::string::npos) << output("far");
  EXPECT_EQ(output("far").find("did you mean"), std::string::npos) << output("far");

  EXPECT_EQ(run("none", {}), 2);
  EXPECT_NE(output("none").find("A subcommand is required"), std::string::npos) << output("none");
}

TEST_F(CliUsage, HelpListsEveryCommandAndExitsZero) {
  EXPECT_EQ(run("help", {"--help"}), 0);
  for (const char* command : {"sim", "fusion", "echo", "demo", "eval", "calibrate"})
    EXPECT_NE(output("help").find(command), std::string::npos) << command << " missing from:\n" << output("help");
}

}  // namespace
}  // namespace bsn::integration
