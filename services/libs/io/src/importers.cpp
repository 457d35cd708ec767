#include "bsn/io/importers.hpp"

#include <Eigen/Geometry>
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
namespace {

namespace fs = std::filesystem;

std::string read_text(const std::string& path) {
  if (std::error_code ec; fs::is_directory(path, ec)) throw IoError(path + ": is a directory, not a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path + ": cannot open");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string stem_of(const std::string& source) { return fs::path(source).stem().string(); }

/// At most 40 printable characters of a cell, for an error message.
std::string shown(std::string_view cell) {
  std::string out;
  for (char c : cell.substr(0, 40)) out += (c >= 32 && c < 127) ? c : '?';
  return cell.size() > 40 ? out + "..." : out;
}

/// Lines of a text, one at a time, with their numbers; a trailing '\r' is dropped.
class Lines {
 public:
  explicit Lines(std::string_view text) : text_(text) {}
  bool next(std::string_view& line) {
    if (pos_ >= text_.size()) return false;
    const auto end = text_.find('\n', pos_);
    line = text_.substr(pos_, end == std::string_view::npos ? std::string_view::npos : end - pos_);
    pos_ = end == std::string_view::npos ? text_.size() : end + 1;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    ++number_;
    return true;
  }
  int number() const { return number_; }

 private:
  std::string_view text_;
  std::size_t pos_ = 0;
  int number_ = 0;
};

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  if (s.size() >= 2 && s.front() == '"' && s.back() == '"') s = s.substr(1, s.size() - 2);
  return s;
}

void split_cells(std::string_view line, std::vector<std::string_view>& cells) {
  cells.clear();
  std::size_t start = 0;
  while (true) {
    const auto comma = line.find(',', start);
    cells.push_back(trim(line.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start)));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
}

/// A decimal number filling the whole cell; an empty cell or nan is NaN when `empty_is_nan`. Infinity is refused.
bool parse_number(std::string_view cell, double& v, bool empty_is_nan) {
  if (cell.empty() || cell == "nan" || cell == "NaN" || cell == "NAN") {
    v = std::numeric_limits<double>::quiet_NaN();
    return empty_is_nan;
  }
  if (cell.front() == '+') cell.remove_prefix(1);
  const auto [end, ec] = std::from_chars(cell.data(), cell.data() + cell.size(), v);
  return ec == std::errc() && end == cell.data() + cell.size() && std::isfinite(v);
}

/// The median interval's inverse; throws when the times do not increase.
double rate_from_times(const std::vector<std::uint64_t>& t, const std::string& source) {
  std::vector<double> dt;
  dt.reserve(t.size());
  for (std::size_t i = 1; i < t.size(); ++i) dt.push_back(static_cast<double>(t[i] - t[i - 1]));
  std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2), dt.end());
  const double median = dt[dt.size() / 2];
  if (!(median > 0.0)) throw FormatError(source + ": timestamps do not increase");
  return 1e9 / median;
}

double factor_or_default(const ImportOptions& o, const std::string& quantity, const std::string& fallback,
                         const std::string& source) {
  const auto it = o.units.find(quantity);
  try {
    return unit_factor(quantity, it == o.units.end() ? fallback : it->second);
  } catch (const std::invalid_argument& e) {
    throw FormatError(source + ": " + e.what());
  }
}

// ---- bsn's CSV -----------------------------------------------------------------------------------------------------

class BsnCsvImporter final : public RecordingImporter {
 public:
  std::string name() const override { return "bsn-csv"; }
  std::vector<ImportedNode> read(const std::string& path, const ImportOptions& o) const override {
    return {{stem_of(path), read_csv(path, o.units)}};
  }
  std::vector<ImportedNode> parse(std::string_view text, const std::string& source,
                                  const ImportOptions& o) const override {
    std::istringstream in{std::string(text)};
    return {{stem_of(source), read_csv(in, source, o.units)}};
  }
};

// ---- BROAD HDF5 ----------------------------------------------------------------------------------------------------

class BroadImporter final : public RecordingImporter {
 public:
  std::string name() const override { return "broad-hdf5"; }
  std::vector<ImportedNode> read(const std::string& path, const ImportOptions&) const override {
    std::vector<ImportedNode> nodes(1);  // not a braced list: its elements would be copied, arrays and all
    nodes[0].name = stem_of(path);
    nodes[0].rec = read_broad_hdf5(path);
    return nodes;
  }
  std::vector<ImportedNode> parse(std::string_view, const std::string& source, const ImportOptions&) const override {
    throw IoError(source + ": BROAD HDF5 is read from files only");
  }
};

