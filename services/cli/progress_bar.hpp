// A one-line progress bar on stderr, shown only when stderr is a terminal (`bsn eval`, `bsn tune`).
#pragma once

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <string>

namespace bsn::services {

class ProgressBar {
 public:
  explicit ProgressBar(std::size_t total) : total_(total), enabled_(isatty(STDERR_FILENO) != 0) {}
  void show(std::size_t done, const std::string& what) const {
    if (!enabled_) return;
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(kWidth * std::min(done, total_) / std::max<std::size_t>(1, total_));
    std::fprintf(stderr, "\r[%.*s%*s] %zu/%zu %-50.50s", filled, "##############################", kWidth - filled, "",
                 done, total_, what.c_str());
    std::fflush(stderr);
  }
  void finish() const {
    if (enabled_) std::fprintf(stderr, "\r%*s\r", 100, "");
  }

 private:
  std::size_t total_;
  bool enabled_;
};

}  // namespace bsn::services
