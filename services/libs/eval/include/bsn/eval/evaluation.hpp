// Offline evaluation of orientation filters on recordings with a reference (BROAD trials, simulator output,
// CSV files), with BROAD's metrics: total, heading and inclination RMSE over the samples that count.
#pragma once

#include <string>
#include <vector>

#include "bsn/fusion/orientation_error.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/io/recording.hpp"

namespace bsn::eval {

struct TrialResult {
  std::string trial;                        ///< file stem, e.g. "02_undisturbed_slow_rotation_B"
  std::string filter;                       ///< filter spec as given, e.g. "complementary" or "seel_ruppin:tau_acc_s=3"
  fusion::ErrorAngles rmse;                 ///< radians
  std::size_t scored = 0;                   ///< samples that counted (movement and a finite reference)
  std::size_t rejected = 0;                 ///< samples the filter rejected
  std::size_t non_finite = 0;               ///< estimates that were not finite (must stay 0)
  std::vector<float> time_s;                ///< (downsampled) time of the error series, s
  std::vector<float> total_deg;             ///< (downsampled) total error over time, deg (NaN where not scored)
  std::string series_name = "total error";  ///< what total_deg holds (the standard tests plot their judged angle)
  double unscored_until_s = 0.0;            ///< time of the first scored sample (the plot shades what is before)
};

/// Runs one fresh filter from the first sample over the whole recording; scores the movement samples with a
/// finite reference. Keeps at most `max_series_points` points of the error series for plots.
TrialResult run_trial(const io::Recording& rec, const std::string& trial, const fusion::FilterSpec& spec,
                      const std::string& filter_label, std::size_t max_series_points = 2000);

/// Parses "name" or "name:key=value,key=value" into a filter spec. Throws std::invalid_argument.
fusion::FilterSpec parse_filter_argument(const std::string& text);

/// Mean over the trials of one filter, per angle.
struct FilterMean {
  std::string filter;
  fusion::ErrorAngles mean_rmse;  ///< radians
  std::size_t trials = 0;
};
std::vector<FilterMean> means_by_filter(const std::vector<TrialResult>& results);

/// The JSON other tools read:
/// {"trials": [{"trial", "filter", "total_rmse_deg", "heading_rmse_deg", "inclination_rmse_deg"}],
///  "means": [{"filter", "total_rmse_deg", "heading_rmse_deg", "inclination_rmse_deg"}]}
std::string to_json(const std::vector<TrialResult>& results);

/// A human table, one row per trial and filter, then the means.
std::string to_table(const std::vector<TrialResult>& results);

/// The same figures as Markdown for the manual (docs/filters.md pastes it): the filters sorted by mean total RMSE,
/// with each filter's worst trial and its ratio to the filter's mean, then one row per trial with a column per filter.
std::string to_markdown(const std::vector<TrialResult>& results);

/// An SVG image: one panel per trial, the error series over time, one line per filter (ten colours, and dash
/// patterns that tell the filters apart in grey print too), axes with ticks and a grid, the unscored start
/// shaded and labelled.
std::string to_svg(const std::vector<TrialResult>& results);

}  // namespace bsn::eval
