#include "bsn/eval/standard_tests.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>

#include "bsn/fusion/orientation_error.hpp"
#include "bsn/io/json.hpp"
#include "bsn/sim/scenario.hpp"
#include "bsn/sim/scenario_file.hpp"

namespace bsn::eval {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

double judged_angle(StandardTest::Judged j, const fusion::ErrorAngles& e) {
  switch (j) {
    case StandardTest::Judged::kInclination:
      return e.inclination;
    case StandardTest::Judged::kHeading:
      return e.heading;
    case StandardTest::Judged::kTotal:
      break;
  }
  return e.total;
}

const char* judged_name(StandardTest::Judged j) {
  switch (j) {
    case StandardTest::Judged::kInclination:
      return "inclination";
    case StandardTest::Judged::kHeading:
      return "heading";
    case StandardTest::Judged::kTotal:
      break;
  }
  return "total";
}

}  // namespace

const std::vector<StandardTest>& fan_standard_tests() {
  using J = StandardTest::Judged;
  static const std::vector<StandardTest> tests = {
      {"A", "fan_a", J::kTotal, "static and dynamic accuracy, clean field"},
      {"B", "fan_b", J::kInclination, "pitch and roll while a magnet is brought close five times"},
      {"C", "fan_c", J::kHeading, "heading over 20 min in a continuous strong disturbance"},
      {"D", "fan_d", J::kHeading, "heading under a small disturbance below the thresholds"},
      {"E", "fan_e", J::kTotal, "motion through a disturbed area for 10, 30 and 60 s"},
  };
  return tests;
}

Grade grade_of(double error_deg) {
  if (error_deg <= 2.0) return Grade::kGood;
  if (error_deg <= 5.0) return Grade::kAcceptable;
  return Grade::kPoor;  // NaN lands here too
}

const char* grade_name(Grade g) {
  switch (g) {
    case Grade::kGood:
      return "good";
    case Grade::kAcceptable:
      return "acceptable";
    case Grade::kPoor:
      break;
  }
  return "poor";
}

