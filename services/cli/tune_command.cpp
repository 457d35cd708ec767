// `bsn tune`: identify a filter's parameters on recordings with a reference orientation (Nez et al. 2018's
// identification, with a global + local search instead of the exhaustive grid), with held-out scoring and
// per-intensity sets.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "bsn/eval/evaluation.hpp"
#include "bsn/eval/tune_runner.hpp"
#include "bsn/eval/tuning.hpp"
#include "bsn/io/json.hpp"
#include "bsn/io/recording.hpp"
#include "progress_bar.hpp"
#include "tools.hpp"

namespace bsn::services {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;
// A class needs this much scored motion in a recording for the recording to count for that class's set: the
// MEKF's start-up transients and the 10 s minimum between switches of mekf_adaptive make shorter stretches
// uninformative.
constexpr double kMinClassSeconds = 10.0;

struct TuneOptions {
  std::string filter;               ///< "name" or "name:key=value,..." (fixed parameters)
  std::vector<std::string> inputs;  ///< recordings or folders
  std::vector<std::string> params;  ///< name=lo:hi[:log]
  std::string criterion = "nez";
  std::size_t holdout = 0;  ///< the last K recordings are scored only
  bool by_intensity = false;
  std::string json_path;
  std::size_t max_evaluations = 600;
  std::size_t global_points = 48;
  unsigned threads = 2;
};

std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

std::string deg(double rad) {
  if (!std::isfinite(rad)) return "n/a";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", rad * kDeg);
  return buf;
}

std::string filter_block(const fusion::FilterSpec& spec) {
  std::string s = "filter: {name: " + spec.name;
  for (const auto& [k, v] : spec.parameters) s += ", " + k + ": " + fmt(v);
  return s + "}";
}

// One identification's report: the filter block, the range-end warnings, per-recording and criterion rows.
std::string report(const eval::TuneSetup& setup, const eval::TuneResult& r, double seconds) {
  std::string out = filter_block(r.spec) + "\n";
  for (std::size_t d = 0; d < setup.ranges.size(); ++d) {
    const double u = r.optimiser.unit[d];
    if (u <= 0.0 || u >= 1.0) {
      out += "note: " + setup.ranges[d].name + " = " + fmt(r.values[d]) + " is at the " +
             (u <= 0.0 ? "lower" : "upper") + " end of its range; widen it with --param\n";
    }
  }
  char line[256];
  std::snprintf(line, sizeof line, "%zu evaluations (%zu global), %.1f s\n\n", r.optimiser.evaluations,
                r.optimiser.global_evaluations, seconds);
  out += line;
  std::snprintf(line, sizeof line, "%-40s %-9s %12s %14s\n", "recording", "set", "tuned (deg)", "defaults (deg)");
  out += line;
  const auto rows = [&](const std::vector<const eval::TuneRecording*>& recs, const std::vector<double>& tuned,
                        const std::vector<double>& base, const char* set) {
    for (std::size_t i = 0; i < recs.size(); ++i) {
      std::snprintf(line, sizeof line, "%-40.40s %-9s %12s %14s\n", recs[i]->name.c_str(), set, deg(tuned[i]).c_str(),
                    deg(base[i]).c_str());
      out += line;
    }
  };
  rows(setup.fit, r.fit_rmse, r.base_fit_rmse, "fit");
  rows(setup.held_out, r.held_out_rmse, r.base_held_out_rmse, "held-out");
  const std::string what = std::string("criterion ") + eval::criterion_name(setup.criterion);
  std::snprintf(line, sizeof line, "%-40s %-9s %12s %14s\n", what.c_str(), "fit", deg(r.fit_criterion).c_str(),
                deg(r.base_fit_criterion).c_str());
  out += line;
  if (!setup.held_out.empty()) {
    std::snprintf(line, sizeof line, "%-40s %-9s %12s %14s\n", what.c_str(), "held-out",
                  deg(r.held_out_criterion).c_str(), deg(r.base_held_out_criterion).c_str());
    out += line;
  }
  return out;
}

std::string json_of(const eval::TuneSetup& setup, const eval::TuneResult& r, double seconds) {
  using io::json_number;
  using io::json_string;
  const auto num = [](double v) { return std::isfinite(v) ? json_number(v) : std::string("null"); };
  std::string s = "{\"filter\": " + json_string(setup.base.name) +
                  ", \"criterion\": " + json_string(eval::criterion_name(setup.criterion)) + ", \"parameters\": {";
  for (std::size_t i = 0; i < r.spec.parameters.size(); ++i) {
    s += (i ? ", " : "") + json_string(r.spec.parameters[i].first) + ": " + num(r.spec.parameters[i].second);
  }
  s += "}, \"evaluations\": " + std::to_string(r.optimiser.evaluations) + ", \"seconds\": " + num(seconds) +
       ", \"recordings\": [";
  bool first = true;
  const auto rows = [&](const std::vector<const eval::TuneRecording*>& recs, const std::vector<double>& tuned,
                        const std::vector<double>& base, const char* set) {
    for (std::size_t i = 0; i < recs.size(); ++i) {
      s += (first ? "" : ", ") + std::string("{\"recording\": ") + json_string(recs[i]->name) +
           ", \"set\": " + json_string(set) + ", \"tuned_total_rmse_deg\": " + num(tuned[i] * kDeg) +
           ", \"defaults_total_rmse_deg\": " + num(base[i] * kDeg) + "}";
      first = false;
    }
  };
  rows(setup.fit, r.fit_rmse, r.base_fit_rmse, "fit");
  rows(setup.held_out, r.held_out_rmse, r.base_held_out_rmse, "held_out");
  s += "], \"fit_criterion_deg\": " + num(r.fit_criterion * kDeg) +
       ", \"held_out_criterion_deg\": " + num(r.held_out_criterion * kDeg) +
       ", \"defaults_fit_criterion_deg\": " + num(r.base_fit_criterion * kDeg) +
       ", \"defaults_held_out_criterion_deg\": " + num(r.base_held_out_criterion * kDeg) + "}";
  return s;
}

int fail(const std::string& message) {
  std::fprintf(stderr, "bsn tune: error: %s\n", message.c_str());
  return 2;
}

/// The filter, criterion and parameter ranges of the identification; 0, or 2 (said) when one is wrong.
int tune_setup(const TuneOptions& opt, eval::TuneSetup& setup) {
  try {
    setup.base = eval::parse_filter_argument(opt.filter);
    (void)fusion::make_filter(setup.base);  // an unknown filter or fixed parameter fails here, before any work
    setup.criterion = eval::parse_criterion(opt.criterion);
    for (const auto& p : opt.params) setup.ranges.push_back(eval::parse_param_range(p));
    if (setup.ranges.empty()) setup.ranges = eval::default_param_ranges(setup.base.name);
    if (setup.ranges.empty()) {
      return fail("filter '" + setup.base.name + "' has no default ranges; name what to identify with --param");
    }
    eval::check_param_ranges(setup.base, setup.ranges);
  } catch (const std::exception& e) {
    return fail(e.what());
  }
  setup.options.max_evaluations = opt.max_evaluations;
  setup.options.global_points = opt.global_points;
  setup.threads = opt.threads;
  return 0;
}

/// The recordings named, each with a reference orientation; 0, or 2 (said) when one is unreadable or none fits.
int tune_recordings(const TuneOptions& opt, std::vector<eval::TuneRecording>& recordings) {
  try {
    for (const auto& file : expand_recording_inputs(opt.inputs)) {
      eval::TuneRecording t{file.stem().string(), io::read_recording(file.string()), {}};
      eval::check_tuning_recording(t.rec, file.string());
      recordings.push_back(std::move(t));
    }
  } catch (const std::exception& e) {
    return fail(e.what());
  }
  if (recordings.empty()) return fail("name recordings with a reference orientation (files or folders)");
  if (opt.holdout >= recordings.size()) {
    return fail("--holdout " + std::to_string(opt.holdout) + " leaves no recording to fit on (" +
                std::to_string(recordings.size()) + " given)");
  }
  return 0;
}

/// One identification: a label, the recordings (with the class's mask) and how many of them are held out.
struct Job {
  std::string label;
  int intensity = -1;                     ///< the class with --by-intensity
  std::vector<eval::TuneRecording> recs;  ///< with the class's mask
  std::size_t holdout = 0;
  std::string note;  ///< printed with the set's results
};

/// One job per intensity class that enough of the recordings hold (masks restrict the scored samples); the last
/// `holdout` recordings are held out.
std::vector<Job> intensity_jobs(const std::vector<eval::TuneRecording>& recordings, std::size_t holdout) {
  std::vector<Job> jobs;
  std::vector<std::vector<std::uint8_t>> classes;
  for (const auto& t : recordings) classes.push_back(eval::intensity_classes(t.rec));
  for (int c = 0; c < 4; ++c) {
    Job job{eval::intensity_name(c), c, {}, 0, ""};
    std::size_t skipped = 0;
    for (std::size_t i = 0; i < recordings.size(); ++i) {
      eval::TuneRecording t{recordings[i].name, recordings[i].rec, {}};
      t.mask.assign(t.rec.size(), 0);
      std::size_t n = 0;
      for (std::size_t k = 0; k < t.rec.size(); ++k) {
        const bool counts = t.rec.movement.empty() || t.rec.movement[k] != 0;
        t.mask[k] = counts && classes[i][k] == c;
        n += t.mask[k];
      }
      const bool held = i >= recordings.size() - holdout;
      if (static_cast<double>(n) < kMinClassSeconds * t.rec.sampling_rate_hz) {
        ++skipped;
        continue;
      }
      job.recs.push_back(std::move(t));
      job.holdout += held;
    }
    if (job.recs.size() == job.holdout) {
      std::printf("\nintensity %s: fewer than %.0f s of it in every recording to fit on; no set identified\n",
                  job.label.c_str(), kMinClassSeconds);
      continue;
    }
    if (skipped > 0) {
      job.note =
          std::to_string(skipped) + " recording(s) with less than " + fmt(kMinClassSeconds) + " s of it left out\n";
    }
    jobs.push_back(std::move(job));
  }
  return jobs;
}

/// The per-class mekf sets as mekf_adaptive's table, printed and appended to `json`; 0, or 2 (said).
int report_adaptive(const std::vector<eval::ClassSet>& class_sets, double rate_lo, double rate_hi, std::string& json) {
  // mekf_adaptive scales sigma_a and sigma_m from table_rate_hz to the rate it runs at; recordings of different
  // rates (more than 1 % apart) leave no single rate, so the sets are then taken as they are (0).
  const bool one_rate = rate_hi <= rate_lo * 1.01;
  fusion::FilterSpec adaptive;
  try {
    adaptive = eval::adaptive_spec_of(class_sets, one_rate ? rate_lo : 0.0);
  } catch (const std::exception& e) {
    return fail(e.what());
  }
  std::printf("\nmekf_adaptive with these sets (a class without a set keeps its default):\n%s\n",
              filter_block(adaptive).c_str());
  for (int c = 0; c < 4; ++c) {
    const bool has_set = std::any_of(class_sets.begin(), class_sets.end(),
                                     [c](const eval::ClassSet& set) { return set.intensity == c; });
    if (!has_set) {
      std::printf(
          "note: %s has no set and keeps its default set; with little of it in the recordings, consider the "
          "nearest class's set for it (README, Tuning)\n",
          eval::intensity_name(c));
    }
  }
  if (!one_rate) {
    std::printf("note: the recordings' rates differ (%.4g to %.4g Hz): table_rate_hz 0 uses the sets unscaled\n",
                rate_lo, rate_hi);
  }
  json += ", \"mekf_adaptive\": {\"name\": \"mekf_adaptive\", \"parameters\": {";
  for (std::size_t i = 0; i < adaptive.parameters.size(); ++i) {
    json += (i ? ", " : "") + io::json_string(adaptive.parameters[i].first) + ": " +
            io::json_number(adaptive.parameters[i].second);
  }
  json += "}}";
  return 0;
}

int run_tune(const TuneOptions& opt) {
  eval::TuneSetup setup;
  if (const int code = tune_setup(opt, setup); code != 0) return code;
  std::vector<eval::TuneRecording> recordings;
  if (const int code = tune_recordings(opt, recordings); code != 0) return code;

  std::printf("bsn tune: %s on %zu recording(s) (%zu fit, %zu held out), criterion %s%s, %zu parameter(s)\n",
              setup.base.name.c_str(), recordings.size(), recordings.size() - opt.holdout, opt.holdout,
              eval::criterion_name(setup.criterion),
              setup.criterion == eval::Criterion::kNez ? " (mean + SD of the total RMSE, Nez 2018 s. 2.5)"
                                                       : " (mean total RMSE)",
              setup.ranges.size());

  // One identification per class with --by-intensity, else one.
  std::vector<Job> jobs;
  if (!opt.by_intensity) {
    jobs.push_back({"", -1, std::move(recordings), opt.holdout, ""});
  } else {
    jobs = intensity_jobs(recordings, opt.holdout);
  }

  // Per-class mekf sets become mekf_adaptive's table; they were identified at the recordings' rate.
  std::vector<eval::ClassSet> class_sets;
  double rate_lo = std::numeric_limits<double>::infinity(), rate_hi = 0.0;
  for (const Job& job : jobs) {
    for (const auto& t : job.recs) {
      rate_lo = std::min(rate_lo, t.rec.sampling_rate_hz);
      rate_hi = std::max(rate_hi, t.rec.sampling_rate_hz);
    }
  }
  std::string json = "{\"sets\": [";
  for (std::size_t j = 0; j < jobs.size(); ++j) {
    Job& job = jobs[j];
    setup.fit.clear();
    setup.held_out.clear();
    for (std::size_t i = 0; i < job.recs.size(); ++i) {
      (i < job.recs.size() - job.holdout ? setup.fit : setup.held_out).push_back(&job.recs[i]);
    }
    ProgressBar bar(setup.options.max_evaluations);
    const std::string what = job.label.empty() ? "best " : job.label + ": best ";
    const auto t0 = std::chrono::steady_clock::now();
    eval::TuneResult r;
    try {
      r = eval::tune(setup,
                     [&](std::size_t done, std::size_t, double best) { bar.show(done, what + deg(best) + " deg"); });
    } catch (const std::exception& e) {
      bar.finish();
      return fail(e.what());
    }
    bar.finish();
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("\n%s%s%s", job.label.empty() ? "" : ("intensity " + job.label + ":\n").c_str(), job.note.c_str(),
                report(setup, r, seconds).c_str());
    std::string one = json_of(setup, r, seconds);
    if (!job.label.empty()) one.insert(1, "\"intensity\": " + io::json_string(job.label) + ", ");
    json += (j ? ", " : "") + one;
    if (job.intensity >= 0 && setup.base.name == "mekf") class_sets.push_back({job.intensity, r.spec});
  }
  json += "]";
  if (!class_sets.empty()) {
    if (const int code = report_adaptive(class_sets, rate_lo, rate_hi, json); code != 0) return code;
  }
  json += "}\n";
  if (!opt.json_path.empty()) {
    std::ofstream out(opt.json_path);
    out << json;
    if (!out) {
      std::fprintf(stderr, "bsn tune: error: cannot write %s\n", opt.json_path.c_str());
      return 1;
    }
  }
  return 0;
}

}  // namespace

