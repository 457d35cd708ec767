#include "bsn/io/recording.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>

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
  s.has_mag = has_mag(i);
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

/// A header cell: the column's name and the unit in brackets after it ("acc_x [g]" -> "acc_x", "g"), if any.
struct HeaderCell {
  std::string name, unit;
};

HeaderCell header_cell(const std::string& cell) {
  const auto open = cell.find('[');
  if (open == std::string::npos || cell.back() != ']') return {cell, ""};
  HeaderCell h{cell.substr(0, open), cell.substr(open + 1, cell.size() - open - 2)};
  h.name.erase(h.name.find_last_not_of(" \t") + 1);
  h.unit.erase(0, h.unit.find_first_not_of(" \t"));
  h.unit.erase(h.unit.find_last_not_of(" \t") + 1);
  return h;
}

/// A CSV recording's header: its columns and the units stated in it, and the --unit options given.
struct CsvHeader {
  const std::string& path;
  const UnitOptions& units;
  int line = 0;                                 ///< its line number
  std::map<std::string, std::size_t> col;       ///< column name -> index
  std::map<std::string, std::string> col_unit;  ///< column -> unit stated in the header

  std::string at() const { return path + ":" + std::to_string(line) + ": "; }
  std::size_t need(const char* name) const {
    if (!col.contains(name)) throw FormatError(at() + "missing column '" + name + "'");
    return col.at(name);
  }
  /// The factor of a column into bsn's unit: its header's unit, else the --unit given, else the format's default.
  /// A name that fixes the unit (t_s, t_ns) takes no other; a header unit and a different --unit is an error.
  double factor(const std::string& column, const std::string& quantity, const std::string& default_unit,
                bool name_fixes_unit) const {
    const auto stated = col_unit.find(column);
    const auto given = units.find(quantity);
    std::string unit = default_unit;
    if (stated != col_unit.end()) {
      if (name_fixes_unit && stated->second != default_unit)
        throw FormatError(at() + "column '" + column + "' is in " + default_unit + " by its name, not " +
                          stated->second);
      unit = stated->second;
    }
    if (given != units.end()) {
      if ((stated != col_unit.end() || name_fixes_unit) && given->second != unit)
        throw FormatError(at() + "column '" + column + "' is in " + unit + ", but --unit " + quantity + "=" +
                          given->second + " was given");
      unit = given->second;
    }
    if (unit.empty())
      throw FormatError(at() + "column '" + column + "' needs its unit: '" + column +
                        " [s]' (or ms, us, "
                        "ns), or --unit " +
                        quantity + "=UNIT");
    try {
      return unit_factor(quantity, unit);
    } catch (const std::invalid_argument& e) {
      throw FormatError(at() + "column '" + column + "': " + e.what());
    }
  }
};

/// Reads up to and including the header line (comments and empty lines before it skipped); `line_no` counts.
CsvHeader read_csv_header(std::istream& in, const std::string& path, const UnitOptions& units, int& line_no) {
  CsvHeader header{path, units, 0, {}, {}};
  std::string line;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    const auto names = split(line);
    for (std::size_t i = 0; i < names.size(); ++i) {
      const HeaderCell h = header_cell(names[i]);
      header.col[h.name] = i;
      if (!h.unit.empty()) header.col_unit[h.name] = h.unit;
    }
    break;
  }
  header.line = line_no;
  return header;
}

/// The rows read (acc, gyr, mag, quat) into `rec`'s channels, and its nominal rate from the median interval.
void fill_channels(const std::vector<std::array<double, 13>>& rows, bool has_quat, const std::string& path,
                   Recording& rec) {
  const auto n = static_cast<Eigen::Index>(rows.size());
  if (n < 2) throw FormatError(path + ": fewer than two samples");
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
  if (!(median_dt > 0.0)) throw FormatError(path + ": timestamps do not increase");
  rec.sampling_rate_hz = 1e9 / median_dt;
}

}  // namespace