std::vector<StandardTestResult> run_standard_tests(
    const std::string& scenario_dir, const std::vector<std::pair<std::string, fusion::FilterSpec>>& filters,
    double startup_s, std::optional<std::uint64_t> seed) {
  std::vector<StandardTestResult> results;
  for (const StandardTest& test : fan_standard_tests()) {
    sim::ScenarioSpec spec = sim::load_scenario(scenario_dir + "/" + test.scenario + ".yaml");
    if (seed) spec.seed = *seed;
    // Simulated once, then every filter runs over the same samples.
    sim::ScenarioRunner runner(spec, {}, false);
    std::vector<sim::ScenarioSample> samples, one;
    samples.reserve(runner.sample_count());
    while (runner.next(one)) samples.push_back(one.front());
    // Where the field is truly disturbed: the same motion with exact sensors, with and without the scenario's
    // magnets, floors and attached magnets; disturbed where they differ by more than 10 % of the earth field (the
    // filters' enter threshold). "Early" = within the first kEarlyS of each disturbed stretch, before any rule
    // for a long disturbance (a new reference after 20 s, the reduced gain after 60 s) may take the field in.
    constexpr double kEarlyS = 10.0;
    std::vector<char> early_disturbed(samples.size(), 0);
    {
      sim::ScenarioSpec clean = spec;
      clean.magnetic.dipoles.clear();
      clean.magnetic.floor_regions.clear();
      clean.magnetic.attached_magnets.clear();
      sim::ScenarioRunner exact(spec, {}, true), exact_clean(clean, {}, true);
      std::vector<sim::ScenarioSample> a, b;
      double stretch_start = -1.0;
      for (std::size_t i = 0; i < samples.size() && exact.next(a) && exact_clean.next(b); ++i) {
        const fusion::Vec3& m = a.front().sample.mag;
        const fusion::Vec3& m0 = b.front().sample.mag;
        const double t = static_cast<double>(a.front().sample.timestamp_ns) * 1e-9;
        if ((m - m0).norm() > 0.1 * m0.norm()) {
          if (stretch_start < 0.0) stretch_start = t;
          early_disturbed[i] = t - stretch_start < kEarlyS;
        } else {
          stretch_start = -1.0;
        }
      }
    }
    const std::size_t max_points = 2000;
    const std::size_t stride = std::max<std::size_t>(1, (samples.size() + max_points - 1) / max_points);
    for (const auto& [label, filter_spec] : filters) {
      auto filter = fusion::make_filter(filter_spec);
      StandardTestResult r;
      r.test = test.id;
      r.filter = label;
      r.trial.trial = test.scenario;
      r.trial.filter = label;
      r.trial.series_name = std::string(judged_name(test.judged)) + " error";
      r.trial.unscored_until_s = startup_s;
      fusion::RmsErrorAccumulator acc;
      double judged_sq = 0.0, with_mag = 0.0, rejected = 0.0, early = 0.0, caught = 0.0;
      for (std::size_t i = 0; i < samples.size(); ++i) {
        const sim::ScenarioSample& s = samples[i];
        if (s.dropped) continue;  // the sensor lost it: the filter never sees it
        if (filter->update(s.sample) == fusion::UpdateResult::kRejected) ++r.trial.rejected;
        const double t_s = static_cast<double>(s.sample.timestamp_ns) * 1e-9;
        const fusion::Quat q = filter->orientation();
        double err_deg = std::nan("");
        if (!q.coeffs().allFinite()) {
          ++r.trial.non_finite;
        } else if (t_s >= startup_s && s.movement && filter->initialised()) {
          const fusion::ErrorAngles e = fusion::error_angles(q, s.truth);
          acc.add(e);
          const double j = judged_angle(test.judged, e);
          judged_sq += j * j;
          err_deg = j * kDeg;
          if (s.sample.has_mag) {
            with_mag += 1.0;
            if (filter->flags().mag_rejected) rejected += 1.0;
            if (early_disturbed[i]) {
              early += 1.0;
              if (filter->flags().mag_rejected) caught += 1.0;
            }
          }
        }
        if (i % stride == 0) {
          r.trial.time_s.push_back(static_cast<float>(t_s));
          r.trial.total_deg.push_back(static_cast<float>(err_deg));
        }
      }
      r.trial.rmse = acc.rms();
      r.trial.scored = acc.count();
      r.error_deg = acc.count() > 0 ? std::sqrt(judged_sq / static_cast<double>(acc.count())) * kDeg : std::nan("");
      if (r.trial.non_finite > 0) r.error_deg = std::nan("");
      r.grade = grade_of(r.error_deg);
      r.mag_rejected_fraction = with_mag > 0.0 ? rejected / with_mag : 0.0;
      r.disturbed_samples = static_cast<std::size_t>(early);
      r.caught_fraction = early > 0.0 ? caught / early : std::nan("");
      results.push_back(std::move(r));
    }
  }
  return results;
}

std::string standard_tests_markdown(const std::vector<StandardTestResult>& results) {
  std::vector<std::string> filters;
  for (const auto& r : results)
    if (std::find(filters.begin(), filters.end(), r.filter) == filters.end()) filters.push_back(r.filter);
  std::string out = "| filter |", rule = "|---|";
  for (const StandardTest& t : fan_standard_tests()) {
    out += " " + t.id + " (" + judged_name(t.judged) + ") |";
    rule += "---|";
  }
  out += "\n" + rule + "\n";
  char cell[128];
  for (const auto& f : filters) {
    out += "| `" + f + "` |";
    for (const StandardTest& t : fan_standard_tests()) {
      const auto it = std::find_if(results.begin(), results.end(),
                                   [&](const StandardTestResult& r) { return r.filter == f && r.test == t.id; });
      if (it == results.end()) {
        out += " - |";
      } else {
        std::snprintf(cell, sizeof cell, " %.2f° %s |", it->error_deg, grade_name(it->grade));
        out += cell;
      }
    }
    out += "\n";
  }
  return out;
}

