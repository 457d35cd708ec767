// Shared pieces of the process-level integration tests: a fixture that owns a private temporary directory and
// the child processes of one test (stopped in reverse start order, their log tails printed if the test failed),
// and small helpers for deadlines, files and /proc.
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "bsn/dds/child_process.hpp"

namespace bsn::integration {

using Clock = std::chrono::steady_clock;

/// Path of the `bsn` program under test (set by CMake).
std::string bsn_executable();

/// The DDS domain id of test number `offset` (0..99): $BSN_TEST_DOMAIN_BASE (default 20) + offset. Two test runs
/// on one machine use different bases so that they never see each other. Throws if the id leaves 0..232.
int test_domain(int offset);

/// Polls `done` every 20 ms until it returns true (-> true) or `timeout` passes (-> false).
bool wait_until(const std::function<bool()>& done, std::chrono::milliseconds timeout);

/// Writes `text` to `path` (throws on failure).
void write_file(const std::filesystem::path& path, const std::string& text);

/// Whole contents of a file ("" if it cannot be read).
std::string read_file(const std::filesystem::path& path);

/// The last `lines` lines of a file.
std::string tail(const std::filesystem::path& path, std::size_t lines = 40);

/// "exited with 0", "killed by signal 9", ... for a waitpid status (or "still running" for nullopt).
std::string describe_status(const std::optional<int>& status);

/// True if the waitpid status is a normal exit with code 0.
bool exited_cleanly(const std::optional<int>& status);

/// The exit code of a waitpid status, or -1 if the process did not exit normally (a signal, still running).
int exit_code(const std::optional<int>& status);

/// Names of the entries of a directory (empty if it does not exist).
std::set<std::string> directory_entries(const std::filesystem::path& dir);

/// Pids of the running processes whose parent is `pid`.
std::vector<int> children_of(int pid);

/// Names of the /dev/shm entries that process `pid` has mapped or open (empty if it has gone).
std::set<std::string> shm_entries_used_by(int pid);

/// Names of the /dev/shm entries that any running process has mapped or open.
std::set<std::string> shm_entries_in_use();

/// Processes (pid, command line) other than this one that run `bsn` with "--domain <domain>".
std::vector<std::pair<int, std::string>> bsn_processes_in_domain(int domain);

/// Owns a temporary directory (mkdtemp) and the child processes of one test.
class ProcessTest : public ::testing::Test {
 protected:
  void SetUp() override;
  /// Stops every child still running (reverse start order), prints their logs if the test failed and removes
  /// the temporary directory.
  void TearDown() override;

  /// Starts `bsn <args...>` with stdout and stderr to <dir>/<name>.log.
  dds::ChildProcess& spawn(const std::string& name, const std::vector<std::string>& args);
  /// Starts any program (argv[0] an absolute path), stopped and logged like the others.
  dds::ChildProcess& spawn_command(const std::string& name, const std::vector<std::string>& argv);

  /// SIGTERM, then SIGKILL after `grace`; returns the waitpid status.
  std::optional<int> stop(const std::string& name, std::chrono::milliseconds grace = std::chrono::milliseconds(5000));

  dds::ChildProcess& child(const std::string& name);
  std::filesystem::path log_path(const std::string& name) const { return dir_ / (name + ".log"); }
  const std::filesystem::path& dir() const { return dir_; }

 private:
  std::filesystem::path dir_;
  std::vector<std::pair<std::string, std::unique_ptr<dds::ChildProcess>>> children_;
};

}  // namespace bsn::integration
