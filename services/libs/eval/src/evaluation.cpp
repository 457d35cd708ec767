#include "bsn/eval/evaluation.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "bsn/io/json.hpp"

namespace bsn::eval {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

using io::json_number;
using io::json_string;

std::string angles_json(const fusion::ErrorAngles& e) {
  return "\"total_rmse_deg\": " + json_number(e.total * kDeg) +
         ", \"heading_rmse_deg\": " + json_number(e.heading * kDeg) +
         ", \"inclination_rmse_deg\": " + json_number(e.inclination * kDeg);
}

std::string xml_text(const std::string& s) {
  std::string out;
  for (const char c : s) {
    if (c == '<')
      out += "&lt;";
    else if (c == '>')
      out += "&gt;";
    else if (c == '&')
      out += "&amp;";
    else
      out += c;
  }
  return out;
}

}  // namespace

TrialResult run_trial(const io::Recording& rec, const std::string& trial, const fusion::FilterSpec& spec,
                      const std::string& filter_label, std::size_t max_series_points) {
  TrialResult result;
  result.trial = trial;
  result.filter = filter_label;
  auto filter = fusion::make_filter(spec);
  fusion::RmsErrorAccumulator acc;
  const std::size_t n = rec.size();
  const std::size_t stride =
      std::max<std::size_t>(1, (n + max_series_points - 1) / std::max<std::size_t>(1, max_series_points));
  const bool has_ref = rec.opt_quat.rows() > 0;
  bool scored_any = false;
  for (std::size_t i = 0; i < n; ++i) {
    if (filter->update(rec.sample(i)) == fusion::UpdateResult::kRejected) ++result.rejected;
    const fusion::Quat q = filter->orientation();
    if (!q.coeffs().allFinite()) {
      ++result.non_finite;
      continue;
    }
    double err_deg = std::nan("");
    const bool counts = rec.movement.empty() || rec.movement[i] != 0;
    if (has_ref && counts && filter->initialised()) {
      const auto r = rec.opt_quat.row(static_cast<Eigen::Index>(i));
      if (r.allFinite()) {
        const fusion::ErrorAngles e = fusion::error_angles(q, fusion::Quat(r(0), r(1), r(2), r(3)));
        acc.add(e);
        err_deg = e.total * kDeg;
        if (!scored_any) result.unscored_until_s = static_cast<double>(rec.time_ns(i)) * 1e-9;
        scored_any = true;
      }
    }
    if (i % stride == 0) {
      result.time_s.push_back(static_cast<float>(static_cast<double>(rec.time_ns(i)) * 1e-9));
      result.total_deg.push_back(static_cast<float>(err_deg));
    }
  }
  result.rmse = acc.rms();
  result.scored = acc.count();
  return result;
}

