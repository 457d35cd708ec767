// Which bodies (subjects) a fusion process serves: body files, each one subject, or a team file that lists several.
// Every problem is reported as "FILE:LINE: what is wrong" (ConfigError).
#pragma once

#include <string>
#include <vector>

#include "bsn/config/body_config.hpp"

namespace bsn::config {

/// One subject: its name (a DDS partition; "" for a body file without `subject:`), its body file and the share
/// (which fusion process of several serves it; 0 when the file gives none).
struct SubjectEntry {
  std::string subject;
  std::string body_path;
  int share = 0;
};

/// The subjects of `path`. A team file (top-level `subjects:`, a list of `name`, `body` (path relative to the team
/// file) and optional `share`) gives one entry per subject; a body file gives one, named by its `subject:` key.
/// Throws ConfigError.
std::vector<SubjectEntry> load_subject_entries(const std::string& path);

/// What is wrong with `name` as a subject name ("" if nothing): 1..64 letters, digits, '.', '_' and '-'. A subject
/// is a DDS partition, and these exclude the pattern characters that would select several partitions.
std::string subject_name_problem(const std::string& name);

}  // namespace bsn::config
