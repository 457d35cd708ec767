// An invariant of a fuzz target: when it fails, the input is a finding (libFuzzer saves it as a crash artifact).
#pragma once

#include <cstdio>
#include <cstdlib>

#define BSN_FUZZ_CHECK(condition, what)                                                                            \
  do {                                                                                                             \
    if (!(condition)) {                                                                                            \
      std::fprintf(stderr, "bsn fuzz invariant broken at %s:%d: %s (%s)\n", __FILE__, __LINE__, what, #condition); \
      std::abort();                                                                                                \
    }                                                                                                              \
  } while (0)
