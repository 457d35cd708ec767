// The YAML readers of the body model, calibration and scenario files: the first byte picks the reader, the rest is
// the file's text. Invariant: every problem is the reader's own error (ConfigError / ScenarioError, with a
// "SOURCE:LINE: problem" message); any other exception or a crash is a finding.
#include <cstring>
#include <string>

#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/sim/scenario_file.hpp"
#include "fuzz_check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    switch (data[0] % 3) {
      case 0: {
        const auto body = bsn::config::parse_body_model(text, "fuzz.yaml");
        BSN_FUZZ_CHECK(!body.segments.empty(), "a body model without segments was accepted");
        break;
      }
      case 1:
        bsn::config::parse_calibration(text, "fuzz.calib.yaml");
        break;
      default:
        bsn::sim::parse_scenario(text, "fuzz.yaml");
        break;
    }
  } catch (const bsn::config::ConfigError& e) {
    BSN_FUZZ_CHECK(std::strncmp(e.what(), "fuzz", 4) == 0, "an error that does not name its file");
  } catch (const bsn::sim::ScenarioError& e) {
    BSN_FUZZ_CHECK(std::strncmp(e.what(), "fuzz", 4) == 0, "an error that does not name its file");
  }
  return 0;
}
