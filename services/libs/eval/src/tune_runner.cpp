#include "bsn/eval/tune_runner.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <thread>

#include "bsn/fusion/mekf_filter.hpp"
#include "bsn/fusion/orientation_error.hpp"

namespace bsn::eval {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::vector<double> rmse_column(const std::vector<std::vector<double>>& table, std::size_t point) {
  return point < table.size() ? table[point] : std::vector<double>{};
}

}  // namespace

void check_tuning_recording(const io::Recording& rec, const std::string& source) {
  if (rec.opt_quat.rows() == 0) {
    throw std::invalid_argument(source + ": no reference orientation (opt_quat or quat_* columns); tuning needs one");
  }
  std::size_t counted = 0, with_reference = 0;
  for (std::size_t i = 0; i < rec.size(); ++i) {
    const auto r = rec.opt_quat.row(static_cast<Eigen::Index>(i));
    const bool finite = r.allFinite();
    if (!finite && r.array().isFinite().any()) {
      throw std::invalid_argument(source + ": reference orientation of sample " + std::to_string(i) +
                                  " is partly NaN (a row is all numbers or all NaN)");
    }
    if (finite && std::abs(r.norm() - 1.0) > 1e-3) {
      throw std::invalid_argument(source + ": reference orientation of sample " + std::to_string(i) +
                                  " is not a unit quaternion");
    }
    if (rec.movement.empty() || rec.movement[i] != 0) {
      ++counted;
      if (finite) ++with_reference;
    }
  }
  if (counted == 0) throw std::invalid_argument(source + ": no sample counts (movement is 0 throughout)");
  if (2 * with_reference < counted) {
    throw std::invalid_argument(source + ": the reference orientation is NaN in " +
                                std::to_string(counted - with_reference) + " of the " + std::to_string(counted) +
                                " samples that count");
  }
}

double total_rmse(const io::Recording& rec, const fusion::FilterSpec& spec, std::span<const std::uint8_t> mask) {
  auto filter = fusion::make_filter(spec);
  double sum_sq = 0.0;
  std::size_t scored = 0;
  const bool use_mask = !mask.empty();
  for (std::size_t i = 0; i < rec.size(); ++i) {
    (void)filter->update(rec.sample(i));
    const fusion::Quat q = filter->orientation();
    if (!q.coeffs().allFinite()) return kNaN;
    const bool counts = use_mask ? (i < mask.size() && mask[i] != 0) : (rec.movement.empty() || rec.movement[i] != 0);
    if (!counts || !filter->initialised()) continue;
    const auto r = rec.opt_quat.row(static_cast<Eigen::Index>(i));
    if (!r.allFinite()) continue;
    const double e = fusion::error_angles(q, fusion::Quat(r(0), r(1), r(2), r(3))).total;
    sum_sq += e * e;
    ++scored;
  }
  return scored == 0 ? kNaN : std::sqrt(sum_sq / static_cast<double>(scored));
}

std::vector<std::vector<double>> rmse_table(const fusion::FilterSpec& base, const std::vector<ParamRange>& ranges,
                                            const std::vector<std::vector<double>>& values,
                                            const std::vector<const TuneRecording*>& recordings, unsigned threads) {
  const std::size_t n_rec = recordings.size();
  std::vector<std::vector<double>> table(values.size(), std::vector<double>(n_rec, kNaN));
  const std::size_t jobs = values.size() * n_rec;
  std::atomic<std::size_t> next{0};
  // Longest recordings first would balance better; the jobs are many and similar, so a shared counter suffices.
  auto work = [&] {
    for (std::size_t j = next++; j < jobs; j = next++) {
      const std::size_t p = j / n_rec, r = j % n_rec;
      try {
        const TuneRecording& t = *recordings[r];
        table[p][r] = total_rmse(t.rec, spec_with(base, ranges, values[p]), t.mask);
      } catch (const std::exception&) {
        table[p][r] = kNaN;  // a value the filter refuses: the point is simply not a candidate
      }
    }
  };
  const unsigned n_threads = std::max(1u, std::min<unsigned>(threads, static_cast<unsigned>(jobs)));
  std::vector<std::jthread> pool;
  for (unsigned t = 1; t < n_threads; ++t) pool.emplace_back(work);
  work();
  pool.clear();  // joins
  return table;
}

TuneSetup nez_mekf_setup(const TuneRecording& rec, int preset) {
  TuneSetup setup;
  setup.base = {"mekf", {{"preset", static_cast<double>(preset)}, {"mag_latency_s", 0.0}, {"rest_bias_update", 0.0}}};
  setup.ranges = default_param_ranges("mekf");
  setup.fit = {&rec};
  return setup;
}