// ---- DIODEM / RING -------------------------------------------------------------------------------------------------
// Per trial (one motion of an experiment) three CSV files: <exp>_<motion>_imu_rigid.csv, _imu_nonrigid.csv and
// _omc.csv. Each: line 1 "<label>: <rate in Hz>", line 2 a description (skipped), line 3 the header, then one row
// per sample. IMU files name seg<k>_{acc,gyr,mag}_{x,y,z}; the OMC file seg<k>_quat_{w,x,y,z} and
// seg<k>_marker<m>_{x,y,z}, at its own rate. Units: acc m/s^2, gyr rad/s, mag Xsens a.u.; quaternions
// sensor-to-earth.

struct Table {
  double rate_hz = 0.0;
  std::vector<std::string> names;
  std::vector<std::vector<double>> columns;
  std::size_t rows() const { return columns.empty() ? 0 : columns[0].size(); }
  const std::vector<double>* column(const std::string& n) const {
    const auto it = std::find(names.begin(), names.end(), n);
    return it == names.end() ? nullptr : &columns[static_cast<std::size_t>(it - names.begin())];
  }
};

Table read_diodem_table(std::string_view text, const std::string& source) {
  Lines lines(text);
  std::string_view line;
  auto at = [&] { return source + ":" + std::to_string(lines.number()) + ": "; };
  Table t;
  if (!lines.next(line)) throw FormatError(source + ": empty, not a DIODEM file");
  const auto colon = line.find(':');
  double rate = 0.0;
  if (colon == std::string_view::npos || !parse_number(trim(line.substr(colon + 1)), rate, false) ||
      !(rate > 0.0 && rate <= 1e6))
    throw FormatError(at() + "expected the sampling rate as '<label>: <Hz>', got '" + shown(line) + "'");
  t.rate_hz = rate;
  if (!lines.next(line)) throw FormatError(source + ": ends after line 1; line 2 describes, line 3 names the columns");
  if (!lines.next(line)) throw FormatError(source + ": ends after line 2; line 3 names the columns");
  std::vector<std::string_view> cells;
  split_cells(line, cells);
  for (std::string_view c : cells) {
    if (c.empty()) throw FormatError(at() + "an empty column name");
    if (std::find(t.names.begin(), t.names.end(), c) != t.names.end())
      throw FormatError(at() + "column '" + shown(c) + "' named twice");
    t.names.emplace_back(c);
  }
  t.columns.resize(t.names.size());
  while (lines.next(line)) {
    if (trim(line).empty()) continue;
    split_cells(line, cells);
    if (cells.size() != t.names.size())
      throw FormatError(at() + std::to_string(cells.size()) + " cells, but the header names " +
                        std::to_string(t.names.size()) + " columns");
    for (std::size_t c = 0; c < cells.size(); ++c) {
      double v = 0.0;
      if (!parse_number(cells[c], v, true))
        throw FormatError(at() + "'" + shown(cells[c]) + "' in column '" + t.names[c] + "' is not a finite number");
      t.columns[c].push_back(v);
    }
  }
  return t;
}

/// The segments of an IMU table: every prefix P with P_acc_x; each needs acc and gyr, mag is optional.
std::vector<std::string> diodem_segments(const Table& t, const std::string& source) {
  std::vector<std::string> segs;
  for (const std::string& n : t.names) {
    if (n.size() > 6 && n.compare(n.size() - 6, 6, "_acc_x") == 0) segs.push_back(n.substr(0, n.size() - 6));
  }
  for (const std::string& s : segs) {
    for (const char* q : {"_acc_", "_gyr_"}) {
      for (const char* a : {"x", "y", "z"}) {
        if (!t.column(s + q + a))
          throw FormatError(source + ":3: segment '" + s + "' has no column '" + s + q + a + "'");
      }
    }
    const int mags =
        (t.column(s + "_mag_x") ? 1 : 0) + (t.column(s + "_mag_y") ? 1 : 0) + (t.column(s + "_mag_z") ? 1 : 0);
    if (mags != 0 && mags != 3) throw FormatError(source + ":3: segment '" + s + "' has only some mag columns");
  }
  return segs;
}

