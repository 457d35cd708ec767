// A private folder for a command's child logs ($TMPDIR or /tmp), removed at the end unless kept (it then holds the
// logs of a failure), and removed by a reaper process if the command dies without a word (SIGKILL).
#pragma once

#include <filesystem>
#include <optional>

namespace bsn::services {

/// A forked helper that removes `dir` once this process has gone, however it went (a SIGKILL included), unless
/// keep() was called. It learns of the end from the pipe between them: the kernel closes this end on any exit.
class FolderReaper {
 public:
  /// Forks: call it before any other thread exists (a DDS participant's).
  explicit FolderReaper(const std::filesystem::path& dir);
  ~FolderReaper();
  FolderReaper(const FolderReaper&) = delete;
  FolderReaper& operator=(const FolderReaper&) = delete;
  /// The folder stays (it holds the logs of a failure).
  void keep();

 private:
  int write_fd_ = -1;
};

/// Makes the folder `$TMPDIR/PREFIX-XXXXXX` (or under /tmp); nullopt (errno says why) if it cannot.
std::optional<std::filesystem::path> make_private_folder(const char* prefix);

}  // namespace bsn::services