TuneResult tune(const TuneSetup& setup, const OptimiserProgress& progress) {
  check_param_ranges(setup.base, setup.ranges);
  if (setup.fit.empty()) throw std::invalid_argument("no recordings to identify the parameters on");
  const auto to_values = [&](const std::vector<double>& unit) {
    std::vector<double> v(unit.size());
    for (std::size_t d = 0; d < unit.size(); ++d) v[d] = setup.ranges[d].value_at(unit[d]);
    return v;
  };
  const BatchObjective objective = [&](const std::vector<std::vector<double>>& points) {
    std::vector<std::vector<double>> values;
    for (const auto& p : points) values.push_back(to_values(p));
    const auto table = rmse_table(setup.base, setup.ranges, values, setup.fit, setup.threads);
    std::vector<double> out;
    for (const auto& row : table) out.push_back(criterion_value(setup.criterion, row));
    return out;
  };
  TuneResult result;
  result.optimiser = minimise(setup.ranges.size(), objective, setup.options, {}, progress);
  result.values = to_values(result.optimiser.unit);
  result.spec = spec_with(setup.base, setup.ranges, result.values);

  // Scores: the identified set and the base, on the fit and the held-out recordings.
  std::vector<const TuneRecording*> all = setup.fit;
  all.insert(all.end(), setup.held_out.begin(), setup.held_out.end());
  const auto tuned = rmse_table(setup.base, setup.ranges, {result.values}, all, setup.threads);
  const auto base = rmse_table(setup.base, {}, {{}}, all, setup.threads);
  const auto split = [&](const std::vector<double>& row, std::vector<double>& fit, std::vector<double>& held) {
    fit.assign(row.begin(), row.begin() + static_cast<std::ptrdiff_t>(setup.fit.size()));
    held.assign(row.begin() + static_cast<std::ptrdiff_t>(setup.fit.size()), row.end());
  };
  split(rmse_column(tuned, 0), result.fit_rmse, result.held_out_rmse);
  split(rmse_column(base, 0), result.base_fit_rmse, result.base_held_out_rmse);
  const auto crit = [&](const std::vector<double>& v) {
    return v.empty() ? kNaN : criterion_value(setup.criterion, v);
  };
  result.fit_criterion = crit(result.fit_rmse);
  result.held_out_criterion = crit(result.held_out_rmse);
  result.base_fit_criterion = crit(result.base_fit_rmse);
  result.base_held_out_criterion = crit(result.base_held_out_rmse);
  return result;
}

std::vector<std::uint8_t> intensity_classes(const io::Recording& rec) {
  const fusion::MekfFilter::Params p;
  const auto level = [](double v, double t0, double t1, double t2) { return v < t0 ? 0 : v < t1 ? 1 : v < t2 ? 2 : 3; };
  std::vector<std::uint8_t> out(rec.size(), 0);
  std::array<double, 4> last_seen_s = {-1e300, -1e300, -1e300, -1e300};
  for (std::size_t i = 0; i < rec.size(); ++i) {
    const double t = static_cast<double>(rec.time_ns(i)) * 1e-9;
    const auto a = rec.acc.row(static_cast<Eigen::Index>(i));
    const auto g = rec.gyr.row(static_cast<Eigen::Index>(i));
    const double ext = std::abs(a.norm() - fusion::kGravity);
    const int c = std::max(level(ext, p.static_acc_m_s2, p.slow_acc_m_s2, p.intermediate_acc_m_s2),
                           level(g.norm(), p.static_gyr_rad_s, p.slow_gyr_rad_s, p.intermediate_gyr_rad_s));
    last_seen_s[static_cast<std::size_t>(c)] = t;
    int held = c;
    for (int k = 3; k > c; --k) {
      if (t - last_seen_s[static_cast<std::size_t>(k)] <= p.intensity_hold_s) {
        held = k;
        break;
      }
    }
    out[i] = static_cast<std::uint8_t>(held);
  }
  return out;
}

const char* intensity_name(int c) {
  // The names are string literals, so data() is null-terminated.
  return c >= 0 && c < 4 ? fusion::kIntensityNames[static_cast<std::size_t>(c)].data() : "?";
}

fusion::FilterSpec adaptive_spec_of(const std::vector<ClassSet>& sets, double table_rate_hz) {
  fusion::FilterSpec out{"mekf_adaptive", {{"table_rate_hz", table_rate_hz}}};
  for (const ClassSet& c : sets) {
    if (c.intensity < 0 || c.intensity > 3) {
      throw std::invalid_argument("intensity class " + std::to_string(c.intensity) + " is not 0..3");
    }
    if (c.mekf.name != "mekf") throw std::invalid_argument("a class set must be a mekf spec, got " + c.mekf.name);
    const auto filter = fusion::make_filter(c.mekf);
    const fusion::MekfNoise n = dynamic_cast<const fusion::MekfFilter&>(*filter).noise();
    const std::string cls(fusion::kIntensityNames[static_cast<std::size_t>(c.intensity)]);
    out.parameters.emplace_back("sigma_g_" + cls, n.sigma_g);
    out.parameters.emplace_back("sigma_bg_" + cls, n.sigma_bg);
    out.parameters.emplace_back("sigma_a_" + cls, n.sigma_a);
    out.parameters.emplace_back("sigma_m_" + cls, n.sigma_m);
  }
  return out;
}

io::Recording simulate_recording(const sim::ScenarioSpec& spec, bool ideal) {
  sim::ScenarioRunner runner(spec, {}, ideal);
  const auto n = static_cast<Eigen::Index>(runner.sample_count());
  io::Recording rec = io::sized_recording(spec.rate_hz, n);
  rec.movement.reserve(static_cast<std::size_t>(n));
  rec.timestamp_ns.reserve(static_cast<std::size_t>(n));
  std::vector<sim::ScenarioSample> out;
  Eigen::Index k = 0;
  while (runner.next(out)) {
    const sim::ScenarioSample& s = out.front();
    if (s.dropped) continue;
    io::set_measurement_row(rec, k, s.sample);
    rec.opt_quat.row(k) << s.truth.w(), s.truth.x(), s.truth.y(), s.truth.z();
    rec.movement.push_back(s.movement ? 1 : 0);
    rec.timestamp_ns.push_back(s.sample.timestamp_ns);
    ++k;
  }
  rec.gyr.conservativeResize(k, 3);
  rec.acc.conservativeResize(k, 3);
  rec.mag.conservativeResize(k, 3);
  rec.opt_quat.conservativeResize(k, 4);
  return rec;
}

}  // namespace bsn::eval