Command tune_command() {
  return {
      "tune", "Identify a filter's parameters on recordings with a reference orientation", [](CLI::App* cmd) {
        auto opt = std::make_shared<TuneOptions>();
        cmd->add_option("--filter", opt->filter, "NAME or NAME:key=value,... (the values stay fixed)")->required();
        cmd->add_option("recordings", opt->inputs, "recordings with a reference (.hdf5 BROAD layout, .csv) or folders")
            ->required();
        cmd->add_option("--param", opt->params,
                        "name=lo:hi[:log], repeatable; default: mekf's four sigmas, seel_ruppin's tau_acc_s, "
                        "tau_mag_s, zeta");
        cmd->add_option("--criterion", opt->criterion, "nez (mean + SD of the RMSE, Nez 2018) or rmse (mean)")
            ->capture_default_str();
        cmd->add_option("--holdout", opt->holdout, "score only, on the last K recordings named")
            ->check(non_negative_number(1e6));
        cmd->add_flag("--by-intensity", opt->by_intensity,
                      "one set per Nez Table 1 intensity class (static, slow, intermediate, fast)");
        cmd->add_option("--json", opt->json_path, "also write the results as JSON to FILE");
        cmd->add_option("--max-evaluations", opt->max_evaluations, "budget of filter settings tried per set")
            ->check(number_in(2, 1e6))
            ->capture_default_str();
        cmd->add_option("--global-points", opt->global_points, "quasi-random points of the global stage")
            ->check(number_in(1, 1e5))
            ->capture_default_str();
        cmd->add_option("--threads", opt->threads, "worker threads")->check(number_in(1, 64))->capture_default_str();
        return [opt] { return run_tune(*opt); };
      }};
}

}  // namespace bsn::services
