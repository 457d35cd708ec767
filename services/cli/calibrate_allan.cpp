#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "bsn/calib/allan.hpp"
#include "bsn/io/recording.hpp"
#include "calibrate_modes.hpp"

namespace bsn::services {
namespace {

struct AxisCurve {
  std::string name;  ///< e.g. "gyr_x"
  std::string unit;  ///< the channel's unit, e.g. "rad/s"
  std::vector<calib::AllanPoint> curve;
  calib::NoiseCoefficients coefficients{0, 0, 0};
};

// The sensors of the curves ("gyr" of "gyr_x", ...), in their first order.
std::vector<std::string> sensors_of(const std::vector<AxisCurve>& curves) {
  std::vector<std::string> sensors;
  for (const auto& c : curves) {
    const std::string sensor = c.name.substr(0, c.name.find('_'));
    if (std::find(sensors.begin(), sensors.end(), sensor) == sensors.end()) sensors.push_back(sensor);
  }
  return sensors;
}

// One panel per sensor (its own unit on the y axis), log-log, one line per axis, and where each axis's N (the -1/2
// line at tau = 1 s), B (the flat minimum, adev = 0.664 B) and K (the +1/2 line at tau = 3 s) were read.
std::string svg_plot(const std::vector<AxisCurve>& curves) {
  const std::vector<std::string> sensors = sensors_of(curves);
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

}  // namespace

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

}  // namespace bsn::services
