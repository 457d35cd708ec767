#include "bsn/calib/allan.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

namespace bsn::calib {

std::vector<AllanPoint> allan_deviation(const Eigen::Ref<const Eigen::VectorXd>& x, double sample_rate_hz,
                                        int points_per_decade) {
  std::vector<AllanPoint> curve;
  const Eigen::Index n = x.size();
  if (n < 3 || !(sample_rate_hz > 0.0) || !std::isfinite(sample_rate_hz) || !x.allFinite()) return curve;
  points_per_decade = std::max(1, points_per_decade);
  const double tau0 = 1.0 / sample_rate_hz;
  // theta_k = tau0 * sum_{i<k} x_i: the integrated signal (angle for a gyro).
  Eigen::VectorXd theta(n + 1);
  theta(0) = 0.0;
  for (Eigen::Index k = 0; k < n; ++k) theta(k + 1) = theta(k) + x(k) * tau0;
  // Cluster sizes 1 .. (n-1)/2, logarithmically spaced, each once.
  const auto max_m = static_cast<double>((n - 1) / 2);
  std::vector<Eigen::Index> sizes;
  for (int i = 0;; ++i) {
    const double m = std::floor(std::pow(10.0, static_cast<double>(i) / points_per_decade));
    if (m > max_m) break;
    const auto mi = static_cast<Eigen::Index>(m);
    if (sizes.empty() || sizes.back() != mi) sizes.push_back(mi);
  }
  for (const Eigen::Index m : sizes) {
    const Eigen::Index terms = n + 1 - 2 * m;
    double sum = 0.0;
    for (Eigen::Index k = 0; k < terms; ++k) {
      const double d = theta(k + 2 * m) - 2.0 * theta(k + m) + theta(k);
      sum += d * d;
    }
    const double tau = static_cast<double>(m) * tau0;
    const double avar = sum / (2.0 * tau * tau * static_cast<double>(terms));
    curve.push_back({tau, std::sqrt(avar), static_cast<std::size_t>(terms)});
  }
  return curve;
}

OwnRateSeries own_rate_series(const Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>& xyz,
                              std::span<const std::uint64_t> t_ns) {
  OwnRateSeries out;
  const auto n = static_cast<std::size_t>(std::min<Eigen::Index>(xyz.rows(), static_cast<Eigen::Index>(t_ns.size())));
  std::vector<Eigen::Index> rows;
  for (std::size_t i = 0; i < n; ++i) {
    if (xyz.row(static_cast<Eigen::Index>(i)).allFinite()) rows.push_back(static_cast<Eigen::Index>(i));
  }
  out.xyz.resize(static_cast<Eigen::Index>(rows.size()), 3);
  for (std::size_t k = 0; k < rows.size(); ++k) out.xyz.row(static_cast<Eigen::Index>(k)) = xyz.row(rows[k]);
  if (rows.size() < 3) return out;
  std::vector<double> dt;
  for (std::size_t k = 1; k < rows.size(); ++k) {
    const auto a = t_ns[static_cast<std::size_t>(rows[k - 1])], b = t_ns[static_cast<std::size_t>(rows[k])];
    dt.push_back(b > a ? static_cast<double>(b - a) * 1e-9 : 0.0);
  }
  std::vector<double> sorted = dt;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
  const double median = sorted[sorted.size() / 2];
  if (!(median > 0.0)) return out;
  out.rate_hz = 1.0 / median;
  for (const double d : dt) out.gaps += d > 1.5 * median;
  return out;
}

NoiseCoefficients fit_noise_coefficients(const std::vector<AllanPoint>& curve) {
  NoiseCoefficients out{0.0, 0.0, 0.0};
  std::vector<AllanPoint> points;
  for (const AllanPoint& p : curve)
    if (p.adev > 0.0 && p.tau_s > 0.0 && std::isfinite(p.adev) && std::isfinite(p.tau_s)) points.push_back(p);
  if (points.empty()) return out;

  double adev_min = std::numeric_limits<double>::infinity();
  for (const AllanPoint& p : points) adev_min = std::min(adev_min, p.adev);
  out.bias_instability = adev_min / 0.664;

  // Weighted linear least squares in (N^2, C, K^2) on sigma_model^2 / sigma^2 - 1, with the weight the number
  // of independent clusters (total time / tau); the non-negativity by trying every subset of the three terms.
  const double total_time = points.front().tau_s * static_cast<double>(points.front().clusters + 2);
  const auto rows = static_cast<Eigen::Index>(points.size());
  Eigen::MatrixXd design(rows, 3);
  Eigen::VectorXd rhs(rows);
  for (Eigen::Index i = 0; i < rows; ++i) {
    const AllanPoint& p = points[static_cast<std::size_t>(i)];
    const double w = std::sqrt(std::max(1.0, total_time / p.tau_s - 1.0));
    const double var = p.adev * p.adev;
    design.row(i) << w / (p.tau_s * var), w / var, w * p.tau_s / (3.0 * var);
    rhs(i) = w;
  }
  double best_cost = std::numeric_limits<double>::infinity();
  Eigen::Vector3d best = Eigen::Vector3d::Zero();
  for (int mask = 1; mask < 8; ++mask) {
    std::vector<Eigen::Index> cols;
    for (int c = 0; c < 3; ++c)
      if (mask & (1 << c)) cols.push_back(c);
    if (static_cast<Eigen::Index>(cols.size()) > rows) continue;
    Eigen::MatrixXd sub(rows, static_cast<Eigen::Index>(cols.size()));
    for (std::size_t c = 0; c < cols.size(); ++c) sub.col(static_cast<Eigen::Index>(c)) = design.col(cols[c]);
    const Eigen::VectorXd sol = sub.colPivHouseholderQr().solve(rhs);
    if (!sol.allFinite() || (sol.array() < 0.0).any()) continue;
    const double cost = (sub * sol - rhs).squaredNorm();
    if (cost < best_cost) {
      best_cost = cost;
      best.setZero();
      for (std::size_t c = 0; c < cols.size(); ++c) best(cols[c]) = sol(static_cast<Eigen::Index>(c));
    }
  }
  out.white_density = std::sqrt(best(0));
  out.rate_random_walk = std::sqrt(best(2));
  return out;
}

FilterNoise filter_noise(const NoiseCoefficients& c, double sample_rate_hz) {
  FilterNoise f;
  if (!(sample_rate_hz > 0.0) || !std::isfinite(sample_rate_hz)) return f;
  f.sigma_white = c.white_density * std::sqrt(sample_rate_hz);
  f.sigma_bias = c.bias_instability;
  f.bias_walk = c.rate_random_walk;
  return f;
}

}  // namespace bsn::calib
