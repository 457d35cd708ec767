// The real `bsn` on mistyped command lines: a usage error exits 2 before any DDS set-up, and a typo of a command
// or option is answered with the nearest name.
#include <gtest/gtest.h>

#include <filesystem>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

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
    return exit_code(status);
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
  // The message says which commands there are, also after an unknown option alone.
  EXPECT_NE(output("none").find("(one of: sim, fusion"), std::string::npos) << output("none");
  EXPECT_EQ(run("option_only", {"-x"}), 2);
  EXPECT_NE(output("option_only").find("(one of: sim, fusion"), std::string::npos) << output("option_only");
  // A value after an unknown option is no command name: the command word after it is the one named.
  EXPECT_EQ(run("value", {"--domain", "5", "fuson"}), 2);
  EXPECT_NE(output("value").find("unknown command 'fuson'; did you mean 'fusion'?"), std::string::npos)
      << output("value");
}

TEST_F(CliUsage, AbsurdNumbersAreRefusedAtParseTimeNamingTheOption) {
  // Every numeric option of every command: negative, zero where it must be positive, not finite, or beyond any
  // sensible value. Exit 2 before anything runs, with the option in the message.
  const std::string domain = std::to_string(test_domain(26));
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"fusion", "--stale-timeout", "-1"}, "--stale-timeout"},
      {{"fusion", "--stale-timeout", "nan"}, "--stale-timeout"},
      {{"fusion", "--status-period", "-1"}, "--status-period"},
      {{"fusion", "--status-period", "0"}, "--status-period"},
      {{"fusion", "--max-time-jump", "-1"}, "--max-time-jump"},
      {{"fusion", "--max-time-jump", "1e300"}, "--max-time-jump"},
      {{"sim", "--node", "n", "--duration", "-1"}, "--duration"},
      {{"sim", "--node", "n", "--rate", "0"}, "--rate"},
      {{"sim", "--node", "n", "--rate", "inf"}, "--rate"},
      {{"sim", "--node", "n", "--speed", "-2"}, "--speed"},
      {{"demo", "--rate", "-5"}, "--rate"},
      {{"demo", "--duration", "-1"}, "--duration"},
      {{"echo", "bsn/raw", "--count", "-1"}, "--count"},
      {{"echo", "bsn/raw", "--rate", "-1"}, "--rate"},
      {{"echo", "bsn/raw", "--timeout", "-3"}, "--timeout"},
      {{"calibrate", "--input", "x.csv", "--field-magnitude", "-1"}, "--field-magnitude"},
      {{"calibrate", "--input", "x.csv", "--rest-threshold", "0"}, "--rest-threshold"},
      {{"calibrate", "--input", "x.csv", "--min-pose", "-1"}, "--min-pose"},
  };
  for (std::size_t i = 0; i < cases.size(); ++i) {
    auto args = cases[i].first;
    if (args[0] != "calibrate") args.insert(args.end(), {"--domain", domain});
    const std::string name = "absurd" + std::to_string(i);
    std::string command;
    for (const auto& a : args) command += a + " ";
    EXPECT_EQ(run(name, args), 2) << command << "\n" << output(name);
    EXPECT_NE(output(name).find(cases[i].second + ": must be a finite number"), std::string::npos) << command << "\n"
                                                                                                   << output(name);
    EXPECT_EQ(output(name).find("joint"), std::string::npos) << command << " started running:\n" << output(name);
  }
}

TEST_F(CliUsage, ADirectoryGivenAsAFileIsNamedSo) {
  // A directory used to be reported as "the file is empty".
  std::filesystem::create_directories(dir() / "adir");
  EXPECT_EQ(run("body", {"fusion", "--body", (dir() / "adir").string(), "--domain", std::to_string(test_domain(26))}),
            2);
  EXPECT_NE(output("body").find("is a directory, not a body model file"), std::string::npos) << output("body");
  write_file(dir() / "body.yaml", "segments:\n  - name: a\n    node: a\n    calibration: adir\n");
  EXPECT_EQ(run("calibration",
                {"fusion", "--body", (dir() / "body.yaml").string(), "--domain", std::to_string(test_domain(26))}),
            2);
  EXPECT_NE(output("calibration").find("is a directory, not a calibration file"), std::string::npos)
      << output("calibration");
  EXPECT_EQ(run("scenario", {"sim", "--scenario", (dir() / "adir").string(), "--out", (dir() / "o").string()}), 2);
  EXPECT_NE(output("scenario").find("directory"), std::string::npos) << output("scenario");
}

