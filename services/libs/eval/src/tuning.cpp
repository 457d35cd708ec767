#include "bsn/eval/tuning.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <stdexcept>

namespace bsn::eval {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

double parse_number(const std::string& text, const std::string& what) {
  std::size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size()) throw std::invalid_argument(what + ": '" + text + "' is not a number");
  if (!std::isfinite(v)) throw std::invalid_argument(what + ": '" + text + "' is not a finite number");
  return v;
}

void check_range(const ParamRange& r) {
  const std::string what = "--param " + r.name;
  if (!std::isfinite(r.lo) || !std::isfinite(r.hi)) throw std::invalid_argument(what + ": bounds must be finite");
  if (!(r.lo < r.hi)) {
    throw std::invalid_argument(what + ": empty or inverted range " + std::to_string(r.lo) + ":" +
                                std::to_string(r.hi) + " (need lo < hi)");
  }
  if (r.log && !(r.lo > 0.0)) throw std::invalid_argument(what + ": a log range needs lo > 0");
}

// The global stage: the centre of the unit cube, the given start points (clamped into it), then Halton points.
std::vector<std::vector<double>> global_stage_points(std::size_t dims, const OptimiserOptions& options,
                                                     const std::vector<std::vector<double>>& start) {
  std::vector<std::vector<double>> global(1, std::vector<double>(dims, 0.5));
  for (const auto& s : start) {
    if (s.size() != dims) throw std::invalid_argument("minimise: a start point has the wrong dimension");
    std::vector<double> p(dims);
    for (std::size_t d = 0; d < dims; ++d) p[d] = std::clamp(s[d], 0.0, 1.0);
    global.push_back(p);
  }
  for (std::size_t i = 1; i <= options.global_points; ++i) global.push_back(halton_point(i, dims));
  return global;
}

}  // namespace

double ParamRange::value_at(double u) const {
  u = std::clamp(u, 0.0, 1.0);
  if (log) return std::exp(std::log(lo) + u * (std::log(hi) - std::log(lo)));
  return lo + u * (hi - lo);
}

ParamRange parse_param_range(const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0) {
    throw std::invalid_argument("--param '" + text + "': expected name=lo:hi or name=lo:hi:log");
  }
  ParamRange r;
  r.name = text.substr(0, eq);
  const std::string what = "--param " + r.name;
  std::vector<std::string> parts;
  std::size_t from = eq + 1;
  while (true) {
    const auto colon = text.find(':', from);
    parts.push_back(text.substr(from, colon == std::string::npos ? std::string::npos : colon - from));
    if (colon == std::string::npos) break;
    from = colon + 1;
  }
  if (parts.size() < 2 || parts.size() > 3 || (parts.size() == 3 && parts[2] != "log" && parts[2] != "lin")) {
    throw std::invalid_argument(what + ": expected lo:hi or lo:hi:log, got '" + text.substr(eq + 1) + "'");
  }
  r.lo = parse_number(parts[0], what + " lower bound");
  r.hi = parse_number(parts[1], what + " upper bound");
  r.log = parts.size() == 3 && parts[2] == "log";
  check_range(r);
  return r;
}

void check_param_ranges(const fusion::FilterSpec& base, const std::vector<ParamRange>& ranges) {
  if (ranges.empty()) throw std::invalid_argument("filter '" + base.name + "': no parameters to identify (--param)");
  for (std::size_t i = 0; i < ranges.size(); ++i) {
    check_range(ranges[i]);
    for (std::size_t j = 0; j < i; ++j) {
      if (ranges[j].name == ranges[i].name) throw std::invalid_argument("--param " + ranges[i].name + ": given twice");
    }
  }
  // The filter itself judges the names and the values: an unknown name throws "has no parameter", a value it
  // does not accept throws naming the parameter.
  for (const double u : {0.0, 1.0}) {
    std::vector<double> values;
    for (const auto& r : ranges) values.push_back(r.value_at(u));
    try {
      (void)fusion::make_filter(spec_with(base, ranges, values));
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(std::string(e.what()) +
                                  (u == 0.0 ? " (at the ranges' lower ends)" : " (at the ranges' upper ends)"));
    }
  }
}

std::vector<ParamRange> default_param_ranges(const std::string& filter) {
  if (filter == "mekf") {
    // Lower ends at or below Nez Table 2 (Allan) values, upper ends beyond Table 3's largest.
    return {{"sigma_g", 1e-4, 1.0, true},
            {"sigma_bg", 1e-6, 1e-2, true},
            {"sigma_a", 1e-2, 100.0, true},
            {"sigma_m", 0.1, 300.0, true}};
  }
  if (filter == "seel_ruppin") {
    return {{"tau_acc_s", 0.05, 20.0, true}, {"tau_mag_s", 0.2, 60.0, true}, {"zeta", 0.0, 4.0, false}};
  }
  return {};
}

fusion::FilterSpec spec_with(const fusion::FilterSpec& base, const std::vector<ParamRange>& ranges,
                             std::span<const double> values) {
  fusion::FilterSpec spec = base;
  for (std::size_t i = 0; i < ranges.size() && i < values.size(); ++i) {
    std::erase_if(spec.parameters, [&](const auto& kv) { return kv.first == ranges[i].name; });
    spec.parameters.emplace_back(ranges[i].name, values[i]);
  }
  return spec;
}

Criterion parse_criterion(const std::string& text) {
  if (text == "nez") return Criterion::kNez;
  if (text == "rmse") return Criterion::kRmse;
  throw std::invalid_argument("--criterion: '" + text + "' is neither nez nor rmse");
}

