// Scenario files (YAML) -> ScenarioSpec. Every key is validated: an unknown key, a wrong type or a bad value
// is a ScenarioError "FILE:LINE: problem". The format is described in sim_publishers/scenarios/README.md.
#pragma once

#include <stdexcept>
#include <string>

#include "bsn/sim/scenario.hpp"

namespace bsn::sim {

class ScenarioError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Parses scenario YAML text; `source` names it in error messages.
ScenarioSpec parse_scenario(const std::string& yaml_text, const std::string& source);

/// Reads and parses a scenario file.
ScenarioSpec load_scenario(const std::string& path);

}  // namespace bsn::sim
