#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bsn/dds/child_process.hpp"
#include "bsn/eval/evaluation.hpp"
#include "bsn/eval/standard_tests.hpp"
#include "bsn/io/recording.hpp"
#include "process_command.hpp"
#include "progress_bar.hpp"
#include "tools.hpp"

namespace bsn::services {
namespace {

struct EvalOptions {
  std::vector<std::string> inputs;   ///< files (.hdf5 BROAD layout, .csv) or folders of them
  std::vector<std::string> filters;  ///< "name" or "name:key=value,...", or "all"; empty = all
  bool json = false;                 ///< print the JSON object instead of the table
  bool markdown = false;             ///< print Markdown tables for the manual instead of the table
  std::string plot_path;             ///< write an SVG of error over time here ("" = no plot)
  bool standard_tests = false;       ///< run Fan et al. 2018's tests A-E on the simulator instead of recordings
  std::string scenario_dir;          ///< where fan_a..fan_e.yaml are ("" = default_scenario_dir())
  std::string body_path;             ///< a body: score segments and joints (run_body_eval)
  std::string align_window = "all";  ///< with a body: the window of the per-segment alignment
  ImportSelection import;            ///< with a body: how the recordings are read
};

// The scenarios of this checkout when bsn runs from its build tree, else those installed beside the program
// (<prefix>/share/bsn/scenarios, as the Debian package puts them).
std::string default_scenario_dir() {
  if (std::filesystem::is_directory(BSN_SCENARIO_DIR)) return BSN_SCENARIO_DIR;
  return (std::filesystem::path(dds::self_executable()).parent_path().parent_path() / "share/bsn/scenarios").string();
}

namespace fs = std::filesystem;

using NamedFilters = std::vector<std::pair<std::string, fusion::FilterSpec>>;

/// The filters of --filter ("all" or none: every registered one); 0, or 2 (said) when one is unknown.
int eval_filters(const EvalOptions& opt, NamedFilters& filters) {
  try {
    std::vector<std::string> args = opt.filters;
    if (args.empty()) args.push_back("all");
    for (const auto& a : args) {
      if (a == "all") {
        for (const auto& n : fusion::filter_names()) filters.emplace_back(n, fusion::FilterSpec{n, {}});
      } else {
        fusion::FilterSpec spec = eval::parse_filter_argument(a);
        (void)fusion::make_filter(spec);  // unknown names and parameters fail here, before any work
        filters.emplace_back(a, spec);
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 2;
  }
  return 0;
}

/// --plot: the trials' error over time as SVG; 0, or 1 (said) when it cannot be written.
int write_plot(const EvalOptions& opt, const std::vector<eval::TrialResult>& trials) {
  if (opt.plot_path.empty()) return 0;
  std::ofstream out(opt.plot_path);
  out << eval::to_svg(trials);
  if (!out) {
    std::fprintf(stderr, "bsn eval: error: cannot write %s\n", opt.plot_path.c_str());
    return 1;
  }
  if (!opt.json && !opt.markdown) std::printf("plot: %s\n", opt.plot_path.c_str());
  return 0;
}

/// --standard-tests: Fan et al. 2018's tests A-E on the simulator.
int standard_tests(const EvalOptions& opt, const NamedFilters& filters) {
  if (!opt.inputs.empty()) {
    std::fprintf(stderr, "bsn eval: error: --standard-tests runs the shipped scenarios and takes no recordings\n");
    return 2;
  }
  std::vector<eval::StandardTestResult> results;
  try {
    results = eval::run_standard_tests(opt.scenario_dir.empty() ? default_scenario_dir() : opt.scenario_dir, filters);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 2;
  }
  std::fputs(opt.json       ? eval::standard_tests_json(results).c_str()
             : opt.markdown ? eval::standard_tests_markdown(results).c_str()
                            : eval::standard_tests_table(results).c_str(),
             stdout);
  int exit_code = 0;
  std::vector<eval::TrialResult> trials;
  for (const auto& r : results) {
    trials.push_back(r.trial);
    if (r.trial.non_finite > 0) {
      std::fprintf(stderr, "bsn eval: error: %s gave %zu non-finite orientations in test %s\n", r.filter.c_str(),
                   r.trial.non_finite, r.test.c_str());
      exit_code = 1;
    }
  }
  if (const int code = write_plot(opt, trials); code != 0) return code;
  return exit_code;
}

/// Every filter on every recording named; the worst exit code (2 an unreadable recording, 1 non-finite output).
int score_recordings(const std::vector<fs::path>& files, const NamedFilters& filters,
                     std::vector<eval::TrialResult>& results) {
  ProgressBar bar(files.size() * filters.size());
  std::size_t done = 0;
  int exit_code = 0;
  for (const auto& file : files) {
    io::Recording rec;
    try {
      rec = io::read_recording(file.string());
    } catch (const io::IoError& e) {
      bar.finish();
      std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
      exit_code = 2;  // bad input (unreadable, empty, cut short), as for a missing file
      done += filters.size();
      continue;
    }
    if (rec.opt_quat.rows() == 0) {
      std::fprintf(stderr, "bsn eval: warning: %s has no reference orientation; nothing is scored\n",
                   file.string().c_str());
    }
    for (const auto& [label, spec] : filters) {
      bar.show(done, file.stem().string() + " / " + label);
      results.push_back(eval::run_trial(rec, file.stem().string(), spec, label));
      if (results.back().non_finite > 0) {
        std::fprintf(stderr, "bsn eval: error: %s gave %zu non-finite orientations on %s\n", label.c_str(),
                     results.back().non_finite, file.string().c_str());
        exit_code = std::max(exit_code, 1);
      }
      ++done;
    }
  }
  bar.finish();
  return exit_code;
}

int run_eval(const EvalOptions& opt) {
  if (opt.body_path.empty() && !opt.import.is_default()) {
    std::fprintf(stderr, "bsn eval: error: --format, --unit and --imu go with --body (the importers' options)\n");
    return 2;
  }
  if (!opt.body_path.empty()) {
    if (opt.markdown) {
      std::fprintf(stderr, "bsn eval: error: --markdown prints the filters' tables; with --body use --json\n");
      return 2;
    }
    if (opt.inputs.size() != 1) {
      std::fprintf(stderr, "bsn eval: error: --body scores one session file or folder of recordings at a time\n");
      return 2;
    }
    return run_body_eval({.input = opt.inputs[0],
                          .body_path = opt.body_path,
                          .import = opt.import,
                          .filters = opt.filters,
                          .align_window = opt.align_window,
                          .json = opt.json,
                          .plot_path = opt.plot_path});
  }
  NamedFilters filters;
  if (const int code = eval_filters(opt, filters); code != 0) return code;
  if (opt.standard_tests) return standard_tests(opt, filters);
  if (opt.inputs.empty()) {
    std::fprintf(stderr, "bsn eval: error: name recordings (files or folders), or give --standard-tests\n");
    return 2;
  }

  std::vector<fs::path> files;
  try {
    files = expand_recording_inputs(opt.inputs);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 2;
  }

  std::vector<eval::TrialResult> results;
  const int exit_code = score_recordings(files, filters, results);
  std::fputs(opt.json       ? eval::to_json(results).c_str()
             : opt.markdown ? eval::to_markdown(results).c_str()
                            : eval::to_table(results).c_str(),
             stdout);
  if (const int code = write_plot(opt, results); code != 0) return code;
  return exit_code;
}

}  // namespace

bool is_recording_file(const fs::path& p) {
  return p.extension() == ".hdf5" || p.extension() == ".h5" || p.extension() == ".csv";
}

std::vector<fs::path> expand_recording_inputs(const std::vector<std::string>& inputs) {
  std::vector<fs::path> files;
  for (const auto& in : inputs) {
    const fs::path p(in);
    if (fs::is_directory(p)) {
      std::vector<fs::path> inside;
      for (const auto& e : fs::directory_iterator(p)) {
        if (e.is_regular_file() && is_recording_file(e.path())) inside.push_back(e.path());
      }
      std::sort(inside.begin(), inside.end());
      if (inside.empty()) throw std::runtime_error(in + ": no .hdf5 or .csv recordings in this folder");
      files.insert(files.end(), inside.begin(), inside.end());
    } else if (fs::exists(p)) {
      files.push_back(p);
    } else {
      throw std::runtime_error(in + ": no such file or folder");
    }
  }
  return files;
}

Command eval_command() {
  return {"eval", "Score filters against the reference of recordings (BROAD HDF5, CSV)", [](CLI::App* cmd) {
            auto opt = std::make_shared<EvalOptions>();
            cmd->add_option("inputs", opt->inputs, "recordings (.hdf5 in BROAD layout, .csv) or folders of them");
            cmd->add_option("--filter", opt->filters, "NAME or NAME:key=value,...; repeatable; 'all' = every filter")
                ->take_all();
            auto* json = cmd->add_flag("--json", opt->json, "print one JSON object instead of the table");
            cmd->add_flag("--markdown", opt->markdown,
                          "print Markdown tables (the manual's accuracy tables are this output) instead of the table")
                ->excludes(json);
            cmd->add_option("--body", opt->body_path,
                            "a body model: score its segments and joints against the recordings' reference "
                            "orientations (one session file or folder of <node>.hdf5)");
            cmd->add_option("--align-window", opt->align_window,
                            "with --body: per-segment constant alignment fitted over all, none or A:B (seconds)")
                ->capture_default_str();
            add_import_options(cmd, opt->import);  // with --body
            cmd->add_option("--plot", opt->plot_path, "write an SVG image of the total error over time per filter");
            cmd->add_flag("--standard-tests", opt->standard_tests,
                          "run Fan et al. 2018's tests A-E on the simulator and print their Table 5 with grades");
            cmd->add_option("--scenarios", opt->scenario_dir,
                            "folder of fan_a..fan_e.yaml for --standard-tests (default: this checkout's "
                            "sim_publishers/scenarios, else <prefix>/share/bsn/scenarios beside the program)");
            return [opt] { return run_eval(*opt); };
          }};
}

}  // namespace bsn::services
