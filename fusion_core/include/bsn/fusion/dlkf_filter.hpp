// The dual linear Kalman filter with TRIAD (DLKF) of Fan et al. 2018 §2.4.1 and Fig. 4 (after Ligorio & Sabatini):
//  - one linear Kalman filter separates gravity from external acceleration: state [g_S, a_S] in the sensor frame,
//    g_S turned by the (bias-corrected) gyro, a_S a first-order Gauss-Markov process, measurement acc = g_S + a_S;
//  - a second, identical in form, separates the geomagnetic field from the magnetic disturbance: [h_S, d_S],
//    measurement mag = h_S + d_S;
//  - TRIAD (Fan eqs. 1-4) turns the two estimated vectors into the orientation, gravity first, so roll and pitch
//    never depend on the magnetometer.
// Both filters are linear in their state: the gyro enters as a known input in the transition matrix, and the gyro
// noise enters Q through the current estimate (Q = sigma_g^2 dt [v x][v x]^T). The gyro bias is removed with Fan's
// low-pass method (§2.3.3), as Fan do for every filter but the EKF.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string_view>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/gyro_bias_lowpass.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/r_adaption.hpp"
#include "bsn/fusion/rest_detector.hpp"

namespace bsn::fusion {

namespace dlkf {

using Mat6 = Eigen::Matrix<double, 6, 6>;
using Vec6 = Eigen::Matrix<double, 6, 1>;

/// One of the two linear Kalman filters: a vector v fixed in the earth frame, seen in the sensor frame, plus a
/// disturbance d (first-order Gauss-Markov, stationary standard deviation sigma_d, correlation time tau_d);
/// measurement y = v + d + noise.
struct SplitKalman {
  Vec6 x = Vec6::Zero();  ///< [v, d], sensor frame
  Mat6 p = Mat6::Identity();