/// The quaternion of segment `s` in row i, or nullopt when any component is NaN or it is far from unit length.
bool table_quat(const Table& t, const std::string& s, std::size_t i, Eigen::Quaterniond& q) {
  const auto* w = t.column(s + "_quat_w");
  const auto* x = t.column(s + "_quat_x");
  const auto* y = t.column(s + "_quat_y");
  const auto* z = t.column(s + "_quat_z");
  if (!w || !x || !y || !z) return false;
  q = Eigen::Quaterniond((*w)[i], (*x)[i], (*y)[i], (*z)[i]);
  const double n = q.norm();
  if (!std::isfinite(n) || n < 0.5 || n > 1.5) return false;
  q.normalize();
  return true;
}

std::vector<ImportedNode> diodem_nodes(const Table& imu, const std::string& imu_source, const Table* omc,
                                       const std::string& omc_source, const ImportOptions& o) {
  const std::vector<std::string> segs = diodem_segments(imu, imu_source);
  if (segs.empty()) throw FormatError(imu_source + ":3: no '<segment>_acc_x' column: not a DIODEM IMU file");
  const std::size_t n = imu.rows();
  if (n < 2) throw FormatError(imu_source + ": fewer than two samples");
  const double f_acc = factor_or_default(o, "acc", "m/s^2", imu_source);
  const double f_gyr = factor_or_default(o, "gyr", "rad/s", imu_source);
  const double f_mag = factor_or_default(o, "mag", "au", imu_source);
  if (omc) {
    for (const std::string& s : segs) {
      const int parts = (omc->column(s + "_quat_w") ? 1 : 0) + (omc->column(s + "_quat_x") ? 1 : 0) +
                        (omc->column(s + "_quat_y") ? 1 : 0) + (omc->column(s + "_quat_z") ? 1 : 0);
      if (parts != 0 && parts != 4)
        throw FormatError(omc_source + ":3: segment '" + s + "' has only some of its quaternion's columns");
    }
  }
  std::vector<ImportedNode> nodes;
  for (const std::string& s : segs) {
    ImportedNode node{s, {}};
    Recording& r = node.rec;
    r.sampling_rate_hz = imu.rate_hz;
    r.acc.resize(static_cast<Eigen::Index>(n), 3);
    r.gyr.resize(static_cast<Eigen::Index>(n), 3);
    r.mag.resize(static_cast<Eigen::Index>(n), 3);
    const bool has_mag = imu.column(s + "_mag_x") != nullptr;
    for (int a = 0; a < 3; ++a) {
      const std::string axis(1, static_cast<char>('x' + a));
      const auto& acc = *imu.column(s + "_acc_" + axis);
      const auto& gyr = *imu.column(s + "_gyr_" + axis);
      const auto* mag = has_mag ? imu.column(s + "_mag_" + axis) : nullptr;
      for (std::size_t i = 0; i < n; ++i) {
        const auto row = static_cast<Eigen::Index>(i);
        r.acc(row, a) = acc[i] * f_acc;
        r.gyr(row, a) = gyr[i] * f_gyr;
        r.mag(row, a) = mag ? (*mag)[i] * f_mag : std::numeric_limits<double>::quiet_NaN();
      }
    }
    // A row with any magnetometer axis missing has no magnetometer sample at all.
    for (Eigen::Index i = 0; i < r.mag.rows(); ++i) {
      if (r.mag.row(i).array().isNaN().any()) r.mag.row(i).setConstant(std::numeric_limits<double>::quiet_NaN());
    }
    // The reference: the same table's quaternions, or the OMC table's interpolated (slerp) onto the IMU's times.
    const Table* q_table = imu.column(s + "_quat_w") ? &imu : (omc && omc->column(s + "_quat_w") ? omc : nullptr);
    if (q_table) {
      r.opt_quat.resize(static_cast<Eigen::Index>(n), 4);
      r.opt_quat.setConstant(std::numeric_limits<double>::quiet_NaN());
      for (std::size_t i = 0; i < n; ++i) {
        Eigen::Quaterniond q;
        bool ok = false;
        if (q_table == &imu) {
          ok = table_quat(imu, s, i, q);
        } else {
          // The optical sample index of IMU sample i; within 1e-9 of an integer it is that sample (equal rates).
          double f = static_cast<double>(i) * omc->rate_hz / imu.rate_hz;
          if (std::abs(f - std::round(f)) < 1e-9) f = std::round(f);
          const auto k = static_cast<std::size_t>(f);
          const double frac = f - static_cast<double>(k);
          Eigen::Quaterniond q0, q1;
          if (k < omc->rows() && table_quat(*omc, s, k, q0)) {
            if (frac == 0.0) {
              q = q0;
              ok = true;
            } else if (k + 1 < omc->rows() && table_quat(*omc, s, k + 1, q1)) {
              q = q0.slerp(frac, q1).normalized();
              // The sign of the nearer optical sample (slerp takes the shorter way, which may flip it).
              if (q.dot(frac < 0.5 ? q0 : q1) < 0.0) q.coeffs() = -q.coeffs();
              ok = true;
            }
          }
        }
        if (ok) r.opt_quat.row(static_cast<Eigen::Index>(i)) << q.w(), q.x(), q.y(), q.z();
      }
    }
    r.validate(imu_source);
    nodes.push_back(std::move(node));
  }
  return nodes;
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

class DiodemImporter final : public RecordingImporter {
 public:
  std::string name() const override { return "diodem"; }
  std::vector<ImportedNode> read(const std::string& path, const ImportOptions& o) const override {
    if (o.imu != "rigid" && o.imu != "nonrigid")
      throw std::invalid_argument("--imu must be rigid or nonrigid, not '" + o.imu + "'");
    const std::string imu_suffix = "_imu_" + o.imu + ".csv";
    std::string imu_path, omc_path;
    if (std::error_code ec; fs::is_directory(path, ec)) {
      for (const auto& e : fs::directory_iterator(path)) {
        const std::string f = e.path().string();
        if (ends_with(f, imu_suffix)) {
          if (!imu_path.empty())
            throw FormatError(path + ": two trials' " + imu_suffix + " files: " + imu_path + " and " + f +
                              " (give one file)");
          imu_path = f;
        }
      }
      if (imu_path.empty()) throw FormatError(path + ": no *" + imu_suffix + " file: not a DIODEM trial folder");
    } else {
      imu_path = path;
    }
    for (const char* s : {"_imu_rigid.csv", "_imu_nonrigid.csv"}) {
      if (ends_with(imu_path, s)) {
        const std::string candidate = imu_path.substr(0, imu_path.size() - std::string(s).size()) + "_omc.csv";
        if (fs::exists(candidate)) omc_path = candidate;
      }
    }
    const std::string imu_text = read_text(imu_path);
    const Table imu = read_diodem_table(imu_text, imu_path);
    if (omc_path.empty()) return diodem_nodes(imu, imu_path, nullptr, "", o);
    const std::string omc_text = read_text(omc_path);
    const Table omc = read_diodem_table(omc_text, omc_path);
    return diodem_nodes(imu, imu_path, &omc, omc_path, o);
  }
  std::vector<ImportedNode> parse(std::string_view text, const std::string& source,
                                  const ImportOptions& o) const override {
    return diodem_nodes(read_diodem_table(text, source), source, nullptr, "", o);
  }
};

// ---- Xsens DOT (Movella DOT) CSV export ---------------------------------------------------------------------------
// Xsens DOT User Manual (XD0502P), 4.2.2 and 4.2.5: Acc_X..Z m/s^2, Gyr_X..Z deg/s, Mag_X..Z a.u. (1 a.u. is the
// field at Xsens' calibration lab, about 40 uT), all in the sensor frame; SampleTimeFine in us of the sensor's clock,
// wrapping at 2^32. Lines before the header (the app's device information) are skipped.

class XsensDotImporter final : public RecordingImporter {
 public:
  std::string name() const override { return "xsens-dot"; }
  std::vector<ImportedNode> read(const std::string& path, const ImportOptions& o) const override {
    const std::string text = read_text(path);
    return parse(text, path, o);
  }
  std::vector<ImportedNode> parse(std::string_view text, const std::string& source,
                                  const ImportOptions& o) const override {
    Lines lines(text);
    std::string_view line;
    std::vector<std::string_view> cells;
    auto at = [&] { return source + ":" + std::to_string(lines.number()) + ": "; };
    std::map<std::string, std::size_t, std::less<>> col;
    while (lines.next(line)) {
      split_cells(line, cells);
      if (std::find(cells.begin(), cells.end(), std::string_view("SampleTimeFine")) == cells.end()) continue;
      for (std::size_t i = 0; i < cells.size(); ++i) {
        if (!col.emplace(std::string(cells[i]), i).second && !cells[i].empty())
          throw FormatError(at() + "column '" + shown(cells[i]) + "' named twice");
      }
      break;
    }
    if (col.empty())
      throw FormatError(source +
                        ": no header line naming SampleTimeFine: not an Xsens DOT export (its header "
                        "names PacketCounter, SampleTimeFine, Acc_X, ..., Gyr_X, ...)");
    const int header_line = lines.number();
    auto need = [&](const char* n) {
      const auto it = col.find(n);
      if (it == col.end())
        throw FormatError(source + ":" + std::to_string(header_line) + ": no column '" + n +
                          "' (export the inertial data: Acc and Gyr)");
      return it->second;
    };
    const std::size_t c_t = need("SampleTimeFine");
    const std::size_t c_acc[3] = {need("Acc_X"), need("Acc_Y"), need("Acc_Z")};
    const std::size_t c_gyr[3] = {need("Gyr_X"), need("Gyr_Y"), need("Gyr_Z")};
    const bool has_mag = col.contains("Mag_X");
    const std::size_t c_mag[3] = {has_mag ? need("Mag_X") : 0, has_mag ? need("Mag_Y") : 0,
                                  has_mag ? need("Mag_Z") : 0};
    const double f_acc = factor_or_default(o, "acc", "m/s^2", source);
    const double f_gyr = factor_or_default(o, "gyr", "deg/s", source);
    const double f_mag = factor_or_default(o, "mag", "au", source);
    const std::size_t needed =
        1 + std::max({c_t, c_acc[0], c_acc[1], c_acc[2], c_gyr[0], c_gyr[1], c_gyr[2], c_mag[0], c_mag[1], c_mag[2]});
    std::vector<double> values;
    Recording r;
    std::uint64_t wraps = 0, previous = 0;
    bool first = true;
    while (lines.next(line)) {
      if (trim(line).empty()) continue;
      split_cells(line, cells);
      if (cells.size() < needed)
        throw FormatError(at() + std::to_string(cells.size()) + " cells, fewer than the header's columns");
      std::uint64_t tick = 0;
      const std::string_view tc = cells[c_t];
      const auto [end, ec] = std::from_chars(tc.data(), tc.data() + tc.size(), tick);
      if (ec != std::errc() || end != tc.data() + tc.size() || tick > 0xFFFFFFFFull)
        throw FormatError(at() + "SampleTimeFine '" + shown(tc) + "' is not an integer in 0..4294967295 (us)");
      if (!first && tick + wraps * (1ull << 32) <= previous) {
        // The 32-bit microsecond clock wraps about every 71.6 minutes; anything else going back is corrupt.
        if (previous - wraps * (1ull << 32) > tick + (1ull << 31)) {
          ++wraps;
        } else {
          throw FormatError(at() + "SampleTimeFine goes from " + std::to_string(previous % (1ull << 32)) + " to " +
                            std::to_string(tick) + " us: time must increase (a reboot mid-recording?)");
        }
      }
      previous = tick + wraps * (1ull << 32);
      first = false;
      r.timestamp_ns.push_back(previous * 1000);
      for (int k = 0; k < 9; ++k) {
        if (k >= 6 && !has_mag) {
          values.push_back(std::numeric_limits<double>::quiet_NaN());
          continue;
        }
        const std::size_t c = k < 3 ? c_acc[k] : k < 6 ? c_gyr[k - 3] : c_mag[k - 6];
        double v = 0.0;
        if (!parse_number(cells[c], v, k >= 6))
          throw FormatError(at() + "'" + shown(cells[c]) + "' in column " + std::to_string(c + 1) +
                            " is not a finite number");
        values.push_back(v * (k < 3 ? f_acc : k < 6 ? f_gyr : f_mag));
      }
    }
    const auto n = static_cast<Eigen::Index>(r.timestamp_ns.size());
    if (n < 2) throw FormatError(source + ": fewer than two samples");
    r.acc.resize(n, 3);
    r.gyr.resize(n, 3);
    r.mag.resize(n, 3);
    for (Eigen::Index i = 0; i < n; ++i) {
      const double* v = &values[static_cast<std::size_t>(9 * i)];
      r.acc.row(i) << v[0], v[1], v[2];
      r.gyr.row(i) << v[3], v[4], v[5];
      r.mag.row(i) << v[6], v[7], v[8];
      if (r.mag.row(i).array().isNaN().any()) r.mag.row(i).setConstant(std::numeric_limits<double>::quiet_NaN());
    }
    r.sampling_rate_hz = rate_from_times(r.timestamp_ns, source);
    r.validate(source);
    return {{stem_of(source), std::move(r)}};
  }
};

const BsnCsvImporter kBsnCsv;
const BroadImporter kBroad;
const DiodemImporter kDiodem;
const XsensDotImporter kXsensDot;

bool is_diodem_file(const std::string& p) {
  return ends_with(p, "_imu_rigid.csv") || ends_with(p, "_imu_nonrigid.csv") || ends_with(p, "_omc.csv");
}

}  // namespace