TEST_F(CliUsage, ADomainOutOfRangeIsAUsageErrorNeverAFallback) {
  // Domain 0 may be another system's: a bad BSN_DOMAIN or --domain must stop the command (exit 2, naming the value)
  // before any DDS participant exists, not warn and run in domain 0.
  auto run_with_env = [&](const std::string& name, const std::string& env, std::vector<std::string> args) {
    args.insert(args.begin(), {"BSN_DOMAIN=" + env, bsn_executable()});
    const auto status = spawn_command(name,
                                      [&] {
                                        std::vector<std::string> argv{"/usr/bin/env"};
                                        argv.insert(argv.end(), args.begin(), args.end());
                                        return argv;
                                      }())
                            .wait_for(20s);
    EXPECT_TRUE(status.has_value()) << name << " did not exit within 20 s";
    return exit_code(status);
  };
  const std::vector<std::string> bad_environment{"233", "300", "-1", "abc", "5x", "99999999999999999999"};
  for (std::size_t i = 0; i < bad_environment.size(); ++i) {
    const std::string& env = bad_environment[i];
    const std::string name = "env" + std::to_string(i);
    EXPECT_EQ(run_with_env(name, env, {"fusion"}), 2) << "BSN_DOMAIN=" << env << "\n" << output(name);
    EXPECT_NE(output(name).find("BSN_DOMAIN='" + env + "' is not a DDS domain id in 0..232"), std::string::npos)
        << output(name);
    EXPECT_EQ(output(name).find("using 0"), std::string::npos) << output(name);
  }
  const std::vector<std::string> bad_option{"233", "-1", "1e2", "x"};
  for (std::size_t i = 0; i < bad_option.size(); ++i) {
    const std::string name = "option" + std::to_string(i);
    EXPECT_EQ(run(name, {"echo", "bsn/raw", "--domain", bad_option[i]}), 2) << bad_option[i];
    EXPECT_NE(output(name).find("'" + bad_option[i] + "' is not a DDS domain id in 0..232"), std::string::npos)
        << output(name);
    EXPECT_NE(output(name).find("--domain"), std::string::npos) << output(name);
  }
  // --domain given overrides a bad BSN_DOMAIN: the command runs (and here times out waiting for a sample: exit 1).
  EXPECT_EQ(run_with_env(
                "override", "300",
                {"echo", "bsn/raw", "--count", "1", "--timeout", "0.5", "--domain", std::to_string(test_domain(87))}),
            1)
      << output("override");
  EXPECT_NE(output("override").find("timeout"), std::string::npos) << output("override");
}

TEST_F(CliUsage, HelpListsEveryCommandAndExitsZero) {
  EXPECT_EQ(run("help", {"--help"}), 0);
  for (const char* command : {"sim", "fusion", "echo", "demo", "eval", "calibrate"})
    EXPECT_NE(output("help").find(command), std::string::npos) << command << " missing from:\n" << output("help");
}

// Every command `bsn --help` lists ends its own --help with examples (and the choices where there are any).
TEST_F(CliUsage, EveryCommandsHelpHasExamples) {
  ASSERT_EQ(run("help", {"--help"}), 0);
  const std::string help = output("help");
  const std::size_t list = help.find("Subcommands:");
  ASSERT_NE(list, std::string::npos) << help;
  std::vector<std::string> commands;
  std::istringstream lines(help.substr(list));
  std::string line;
  std::getline(lines, line);
  while (std::getline(lines, line)) {
    std::istringstream words(line);
    std::string name;
    if (words >> name) commands.push_back(name);
  }
  ASSERT_GE(commands.size(), 12u) << help;
  for (const std::string& c : commands) {
    EXPECT_EQ(run("help_" + c, {c, "--help"}), 0) << c;
    const std::string text = output("help_" + c);
    const std::size_t at = text.find("Examples:\n  bsn ");
    EXPECT_NE(at, std::string::npos) << "bsn " << c << " --help has no examples:\n" << text;
  }
  EXPECT_NE(output("help_eval").find("Filters: all, "), std::string::npos) << output("help_eval");
  EXPECT_NE(output("help_eval").find("t_s or t_ns"), std::string::npos) << output("help_eval");
  EXPECT_NE(output("help_fusion").find("the default body: pelvis"), std::string::npos) << output("help_fusion");
}

}  // namespace
}  // namespace bsn::integration