  /// x from the first measurement y (v = y, d = 0) with the exact covariance of that choice:
  /// e_v = d + n, e_d = -d.
  void initialise(const Vec3& y, double var_noise, double var_disturbance);
  /// Turns v by the rotation `turn` (sensor frame, earth-fixed vector: v <- turn v), decays d by c = exp(-dt/tau_d).
  void predict(const Eigen::Matrix3d& turn, double gyro_var_dt, double c, double var_disturbance);
  /// Measurement y = v + d with noise variance var_noise per axis (Joseph form).
  void correct(const Vec3& y, double var_noise);
  Vec3 vector() const { return x.head<3>(); }
  Vec3 disturbance() const { return x.tail<3>(); }
};

}  // namespace dlkf

/// The DLKF's parameters: own fields below; R-adaption (its reference is the field at initialisation), rest flag and
/// timing come from the base structs (documented there). max_gap_s must be <= 60 s. A restart after a gap keeps the
/// low-pass bias.
struct DlkfParams : MagRejectionParams, RestDetector::Params, FilterTimingParams {
  /// Gyro noise density (global error, including scale and misalignment), rad/s per sqrt(Hz): the direction of each
  /// estimated vector diffuses with variance sigma_g^2 dt per step. Default 0.002, chosen with sigma_ext_acc on the
  /// eight BROAD trials: a good gyro is trusted for tens of seconds, the accelerometer mainly removes slow drift.
  double sigma_g = 0.002;
  /// Accelerometer white noise, m/s^2 per sample. Default 0.05 (MEMS accelerometer at 100 Hz).
  double sigma_a = 0.05;
  /// External acceleration: stationary standard deviation, m/s^2 (default 3, see sigma_g), and correlation time, s
  /// (default 0.1 s: body-segment accelerations change within a tenth of a second).
  double sigma_ext_acc = 3.0;
  double tau_ext_acc_s = 0.1;
  /// Accelerometer R-adaption: the accelerometer update is skipped (infinite variance) while | |acc| - g |
  /// exceeds this, m/s^2; 0 = never. Default 2 m/s^2: larger external accelerations are not Gauss-Markov noise
  /// of sigma_ext_acc but sustained motion, and would otherwise be absorbed into the gravity estimate.
  double acc_rejection_m_s2 = 2.0;
  /// ... and while | |acc| - g |, low-passed with this time constant, exceeds acc_rejection_m_s2, s; 0 = judge each
  /// reading alone. Default 0.25 s: in sustained strong motion the few readings whose norm passes near g are not
  /// gravity either (an acceleration of several g crossing through).
  double acc_rejection_lowpass_s = 0.25;
  /// While the low-passed deviation exceeds acc_rejection_m_s2 (sustained motion), gravity is corrected instead with
  /// the specific force low-passed in the earth frame of the current estimate (first order, this time constant, s;
  /// 0 = no correction then, only the gyro): the external acceleration of a body whose velocity stays bounded
  /// averages out there while gravity does not (the idea of seel_ruppin's acceleration low-pass, after VQF).
  /// Default 3 s, the middle of the flat optimum on the eight BROAD trials.
  double sustained_acc_tau_s = 3.0;
  /// The standard deviation that low-passed measurement is given, m/s^2 per sample. Default 1 (the result hardly
  /// depends on it).
  double sustained_acc_sigma = 1.0;
  /// Magnetometer error per sample, uT: its noise and whatever the disturbance state does not model (calibration
  /// residual, lag, disturbances below the detector's thresholds), Nez's "global error". Default 20 uT: with the
  /// white noise alone the field vector follows the magnetometer within tenths of a second, so a magnet approaching a
  /// resting sensor would turn the heading before the detector flags it (Fan et al.'s test B).
  double sigma_m = 20.0;
  /// Magnetic disturbance: stationary standard deviation, uT (default 3), and correlation time, s (default 1 s).
  double sigma_mag_disturbance = 3.0;
  double tau_mag_disturbance_s = 1.0;
  /// Low-pass gyro bias (Fan §2.3.3, eqs. 11-12): 1 = on (default), 0 = off; corner frequency (Hz, default 0.05),
  /// still threshold on every gyro component (rad/s, default 3 deg/s) and minimum still time (s, default 2). Its own
  /// fields, not GyroBiasLowPass::Params: the still threshold's default is one ulp below the others' (3 deg/s rounded
  /// differently).
  double gyro_bias_lowpass = 1.0;
  double bias_corner_frequency_hz = 0.05;
  double bias_omega_min_rad_s = 0.05235987755982988;
  double bias_min_static_s = 2.0;
};

/// Everything the DLKF keeps between samples.
struct DlkfState {
  dlkf::SplitKalman gravity;             ///< [g_S (m/s^2), external acceleration a_S (m/s^2)]
  dlkf::SplitKalman magnetic;            ///< [h_S (uT), disturbance d_S (uT)]
  bool have_mag = false;                 ///< the magnetic filter holds a measured field (else a gyro-carried heading)
  MagneticRAdaption::Reference mag_ref;  ///< magnitude and dip at the first magnetometer sample (R-adaption)
  Quat q = Quat::Identity();             ///< TRIAD result, sensor-to-earth
  Vec3 gyr_prev = Vec3::Zero();
  bool have_gyr_prev = false;
  RestDetector rest;             ///< still-sensor detection (flags().resting, the bias updates' gate)
  GyroBiasLowPass bias_lowpass;  ///< the gyro bias estimate at rest
  MagneticRAdaption r_adaption;  ///< magnetometer variance by its disturbance
  FilterFlags flags;
  Vec3 acc_earth_lp = Vec3::Zero();  ///< specific force low-passed in the estimate's earth frame, m/s^2
  bool acc_earth_started = false;
  double acc_deviation_lp = 0.0;  ///< | |acc| - g | low-passed over acc_rejection_lowpass_s, m/s^2
  double decay_dt = -1.0;         ///< the step the decay factors below were computed for, s (cache)
  double decay_ext = 0.0;         ///< exp(-dt / tau_ext_acc)
  double decay_dist = 0.0;        ///< exp(-dt / tau_mag_disturbance)
  double acc_lowpass_k = 0.0;     ///< dt / (acc_rejection_lowpass_s + dt)
  double acc_earth_k = 0.0;       ///< dt / (sustained_acc_tau_s + dt)
};

class DlkfFilter final : public FilterBase<DlkfParams, DlkfState> {
 public:
  struct Coefficients {
    double var_g = 0.0;          ///< sigma_g^2
    double var_a = 0.0;          ///< sigma_a^2
    double var_ext = 0.0;        ///< sigma_ext_acc^2
    double var_sustained = 0.0;  ///< sustained_acc_sigma^2
    double var_m = 0.0;          ///< sigma_m^2
    double var_dist = 0.0;       ///< sigma_mag_disturbance^2
    double inv_tau_ext = 0.0;
    double inv_tau_dist = 0.0;
    double acc_accept_min2 = 0.0;  ///< (max(g - acc_rejection_m_s2, 0))^2: |acc|^2 range of the R-adaption
    double acc_accept_max2 = 0.0;  ///< (g + acc_rejection_m_s2)^2
  };

  explicit DlkfFilter(const Params& params);
  DlkfFilter() : DlkfFilter(Params{}) {}

  /// Covariances of the two linear filters: [g_S, a_S] and [h_S, d_S].
  const dlkf::Mat6& gravity_covariance() const { return state_.gravity.p; }
  const dlkf::Mat6& magnetic_covariance() const { return state_.magnetic.p; }

  /// TRIAD (Fan eqs. 1-3) with gravity dominant: the sensor-to-earth orientation whose earth z is along `up`
  /// (sensor frame) and whose earth y is along the horizontal part of `field`. Requires them not parallel.
  static Quat triad(const Vec3& up, const Vec3& field);

 private:
  UpdateResult start(const ImuSample& s) override;
  UpdateResult step(const ImuSample& s, double dt) override;
  /// Clears everything but the bias low-pass.
  void restart_keeping_bias();
  /// step(): the bias low-pass, the turn of the sensor frame over the step (returned) and the gravity filter's
  /// prediction; the accelerometer's correction of gravity; the magnetic filter's prediction and correction.
  Eigen::Matrix3d predict(const ImuSample& s, double dt);
  void update_gravity(const ImuSample& s, const Eigen::Matrix3d& turn);
  void update_magnetic(const ImuSample& s, double dt, const Eigen::Matrix3d& turn);
  void initialise_magnetic(const Vec3& mag);

  Coefficients coeff_;
};

std::unique_ptr<OrientationFilter> make_dlkf_filter(const FilterSpec& spec);

}  // namespace bsn::fusion
