// The recording importers (bsn process, bsn eval --body) on arbitrary text. The first byte picks the importer
// (diodem, xsens-dot, bsn-csv) and its unit options; the rest is the file. Invariants: a problem is an IoError
// (FormatError); what comes back is a valid recording per node with a positive rate, increasing timestamps where
// the format has its own, and references that are unit quaternions or NaN rows.
#include <cmath>
#include <string>
#include <string_view>

#include "bsn/io/importers.hpp"
#include "fuzz_check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  static const char* const names[] = {"diodem", "xsens-dot", "bsn-csv"};
  const std::uint8_t pick = data[0];
  const std::string format = names[pick % 3];
  bsn::io::ImportOptions options;
  if (pick & 0x10) options.units["gyr"] = "deg/s";
  if (pick & 0x20) options.units["mag"] = "au:50";
  if (pick & 0x40) options.units["time"] = "ms";
  const std::string_view text(reinterpret_cast<const char*>(data + 1), size - 1);
  try {
    const auto nodes = bsn::io::recording_importer(format).parse(text, "fuzz.csv", options);
    BSN_FUZZ_CHECK(!nodes.empty(), "no node and no error");
    for (const bsn::io::ImportedNode& n : nodes) {
      const bsn::io::Recording& r = n.rec;
      r.validate("fuzz");
      BSN_FUZZ_CHECK(r.size() >= 2, "fewer than two samples and no error");
      BSN_FUZZ_CHECK(std::isfinite(r.sampling_rate_hz) && r.sampling_rate_hz > 0, "a rate that is not > 0");
      for (std::size_t i = 1; i < r.timestamp_ns.size() && format == "xsens-dot"; ++i)
        BSN_FUZZ_CHECK(r.timestamp_ns[i] > r.timestamp_ns[i - 1], "a time that does not increase");
      for (Eigen::Index i = 0; i < r.opt_quat.rows(); ++i) {
        const auto q = r.opt_quat.row(i);
        BSN_FUZZ_CHECK(q.array().isNaN().all() || std::abs(q.norm() - 1.0) < 1e-9, "a reference not unit nor NaN");
      }
    }
  } catch (const bsn::io::IoError&) {
  }
  return 0;
}
