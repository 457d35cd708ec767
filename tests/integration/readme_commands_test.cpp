// Every shell command of the README and of the manual's pages in docs/ (in the order the README links them), run as
// a newcomer runs it: block by block in order, each block's commands in order in one bash (`set -euo pipefail`), in a
// scratch copy of the repository whose `build` is the build under test, on this test's own DDS domain ($BSN_DOMAIN).
// A command that fails, or does not finish within its time, fails the test naming its file and line. Blocks opted
// out by a `readme-test: skip` marker, and commands that need what this machine may not have (the BROAD
// recordings), are listed with their reasons.
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "process_fixture.hpp"
#include "readme_blocks.hpp"

namespace bsn::integration {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

/// The longest one README command may take. The longest on purpose is the first-10-minutes demo (30 s); this
/// leaves room for a loaded 2-core CI machine.
constexpr auto kCommandTimeout = 150s;

/// README commands the test does not run, because what they do is already done when it runs, and what it checks
/// instead. The README's build command would install packages (root, network) and configure and build a second
/// tree (minutes); the test runs in the tree the test workflow built from the same preset, so `build/bsn` exists
/// exactly as that command leaves it.
struct ProvidedCommand {
  std::string command;  // as in the README, without its comment
  std::string check;    // a shell command that holds once it has been done
  std::string reason;
};
const std::vector<ProvidedCommand>& provided_commands() {
  static const std::vector<ProvidedCommand> provided = {
      {"./deploy/setup.sh && cmake --workflow --preset build", "test -x build/bsn",
       "installs packages and builds bsn: mapped to the build under test (build/bsn must exist)"},
  };
  return provided;
}

/// Where the BROAD recordings are looked for: $BSN_BROAD_DIR, else ../shared/data/broad next to the checkout.
std::string broad_dir_wanted() {
  const char* env = std::getenv("BSN_BROAD_DIR");
  return env && *env ? env : BSN_BROAD_DIR_DEFAULT;
}

/// The BROAD recordings' folder if it holds any .hdf5 file, else "".
std::string broad_dir() {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(broad_dir_wanted(), ec)) {
    if (e.path().extension() == ".hdf5") return fs::canonical(broad_dir_wanted()).string();
  }
  return "";
}

bool needs_broad(const std::string& command) {
  return command.find("BSN_BROAD_DIR") != std::string::npos || command.find("shared/data/broad") != std::string::npos;
}

/// 'text' quoted for bash.
std::string quoted(const std::string& text) {
  std::string q = "'";
  for (char c : text) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

/// The repository's files as git tracks them ("" paths if `from` is not a git checkout or git is missing).
std::vector<std::string> tracked_files(const fs::path& from) {
  std::vector<std::string> files;
  const std::string command = "git -C " + quoted(from.string()) + " ls-files -z 2>/dev/null";
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) return files;
  std::string name;
  for (int c; (c = std::fgetc(pipe)) != EOF;) {
    if (c != '\0') {
      name += static_cast<char>(c);
    } else if (!name.empty()) {
      files.push_back(std::move(name));
      name.clear();
    }
  }
  if (::pclose(pipe) != 0) files.clear();
  return files;
}

/// A copy of the repository as a clone has it, where README commands may write: the tracked files (so what a
/// developer made in the checkout by following the README, walk.h5 or trial/, is not there), or without git (or
/// as another user) every file but the build folders and hidden ones (.git, CI caches).
void copy_repository(const fs::path& from, const fs::path& to) {
  fs::create_directories(to);
  const std::vector<std::string> tracked = tracked_files(from);
  for (const auto& file : tracked) {
    if (!fs::exists(fs::symlink_status(from / file))) continue;  // deleted in the working tree, not yet in git
    fs::create_directories((to / file).parent_path());
    fs::copy(from / file, to / file, fs::copy_options::copy_symlinks);
  }
  if (!tracked.empty()) return;
  for (const auto& e : fs::directory_iterator(from)) {
    const std::string name = e.path().filename().string();
    if (name.rfind("build", 0) == 0 || name.rfind(".", 0) == 0) continue;  // build trees, .git, caches
    fs::copy(e.path(), to / name, fs::copy_options::recursive | fs::copy_options::copy_symlinks);
  }
}