std::string standard_tests_table(const std::vector<StandardTestResult>& results) {
  std::vector<std::string> filters;
  for (const auto& r : results) {
    if (std::find(filters.begin(), filters.end(), r.filter) == filters.end()) filters.push_back(r.filter);
  }
  std::size_t fw = 6;
  for (const auto& f : filters) fw = std::max(fw, f.size());
  std::string out = "Fan et al. 2018, Table 5 (RMSE of the judged angle, deg; good <= 2, acceptable 2-5, poor > 5)\n";
  char cell[256];
  std::snprintf(cell, sizeof cell, "%-*s", static_cast<int>(fw), "filter");
  out += cell;
  for (const StandardTest& t : fan_standard_tests()) {
    std::snprintf(cell, sizeof cell, "  %-18s", (t.id + " (" + judged_name(t.judged) + ")").c_str());
    out += cell;
  }
  out += "\n";
  for (const auto& f : filters) {
    std::snprintf(cell, sizeof cell, "%-*s", static_cast<int>(fw), f.c_str());
    out += cell;
    for (const StandardTest& t : fan_standard_tests()) {
      const StandardTestResult* found = nullptr;
      for (const auto& r : results) {
        if (r.filter == f && r.test == t.id) found = &r;
      }
      if (found) {
        std::snprintf(cell, sizeof cell, "  %6.2f %-11s", found->error_deg, grade_name(found->grade));
      } else {
        std::snprintf(cell, sizeof cell, "  %-18s", "-");
      }
      out += cell;
    }
    out += "\n";
  }
  for (const StandardTest& t : fan_standard_tests()) out += t.id + ": " + t.scenario + ", " + t.what + "\n";
  out +=
      "Disturbance caught (magnetometer rejected in the first 10 s of each stretch where the field is off by\n"
      "more than 10 %), percent of those samples:\n";
  for (const auto& f : filters) {
    std::snprintf(cell, sizeof cell, "%-*s", static_cast<int>(fw), f.c_str());
    out += cell;
    for (const auto& r : results) {
      if (r.filter != f || r.disturbed_samples == 0) continue;
      std::snprintf(cell, sizeof cell, "  %s %5.1f %%", r.test.c_str(), 100.0 * r.caught_fraction);
      out += cell;
    }
    out += "\n";
  }
  return out;
}

std::string standard_tests_json(const std::vector<StandardTestResult>& results) {
  using io::json_number;
  using io::json_string;
  std::string out = "{\"tests\": [";
  bool first = true;
  for (const StandardTest& t : fan_standard_tests()) {
    out += (first ? "" : ", ") + std::string("{\"test\": ") + json_string(t.id) +
           ", \"scenario\": " + json_string(t.scenario) + ", \"judged\": " + json_string(judged_name(t.judged)) +
           ", \"what\": " + json_string(t.what) + "}";
    first = false;
  }
  out += "], \"results\": [";
  for (std::size_t i = 0; i < results.size(); ++i) {
    const auto& r = results[i];
    out += (i ? ", " : "") + std::string("{\"test\": ") + json_string(r.test) +
           ", \"filter\": " + json_string(r.filter) + ", \"error_deg\": " + json_number(r.error_deg) +
           ", \"grade\": " + json_string(grade_name(r.grade)) +
           ", \"mag_rejected_fraction\": " + json_number(r.mag_rejected_fraction) +
           ", \"caught_fraction\": " + json_number(r.caught_fraction) +
           ", \"total_rmse_deg\": " + json_number(r.trial.rmse.total * kDeg) +
           ", \"heading_rmse_deg\": " + json_number(r.trial.rmse.heading * kDeg) +
           ", \"inclination_rmse_deg\": " + json_number(r.trial.rmse.inclination * kDeg) + "}";
  }
  return out + "]}\n";
}

}  // namespace bsn::eval