fusion::FilterSpec parse_filter_argument(const std::string& text) {
  fusion::FilterSpec spec;
  const auto colon = text.find(':');
  spec.name = text.substr(0, colon);
  if (spec.name.empty()) throw std::invalid_argument("filter '" + text + "': empty name");
  if (colon == std::string::npos) return spec;
  std::stringstream rest(text.substr(colon + 1));
  std::string item;
  while (std::getline(rest, item, ',')) {
    const auto eq = item.find('=');
    if (eq == std::string::npos || eq == 0) {
      throw std::invalid_argument("filter '" + text + "': '" + item + "' is not key=value");
    }
    const std::string value = item.substr(eq + 1);
    std::size_t used = 0;
    double v = 0.0;
    try {
      v = std::stod(value, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != value.size()) {
      throw std::invalid_argument("filter '" + text + "': value '" + value + "' is not a number");
    }
    spec.parameters.emplace_back(item.substr(0, eq), v);
  }
  return spec;
}

std::vector<FilterMean> means_by_filter(const std::vector<TrialResult>& results) {
  std::vector<FilterMean> means;
  for (const auto& r : results) {
    auto it = std::find_if(means.begin(), means.end(), [&](const FilterMean& m) { return m.filter == r.filter; });
    if (it == means.end()) it = means.insert(means.end(), FilterMean{r.filter, {}, 0});
    it->mean_rmse.total += r.rmse.total;
    it->mean_rmse.heading += r.rmse.heading;
    it->mean_rmse.inclination += r.rmse.inclination;
    ++it->trials;
  }
  for (auto& m : means) {
    const double n = static_cast<double>(m.trials);
    m.mean_rmse = {m.mean_rmse.total / n, m.mean_rmse.heading / n, m.mean_rmse.inclination / n};
  }
  return means;
}

std::string to_json(const std::vector<TrialResult>& results) {
  std::string out = "{\"trials\": [";
  for (std::size_t i = 0; i < results.size(); ++i) {
    const auto& r = results[i];
    out += (i ? ", " : "") + std::string("{\"trial\": ") + json_string(r.trial) +
           ", \"filter\": " + json_string(r.filter) + ", " + angles_json(r.rmse) + "}";
  }
  out += "], \"means\": [";
  const auto means = means_by_filter(results);
  for (std::size_t i = 0; i < means.size(); ++i) {
    out += (i ? ", " : "") + std::string("{\"filter\": ") + json_string(means[i].filter) + ", " +
           angles_json(means[i].mean_rmse) + "}";
  }
  return out + "]}\n";
}

std::string to_table(const std::vector<TrialResult>& results) {
  std::size_t trial_w = 5, filter_w = 6;
  for (const auto& r : results) {
    trial_w = std::max(trial_w, r.trial.size());
    filter_w = std::max(filter_w, r.filter.size());
  }
  const int tw = static_cast<int>(trial_w), fw = static_cast<int>(filter_w);
  std::string out;
  char line[512];
  std::snprintf(line, sizeof line, "%-*s  %-*s  %9s  %9s  %11s   (RMSE, degrees)\n", tw, "trial", fw, "filter", "total",
                "heading", "inclination");
  out += line;
  for (const auto& r : results) {
    std::snprintf(line, sizeof line, "%-*s  %-*s  %9.2f  %9.2f  %11.2f%s\n", tw, r.trial.c_str(), fw, r.filter.c_str(),
                  r.rmse.total * kDeg, r.rmse.heading * kDeg, r.rmse.inclination * kDeg,
                  r.scored == 0 ? "   (no reference samples)" : "");
    out += line;
  }
  for (const auto& m : means_by_filter(results)) {
    std::snprintf(line, sizeof line, "%-*s  %-*s  %9.2f  %9.2f  %11.2f\n", tw, "mean", fw, m.filter.c_str(),
                  m.mean_rmse.total * kDeg, m.mean_rmse.heading * kDeg, m.mean_rmse.inclination * kDeg);
    out += line;
  }
  return out;
}

std::string to_markdown(const std::vector<TrialResult>& results) {
  std::vector<FilterMean> means = means_by_filter(results);
  std::stable_sort(means.begin(), means.end(),
                   [](const FilterMean& a, const FilterMean& b) { return a.mean_rmse.total < b.mean_rmse.total; });
  std::string out =
      "| filter | total | heading | inclination | worst trial | worst / mean |\n|---|---|---|---|---|---|\n";
  char line[512];
  for (const FilterMean& m : means) {
    const TrialResult* worst = nullptr;
    for (const auto& r : results)
      if (r.filter == m.filter && (!worst || r.rmse.total > worst->rmse.total)) worst = &r;
    std::snprintf(line, sizeof line, "| `%s` | %.2f° | %.2f° | %.2f° | %s (%.2f°) | %.2f× |\n", m.filter.c_str(),
                  m.mean_rmse.total * kDeg, m.mean_rmse.heading * kDeg, m.mean_rmse.inclination * kDeg,
                  worst->trial.c_str(), worst->rmse.total * kDeg,
                  m.mean_rmse.total > 0 ? worst->rmse.total / m.mean_rmse.total : 0.0);
    out += line;
  }
  std::vector<std::string> trials;
  for (const auto& r : results)
    if (std::find(trials.begin(), trials.end(), r.trial) == trials.end()) trials.push_back(r.trial);
  out += "\nTotal RMSE per trial (degrees):\n\n| trial |";
  std::string rule = "|---|";
  for (const FilterMean& m : means) {
    out += " `" + m.filter + "` |";
    rule += "---|";
  }
  out += "\n" + rule + "\n";
  for (const auto& trial : trials) {
    out += "| " + trial + " |";
    for (const FilterMean& m : means) {
      const auto it = std::find_if(results.begin(), results.end(),
                                   [&](const TrialResult& r) { return r.trial == trial && r.filter == m.filter; });
      if (it == results.end()) {
        out += " - |";
      } else {
        std::snprintf(line, sizeof line, " %.2f |", it->rmse.total * kDeg);
        out += line;
      }
    }
    out += "\n";
  }
  return out;
}

namespace {

// A "nice" tick step (1, 2 or 5 times a power of ten) giving about `count` ticks over `span`.
double tick_step(double span, double count) {
  const double raw = span / count;
  const double power = std::pow(10.0, std::floor(std::log10(raw)));
  for (const double m : {1.0, 2.0, 5.0}) {
    if (m * power >= raw) return m * power;
  }
  return 10.0 * power;
}

std::string tick_label(double v, double step) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.*f", step < 1.0 ? static_cast<int>(std::ceil(-std::log10(step))) : 0, v);
  return buf;
}

}  // namespace

