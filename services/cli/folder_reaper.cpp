#include "folder_reaper.hpp"

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <string>

#include "bsn/logging/log.hpp"

namespace bsn::services {

FolderReaper::FolderReaper(const std::filesystem::path& dir) {
  int fds[2];
  if (pipe(fds) != 0) return;  // no reaper: the normal exit paths still clean up
  const pid_t middle = fork();
  if (middle == 0) {
    // Forked twice, so the reaper is no child of the demo (whose children are its sims and fusion) and init
    // reaps it.
    if (fork() != 0) _exit(0);
    // The reaper: signals meant for the demo's terminal (Ctrl-C) must not stop it, and it holds none of the
    // demo's files open (a test reading the demo's output waits for every holder of the pipe).
    std::signal(SIGINT, SIG_IGN);
    std::signal(SIGTERM, SIG_IGN);
    const int null_fd = open("/dev/null", O_RDWR);
    for (int fd = 0; fd < 3; ++fd) dup2(null_fd, fd);
    for (int fd = 3; fd < 1024; ++fd)
      if (fd != fds[0]) close(fd);
    char verdict = 0;
    while (read(fds[0], &verdict, 1) < 0 && errno == EINTR) {
    }
    std::error_code ec;
    if (verdict != 'k') std::filesystem::remove_all(dir, ec);
    _exit(0);
  }
  close(fds[0]);
  if (middle > 0) {
    waitpid(middle, nullptr, 0);
    write_fd_ = fds[1];
    fcntl(write_fd_, F_SETFD, FD_CLOEXEC);  // the sims and fusion must not hold it open
  } else {
    close(fds[1]);
  }
}

FolderReaper::~FolderReaper() {
  if (write_fd_ >= 0) close(write_fd_);  // the reaper wakes up, removes the folder unless kept, and exits
}

void FolderReaper::keep() {
  if (write_fd_ >= 0 && write(write_fd_, "k", 1) != 1) logging::log_warn("cannot tell the reaper to keep the logs");
}

std::optional<std::filesystem::path> make_private_folder(const char* prefix) {
  const char* tmp = std::getenv("TMPDIR");
  std::string dir_template = std::string(tmp && *tmp ? tmp : "/tmp") + "/" + prefix + "-XXXXXX";
  if (mkdtemp(dir_template.data()) == nullptr) return std::nullopt;
  return std::filesystem::path(dir_template);
}

}  // namespace bsn::services
