// Identifying a filter's parameters from recordings with a reference orientation (`bsn tune`), as Nez et al. 2018
// (section 2.4-2.5) did for the MEKF's four sigmas by exhaustive search, here by a global stage on Halton points and
// a local pattern search (coordinate steps, halved when no step improves) in the unit cube of the ranges, which are
// searched in log space where asked. Plain C++: no I/O, no threads; the caller evaluates each batch of points, in
// parallel if it likes (tune_runner.hpp does, on two threads).
#pragma once

#include <cstddef>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "bsn/fusion/orientation_filter.hpp"

namespace bsn::eval {

/// One parameter to identify and its search range.
struct ParamRange {
  std::string name;  ///< the filter's parameter name, as in the body model's `filter:` block
  double lo = 0.0;   ///< smallest value searched, in the parameter's unit
  double hi = 0.0;   ///< largest value searched
  bool log = false;  ///< search log(value) uniformly (noise sigmas span decades); needs lo > 0

  /// The value at unit coordinate u in [0, 1] (0 -> lo, 1 -> hi; geometric when log).
  double value_at(double u) const;
};

/// Parses "name=lo:hi" or "name=lo:hi:log". Throws std::invalid_argument naming the parameter: a missing '=',
/// a value that is not a number, NaN or infinity, an empty or inverted range (lo >= hi), lo <= 0 with log.
ParamRange parse_param_range(const std::string& text);

/// Checks `ranges` against the filter `base` names: every name is one of the filter's parameters and occurs once,
/// and the filter accepts both ends of each range. Throws std::invalid_argument naming the parameter.
void check_param_ranges(const fusion::FilterSpec& base, const std::vector<ParamRange>& ranges);

/// The ranges searched when none are given: mekf's four sigmas (Nez Table 2 values as the lower ends, as Nez set
/// them, up to beyond Table 3's largest), seel_ruppin's tau_acc_s, tau_mag_s and zeta. Empty for other filters.
std::vector<ParamRange> default_param_ranges(const std::string& filter);

/// `base` with each range's parameter set to values[i] (replacing an entry of the same name).
fusion::FilterSpec spec_with(const fusion::FilterSpec& base, const std::vector<ParamRange>& ranges,
                             std::span<const double> values);

/// What is minimised over the recordings' total RMSEs.
enum class Criterion {
  kNez,   ///< Nez §2.5: mean RMSE + its standard deviation over the recordings (n - 1; 0 for one recording)
  kRmse,  ///< the plain mean total RMSE
};
/// "nez" or "rmse"; throws std::invalid_argument otherwise.
Criterion parse_criterion(const std::string& text);
const char* criterion_name(Criterion c);
/// The criterion of per-recording RMSEs (any unit); +infinity if one is not finite or there are none.
double criterion_value(Criterion c, std::span<const double> rmse);

/// Budget and resolution of minimise().
struct OptimiserOptions {
  /// Halton points of the global stage (plus the cube's centre). Default 48: with 4 parameters, about 2 per
  /// axis-decade of a 3-decade range, enough to land in the basin of the optimum on the MEKF's smooth surfaces.
  std::size_t global_points = 48;
  /// Local stage: pattern searches from this many of the best global points at once. Default 3.
  std::size_t local_starts = 3;
  /// Local stage: the first step along each coordinate, in unit-cube coordinates. Default 1/8.
  double initial_step = 0.125;
  /// The local stage ends once the step is below this. Default 1/128: on a 3-decade log range a factor of 1.06,
  /// far finer than the criterion's sensitivity.
  double min_step = 1.0 / 128.0;
  /// Hard cap on evaluations over both stages. Default 600.
  std::size_t max_evaluations = 600;
};

/// Evaluates a batch of points (each in the unit cube) and returns one value per point (lower is better; NaN
/// counts as +infinity). It may evaluate them in parallel.
using BatchObjective = std::function<std::vector<double>(const std::vector<std::vector<double>>& points)>;
/// Called after each batch: evaluations so far, the budget, the best value so far.
using OptimiserProgress = std::function<void(std::size_t done, std::size_t budget, double best)>;

struct OptimiserResult {
  std::vector<double> unit;     ///< the best point, unit-cube coordinates
  double value = 0.0;           ///< its objective value
  std::size_t evaluations = 0;  ///< distinct points evaluated
  std::size_t global_evaluations = 0;
  double final_step = 0.0;  ///< the local searches' largest last step (< min_step when all converged)
};

/// Minimises `objective` over the unit cube of `dims` dimensions: the centre and `global_points` Halton points,
/// then pattern searches from the best `local_starts` of them (all their 2 * dims coordinate steps of the current
/// step size in one batch; each moves to its best improving step, or halves its step). `start` points (unit
/// coordinates, e.g. a preset) join the global stage. Throws std::invalid_argument for dims 0 or options out of range.
OptimiserResult minimise(std::size_t dims, const BatchObjective& objective, const OptimiserOptions& options = {},
                         const std::vector<std::vector<double>>& start = {}, const OptimiserProgress& progress = {});

/// The i-th point (i >= 1) of the Halton sequence in `dims` dimensions (bases: the first primes). dims <= 16.
std::vector<double> halton_point(std::size_t i, std::size_t dims);

}  // namespace bsn::eval
