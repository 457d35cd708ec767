// Noise identification from a static recording by the overlapping Allan deviation, and the conversion of its
// coefficients into the standard deviations the Kalman filters take (nez-2018 Table 2: sigma_g, sigma_bg,
// sigma_a, sigma_m). Offline: these functions allocate.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace bsn::calib {

struct AllanPoint {
  double tau_s;          ///< cluster time, s
  double adev;           ///< overlapping Allan deviation at tau, in the unit of x
  std::size_t clusters;  ///< number of overlapping cluster differences averaged (N - 2m)
};

/// Overlapping Allan deviation of a uniformly sampled series x (one axis), at about points_per_decade
/// logarithmically spaced cluster sizes from 1 sample to N/2. Empty when x has fewer than 3 samples, a
/// non-finite value, or sample_rate_hz is not positive.
std::vector<AllanPoint> allan_deviation(const Eigen::Ref<const Eigen::VectorXd>& x, double sample_rate_hz,
                                        int points_per_decade = 10);

/// One sensor channel on its own clock: a magnetometer sampled at 50 Hz beside a 100 Hz IMU has a NaN row in the
/// recording wherever it gave no sample.
struct OwnRateSeries {
  Eigen::Matrix<double, Eigen::Dynamic, 3> xyz;  ///< the rows where all three axes are finite, in order
  double rate_hz = 0.0;  ///< 1 / the median interval between their timestamps; 0 with fewer than 3 rows
  std::size_t gaps = 0;  ///< intervals longer than 1.5 median intervals (a lost sample; Allan assumes none)
};
/// Picks a channel's own samples out of `xyz` (N x 3) with their timestamps `t_ns` (N, increasing).
OwnRateSeries own_rate_series(const Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>& xyz,
                              std::span<const std::uint64_t> t_ns);

struct NoiseCoefficients {
  double white_density;     ///< N: angle/velocity random walk, unit/sqrt(Hz) (e.g. rad/s/sqrt(Hz)), read at
                            ///< tau = 1 s of the -1/2 slope fit
  double bias_instability;  ///< B, unit (e.g. rad/s), from the flat minimum (adev_min / 0.664)
  double rate_random_walk;  ///< K, unit/s/sqrt(Hz) (e.g. rad/s^2/sqrt(Hz)), from the +1/2 slope, read at tau = 3 s
};

/// Fits sigma^2(tau) = N^2 / tau + C + K^2 tau / 3 to the curve by weighted least squares on the relative error
/// (weight: the number of independent clusters, ~N_samples / m), with every coefficient >= 0: N is then the -1/2
/// line at tau = 1 s and K the +1/2 line at tau = 3 s. B = min(adev) / 0.664 (= sqrt(2 ln 2 / pi)), the flat
/// part's level. All zero for an empty curve.
NoiseCoefficients fit_noise_coefficients(const std::vector<AllanPoint>& curve);

/// The standard deviations of one sensor's noise for a Kalman filter sampled at rate f_s (nez-2018 Table 2):
///   sigma_white = N sqrt(f_s)   white measurement noise per sample (sigma_g in rad/s, sigma_a in m/s^2,
///                               sigma_m in uT): a density N over the bandwidth f_s/2 of a sampled signal
///                               gives variance N^2 f_s / 2 per one-sided, N^2 f_s with the two-sided
///                               convention of the Allan relation sigma^2(tau) = N^2 / tau at tau = 1/f_s.
///   sigma_bias  = B             bias-instability level (sigma_bg in rad/s, as nez-2018 Table A1 sets it)
///   bias_walk   = K             bias random-walk density, unit/s/sqrt(Hz): per step of dt the bias moves by
///                               K sqrt(dt) (std), a process-noise alternative to sigma_bias.
struct FilterNoise {
  double sigma_white = 0.0;
  double sigma_bias = 0.0;
  double bias_walk = 0.0;
};
FilterNoise filter_noise(const NoiseCoefficients& c, double sample_rate_hz);

}  // namespace bsn::calib
