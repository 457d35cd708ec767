#include "calibration_store.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <stdexcept>

namespace bsn::services {
namespace fs = std::filesystem;

namespace {

constexpr const char* kSuffix = ".calib.yaml";
constexpr const char* kTemporaryMark = ".tmp-";

std::string encode_node(const std::string& node) {
  std::string out;
  for (const char c : node) {
    const auto u = static_cast<unsigned char>(c);
    if (std::isalnum(u) || c == '_' || c == '-') {
      out += c;
    } else {
      char hex[4];
      std::snprintf(hex, sizeof hex, "%%%02X", u);
      out += hex;
    }
  }
  return out;
}

std::string decode_node(const std::string& name) {
  std::string out;
  for (std::size_t i = 0; i < name.size(); ++i) {
    if (name[i] == '%' && i + 2 < name.size()) {
      out += static_cast<char>(std::strtol(name.substr(i + 1, 2).c_str(), nullptr, 16));
      i += 2;
    } else {
      out += name[i];
    }
  }
  return out;
}

bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

// Writes the whole text and flushes it to the disk; throws with errno's words.
void write_durably(const std::string& path, const std::string& text) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error("cannot create " + path + ": " + std::strerror(errno));
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string why = std::strerror(errno);
      ::close(fd);
      throw std::runtime_error("cannot write " + path + ": " + why);
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0)
    throw std::runtime_error("cannot flush " + path + ": " + std::strerror(errno));
}

}  // namespace

std::string default_calibration_store() {
  if (const char* state = std::getenv("XDG_STATE_HOME"); state != nullptr && *state == '/')
    return (fs::path(state) / "bsn" / "calibration").string();
  const char* home = std::getenv("HOME");
  return (fs::path(home != nullptr && *home != '\0' ? home : ".") / ".local" / "state" / "bsn" / "calibration")
      .string();
}

CalibrationStore::CalibrationStore(std::string dir) : dir_(std::move(dir)) {
  std::error_code ec;
  fs::create_directories(dir_, ec);
  if (ec || !fs::is_directory(dir_))
    throw std::runtime_error("cannot create the calibration store " + dir_ + ": " + ec.message());
}

std::string CalibrationStore::path_of(const std::string& node, calib::CalibrationKind kind) const {
  return (fs::path(dir_) / (encode_node(node) + "." + calib::kind_name(kind) + kSuffix)).string();
}

std::string CalibrationStore::save(const std::string& node, const calib::SessionResult& result,
                                   const std::string& request_id) {
  const std::string path = path_of(node, result.kind);
  std::string text = "# bsn calibration service: " + std::string(calib::kind_name(result.kind)) + " of node '" + node +
                     "', request '" + request_id + "', " + utc_now() + ". u = transform * (raw - bias)\n";
  switch (result.kind) {
    case calib::CalibrationKind::magnetometer:
      text += config::calibration_to_yaml(node, &result.field, nullptr, nullptr, request_id);
      break;
    case calib::CalibrationKind::accelerometer:
      text += config::calibration_to_yaml(node, nullptr, &result.field, nullptr, request_id);
      break;
    case calib::CalibrationKind::gyro_bias:
      text += config::calibration_to_yaml(node, nullptr, nullptr, &result.gyro, request_id);
      break;
    case calib::CalibrationKind::alignment:
      throw std::logic_error("an alignment is stored with save_alignment()");
  }
  return replace_file(path, text);
}

std::string CalibrationStore::save_alignment(const std::string& node, const config::AlignmentRecord& alignment,
                                             const std::string& request_id) {
  const std::string path = path_of(node, calib::CalibrationKind::alignment);
  const std::string text = "# bsn calibration service: alignment of node '" + node + "' (segment '" +
                           alignment.segment + "'), request '" + request_id + "', " + utc_now() +
                           ". v_segment = sensor_to_segment * v_sensor\n" +
                           config::alignment_to_yaml(node, alignment, request_id);
  return replace_file(path, text);
}

std::string CalibrationStore::replace_file(const std::string& path, const std::string& text) {
  const std::string temporary = path + kTemporaryMark + std::to_string(::getpid());
  try {
    write_durably(temporary, text);
  } catch (...) {
    ::unlink(temporary.c_str());
    throw;
  }
  // Keep the file being replaced as .previous (a hard link, so `path` never disappears), then swap atomically.
  const std::string previous = path + ".previous";
  if (fs::exists(path)) {
    ::unlink(previous.c_str());
    if (::link(path.c_str(), previous.c_str()) != 0) {
      std::error_code ec;
      fs::copy_file(path, previous, fs::copy_options::overwrite_existing, ec);
    }
  }
  if (::rename(temporary.c_str(), path.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    ::unlink(temporary.c_str());
    throw std::runtime_error("cannot replace " + path + ": " + why);
  }
  return path;
}

std::vector<StoredCalibration> CalibrationStore::load_all(std::vector<std::string>& problems) const {
  std::vector<StoredCalibration> out;
  std::vector<fs::path> files;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir_, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.find(kTemporaryMark) != std::string::npos) {
      // Left by a write that was interrupted: the file it was meant to replace is intact.
      fs::remove(entry.path(), ec);
      continue;
    }
    if (entry.is_regular_file() && ends_with(name, kSuffix)) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  for (const fs::path& file : files) {
    const std::string name = file.filename().string();
    const std::string stem = name.substr(0, name.size() - std::strlen(kSuffix));
    const std::size_t dot = stem.rfind('.');
    const std::string node_from_name = decode_node(stem.substr(0, dot));
    config::CalibrationDocument doc;
    try {
      doc = config::load_calibration_document(file.string());
    } catch (const config::ConfigError& e) {
      problems.emplace_back(e.what());
      continue;
    }
    const std::string node = doc.node.empty() ? node_from_name : doc.node;
    if (node != node_from_name) {
      problems.push_back(file.string() + ":" + std::to_string(doc.node_line) + ": the file is for node '" + doc.node +
                         "' but is named for node '" + node_from_name + "'");
      continue;
    }
    auto add = [&](calib::CalibrationKind kind) { out.push_back({file.string(), node, kind, doc}); };
    if (doc.calibration.magnetometer) add(calib::CalibrationKind::magnetometer);
    if (doc.calibration.accelerometer) add(calib::CalibrationKind::accelerometer);
    if (doc.calibration.gyroscope) add(calib::CalibrationKind::gyro_bias);
    if (doc.alignment) add(calib::CalibrationKind::alignment);
  }
  return out;
}

}  // namespace bsn::services
