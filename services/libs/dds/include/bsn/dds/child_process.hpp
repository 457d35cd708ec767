// A child process that cannot outlive its parent (PR_SET_PDEATHSIG) and is stopped with SIGTERM, then
// SIGKILL after a grace period. Used by `bsn demo` and the process-level tests.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <optional>
#include <string>
#include <vector>

namespace bsn::dds {

class ChildProcess {
 public:
  /// Starts `argv[0]` with the arguments. stdout/stderr go to `log_path` if given ("" = inherit).
  /// Throws std::runtime_error if the process cannot be started.
  explicit ChildProcess(const std::vector<std::string>& argv, const std::string& log_path = "");
  ~ChildProcess();  ///< stops the process if it still runs
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  pid_t pid() const { return pid_; }

  /// True while the process runs (reaps it if it has ended).
  bool running();

  /// Sends a signal (SIGKILL to simulate a crash).
  void signal(int sig);

  /// SIGTERM, wait up to `grace`, then SIGKILL. Returns the exit status as from waitpid, or nullopt.
  std::optional<int> stop(std::chrono::milliseconds grace = std::chrono::milliseconds(3000));

  /// Waits up to `timeout` for the process to end by itself. Returns its waitpid status or nullopt.
  std::optional<int> wait_for(std::chrono::milliseconds timeout);

 private:
  pid_t pid_ = -1;
  std::optional<int> status_;
};

/// Path of the running executable (/proc/self/exe).
std::string self_executable();

}  // namespace bsn::dds