std::string to_svg(const std::vector<TrialResult>& results) {
  // Panels: one per trial, in order of first appearance; lines: one colour and dash pattern per filter.
  std::vector<std::string> trials, filters;
  for (const auto& r : results) {
    if (std::find(trials.begin(), trials.end(), r.trial) == trials.end()) trials.push_back(r.trial);
    if (std::find(filters.begin(), filters.end(), r.filter) == filters.end()) filters.push_back(r.filter);
  }
  static constexpr const char* kColours[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd",
                                             "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"};
  static constexpr const char* kDashes[] = {"", "6,3", "2,2", "8,3,2,3"};
  auto style = [&](std::size_t f) {
    std::string st = std::string("stroke=\"") + kColours[f % 10] + "\"";
    const char* dash = kDashes[(f / 2 + f) % 4];  // neighbours in the list differ in colour and pattern
    if (*dash) st += std::string(" stroke-dasharray=\"") + dash + "\"";
    return st;
  };
  const double width = 960, panel_h = 200, left = 60, right = 20, gap = 70;
  const double legend_rows = std::ceil(static_cast<double>(filters.size()) / 4.0);
  const double top = 20 + 18.0 * legend_rows;  // the legend: four filters a row
  const double height = top + static_cast<double>(trials.size()) * (panel_h + gap) + 10;
  const double plot_w = width - left - right;
  std::ostringstream svg;
  svg << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << width << "\" height=\"" << height
      << "\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  for (std::size_t f = 0; f < filters.size(); ++f) {
    const double x = left + plot_w / 4.0 * static_cast<double>(f % 4);
    const double y = 16 + 18.0 * std::floor(static_cast<double>(f) / 4.0);
    svg << "<line x1=\"" << x << "\" y1=\"" << y << "\" x2=\"" << x + 30 << "\" y2=\"" << y << "\" " << style(f)
        << " stroke-width=\"2\"/><text x=\"" << x + 36 << "\" y=\"" << y + 4 << "\">" << xml_text(filters[f])
        << "</text>\n";
  }
  for (std::size_t p = 0; p < trials.size(); ++p) {
    const double y0 = top + static_cast<double>(p) * (panel_h + gap) + 30;
    double t_max = 1e-9, e_max = 1.0, unscored = 0.0;
    std::string series = "total error";
    for (const auto& r : results) {
      if (r.trial != trials[p]) continue;
      series = r.series_name;
      unscored = std::max(unscored, r.unscored_until_s);
      for (std::size_t i = 0; i < r.time_s.size(); ++i) {
        t_max = std::max(t_max, static_cast<double>(r.time_s[i]));
        if (std::isfinite(r.total_deg[i])) e_max = std::max(e_max, static_cast<double>(r.total_deg[i]));
      }
    }
    const double y_step = tick_step(e_max, 5.0);
    e_max = std::ceil(e_max / y_step) * y_step;
    const double x_step = tick_step(t_max, 10.0);
    auto x_of = [&](double t) { return left + plot_w * std::min(1.0, t / t_max); };
    auto y_of = [&](double e) { return y0 + panel_h - panel_h * std::min(1.0, e / e_max); };
    svg << "<text x=\"" << left << "\" y=\"" << y0 - 8 << "\" font-weight=\"bold\">" << xml_text(trials[p]) << ": "
        << xml_text(series) << " (deg) over time (s)</text>\n";
    if (unscored > 0.0) {
      svg << "<rect x=\"" << left << "\" y=\"" << y0 << "\" width=\"" << x_of(unscored) - left << "\" height=\""
          << panel_h << "\" fill=\"#e8e8e8\"/><text x=\"" << left + 4 << "\" y=\"" << y0 + 14
          << "\" fill=\"#555\">not scored</text>\n";
    }
    for (double e = 0.0; e <= e_max + 1e-9 * e_max; e += y_step) {
      const double y = y_of(e);
      svg << "<line x1=\"" << left << "\" y1=\"" << y << "\" x2=\"" << left + plot_w << "\" y2=\"" << y
          << "\" stroke=\"#ddd\"/><line x1=\"" << left - 4 << "\" y1=\"" << y << "\" x2=\"" << left << "\" y2=\"" << y
          << "\" stroke=\"#444\"/><text x=\"" << left - 7 << "\" y=\"" << y + 4 << "\" text-anchor=\"end\">"
          << tick_label(e, y_step) << "</text>\n";
    }
    for (double t = 0.0; t <= t_max + 1e-9 * t_max; t += x_step) {
      const double x = x_of(t);
      svg << "<line x1=\"" << x << "\" y1=\"" << y0 << "\" x2=\"" << x << "\" y2=\"" << y0 + panel_h
          << "\" stroke=\"#ddd\"/><line x1=\"" << x << "\" y1=\"" << y0 + panel_h << "\" x2=\"" << x << "\" y2=\""
          << y0 + panel_h + 4 << "\" stroke=\"#444\"/><text x=\"" << x << "\" y=\"" << y0 + panel_h + 17
          << "\" text-anchor=\"middle\">" << tick_label(t, x_step) << "</text>\n";
    }
    svg << "<rect x=\"" << left << "\" y=\"" << y0 << "\" width=\"" << plot_w << "\" height=\"" << panel_h
        << "\" fill=\"none\" stroke=\"#444\"/>\n";
    svg << "<text x=\"" << left + plot_w / 2 << "\" y=\"" << y0 + panel_h + 32
        << "\" text-anchor=\"middle\">time (s)</text>"
        << "<text transform=\"translate(" << left - 42 << "," << y0 + panel_h / 2
        << ") rotate(-90)\" text-anchor=\"middle\">deg</text>\n";
    for (const auto& r : results) {
      if (r.trial != trials[p]) continue;
      const auto f = static_cast<std::size_t>(std::find(filters.begin(), filters.end(), r.filter) - filters.begin());
      svg << "<polyline fill=\"none\" stroke-width=\"1.2\" " << style(f) << " points=\"";
      for (std::size_t i = 0; i < r.time_s.size(); ++i) {
        if (!std::isfinite(r.total_deg[i])) continue;
        const double x = x_of(r.time_s[i]);
        const double y = y_of(r.total_deg[i]);
        svg << std::lround(x * 10) / 10.0 << "," << std::lround(y * 10) / 10.0 << " ";
      }
      svg << "\"/>\n";
    }
  }
  svg << "</svg>\n";
  return svg.str();
}

}  // namespace bsn::eval