Recording read_csv(const std::string& path, const UnitOptions& units) {
  if (std::error_code ec; std::filesystem::is_directory(path, ec))
    throw IoError(path + ": is a directory, not a CSV file");
  std::ifstream in(path);
  if (!in) throw IoError(path + ": cannot open");
  return read_csv(in, path, units);
}

Recording read_csv(std::istream& in, const std::string& path, const UnitOptions& units) {
  std::string line;
  int line_no = 0;
  const CsvHeader header = read_csv_header(in, path, units, line_no);
  const std::map<std::string, std::size_t>& col = header.col;
  auto at = [&](int l) { return path + ":" + std::to_string(l) + ": "; };
  const int header_line = header.line;
  const char* time_names[] = {"t_ns", "t_s", "t", "time"};
  const char* time_column = nullptr;
  for (const char* t : time_names) {
    if (col.contains(t)) {
      if (time_column) throw FormatError(at(header_line) + "two time columns, '" + time_column + "' and '" + t + "'");
      time_column = t;
    }
  }
  if (!time_column) throw FormatError(at(header_line) + "missing column 't_s' or 't_ns' (or 't [UNIT]')");
  const std::string tc = time_column;
  const std::size_t c_t = col.at(tc);
  const double f_t = header.factor(tc, "time",
                                   tc == "t_ns"  ? "ns"
                                   : tc == "t_s" ? "s"
                                                 : "",
                                   tc == "t_ns" || tc == "t_s");
  const bool time_in_ns = f_t == 1.0;
  const std::size_t c_acc[3] = {header.need("acc_x"), header.need("acc_y"), header.need("acc_z")};
  const std::size_t c_gyr[3] = {header.need("gyr_x"), header.need("gyr_y"), header.need("gyr_z")};
  const bool has_mag = col.contains("mag_x");
  const std::size_t c_mag[3] = {has_mag ? header.need("mag_x") : 0, has_mag ? header.need("mag_y") : 0,
                                has_mag ? header.need("mag_z") : 0};
  const bool has_quat = col.contains("quat_w");
  const std::size_t c_q[4] = {has_quat ? header.need("quat_w") : 0, has_quat ? header.need("quat_x") : 0,
                              has_quat ? header.need("quat_y") : 0, has_quat ? header.need("quat_z") : 0};
  const bool has_movement = col.contains("movement");
  double f[9];
  for (int k = 0; k < 3; ++k) {
    const std::string axis(1, static_cast<char>('x' + k));
    f[k] = header.factor("acc_" + axis, "acc", "m/s^2", false);
    f[3 + k] = header.factor("gyr_" + axis, "gyr", "rad/s", false);
    f[6 + k] = has_mag ? header.factor("mag_" + axis, "mag", "uT", false) : 1.0;
  }

  std::vector<std::array<double, 13>> rows;
  Recording rec;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    const auto cells = split(line);
    auto number = [&](std::size_t c, bool allow_empty) {
      if (c >= cells.size() || cells[c].empty()) {
        if (allow_empty) return std::nan("");
        throw FormatError(at(line_no) + "missing value in column " + std::to_string(c + 1));
      }
      try {
        std::size_t used = 0;
        const double v = std::stod(cells[c], &used);
        if (used != cells[c].size()) throw std::invalid_argument("trailing");
        return v;
      } catch (const std::exception&) {
        throw FormatError(at(line_no) + "'" + cells[c] + "' is not a number");
      }
    };
    std::array<double, 13> r{};
    for (int k = 0; k < 3; ++k) {
      r[static_cast<std::size_t>(k)] = number(c_acc[k], false) * f[k];
      r[static_cast<std::size_t>(3 + k)] = number(c_gyr[k], false) * f[3 + k];
      r[static_cast<std::size_t>(6 + k)] = has_mag ? number(c_mag[k], true) * f[6 + k] : std::nan("");
    }
    for (int k = 0; k < 4; ++k) r[static_cast<std::size_t>(9 + k)] = has_quat ? number(c_q[k], true) : std::nan("");
    rows.push_back(r);
    const double t = number(c_t, false);
    // Beyond 9e18 ns (285 years) a time does not fit the integer nanoseconds it becomes: corrupt, not a time.
    const double t_ns = t * f_t;
    if (!(t_ns >= 0.0 && t_ns < 9e18)) throw FormatError(at(line_no) + "time must be >= 0 and below 9e18 ns");
    rec.timestamp_ns.push_back(time_in_ns ? static_cast<std::uint64_t>(t)
                                          : static_cast<std::uint64_t>(std::llround(t_ns)));
    if (has_movement) rec.movement.push_back(number(col.at("movement"), false) != 0.0 ? 1 : 0);
  }
  fill_channels(rows, has_quat, path, rec);
  rec.validate(path);
  return rec;
}

