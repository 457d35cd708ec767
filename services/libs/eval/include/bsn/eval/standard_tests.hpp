// Fan et al. 2018's standardised tests A-E (section 3) run on the simulator's fan_a..fan_e scenarios, every filter
// through every test, graded as in their Table 5: good <= 2 deg, acceptable 2-5 deg, poor > 5 deg.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "bsn/eval/evaluation.hpp"
#include "bsn/fusion/orientation_filter.hpp"

namespace bsn::eval {

/// One of Fan's tests: which scenario, and which error it judges (the property the test is about).
struct StandardTest {
  std::string id;        ///< "A" .. "E"
  std::string scenario;  ///< file stem in the scenario folder, e.g. "fan_a"
  enum class Judged { kTotal, kInclination, kHeading } judged = Judged::kTotal;
  std::string what;  ///< one line: what the test shows
};

/// Fan's five tests: A total error in a clean field, B inclination under a magnet brought close, C heading over
/// 20 min in a continuous disturbance, D heading under a disturbance below the thresholds, E total error in motion
/// through a disturbed area.
const std::vector<StandardTest>& fan_standard_tests();

enum class Grade { kGood, kAcceptable, kPoor };
/// Table 5's grades: good <= 2 deg, acceptable <= 5 deg, poor beyond (or not finite).
Grade grade_of(double error_deg);
const char* grade_name(Grade g);

struct StandardTestResult {
  std::string test;      ///< "A" .. "E"
  std::string filter;    ///< filter label
  double error_deg = 0;  ///< RMSE of the judged angle over the scored samples, deg
  Grade grade = Grade::kPoor;
  double mag_rejected_fraction = 0.0;  ///< of the scored samples with a magnetometer reading
  /// Scored samples with a magnetometer reading within the first 10 s of a stretch where the true field differs
  /// from the earth field by more than 10 %, and the fraction of them the filter rejected (NaN: none such).
  std::size_t disturbed_samples = 0;
  double caught_fraction = 0.0;
  TrialResult trial;  ///< the full scores and the error series (for --plot)
};

/// Runs every filter in `filters` (label, spec) through every test, with the scenarios read from
/// `scenario_dir`/<scenario>.yaml. Samples before `startup_s` (the filters' start-up) are not scored. `seed`, when
/// given, replaces the scenarios' own seed (another noise realisation of the same tests). Throws
/// sim::ScenarioError or std::invalid_argument for a missing or bad scenario.
std::vector<StandardTestResult> run_standard_tests(
    const std::string& scenario_dir, const std::vector<std::pair<std::string, fusion::FilterSpec>>& filters,
    double startup_s = 3.0, std::optional<std::uint64_t> seed = std::nullopt);

/// Fan's Table 5: one row per filter, one column per test, "error grade" in each cell.
std::string standard_tests_table(const std::vector<StandardTestResult>& results);
/// Fan's Table 5 as Markdown for the manual: one row per filter, the error and grade of each test.
std::string standard_tests_markdown(const std::vector<StandardTestResult>& results);
/// {"tests": [{"test", "scenario", "judged", "what"}], "results": [{"test", "filter", "error_deg", "grade",
///  "mag_rejected_fraction", "caught_fraction", "total_rmse_deg", "heading_rmse_deg", "inclination_rmse_deg"}]}
std::string standard_tests_json(const std::vector<StandardTestResult>& results);

}  // namespace bsn::eval