const std::vector<const RecordingImporter*>& recording_importers() {
  static const std::vector<const RecordingImporter*> all{&kBsnCsv, &kBroad, &kDiodem, &kXsensDot};
  return all;
}

const RecordingImporter& recording_importer(const std::string& name) {
  std::string names;
  for (const RecordingImporter* i : recording_importers()) {
    if (i->name() == name) return *i;
    names += (names.empty() ? "" : ", ") + i->name();
  }
  throw std::invalid_argument("--format '" + name + "' is not a format (auto, " + names + ")");
}

std::string detect_format(const std::string& path) {
  if (std::error_code ec; fs::is_directory(path, ec)) {
    for (const auto& e : fs::directory_iterator(path)) {
      if (is_diodem_file(e.path().string())) return "diodem";
    }
    return "folder";
  }
  if (is_diodem_file(path)) return "diodem";
  const std::string ext = fs::path(path).extension().string();
  if (ext == ".h5" || ext == ".hdf5") return "broad-hdf5";
  // An Xsens DOT export names SampleTimeFine in its header, within its first lines.
  std::ifstream in(path);
  std::string line;
  for (int i = 0; i < 20 && std::getline(in, line); ++i) {
    if (line.find("SampleTimeFine") != std::string::npos) return "xsens-dot";
  }
  return "bsn-csv";
}

