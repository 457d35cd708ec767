// The CSV recording reader (bsn eval, bsn calibrate) on arbitrary text. The reader takes a path, so the input goes
// into an in-memory file (memfd) read through /proc/self/fd. Invariant: a problem is an IoError; what it returns has
// as many timestamps as samples.
#include <sys/mman.h>
#include <unistd.h>

#include <cmath>
#include <string>

#include "bsn/io/recording.hpp"
#include "fuzz_check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const int fd = memfd_create("bsn_fuzz_csv", 0);
  BSN_FUZZ_CHECK(fd >= 0, "memfd_create failed");
  BSN_FUZZ_CHECK(ftruncate(fd, 0) == 0, "ftruncate failed");
  BSN_FUZZ_CHECK(pwrite(fd, data, size, 0) == static_cast<ssize_t>(size), "pwrite failed");
  static const std::string path = "/proc/self/fd/" + std::to_string(fd);
  try {
    const bsn::io::Recording rec = bsn::io::read_csv(path);
    BSN_FUZZ_CHECK(rec.timestamp_ns.empty() || rec.timestamp_ns.size() == rec.size(), "timestamps != samples");
    BSN_FUZZ_CHECK(std::isfinite(rec.sampling_rate_hz) && rec.sampling_rate_hz > 0, "a rate that is not > 0");
  } catch (const bsn::io::IoError&) {
  }
  return 0;
}
