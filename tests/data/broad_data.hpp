// Locating the BROAD recordings for data tests: $BSN_BROAD_DIR, else ../shared/data/broad next to the checkout.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

namespace bsn::testing {

inline std::filesystem::path broad_dir() {
  if (const char* env = std::getenv("BSN_BROAD_DIR")) return env;
  return BSN_BROAD_DIR_DEFAULT;
}

/// The .hdf5 files of the BROAD folder, sorted; empty if the folder is missing.
inline std::vector<std::filesystem::path> broad_files() {
  std::vector<std::filesystem::path> files;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(broad_dir(), ec)) {
    if (e.path().extension() == ".hdf5") files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

}  // namespace bsn::testing

// Skips the test (reported as skipped by ctest) with a message saying where the data was looked for.
#define BSN_REQUIRE_BROAD()                                                         \
  do {                                                                              \
    if (bsn::testing::broad_files().empty()) {                                      \
      GTEST_SKIP() << "BROAD recordings not found in " << bsn::testing::broad_dir() \
                   << " (set BSN_BROAD_DIR to the folder of the .hdf5 files)";      \
    }                                                                               \
  } while (0)
