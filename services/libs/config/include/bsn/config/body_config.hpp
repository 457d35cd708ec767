// Loading the YAML body model. Every problem is reported as "FILE:LINE: what is wrong".
#pragma once

#include <stdexcept>
#include <string>

#include "bsn/fusion/body_model.hpp"

namespace bsn::config {

/// A configuration error whose message names the file, the line and the problem.
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Parses a body model from YAML text; `source` names it in messages (a file path).
fusion::BodyModel parse_body_model(const std::string& yaml_text, const std::string& source);

/// Reads and parses a body model file. Throws ConfigError.
fusion::BodyModel load_body_model(const std::string& path);

/// The YAML text of a body model, in the format load_body_model reads.
std::string body_model_to_yaml(const fusion::BodyModel& body);

}  // namespace bsn::config