Recording sized_recording(double sampling_rate_hz, Eigen::Index rows) {
  Recording rec;
  rec.sampling_rate_hz = sampling_rate_hz;
  rec.gyr.resize(rows, 3);
  rec.acc.resize(rows, 3);
  rec.mag.resize(rows, 3);
  rec.opt_quat.resize(rows, 4);
  return rec;
}

void set_measurement_row(Recording& rec, Eigen::Index row, const fusion::ImuSample& s) {
  rec.gyr.row(row) = s.gyr.transpose();
  rec.acc.row(row) = s.acc.transpose();
  if (s.has_mag) {
    rec.mag.row(row) = s.mag.transpose();
  } else {
    rec.mag.row(row).setConstant(std::numeric_limits<double>::quiet_NaN());
  }
}

// ---- Units -------------------------------------------------------------------------------------------------------

double unit_factor(const std::string& quantity, const std::string& unit) {
  constexpr double kG = 9.80665;  // standard gravity, m/s^2
  constexpr double kDeg = 3.14159265358979323846 / 180.0;
  constexpr double kXsensAu = 40.0;  // Xsens: 1 a.u. = the field at its calibration lab, about 40 uT
  static const std::map<std::string, std::map<std::string, double>> table = {
      {"acc", {{"m/s^2", 1.0}, {"m/s2", 1.0}, {"g", kG}, {"mg", kG * 1e-3}}},
      {"gyr", {{"rad/s", 1.0}, {"deg/s", kDeg}, {"dps", kDeg}, {"mrad/s", 1e-3}}},
      {"mag", {{"uT", 1.0}, {"nT", 1e-3}, {"mT", 1e3}, {"G", 100.0}, {"mG", 0.1}, {"au", kXsensAu}}},
      {"time", {{"ns", 1.0}, {"us", 1e3}, {"ms", 1e6}, {"s", 1e9}}},
  };
  const auto q = table.find(quantity);
  if (q == table.end()) throw std::invalid_argument("'" + quantity + "' is not a quantity (acc, gyr, mag, time)");
  if (quantity == "mag" && unit.rfind("au:", 0) == 0) {
    // au:K: a vendor's arbitrary unit of K uT.
    try {
      std::size_t used = 0;
      const double k = std::stod(unit.substr(3), &used);
      if (used == unit.size() - 3 && k > 0.0 && k < 1e6) return k;
    } catch (const std::exception&) {
    }
    throw std::invalid_argument("'" + unit + "': au:K needs K, the uT of one arbitrary unit, a positive number");
  }
  const auto u = q->second.find(unit);
  if (u != q->second.end()) return u->second;
  std::string known;
  for (const auto& [name, f] : q->second) known += (known.empty() ? "" : ", ") + name;
  if (quantity == "mag") known += ", au:K";
  throw std::invalid_argument("'" + unit + "' is not a unit of " + quantity + " (" + known + ")");
}

void add_unit_option(UnitOptions& units, const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos) throw std::invalid_argument("--unit '" + text + "': QUANTITY=UNIT, e.g. gyr=deg/s");
  const std::string quantity = text.substr(0, eq), unit = text.substr(eq + 1);
  unit_factor(quantity, unit);
  units[quantity] = unit;
}

Recording read_recording(const std::string& path) {
  const bool csv = path.size() >= 4 && path.compare(path.size() - 4, 4, ".csv") == 0;
  return csv ? read_csv(path) : read_broad_hdf5(path);
}

}  // namespace bsn::io
