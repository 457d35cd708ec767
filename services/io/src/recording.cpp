#include "bsn/io/recording.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

namespace bsn::io {

std::uint64_t Recording::time_ns(std::size_t i) const {
  if (!timestamp_ns.empty()) return timestamp_ns[i];
  return static_cast<std::uint64_t>(std::llround(static_cast<double>(i) * 1e9 / sampling_rate_hz));
}

fusion::ImuSample Recording::sample(std::size_t i) const {
  const auto r = static_cast<Eigen::Index>(i);
  fusion::ImuSample s;
  s.timestamp_ns = time_ns(i);
  s.gyr = gyr.row(r).transpose();
  s.acc = acc.row(r).transpose();
  s.mag = mag.row(r).transpose();
  s.has_mag = !s.mag.array().isNaN().all();
  return s;
}

void Recording::validate(const std::string& source) const {
  const auto n = gyr.rows();
  if (acc.rows() != n || mag.rows() != n) {
    throw IoError(source + ": imu_gyr, imu_acc and imu_mag have different lengths (" + std::to_string(n) + ", " +
                  std::to_string(acc.rows()) + ", " + std::to_string(mag.rows()) + ")");
  }
  if (opt_quat.rows() != 0 && opt_quat.rows() != n) throw IoError(source + ": opt_quat length differs from imu_gyr");
  if (opt_pos.rows() != 0 && opt_pos.rows() != n) throw IoError(source + ": opt_pos length differs from imu_gyr");
  if (!movement.empty() && static_cast<Eigen::Index>(movement.size()) != n) {
    throw IoError(source + ": movement length differs from imu_gyr");
  }
  if (!timestamp_ns.empty() && static_cast<Eigen::Index>(timestamp_ns.size()) != n) {
    throw IoError(source + ": timestamps length differs from the samples");
  }
  if (!(sampling_rate_hz > 0.0) || !std::isfinite(sampling_rate_hz)) {
    throw IoError(source + ": sampling rate must be a positive number");
  }
}

namespace {

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::string cell;
  std::istringstream in(line);
  while (std::getline(in, cell, ',')) {
    cell.erase(0, cell.find_first_not_of(" \t\r"));
    cell.erase(cell.find_last_not_of(" \t\r") + 1);
    out.push_back(cell);
  }
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

}  // namespace

Recording read_csv(const std::string& path) {
  if (std::error_code ec; std::filesystem::is_directory(path, ec))
    throw IoError(path + ": is a directory, not a CSV file");
  std::ifstream in(path);
  if (!in) throw IoError(path + ": cannot open");
  std::string line;
  int line_no = 0;
  std::map<std::string, std::size_t> col;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    const auto names = split(line);
    for (std::size_t i = 0; i < names.size(); ++i) col[names[i]] = i;
    break;
  }
  auto need = [&](const char* name) {
    if (!col.contains(name)) throw IoError(path + ":" + std::to_string(line_no) + ": missing column '" + name + "'");
    return col.at(name);
  };
  const bool time_in_ns = col.contains("t_ns");
  if (!time_in_ns && !col.contains("t_s")) throw IoError(path + ": missing column 't_s' or 't_ns'");
  const std::size_t c_t = time_in_ns ? col.at("t_ns") : col.at("t_s");
  const std::size_t c_acc[3] = {need("acc_x"), need("acc_y"), need("acc_z")};
  const std::size_t c_gyr[3] = {need("gyr_x"), need("gyr_y"), need("gyr_z")};
  const bool has_mag = col.contains("mag_x");
  const std::size_t c_mag[3] = {has_mag ? need("mag_x") : 0, has_mag ? need("mag_y") : 0, has_mag ? need("mag_z") : 0};
  const bool has_quat = col.contains("quat_w");
  const std::size_t c_q[4] = {has_quat ? need("quat_w") : 0, has_quat ? need("quat_x") : 0,
                              has_quat ? need("quat_y") : 0, has_quat ? need("quat_z") : 0};
  const bool has_movement = col.contains("movement");

  std::vector<std::array<double, 13>> rows;
  Recording rec;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    const auto cells = split(line);
    auto number = [&](std::size_t c, bool allow_empty) {
      if (c >= cells.size() || cells[c].empty()) {
        if (allow_empty) return std::nan("");
        throw IoError(path + ":" + std::to_string(line_no) + ": missing value in column " + std::to_string(c + 1));
      }
      try {
        std::size_t used = 0;
        const double v = std::stod(cells[c], &used);
        if (used != cells[c].size()) throw std::invalid_argument("trailing");
        return v;
      } catch (const std::exception&) {
        throw IoError(path + ":" + std::to_string(line_no) + ": '" + cells[c] + "' is not a number");
      }
    };
    std::array<double, 13> r{};
    for (int k = 0; k < 3; ++k) {
      r[static_cast<std::size_t>(k)] = number(c_acc[k], false);
      r[static_cast<std::size_t>(3 + k)] = number(c_gyr[k], false);
      r[static_cast<std::size_t>(6 + k)] = has_mag ? number(c_mag[k], true) : std::nan("");
    }
    for (int k = 0; k < 4; ++k) r[static_cast<std::size_t>(9 + k)] = has_quat ? number(c_q[k], true) : std::nan("");
    rows.push_back(r);
    const double t = number(c_t, false);
    // Beyond 9e18 ns (285 years) a time does not fit the integer nanoseconds it becomes: corrupt, not a time.
    const double t_ns = time_in_ns ? t : t * 1e9;
    if (!(t_ns >= 0.0 && t_ns < 9e18))
      throw IoError(path + ":" + std::to_string(line_no) + ": time must be >= 0 and below 9e18 ns");
    rec.timestamp_ns.push_back(time_in_ns ? static_cast<std::uint64_t>(t)
                                          : static_cast<std::uint64_t>(std::llround(t_ns)));
    if (has_movement) rec.movement.push_back(number(col.at("movement"), false) != 0.0 ? 1 : 0);
  }
  const auto n = static_cast<Eigen::Index>(rows.size());
  if (n < 2) throw IoError(path + ": fewer than two samples");
  rec.acc.resize(n, 3);
  rec.gyr.resize(n, 3);
  rec.mag.resize(n, 3);
  if (has_quat) rec.opt_quat.resize(n, 4);
  for (Eigen::Index i = 0; i < n; ++i) {
    const auto& r = rows[static_cast<std::size_t>(i)];
    rec.acc.row(i) << r[0], r[1], r[2];
    rec.gyr.row(i) << r[3], r[4], r[5];
    rec.mag.row(i) << r[6], r[7], r[8];
    if (has_quat) rec.opt_quat.row(i) << r[9], r[10], r[11], r[12];
  }
  std::vector<double> dt;
  for (std::size_t i = 1; i < rec.timestamp_ns.size(); ++i) {
    dt.push_back(static_cast<double>(rec.timestamp_ns[i]) - static_cast<double>(rec.timestamp_ns[i - 1]));
  }
  std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2), dt.end());
  const double median_dt = dt[dt.size() / 2];
  if (!(median_dt > 0.0)) throw IoError(path + ": timestamps do not increase");
  rec.sampling_rate_hz = 1e9 / median_dt;
  rec.validate(path);
  return rec;
}

Recording read_recording(const std::string& path) {
  const bool csv = path.size() >= 4 && path.compare(path.size() - 4, 4, ".csv") == 0;
  return csv ? read_csv(path) : read_broad_hdf5(path);
}

}  // namespace bsn::io
