// The service side of `bsn tune`: runs candidate filters over recordings with a reference on worker threads, feeds
// the optimiser of tuning.hpp, scores the identified set on the fitted and on held-out recordings, and segments
// recordings by Nez's Table 1 intensity classes for --by-intensity.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "bsn/eval/tuning.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/sim/scenario.hpp"

namespace bsn::eval {

/// One recording to tune on.
struct TuneRecording {
  std::string name;                ///< shown in the tables, e.g. the file stem
  io::Recording rec;               ///< with a reference orientation
  std::vector<std::uint8_t> mask;  ///< empty: score the movement samples; else 1 where a sample is scored
};

/// Throws std::invalid_argument naming `source` unless the recording can be tuned on: it has a reference
/// orientation, no reference row is partly NaN, and at least half of the samples that count (movement) have a
/// finite reference (a NaN row is "no reference here", as in BROAD; more than half missing would make the RMSE
/// a figure of a few stretches).
void check_tuning_recording(const io::Recording& rec, const std::string& source);

/// Total RMSE (rad) of a fresh filter run over the whole recording, over the samples that are scored (mask or
/// movement, a finite reference, the filter initialised). NaN if any orientation was not finite or nothing
/// was scored. No allocation per sample.
double total_rmse(const io::Recording& rec, const fusion::FilterSpec& spec, std::span<const std::uint8_t> mask = {});

/// Per point (values in the ranges' units, not unit coordinates), per recording: total RMSE in rad. The
/// (point, recording) runs are shared among `threads` worker threads; a filter that throws gives NaN.
std::vector<std::vector<double>> rmse_table(const fusion::FilterSpec& base, const std::vector<ParamRange>& ranges,
                                            const std::vector<std::vector<double>>& values,
                                            const std::vector<const TuneRecording*>& recordings, unsigned threads);

struct TuneSetup {
  fusion::FilterSpec base;         ///< the filter and the parameters that stay fixed
  std::vector<ParamRange> ranges;  ///< what is identified
  Criterion criterion = Criterion::kNez;
  std::vector<const TuneRecording*> fit;       ///< identified on these
  std::vector<const TuneRecording*> held_out;  ///< only scored (may be empty)
  OptimiserOptions options;
  unsigned threads = 2;  ///< worker threads (the machine's two cores)
};

struct TuneResult {
  std::vector<double> values;  ///< identified value per range, in its unit
  fusion::FilterSpec spec;     ///< base with the identified values
  OptimiserResult optimiser;
  std::vector<double> fit_rmse, held_out_rmse;            ///< identified set, rad, per recording
  std::vector<double> base_fit_rmse, base_held_out_rmse;  ///< the base spec as it is (today's defaults), rad
  double fit_criterion = 0.0, held_out_criterion = 0.0;   ///< rad; held-out NaN without held-out recordings
  double base_fit_criterion = 0.0, base_held_out_criterion = 0.0;
};

/// The seed's experiment on a simulated Nez scenario (bsn_bench_tune, its test, bsn_bench_nez_sources): mekf's four
/// sigmas identified on `rec` from Table 3's set of one intensity (preset 1 slow, 2 intermediate, 3 fast), the filter
/// told that the Opal-like magnetometer does not lag (mag_latency_s 0: the default brings each reading forward by a
/// consumer part's lag, which on a sensor without lag is itself an error growing with the rate of turn) and run as
/// Nez's filter, without the zero-rate update at rest (rest_bias_update 0: the experiment identifies the paper's
/// filter's sigmas, and that update gives the bias information the paper's filter does not have).
TuneSetup nez_mekf_setup(const TuneRecording& rec, int preset);

/// Identifies the ranges' parameters on setup.fit, then scores the result and the base on both sets. `progress`
/// as in minimise(). Throws std::invalid_argument for bad ranges (check_param_ranges) or no fit recordings.
TuneResult tune(const TuneSetup& setup, const OptimiserProgress& progress = {});

/// Per sample, Nez's Table 1 class as mekf_adaptive assigns it with its default thresholds (fusion_core's
/// MekfFilter::Params): 0 static, 1 slow, 2 intermediate, 3 fast, the highest instantaneous class (of | |acc| - g |
/// and |gyr|) within the last intensity_hold_s (0.5 s).
std::vector<std::uint8_t> intensity_classes(const io::Recording& rec);
const char* intensity_name(int c);

/// One class's set as `bsn tune --by-intensity` identifies it: a "mekf" spec fitted on that class's samples.
struct ClassSet {
  int intensity = 0;        ///< 0 static .. 3 fast
  fusion::FilterSpec mekf;  ///< name "mekf" with the identified (and fixed) parameters
};

/// The mekf_adaptive spec that uses the given classes' sets (sigma_<g|bg|a|m>_<class>: all four sigmas each "mekf"
/// spec ends up with, its preset filling what was not identified); classes not given keep Table 3. table_rate_hz is
/// the rate the sets were identified at (mekf_adaptive scales sigma_a and sigma_m from it to the rate it runs at),
/// 0 = use them as they are. Throws std::invalid_argument for a spec that is not a valid "mekf" or a class outside
/// 0..3.
fusion::FilterSpec adaptive_spec_of(const std::vector<ClassSet>& sets, double table_rate_hz);

/// A simulated recording of one segment of a scenario (the sensors as the scenario sets them, or exact with
/// `ideal`), with the truth as reference, the scenario's movement windows, per-sample timestamps and NaN
/// magnetometer rows where the magnetometer gave no sample. Dropped samples are left out.
io::Recording simulate_recording(const sim::ScenarioSpec& spec, bool ideal = false);

}  // namespace bsn::eval
