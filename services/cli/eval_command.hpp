#pragma once

#include <string>
#include <vector>

namespace bsn::services {

struct EvalOptions {
  std::vector<std::string> inputs;   ///< files (.hdf5 BROAD layout, .csv) or folders of them
  std::vector<std::string> filters;  ///< "name" or "name:key=value,...", or "all"; empty = all
  bool json = false;                 ///< print the JSON object instead of the table
  std::string plot_path;             ///< write an SVG of error over time here ("" = no plot)
};

int run_eval(const EvalOptions& options);

}  // namespace bsn::services
