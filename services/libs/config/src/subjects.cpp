#include "bsn/config/subjects.hpp"

#include <yaml-cpp/yaml.h>

#include "bsn/config/calibration_file.hpp"
#include "bsn/config/yaml_reader.hpp"

namespace bsn::config {

namespace {

class Parser : public YamlReader<ConfigError> {
 public:
  using YamlReader::YamlReader;

  std::string subject(const YAML::Node& n) const {
    const std::string name = text(n, "subject");
    if (const std::string problem = subject_name_problem(name); !problem.empty())
      fail(n, "subject '" + name + "' " + problem);
    return name;
  }

  std::vector<SubjectEntry> entries(const YAML::Node& root) const {
    if (!root || root.IsNull() || !root.IsMap()) return {{"", source(), 0}};  // the body parser says what is wrong
    const YAML::Node list = root["subjects"];
    if (!list) return {{root["subject"] ? subject(root["subject"]) : "", source(), 0}};
    check_keys(root, {"name", "subjects"}, "the team file");
    if (!list.IsSequence() || list.size() == 0) fail(list, "'subjects' must be a list of subjects");
    std::vector<SubjectEntry> out;
    for (const YAML::Node& s : list) {
      check_keys(s, {"name", "body", "share"}, "a subject");
      if (!s["name"]) fail(s, "subject without 'name'");
      if (!s["body"]) fail(s, "subject without 'body' (its body file, relative to this file)");
      SubjectEntry e{subject(s["name"]), resolve_relative(text(s["body"], "body"), source()), 0};
      if (e.subject.empty()) fail(s["name"], "a subject's name is empty");
      if (const YAML::Node share = s["share"]) {
        const double v = number(share, "share");
        if (v < 1 || v > 1000 || v != static_cast<int>(v)) fail(share, "share must be a whole number 1..1000");
        e.share = static_cast<int>(v);
      }
      for (const SubjectEntry& other : out)
        if (other.subject == e.subject) fail(s["name"], "subject '" + e.subject + "' is listed twice");
      out.push_back(std::move(e));
    }
    return out;
  }
};

}  // namespace

std::string subject_name_problem(const std::string& name) {
  constexpr std::size_t kMaxChars = 64;
  if (name.size() > kMaxChars) return "is longer than " + std::to_string(kMaxChars) + " characters";
  for (const char c : name) {
    const bool ok =
        (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' || c == '_' || c == '-';
    if (!ok) return "has a character other than letters, digits, '.', '_' and '-'";
  }
  return "";
}

std::vector<SubjectEntry> load_subject_entries(const std::string& path) {
  Parser parser(path);
  const std::string text = read_config_file<ConfigError>(path, "body model");
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception&) {
    return {{"", path, 0}};  // the body parser reports the syntax error with its line
  }
  try {
    return parser.entries(root);
  } catch (const YAML::Exception& e) {
    parser.fail_at(e.mark.line + 1, e.msg);
  }
}

}  // namespace bsn::config