std::vector<ImportedNode> import_recordings(const std::string& path, const std::string& format,
                                            const ImportOptions& options,
                                            const std::function<bool(const std::string&)>& wanted,
                                            std::vector<std::string>* left_out) {
  auto refused = [&](const std::string& name, const std::string& what) {
    if (!wanted || wanted(name)) return false;
    if (left_out) left_out->push_back(what);
    return true;
  };
  const std::string detected = format == "auto" ? detect_format(path) : format;
  std::error_code ec;
  const bool folder = fs::is_directory(path, ec);
  std::vector<ImportedNode> nodes;
  if (!folder || detected == "diodem") {
    if (detected == "folder") throw std::logic_error("detect_format gave folder for a file");
    for (ImportedNode& n : recording_importer(detected).read(path, options)) {
      if (!refused(n.name, path + " (" + n.name + ")")) nodes.push_back(std::move(n));
    }
  } else {
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(path)) {
      if (e.is_regular_file()) files.push_back(e.path());
    }
    std::sort(files.begin(), files.end());
    const RecordingImporter* fixed = format == "auto" ? nullptr : &recording_importer(format);
    for (const fs::path& f : files) {
      const std::string ext = f.extension().string();
      const bool hdf5 = ext == ".h5" || ext == ".hdf5";
      if (!hdf5 && ext != ".csv") continue;
      const RecordingImporter* importer = fixed;
      if (!importer) importer = &recording_importer(detect_format(f.string()));
      if (fixed && hdf5 != (fixed == &kBroad)) continue;  // another format's file
      if (refused(f.stem().string(), f.string())) continue;
      for (ImportedNode& n : importer->read(f.string(), options)) nodes.push_back(std::move(n));
    }
  }
  std::stable_sort(nodes.begin(), nodes.end(),
                   [](const ImportedNode& a, const ImportedNode& b) { return a.name < b.name; });
  for (std::size_t i = 1; i < nodes.size(); ++i) {
    if (nodes[i].name == nodes[i - 1].name) throw FormatError(path + ": two recordings of '" + nodes[i].name + "'");
  }
  return nodes;
}

}  // namespace bsn::io