/// "PID COMMAND LINE" of each living process of group `pgid` (zombies, already ended, are left out: an orphan's
/// zombie waits for this machine's init to reap it).
std::vector<std::string> group_members(pid_t pgid) {
  std::vector<std::string> members;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator("/proc", ec)) {
    // /proc/<pid>/stat: "pid (comm) state ppid pgrp ..."; comm may hold spaces and parentheses.
    const std::string stat = read_file(e.path() / "stat");
    const auto close = stat.rfind(')');
    if (close == std::string::npos) continue;
    std::istringstream rest(stat.substr(close + 1));
    std::string state;
    long ppid = 0, pgrp = 0;
    if (!(rest >> state >> ppid >> pgrp) || pgrp != pgid || state == "Z") continue;
    std::string cmdline = read_file(e.path() / "cmdline");
    for (char& c : cmdline) c = c == '\0' ? ' ' : c;
    members.push_back(e.path().filename().string() + " " + cmdline);
  }
  return members;
}

bool group_alive(pid_t pgid) { return !group_members(pgid).empty(); }

/// Stops every process of group `pgid`: SIGTERM, then SIGKILL after 5 s. Returns those that were left.
std::vector<std::string> stop_group(pid_t pgid) {
  if (!group_alive(pgid)) return {};
  const std::vector<std::string> left = group_members(pgid);
  ::kill(-pgid, SIGTERM);
  if (!wait_until([&] { return !group_alive(pgid); }, 5s)) ::kill(-pgid, SIGKILL);
  wait_until([&] { return !group_alive(pgid); }, 2s);
  return left;
}

/// What running the shell blocks of one Markdown text gave.
struct RunReport {
  std::vector<std::string> failures;  ///< "NAME:LINE: `command` failed ..." (the run stops at the first)
  std::vector<std::string> not_run;   ///< "NAME:LINE: reason" of each block or command not run
  std::vector<std::string> notes;     ///< processes a block left running (stopped)
  int blocks_run = 0, commands_run = 0;
};

