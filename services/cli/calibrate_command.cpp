#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "bsn/calib/allan.hpp"
#include "bsn/calib/pose_segmentation.hpp"
#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/fusion/rotation.hpp"
#include "bsn/io/json.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/io/session_file.hpp"
#include "calibration_client.hpp"
#include "calibration_service.hpp"
#include "tools.hpp"

namespace bsn::services {
namespace {

struct CalibrateOptions {
  std::string input;              ///< recording to calibrate (CSV or BROAD HDF5): hand-turned poses
  std::string allan;              ///< static recording for the Allan deviation instead
  double field_magnitude = 1.0;   ///< M: |calibrated magnetometer| (1 = normalised; 50 for uT, ...)
  bool json = false;              ///< print the JSON object instead of the text report
  std::string output;             ///< calibration file to write ("" = INPUT with extension .calib.yaml)
  std::string node;               ///< node id written into the file
  bool accelerometer = false;     ///< also calibrate the accelerometer (|g| = 9.80665 m/s^2)
  bool gyro_bias = false;         ///< also write the gyro bias from the rests
  double rest_rate_rad_s = 0.05;  ///< rest threshold on |gyro - bias|, rad/s
  double min_pose_s = 1.0;        ///< shortest rest that counts as a pose, s
  std::string plot;               ///< with --allan: write the curves as an SVG here
  bool live = false;              ///< calibrate through the calibration service instead
  std::string alignment;          ///< a folder of per-node recordings to align (<node>.hdf5) instead
  bool field_magnitude_given = false;
  LiveCalibrationOptions live_options;
};

using calib::FieldCalibration;
using calib::Points3;

using io::json_string;
// Calibration parameters keep 10 significant digits: they are applied to raw readings.
std::string number(double v) { return io::json_number(v, 10); }

std::string json_vector(const calib::Vec3& v) {
  return "[" + number(v.x()) + ", " + number(v.y()) + ", " + number(v.z()) + "]";
}

std::string json_quality(const calib::FitQuality& q) {
  std::string warnings;
  for (const auto& w : q.warnings) warnings += (warnings.empty() ? "" : ", ") + json_string(w);
  return "{\"pose_count\": " + std::to_string(q.pose_count) + ", \"sample_count\": " + std::to_string(q.sample_count) +
         ", \"residual_rms\": " + number(q.residual_rms) + ", \"residual_max\": " + number(q.residual_max) +
         ", \"pose_residual_rms\": " + number(q.pose_residual_rms) +
         ", \"sphere_coverage\": " + number(q.sphere_coverage) +
         ", \"octants_covered\": " + std::to_string(q.octants_covered) +
         ", \"ellipsoid_condition\": " + number(q.ellipsoid_condition) +
         ", \"transform_condition\": " + number(q.transform_condition) +
         ", \"ellipsoid_consistency\": " + number(q.ellipsoid_consistency) + ", \"warnings\": [" + warnings + "]}";
}

std::string json_calibration(const FieldCalibration& c) {
  const calib::Mat3& h = c.calibration.transform;
  std::string rows;
  for (int r = 0; r < 3; ++r) rows += (r ? ", " : "") + json_vector(h.row(r).transpose());
  return "{\"bias\": " + json_vector(c.calibration.bias) + ", \"transform\": [" + rows +
         "], \"field_magnitude\": " + number(c.field_magnitude) + ", \"field_vector\": " + json_vector(c.field_vector) +
         ", \"quality\": " + json_quality(c.quality) + "}";
}

void print_report(const char* channel, const FieldCalibration& c) {
  const calib::Mat3& h = c.calibration.transform;
  const calib::FitQuality& q = c.quality;
  std::printf("%s: u = H (raw - B), |u| = %g\n", channel, c.field_magnitude);
  std::printf("  B  = [%.6g, %.6g, %.6g]\n", c.calibration.bias.x(), c.calibration.bias.y(), c.calibration.bias.z());
  for (int r = 0; r < 3; ++r)
    std::printf("  %s [%.6g, %.6g, %.6g]\n", r == 0 ? "H =" : "   ", h(r, 0), h(r, 1), h(r, 2));
  std::printf("  field vector at pose 0: [%.6g, %.6g, %.6g]\n", c.field_vector.x(), c.field_vector.y(),
              c.field_vector.z());
  std::printf("  quality: %zu poses, %zu samples; | |u| - M | rms %.3g (%.2f %%), max %.3g; pose residual rms %.3g\n",
              q.pose_count, q.sample_count, q.residual_rms, 100.0 * q.residual_rms / c.field_magnitude, q.residual_max,
              q.pose_residual_rms);
  std::printf(
      "           sphere coverage %.2f of 1, %d of 8 octants; condition: ellipsoid %.3g, H %.3g; "
      "H^T H vs M^2 Sigma %.2f %%\n",
      q.sphere_coverage, q.octants_covered, q.ellipsoid_condition, q.transform_condition,
      100.0 * q.ellipsoid_consistency);
  for (const auto& w : q.warnings) std::printf("  warning: %s\n", w.c_str());
}

Points3 columns(const io::RowsX3& rows) { return rows.transpose(); }

std::string default_output(const std::string& input) {
  std::filesystem::path p(input);
  p.replace_extension(".calib.yaml");
  return p.string();
}

int run_fit(const CalibrateOptions& opt) {
  io::Recording rec;
  try {
    rec = io::read_recording(opt.input);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bsn calibrate: %s\n", e.what());
    return 2;
  }
  if (!(opt.field_magnitude > 0.0) || !std::isfinite(opt.field_magnitude)) {
    std::fprintf(stderr, "bsn calibrate: --field-magnitude must be positive\n");
    return 2;
  }
  calib::PoseSegmentationParams params;
  params.rest_rate_rad_s = opt.rest_rate_rad_s;
  params.min_pose_s = opt.min_pose_s;
  const Points3 rates = columns(rec.gyr);
  calib::PoseSegmentation poses;
  const FieldCalibration mag = calib::calibrate_field_from_recording(rates, columns(rec.mag), rec.sampling_rate_hz,
                                                                     opt.field_magnitude, params, &poses);
  if (!mag.ok()) {
    std::fprintf(stderr, "bsn calibrate: %s: magnetometer: %s\n", opt.input.c_str(), mag.message.c_str());
    return 1;
  }
  FieldCalibration acc;
  if (opt.accelerometer) {
    acc =
        calib::calibrate_field_from_recording(rates, columns(rec.acc), rec.sampling_rate_hz, fusion::kGravity, params);
    if (!acc.ok()) {
      std::fprintf(stderr, "bsn calibrate: %s: accelerometer: %s\n", opt.input.c_str(), acc.message.c_str());
      return 1;
    }
  }
  calib::ChannelCalibration gyro;
  gyro.bias = poses.gyro_bias;

  const std::string out_path = opt.output.empty() ? default_output(opt.input) : opt.output;
  {
    std::ofstream out(out_path);
    out << "# bsn calibration of " << std::filesystem::path(opt.input).filename().string()
        << " (bsn calibrate): u = transform * (raw - bias)\n"
        << config::calibration_to_yaml(opt.node, &mag, opt.accelerometer ? &acc : nullptr,
                                       opt.gyro_bias ? &gyro : nullptr);
    if (!out) {
      std::fprintf(stderr, "bsn calibrate: cannot write %s\n", out_path.c_str());
      return 2;
    }
  }
  if (opt.json) {
    std::printf("%s\n", json_calibration(mag).c_str());
  } else {
    print_report("magnetometer", mag);
    if (opt.accelerometer) print_report("accelerometer", acc);
    std::printf("gyro bias from %zu rest samples: [%.6g, %.6g, %.6g] rad/s\n", poses.rest_samples, poses.gyro_bias.x(),
                poses.gyro_bias.y(), poses.gyro_bias.z());
    std::printf("wrote %s\n", out_path.c_str());
  }
  return 0;
}

// ---- Allan ----

struct AxisCurve {
  std::string name;  ///< e.g. "gyr_x"
  std::string unit;  ///< the channel's unit, e.g. "rad/s"
  std::vector<calib::AllanPoint> curve;
  calib::NoiseCoefficients coefficients{0, 0, 0};
};

// One panel per sensor (its own unit on the y axis), log-log, one line per axis, and where each axis's N (the -1/2
// line at tau = 1 s), B (the flat minimum, adev = 0.664 B) and K (the +1/2 line at tau = 3 s) were read.
std::string svg_plot(const std::vector<AxisCurve>& curves) {
  std::vector<std::string> sensors;
  for (const auto& c : curves) {
    const std::string sensor = c.name.substr(0, c.name.find('_'));
    if (std::find(sensors.begin(), sensors.end(), sensor) == sensors.end()) sensors.push_back(sensor);
  }
  const double w = 720, panel_h = 320, left = 80, right = 20, top = 30, bottom = 45;
  const double h = panel_h * static_cast<double>(sensors.size());
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"720\" height=\"%.0f\" font-family=\"sans-serif\" "
                "font-size=\"12\">\n<rect width=\"100%%\" height=\"100%%\" fill=\"white\"/>\n",
                h);
  std::string s = buf;
  const char* colours[] = {"#d62728", "#2ca02c", "#1f77b4"};
  for (std::size_t panel = 0; panel < sensors.size(); ++panel) {
    const double y0 = panel_h * static_cast<double>(panel);
    std::vector<const AxisCurve*> mine;
    for (const auto& c : curves)
      if (c.name.rfind(sensors[panel] + "_", 0) == 0) mine.push_back(&c);
    double tmin = INFINITY, tmax = 0, amin = INFINITY, amax = 0;
    for (const auto* c : mine)
      for (const auto& p : c->curve)
        if (p.adev > 0) {
          tmin = std::min(tmin, p.tau_s), tmax = std::max(tmax, p.tau_s);
          amin = std::min(amin, p.adev), amax = std::max(amax, p.adev);
        }
    if (!(tmax > 0)) continue;
    const double lt0 = std::floor(std::log10(tmin)), lt1 = std::ceil(std::log10(tmax));
    const double la0 = std::floor(std::log10(amin)), la1 = std::ceil(std::log10(amax));
    auto x = [&](double t) { return left + (std::log10(t) - lt0) / std::max(1.0, lt1 - lt0) * (w - left - right); };
    auto y = [&](double a) {
      return y0 + top + (la1 - std::log10(a)) / std::max(1.0, la1 - la0) * (panel_h - top - bottom);
    };
    for (double e = lt0; e <= lt1; ++e) {
      std::snprintf(buf, sizeof buf,
                    "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#ddd\"/><text x=\"%.1f\" "
                    "y=\"%.1f\" text-anchor=\"middle\">1e%g</text>\n",
                    x(std::pow(10, e)), y0 + top, x(std::pow(10, e)), y0 + panel_h - bottom, x(std::pow(10, e)),
                    y0 + panel_h - bottom + 16, e);
      s += buf;
    }
    for (double e = la0; e <= la1; ++e) {
      std::snprintf(buf, sizeof buf,
                    "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#ddd\"/><text x=\"%.1f\" "
                    "y=\"%.1f\" text-anchor=\"end\">1e%g</text>\n",
                    left, y(std::pow(10, e)), w - right, y(std::pow(10, e)), left - 4, y(std::pow(10, e)) + 4, e);
      s += buf;
    }
    const std::string unit = mine.front()->unit;
    std::snprintf(buf, sizeof buf,
                  "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">tau (s)</text>\n<text x=\"16\" y=\"%.1f\" "
                  "transform=\"rotate(-90 16 %.1f)\" text-anchor=\"middle\">%s Allan deviation (%s)</text>\n"
                  "<text x=\"%.1f\" y=\"%.1f\">%s: N read at tau = 1 s (circle), B at the minimum (square), K at "
                  "tau = 3 s (triangle)</text>\n",
                  (w + left) / 2, y0 + panel_h - 12, y0 + panel_h / 2, y0 + panel_h / 2, sensors[panel].c_str(),
                  unit.c_str(), left, y0 + 18, sensors[panel].c_str());
    s += buf;
    for (std::size_t i = 0; i < mine.size(); ++i) {
      const AxisCurve& c = *mine[i];
      const char* colour = colours[i % 3];
      std::string points;
      const calib::AllanPoint* lowest = nullptr;
      for (const auto& p : c.curve)
        if (p.adev > 0) {
          std::snprintf(buf, sizeof buf, "%.1f,%.1f ", x(p.tau_s), y(p.adev));
          points += buf;
          if (!lowest || p.adev < lowest->adev) lowest = &p;
        }
      s += "<polyline fill=\"none\" stroke-width=\"1.5\" stroke=\"" + std::string(colour) + "\" points=\"" + points +
           "\"/>\n";
      std::snprintf(buf, sizeof buf, "<text x=\"%.1f\" y=\"%.1f\" fill=\"%s\">%s</text>\n", w - right - 60,
                    y0 + top + 14.0 * static_cast<double>(i + 1), colour, c.name.c_str());
      s += buf;
      // The marks, only where the figure was determined and lies inside the plotted decades.
      const auto inside = [&](double t, double a) {
        return a > 0 && std::log10(t) >= lt0 && std::log10(t) <= lt1 && std::log10(a) >= la0 && std::log10(a) <= la1;
      };
      const double n = c.coefficients.white_density, k = c.coefficients.rate_random_walk;
      if (inside(1.0, n)) {
        std::snprintf(buf, sizeof buf, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"4\" fill=\"none\" stroke=\"%s\"/>\n",
                      x(1.0), y(n), colour);
        s += buf;
      }
      if (lowest && inside(lowest->tau_s, lowest->adev)) {
        std::snprintf(buf, sizeof buf,
                      "<rect x=\"%.1f\" y=\"%.1f\" width=\"8\" height=\"8\" fill=\"none\" stroke=\"%s\"/>\n",
                      x(lowest->tau_s) - 4, y(lowest->adev) - 4, colour);
        s += buf;
      }
      if (inside(3.0, k)) {
        const double cx = x(3.0), cy = y(k);
        std::snprintf(buf, sizeof buf,
                      "<polygon points=\"%.1f,%.1f %.1f,%.1f %.1f,%.1f\" fill=\"none\" stroke=\"%s\"/>\n", cx, cy - 5,
                      cx - 5, cy + 4, cx + 5, cy + 4, colour);
        s += buf;
      }
    }
  }
  return s + "</svg>\n";
}

// A noise figure for the printout: a zero or non-finite one was not determined by the curve (a filter would take
// a zero sigma as a perfect sensor).
std::string figure(double v, const char* format = "%14.4g") {
  if (!(v > 0.0) || !std::isfinite(v)) return "  undetermined";
  char buf[32];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

int run_allan(const CalibrateOptions& opt) {
  io::Recording rec;
  try {
    rec = io::read_recording(opt.allan);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bsn calibrate: %s\n", e.what());
    return 2;
  }
  struct Channel {
    const char* name;
    const io::RowsX3* data;
    const char* unit;
  };
  const Channel channels[] = {{"gyr", &rec.gyr, "rad/s"}, {"acc", &rec.acc, "m/s^2"}, {"mag", &rec.mag, "uT"}};
  std::vector<std::uint64_t> t_ns(rec.size());
  for (std::size_t i = 0; i < rec.size(); ++i) t_ns[i] = rec.time_ns(i);
  std::vector<AxisCurve> curves;
  std::printf("Allan deviation of %s (%zu samples, %.0f s); each channel at its own rate from its own timestamps\n",
              opt.allan.c_str(), rec.size(), rec.size() ? static_cast<double>(t_ns.back() - t_ns.front()) * 1e-9 : 0.0);
  std::printf("%-6s %-8s %9s %14s %14s %14s | %14s\n", "axis", "unit", "rate (Hz)", "N (/sqrt(Hz))", "B",
              "K (/s/sqrt(Hz))", "sigma/sample");
  // sigma_white per channel is at the channel's own rate (a 50 Hz magnetometer's per-sample noise).
  std::vector<double> channel_rate;
  for (const Channel& c : channels) {
    const calib::OwnRateSeries series = calib::own_rate_series(*c.data, t_ns);
    if (!(series.rate_hz > 0.0) || series.xyz.rows() < 100) {
      std::printf("%-6s undetermined (%td samples of its own; the Allan deviation needs at least 100)\n", c.name,
                  series.xyz.rows());
      continue;
    }
    if (series.gaps > 0) {
      std::printf("%-6s note: %zu gaps longer than 1.5 sample intervals (lost samples bias the curve)\n", c.name,
                  series.gaps);
    }
    for (int axis = 0; axis < 3; ++axis) {
      AxisCurve a;
      a.name = std::string(c.name) + "_" + "xyz"[axis];
      a.unit = c.unit;
      const Eigen::VectorXd x = series.xyz.col(axis);
      a.curve = calib::allan_deviation(x, series.rate_hz);
      a.coefficients = calib::fit_noise_coefficients(a.curve);
      const calib::FilterNoise f = calib::filter_noise(a.coefficients, series.rate_hz);
      std::printf("%-6s %-8s %9.4g %s %s %s | %s\n", a.name.c_str(), c.unit, series.rate_hz,
                  figure(a.coefficients.white_density).c_str(), figure(a.coefficients.bias_instability).c_str(),
                  figure(a.coefficients.rate_random_walk).c_str(), figure(f.sigma_white).c_str());
      curves.push_back(std::move(a));
      channel_rate.push_back(series.rate_hz);
    }
  }
  if (curves.empty()) {
    std::fprintf(stderr, "bsn calibrate: %s: no channel to analyse\n", opt.allan.c_str());
    return 1;
  }
  // The Kalman filters' sigmas (nez-2018 Table 2): the worst axis of each sensor; "undetermined" where no axis
  // gave a figure (never 0, which a filter would take as a perfect sensor).
  auto worst = [&](const char* prefix, auto field) {
    double v = 0.0;
    for (std::size_t i = 0; i < curves.size(); ++i)
      if (curves[i].name.rfind(prefix, 0) == 0) v = std::max(v, field(i));
    return v;
  };
  const auto white = [&](std::size_t i) {
    return calib::filter_noise(curves[i].coefficients, channel_rate[i]).sigma_white;
  };
  const auto bias = [&](std::size_t i) { return curves[i].coefficients.bias_instability; };
  std::printf("for the Kalman filters: sigma_g %s rad/s, sigma_bg %s rad/s, sigma_a %s m/s^2, sigma_m %s uT\n",
              figure(worst("gyr", white), "%.3g").c_str(), figure(worst("gyr", bias), "%.3g").c_str(),
              figure(worst("acc", white), "%.3g").c_str(), figure(worst("mag", white), "%.3g").c_str());
  if (!opt.plot.empty()) {
    std::ofstream out(opt.plot);
    out << svg_plot(curves);
    if (!out) {
      std::fprintf(stderr, "bsn calibrate: cannot write %s\n", opt.plot.c_str());
      return 2;
    }
    std::printf("wrote %s\n", opt.plot.c_str());
  }
  return 0;
}

/// The bsn/raw streams of a session file as recordings, by node id (the sampling rate from the median interval).
std::map<std::string, io::Recording> session_recordings(const std::string& path) {
  const io::SessionReader r(path);
  std::map<std::string, io::Recording> out;
  for (const io::SessionStream& s : r.streams_of("bsn/raw")) {
    io::Recording rec;
    rec.timestamp_ns = r.read_u64(s, "timestamp_ns");
    const std::size_t n = rec.timestamp_ns.size();
    const auto acc = r.read_f64(s, "acc", 3), gyr = r.read_f64(s, "gyr", 3), mag = r.read_f64(s, "mag", 3);
    const auto channels = r.read_u32(s, "channels");
    if (acc.size() != 3 * n || gyr.size() != 3 * n || mag.size() != 3 * n || channels.size() != n)
      throw io::IoError(path + ": the datasets of '" + s.group + "' differ in length");
    rec.acc.resize(static_cast<Eigen::Index>(n), 3);
    rec.gyr.resize(static_cast<Eigen::Index>(n), 3);
    rec.mag.resize(static_cast<Eigen::Index>(n), 3);
    for (std::size_t k = 0; k < n; ++k) {
      const auto row = static_cast<Eigen::Index>(k);
      for (int c = 0; c < 3; ++c) {
        rec.acc(row, c) = acc[3 * k + c];
        rec.gyr(row, c) = gyr[3 * k + c];
        rec.mag(row, c) = (channels[k] & 4u) ? mag[3 * k + c] : std::nan("");  // CHANNEL_MAG
      }
    }
    std::vector<std::uint64_t> dt;
    for (std::size_t k = 1; k < n; ++k)
      if (rec.timestamp_ns[k] > rec.timestamp_ns[k - 1]) dt.push_back(rec.timestamp_ns[k] - rec.timestamp_ns[k - 1]);
    if (dt.empty()) continue;
    std::nth_element(dt.begin(), dt.begin() + static_cast<long>(dt.size() / 2), dt.end());
    rec.sampling_rate_hz = 1e9 / static_cast<double>(dt[dt.size() / 2]);
    out.emplace(s.key, std::move(rec));
  }
  return out;
}

/// `--alignment DIR`: the alignment of a recorded lab procedure (N-pose, flexions) from DIR/<node>.hdf5 per node of
/// the body, as the calibration service would align it live; writes DIR/<node>.alignment.calib.yaml (or --output).
int run_offline_alignment(const CalibrateOptions& opt) {
  namespace fs = std::filesystem;
  fusion::BodyModel body;
  // A session file (bsn record) instead of a folder: its bsn/raw per node, its recorded body unless --body.
  const bool from_file = fs::is_regular_file(opt.alignment) && io::is_session_file(opt.alignment);
  std::map<std::string, io::Recording> from_session;
  try {
    if (from_file) from_session = session_recordings(opt.alignment);
    if (!opt.live_options.body_path.empty()) {
      body = config::load_body_model(opt.live_options.body_path);
    } else if (from_file && io::SessionReader(opt.alignment).attributes().count("body_model")) {
      body = config::parse_body_model(io::SessionReader(opt.alignment).attributes().at("body_model"),
                                      opt.alignment + " (its body_model attribute)");
    } else {
      body = fusion::default_lower_body();
    }
  } catch (const config::ConfigError& e) {
    std::fprintf(stderr, "bsn calibrate: error: %s\n", e.what());
    return 2;
  } catch (const io::IoError& e) {
    std::fprintf(stderr, "bsn calibrate: error: %s\n", e.what());
    return 2;
  }
  std::string problem;
  std::vector<calib::AlignmentNode> nodes = alignment_nodes(body, {}, problem);
  std::vector<io::Recording> recordings;
  for (const calib::AlignmentNode& n : nodes) {
    if (from_file) {
      const auto it = from_session.find(n.node);
      if (it == from_session.end()) {
        std::fprintf(stderr,
                     "bsn calibrate: --alignment: %s has no bsn/raw samples of node '%s': the alignment needs every "
                     "node of the body (--body for another body)\n",
                     opt.alignment.c_str(), n.node.c_str());
        return 2;
      }
      recordings.push_back(std::move(it->second));
      continue;
    }
    const std::string path = (fs::path(opt.alignment) / (n.node + ".hdf5")).string();
    if (!fs::exists(path)) {
      std::fprintf(stderr,
                   "bsn calibrate: --alignment: %s is missing: the alignment needs a recording of every node of the "
                   "body (bsn export SESSION.h5 --format broad --out DIR writes DIR/<node>.hdf5; --body for another "
                   "body)\n",
                   path.c_str());
      return 2;
    }
    try {
      recordings.push_back(io::read_recording(path));
    } catch (const std::exception& e) {
      std::fprintf(stderr, "bsn calibrate: error: %s\n", e.what());
      return 2;
    }
  }
  // The samples in time order across the nodes, arriving at their sensor time, as a live collection sees them.
  struct Arrival {
    std::uint64_t t;
    std::size_t node, index;
  };
  std::vector<Arrival> arrivals;
  for (std::size_t i = 0; i < recordings.size(); ++i)
    for (std::size_t k = 0; k < recordings[i].size(); ++k) arrivals.push_back({recordings[i].time_ns(k), i, k});
  std::sort(arrivals.begin(), arrivals.end(), [](const Arrival& a, const Arrival& b) { return a.t < b.t; });
  if (arrivals.empty()) {
    std::fprintf(stderr, "bsn calibrate: --alignment: the recordings hold no sample\n");
    return 2;
  }
  calib::AlignmentSessionParams params;
  const double span_s = static_cast<double>(arrivals.back().t - arrivals.front().t) * 1e-9;
  params.max_duration_s = std::max(params.max_duration_s, span_s + 10.0);
  params.max_samples = std::max(params.max_samples, arrivals.size());
  params.duration_s = span_s + 5.0;
  if (opt.live_options.pose_s > 0.0) params.pose_s = opt.live_options.pose_s;
  if (const std::string why = calib::validate(params); !why.empty()) {
    std::fprintf(stderr, "bsn calibrate: --alignment: %s\n", why.c_str());
    return 2;
  }
  calib::AlignmentSession session(nodes, params, arrivals.front().t);
  for (const Arrival& a : arrivals) {
    calib::SessionSample s = session_sample(recordings[a.node].sample(a.index), a.index);
    s.timestamp_ns = a.t;
    session.add(a.node, s, a.t);
  }
  const calib::AlignmentSessionResult r = session.finish(arrivals.back().t);
  const std::string out_dir = !opt.output.empty() ? opt.output
                              : from_file         ? fs::path(opt.alignment).parent_path().string()
                                                  : opt.alignment;
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  std::size_t aligned = 0;
  if (r.problem.empty())
    std::printf("N-pose %.1f .. %.1f s, flexions to %.1f s\n", r.pose_start_s, r.pose_end_s, r.moves_end_s);
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const calib::NodeAlignment& a = r.nodes[i];
    if (!a.success) {
      std::printf("%s: alignment FAILED: %s\n", nodes[i].node.c_str(), a.message.c_str());
      continue;
    }
    const config::AlignmentRecord record{nodes[i].segment,    a.sensor_to_segment,  a.source,
                                         a.relative_residual, a.axis_observability, a.samples};
    const std::string path = (fs::path(out_dir) / (nodes[i].node + ".alignment.calib.yaml")).string();
    std::ofstream(path) << config::alignment_to_yaml(nodes[i].node, record);
    const calib::Quat& q = a.sensor_to_segment;
    std::printf("%s: aligned to segment %s (%s", nodes[i].node.c_str(), nodes[i].segment.c_str(), a.source.c_str());
    if (a.axis_observability > 0.0)
      std::printf(", hinge residual %.3f, axis observability %.3f", a.relative_residual, a.axis_observability);
    std::printf(")\n  sensor_to_segment = [%.6f, %.6f, %.6f, %.6f] -> %s\n", q.w(), q.x(), q.y(), q.z(), path.c_str());
    ++aligned;
  }
  return aligned == nodes.size() ? 0 : 1;
}

/// Runs the command; returns the process exit code (0 ok, 1 the data do not calibrate, 2 unreadable input).
int run_calibrate(const CalibrateOptions& options) {
  if (options.live) {
    if (!options.input.empty() || !options.allan.empty()) {
      std::fprintf(stderr, "bsn calibrate: --live takes no --input or --allan\n");
      return 2;
    }
    LiveCalibrationOptions live = options.live_options;
    live.node = options.node;
    if (options.field_magnitude_given) live.field_magnitude = options.field_magnitude;
    return run_live_calibration(live);
  }
  if (!options.alignment.empty()) {
    if (!options.input.empty() || !options.allan.empty()) {
      std::fprintf(stderr, "bsn calibrate: --alignment takes no --input or --allan\n");
      return 2;
    }
    return run_offline_alignment(options);
  }
  if (options.input.empty() == options.allan.empty()) {
    std::fprintf(stderr, "bsn calibrate: give exactly one of --input FILE, --allan FILE or --alignment DIR\n");
    return 2;
  }
  return options.allan.empty() ? run_fit(options) : run_allan(options);
}

}  // namespace