const char* criterion_name(Criterion c) { return c == Criterion::kNez ? "nez" : "rmse"; }

double criterion_value(Criterion c, std::span<const double> rmse) {
  if (rmse.empty()) return kInf;
  for (const double v : rmse) {
    if (!std::isfinite(v)) return kInf;
  }
  const double n = static_cast<double>(rmse.size());
  const double mean = std::accumulate(rmse.begin(), rmse.end(), 0.0) / n;
  if (c == Criterion::kRmse || rmse.size() < 2) return mean;
  double ss = 0.0;
  for (const double v : rmse) ss += (v - mean) * (v - mean);
  return mean + std::sqrt(ss / (n - 1.0));
}

std::vector<double> halton_point(std::size_t i, std::size_t dims) {
  static constexpr std::array<std::size_t, 16> kPrimes = {2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53};
  if (dims > kPrimes.size()) throw std::invalid_argument("halton_point: at most 16 dimensions");
  std::vector<double> p(dims);
  for (std::size_t d = 0; d < dims; ++d) {
    const double b = static_cast<double>(kPrimes[d]);
    double f = 1.0, r = 0.0;
    for (std::size_t k = i; k > 0; k /= kPrimes[d]) {
      f /= b;
      r += f * static_cast<double>(k % kPrimes[d]);
    }
    p[d] = r;
  }
  return p;
}

OptimiserResult minimise(std::size_t dims, const BatchObjective& objective, const OptimiserOptions& options,
                         const std::vector<std::vector<double>>& start, const OptimiserProgress& progress) {
  if (dims == 0 || dims > 16) throw std::invalid_argument("minimise: 1 to 16 parameters");
  if (!(options.initial_step > 0.0 && options.initial_step <= 0.5) ||
      !(options.min_step > 0.0 && options.min_step <= options.initial_step) || options.max_evaluations == 0) {
    throw std::invalid_argument("minimise: options out of range");
  }
  // Every point evaluated, so that the pattern search never pays twice for a point it has seen.
  std::map<std::vector<double>, double> seen;
  OptimiserResult best;
  best.value = kInf;
  const std::size_t budget = options.max_evaluations;

  auto evaluate = [&](std::vector<std::vector<double>> batch) {
    std::erase_if(batch, [&](const auto& p) { return seen.count(p) != 0; });
    std::sort(batch.begin(), batch.end());
    batch.erase(std::unique(batch.begin(), batch.end()), batch.end());
    if (seen.size() + batch.size() > budget) batch.resize(budget - std::min(budget, seen.size()));
    if (batch.empty()) return;
    const std::vector<double> values = objective(batch);
    if (values.size() != batch.size()) throw std::logic_error("minimise: the objective returned a wrong count");
    for (std::size_t i = 0; i < batch.size(); ++i) {
      const double v = std::isnan(values[i]) ? kInf : values[i];
      seen[batch[i]] = v;
      // Ties go to the earlier point, so reruns are identical.
      if (v < best.value || best.unit.empty()) {
        best.value = v;
        best.unit = batch[i];
      }
    }
    best.evaluations = seen.size();
    if (progress) progress(seen.size(), budget, best.value);
  };

  evaluate(global_stage_points(dims, options, start));
  best.global_evaluations = seen.size();

  // Local stage: a pattern search on the lattice of the current step, from each of the best `local_starts` points
  // of the global stage at once (the criterion surfaces have several basins: a too stiff accelerometer and a too
  // stiff gyro both give local minima), all their coordinate steps in one batch.
  std::vector<std::pair<double, std::vector<double>>> ranked;
  for (const auto& [p, v] : seen) ranked.emplace_back(v, p);
  std::stable_sort(ranked.begin(), ranked.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  struct Search {
    std::vector<double> centre;
    double value;
    double step;
  };
  std::vector<Search> searches;
  for (std::size_t i = 0; i < ranked.size() && searches.size() < std::max<std::size_t>(1, options.local_starts); ++i) {
    searches.push_back({ranked[i].second, ranked[i].first, options.initial_step});
  }
  double step = options.initial_step;
  while (seen.size() < budget) {
    std::vector<std::vector<double>> batch;
    for (const Search& s : searches) {
      if (s.step < options.min_step) continue;
      for (std::size_t d = 0; d < dims; ++d) {
        for (const double sign : {-1.0, 1.0}) {
          std::vector<double> p = s.centre;
          p[d] = std::clamp(p[d] + sign * s.step, 0.0, 1.0);
          if (p != s.centre) batch.push_back(p);
        }
      }
    }
    if (batch.empty()) break;
    evaluate(batch);
    step = 0.0;
    for (Search& s : searches) {
      if (s.step < options.min_step) continue;
      // The best evaluated neighbour of this search's centre at its step.
      const std::vector<double> centre = s.centre;
      bool moved = false;
      for (std::size_t d = 0; d < dims; ++d) {
        for (const double sign : {-1.0, 1.0}) {
          std::vector<double> p = centre;
          p[d] = std::clamp(p[d] + sign * s.step, 0.0, 1.0);
          const auto it = seen.find(p);
          if (it != seen.end() && it->second < s.value) {
            s.value = it->second;
            s.centre = p;
            moved = true;
          }
        }
      }
      if (!moved) s.step /= 2.0;
      step = std::max(step, s.step);
    }
  }
  best.final_step = step;
  return best;
}

}  // namespace bsn::eval
