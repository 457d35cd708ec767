// Reading validated YAML configuration: every problem becomes an `Error` whose message is "SOURCE:LINE: problem".
// Shared by the body model, the calibration files and the simulator's scenario files.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <sstream>
#include <string>
#include <string_view>

namespace bsn::config {

/// The whole text of the `what` file at `path` ("body model", "calibration", ...); throws Error with a message that
/// says what is wrong: "PATH: is a directory, not a body model file", "PATH: cannot open the body model file (No
/// such file or directory)".
template <class Error>
std::string read_config_file(const std::string& path, const std::string& what) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw Error(path + ": is a directory, not a " + what + " file");
  std::ifstream in(path);
  if (!in) throw Error(path + ": cannot open the " + what + " file (" + std::strerror(errno) + ")");
  std::stringstream text;
  text << in.rdbuf();
  if (in.bad()) throw Error(path + ": cannot read the " + what + " file");
  return text.str();
}

template <class Error>
class YamlReader {
 public:
  explicit YamlReader(std::string source) : source_(std::move(source)) {}

  const std::string& source() const { return source_; }

  [[noreturn]] void fail(const YAML::Node& at, const std::string& what) const { fail_at(at.Mark().line + 1, what); }
  [[noreturn]] void fail_at(int line, const std::string& what) const {
    throw Error(source_ + ":" + std::to_string(line) + ": " + what);
  }

  void require_map(const YAML::Node& n, const std::string& what) const {
    if (!n.IsMap()) fail(n, what + " must be a mapping (key: value)");
  }

  /// `n` must be a mapping whose keys are all in `known`; an unknown key is named with the known ones.
  void check_keys(const YAML::Node& n, std::initializer_list<std::string_view> known, const std::string& where) const {
    require_map(n, where);
    for (const auto& kv : n) {
      const std::string key = kv.first.as<std::string>();
      bool ok = false;
      for (auto k : known) ok = ok || key == k;
      if (!ok) {
        std::string list;
        for (auto k : known) list += std::string(list.empty() ? "" : ", ") + std::string(k);
        fail(kv.first, "unknown key '" + key + "' in " + where + " (known keys: " + list + ")");
      }
    }
  }

  std::string text(const YAML::Node& n, const std::string& what) const {
    if (!n.IsScalar()) fail(n, what + " must be a single value");
    return n.as<std::string>();
  }

  /// A finite number.
  double number(const YAML::Node& n, const std::string& what) const {
    if (!n.IsScalar()) fail(n, what + " must be a number");
    double v = 0.0;
    try {
      v = n.as<double>();
    } catch (const YAML::Exception&) {
      fail(n, what + " must be a number, not '" + n.as<std::string>() + "'");
    }
    if (!std::isfinite(v)) fail(n, what + " must be finite");
    return v;
  }

 private:
  std::string source_;
};

}  // namespace bsn::config