class ReadmeCommands : public ProcessTest {
 protected:
  /// Runs the shell blocks of `markdown` in order, each in one bash with `set -euo pipefail` and cwd `repo`, on
  /// DDS domain `domain`, with $BSN_BROAD_DIR = `broad` ("" = the recordings are missing: commands naming them are
  /// not run). A command that runs longer than `timeout` fails. Each block is its own process group, stopped at
  /// the block's end.
  RunReport run_blocks(const std::string& markdown, const std::string& name, const fs::path& repo, int domain,
                       const std::string& broad, std::chrono::seconds timeout) {
    RunReport report;
    std::vector<readme::CodeBlock> blocks;
    try {
      blocks = readme::extract_code_blocks(markdown, name);
    } catch (const std::invalid_argument& e) {
      report.failures.push_back(e.what());
      return report;
    }
    for (const auto& block : blocks) {
      if (!block.shell) continue;
      if (block.skip_reason) {
        report.not_run.push_back(name + ":" + std::to_string(block.fence_line) + " (block): " + *block.skip_reason);
        continue;
      }
      // One script per block. Before each command it writes the command's line to a progress file, so the test
      // knows which command runs, and for how long.
      std::string tag = name + "-block-" + std::to_string(block.fence_line);
      std::replace(tag.begin(), tag.end(), '/', '_');
      const fs::path progress = dir() / (tag + ".line");
      std::ostringstream script;
      script << "set -euo pipefail\n"
             << "exec < /dev/null\n"  // no command waits for a keyboard
             << "export BSN_DOMAIN=" << domain << "\n"
             << "export XDG_STATE_HOME=" << quoted((dir() / "state").string()) << "\n"  // bsn calibration's store
             << (broad.empty() ? std::string("unset BSN_BROAD_DIR\n") : "export BSN_BROAD_DIR=" + quoted(broad) + "\n")
             << "cd " << quoted(repo.string()) << "\n"
             << "readme_line() { echo \"$1\" > " << quoted(progress.string()) << "; }\n";
      int commands_in_block = 0;
      for (const auto& command : block.commands) {
        const std::string code = readme::strip_comment(command.text);
        const std::string where = name + ":" + std::to_string(command.line);
        script << "readme_line " << command.line << "\n";
        const auto provided = std::find_if(provided_commands().begin(), provided_commands().end(),
                                           [&](const ProvidedCommand& p) { return p.command == code; });
        if (provided != provided_commands().end()) {
          script << provided->check << "\n";
          report.not_run.push_back(where + ": `" + code + "` " + provided->reason);
          continue;
        }
        if (code.find("--domain") != std::string::npos) {
          // It would talk on that domain whatever the test sets: domain 0 is the lab's own system.
          report.failures.push_back(where + ": `" + code +
                                    "` names its DDS domain, so the test cannot keep it off the user's domain: "
                                    "leave --domain out (bsn takes $BSN_DOMAIN) or mark the block as not run");
          return report;
        }
        if (needs_broad(code) && broad.empty()) {
          report.not_run.push_back(where + ": needs the BROAD recordings, which are not in " + broad_dir_wanted() +
                                   " (set BSN_BROAD_DIR to the folder of the .hdf5 files)");
          continue;
        }
        script << command.text << "\n";
        ++commands_in_block;
      }
      script << "readme_line 0\n";
      const fs::path script_path = dir() / (tag + ".sh");
      write_file(script_path, script.str());

      // Its own process group (setsid), so that the commands' background processes end with the block.
      const auto started = Clock::now();
      auto& shell = spawn_command(tag, {"/usr/bin/setsid", "/bin/bash", "--noprofile", "--norc", script_path.string()});
      std::string line = "?";
      auto line_started = Clock::now();
      bool timed_out = false;
      const auto read_progress = [&] {
        std::string now = read_file(progress);
        if (!now.empty() && now.back() == '\n') now.pop_back();
        if (!now.empty() && now != line) {
          line = now;
          line_started = Clock::now();
        }
      };
      while (shell.running()) {
        read_progress();
        if (Clock::now() - line_started > timeout) {
          timed_out = true;
          break;
        }
        std::this_thread::sleep_for(50ms);
      }
      read_progress();  // the line of the command that ended the block
      const auto status = timed_out ? std::optional<int>() : shell.wait_for(0ms);
      for (const auto& p : stop_group(shell.pid()))
        report.notes.push_back(name + ":" + std::to_string(block.fence_line) +
                               ": the block left a process running, stopped: " + p);
      const double seconds = std::chrono::duration<double>(Clock::now() - started).count();

      std::string command_text;
      for (const auto& c : block.commands) {
        if (std::to_string(c.line) == line) command_text = c.text;
      }
      if (timed_out) {
        report.failures.push_back(
            name + ":" + line + ": `" + command_text + "` did not finish within " + std::to_string(timeout.count()) +
            " s (the test's limit for one command); last lines of the block's output:\n" + tail(log_path(tag), 30));
        break;
      }
      if (!exited_cleanly(status)) {
        report.failures.push_back(name + ":" + line + ": `" + command_text + "` failed (the block " +
                                  describe_status(status) + "); last lines of the block's output:\n" +
                                  tail(log_path(tag), 30));
        break;  // later blocks use what this one should have made
      }
      std::printf("[ readme   ] %s:%d: %d command(s) in %.1f s\n", name.c_str(), block.fence_line, commands_in_block,
                  seconds);
      ++report.blocks_run;
      report.commands_run += commands_in_block;
    }
    return report;
  }