Command calibrate_command() {
  return {"calibrate", "Calibrate a hand-turned recording (magnetometer, accelerometer) or identify noise (--allan)",
          [](CLI::App* cmd) {
            auto opt = std::make_shared<CalibrateOptions>();
            cmd->add_option("--input", opt->input, "recording (CSV, BROAD HDF5) of still poses turned by hand");
            cmd->add_option("--allan", opt->allan, "static recording: print Allan noise figures instead");
            cmd->add_option("--alignment", opt->alignment,
                            "a recorded alignment (N-pose, flexions): a session file (bsn record) or a folder with "
                            "DIR/<node>.hdf5 per node of the body: write <node>.alignment.calib.yaml beside it (or "
                            "into --output DIR) instead");
            auto* field = cmd->add_option("--field-magnitude", opt->field_magnitude,
                                          "|calibrated magnetometer|, M (with --live: uT, default 50)")
                              ->capture_default_str()
                              ->check(positive_number(1e6));
            cmd->add_flag("--json", opt->json, "print the magnetometer calibration as one JSON object");
            cmd->add_option("--output", opt->output,
                            "calibration file to write (default: INPUT.calib.yaml); with --alignment: the folder");
            cmd->add_option("--node", opt->node,
                            "node id to record in the calibration file; with --live: the node (or ID,ID,...) to "
                            "calibrate");
            cmd->add_flag("--accelerometer", opt->accelerometer, "also calibrate the accelerometer (|g|)");
            cmd->add_flag("--gyro-bias", opt->gyro_bias, "also write the gyro bias measured at rest");
            cmd->add_option("--rest-threshold", opt->rest_rate_rad_s, "rest when |gyro - bias| < this, rad/s")
                ->capture_default_str()
                ->check(positive_number(100.0));
            cmd->add_option("--min-pose", opt->min_pose_s, "shortest rest counted as a pose, s")
                ->capture_default_str()
                ->check(positive_number(3600.0));
            cmd->add_option("--plot", opt->plot, "with --allan: write the Allan curves as SVG");
            LiveCalibrationOptions& live = opt->live_options;
            cmd->add_flag("--live", opt->live, "calibrate live through `bsn calibration` (see --node, --kind)");
            cmd->add_option("--kind", live.kind,
                            "with --live: magnetometer, gyro-bias, accelerometer or alignment (sensor-to-segment "
                            "rotations of a body's nodes: N-pose, then flexions)")
                ->capture_default_str();
            cmd->add_option("--body", live.body_path,
                            "with --alignment, or --live --kind alignment: the body model whose nodes are aligned "
                            "(default: the 7-segment lower body; with --live, --node picks some of its nodes)");
            cmd->add_option(
                   "--pose", live.pose_s,
                   "with --alignment or --live --kind alignment: the N-pose at the start lasts at least S seconds "
                   "(default 3)")
                ->check(non_negative_number(60.0));
            cmd->add_flag("--all-nodes", live.all_nodes, "with --live: every node publishing on bsn/raw");
            cmd->add_option("--duration", live.duration_s, "with --live: collect for S seconds (0: --samples only)")
                ->capture_default_str();
            cmd->add_option("--samples", live.sample_count, "with --live: or until N samples per node");
            cmd->add_flag("--until-good", live.until_good,
                          "with --live: stop as soon as the quality report is good enough");
            cmd->add_option("--request-id", live.request_id, "with --live: the request id (default: host-pid-time)");
            cmd->add_option("--service-timeout", live.service_timeout_s,
                            "with --live: seconds to wait for a calibration service")
                ->capture_default_str();
            add_domain_option(cmd, live.domain);
            return [opt, field] {
              opt->field_magnitude_given = field->count() > 0;
              return run_calibrate(*opt);
            };
          }};
}

}  // namespace bsn::services