  /// A scratch repository for commands that need none.
  fs::path empty_repo() {
    fs::create_directories(dir() / "repo");
    return dir() / "repo";
  }
};

/// Removes what our commands left in /dev/shm (the README's own Fast DDS subscriber uses Fast DDS's default
/// shared-memory transport; a clean exit leaves nothing, a killed one may): a new Fast DDS entry that no running
/// process uses, other than another domain's port file. The folder is listed before the entries in use are
/// collected, so an entry another test creates meanwhile is either not listed or seen open.
void remove_our_shm_leftovers(const std::set<std::string>& before, int domain) {
  const std::set<std::string> now = directory_entries("/dev/shm");
  const std::set<std::string> in_use = shm_entries_in_use();
  const long port_base = 7400 + 250L * domain;
  for (const auto& e : now) {
    if (before.contains(e) || in_use.contains(e) || e.find("fastrtps") == std::string::npos) continue;
    if (const auto at = e.find("fastrtps_port"); at != std::string::npos) {
      const long port = std::atol(e.c_str() + at + 13);
      if (port < port_base || port >= port_base + 250) continue;  // another domain's
    }
    std::error_code ec;
    fs::remove(fs::path("/dev/shm") / e, ec);
  }
}

TEST_F(ReadmeCommands, EveryRunnableCommandWorksAsWritten) {
  const int domain = test_domain(72);
  // The scratch checkout: <dir>/bsn with build -> the build under test, and <dir>/shared/data/broad as next to
  // this project's own checkout when the recordings are there.
  const fs::path repo = dir() / "bsn";
  copy_repository(BSN_SOURCE_DIR, repo);
  fs::create_directory_symlink(BSN_BINARY_DIR, repo / "build");
  ASSERT_TRUE(fs::equivalent(repo / "build" / "bsn", bsn_executable()))
      << "build/bsn in the scratch copy is not the bsn under test, " << bsn_executable();
  const std::string broad = broad_dir();
  if (!broad.empty()) {
    fs::create_directories(dir() / "shared" / "data");
    fs::create_directory_symlink(broad, dir() / "shared" / "data" / "broad");
  }

  // The README, then the manual's pages in the order the README links them (a page may use what an earlier one
  // made); the run stops at the first file with a failing command.
  const std::string readme = read_file(fs::path(BSN_SOURCE_DIR) / "README.md");
  std::vector<std::string> files = {"README.md"};
  for (const auto& page : readme::manual_pages(readme)) files.push_back(page);
  const std::set<std::string> shm_before = directory_entries("/dev/shm");
  RunReport report;
  for (const auto& file : files) {
    const RunReport one = run_blocks(file == "README.md" ? readme : read_file(fs::path(BSN_SOURCE_DIR) / file), file,
                                     repo, domain, broad, kCommandTimeout);
    report.failures.insert(report.failures.end(), one.failures.begin(), one.failures.end());
    report.not_run.insert(report.not_run.end(), one.not_run.begin(), one.not_run.end());
    report.notes.insert(report.notes.end(), one.notes.begin(), one.notes.end());
    report.blocks_run += one.blocks_run;
    report.commands_run += one.commands_run;
    if (!one.failures.empty()) break;
  }
  remove_our_shm_leftovers(shm_before, domain);

  for (const auto& f : report.failures) ADD_FAILURE() << f;
  for (const auto& n : report.notes) std::printf("[ note     ] %s\n", n.c_str());
  std::printf("[ readme   ] ran %d block(s), %d command(s) on domain %d; not run (%zu):\n", report.blocks_run,
              report.commands_run, domain, report.not_run.size());
  for (const auto& s : report.not_run) std::printf("[ readme   ]   %s\n", s.c_str());
  EXPECT_GT(report.commands_run, 0);
}

// The runner itself: a failing command fails naming its line, later blocks see earlier blocks' files, a block's
// background process is stopped with it, and every command not run is listed with its reason.
TEST_F(ReadmeCommands, TheRunnerNamesTheLineOfAFailingCommandAndListsWhatItDidNotRun) {
  const std::string md =
      "<!-- readme-test: skip, reason: just prose -->\n"  // 1
      "```sh\n"                                           // 2
      "exit 3\n"                                          // 3
      "```\n"                                             // 4
      "```sh\n"                                           // 5
      "echo one > made.txt\n"                             // 6
      "sleep 60 &   # left running\n"                     // 7
      "ls \"$BSN_BROAD_DIR\"\n"                           // 8
      "```\n"                                             // 9
      "```sh\n"                                           // 10
      "test -f made.txt && test \"$BSN_DOMAIN\" = " +
      std::to_string(test_domain(73)) +
      "\n"                                                              // 11
      "echo two | cat\n"                                                // 12
      "false | cat  # pipefail: a failure anywhere in a pipe counts\n"  // 13
      "echo never\n"                                                    // 14
      "```\n"                                                           // 15
      "```sh\n"                                                         // 16
      "echo not reached\n"                                              // 17
      "```\n";                                                          // 18
  const auto started = Clock::now();
  const RunReport report = run_blocks(md, "doc.md", empty_repo(), test_domain(73), "", 60s);
  ASSERT_EQ(report.failures.size(), 1u) << ::testing::PrintToString(report.failures);
  EXPECT_NE(
      report.failures[0].find(
          "doc.md:13: `false | cat  # pipefail: a failure anywhere in a pipe counts` failed (the block exited with 1)"),
      std::string::npos)
      << report.failures[0];
  EXPECT_EQ(report.blocks_run, 1);
  EXPECT_EQ(report.commands_run, 2) << "the BROAD command is not run without the recordings";
  ASSERT_EQ(report.not_run.size(), 2u) << ::testing::PrintToString(report.not_run);
  EXPECT_EQ(report.not_run[0], "doc.md:2 (block): just prose");
  EXPECT_EQ(report.not_run[1].rfind("doc.md:8: needs the BROAD recordings", 0), 0u) << report.not_run[1];
  ASSERT_EQ(report.notes.size(), 1u) << ::testing::PrintToString(report.notes);
  EXPECT_NE(report.notes[0].find("sleep 60"), std::string::npos) << report.notes[0];
  EXPECT_LT(Clock::now() - started, 30s) << "the background sleep was waited for instead of stopped";
}

TEST_F(ReadmeCommands, ACommandNamingItsDomainIsRefusedBeforeAnythingRuns) {
  const std::string md =
      "```sh\n"
      "touch ran.txt\n"
      "./build/bsn echo bsn/status --count 1 --domain 0\n"
      "```\n";
  const RunReport report = run_blocks(md, "doc.md", empty_repo(), test_domain(73), "", 60s);
  ASSERT_EQ(report.failures.size(), 1u) << ::testing::PrintToString(report.failures);
  EXPECT_EQ(
      report.failures[0].rfind("doc.md:3: `./build/bsn echo bsn/status --count 1 --domain 0` names its DDS domain", 0),
      0u)
      << report.failures[0];
  EXPECT_FALSE(fs::exists(dir() / "repo" / "ran.txt")) << "the block ran up to the command naming its domain";
}

TEST_F(ReadmeCommands, ACommandThatRunsTooLongFailsNamingItsLine) {
  const std::string md =
      "```sh\n"
      "true\n"
      "sleep 30 # forever, as far as the test knows\n"
      "```\n";
  const auto started = Clock::now();
  const RunReport report = run_blocks(md, "doc.md", empty_repo(), test_domain(73), "", 1s);
  ASSERT_EQ(report.failures.size(), 1u) << ::testing::PrintToString(report.failures);
  EXPECT_NE(
      report.failures[0].find("doc.md:3: `sleep 30 # forever, as far as the test knows` did not finish within 1 s"),
      std::string::npos)
      << report.failures[0];
  EXPECT_LT(Clock::now() - started, 20s) << "the hanging command was not stopped";
}

}  // namespace
}  // namespace bsn::integration
