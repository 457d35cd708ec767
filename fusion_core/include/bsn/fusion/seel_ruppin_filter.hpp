// Seel & Ruppin (2017): strapdown prediction with an integral bias estimate (eqs. 13-14), an analytical
// correction towards the accelerometer (eqs. 7-10) and a heading-only correction towards the magnetometer
// projected onto the horizontal plane (eqs. 11-12), parametrised by the time constants tau_acc, tau_mag and the
// overshoot measure zeta (section 2.3):
//   k_i = dt / (1.4 tau_i + dt),   k_bias,i = zeta^2 / (160 tau_i) * k_i,   i in {acc, mag}.
// The paper's earth x axis lies along the horizontal magnetic field; ours is ENU (y = magnetic north), so the
// magnetic reference here is earth y. All corrections are applied in the sensor frame as in the paper.
#pragma once

#include <cstdint>
#include <string_view>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/gyro_bias_lowpass.hpp"
#include "bsn/fusion/mag_disturbance_detector.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/rest_detector.hpp"
#include "bsn/fusion/sensor_fixed_field.hpp"

namespace bsn::fusion {

/// The Seel-Ruppin filter's parameters: own fields below; the shared groups come from the base structs (documented
/// there). The bias low-pass acts only with rest_bias_lowpass = 1. During the start-up period (init_period_s) the
/// filter corrects the tilt without the clip and the heading with tau_acc if that is shorter than tau_mag, and learns
/// no bias.
struct SeelRuppinParams : GyroBiasLowPass::Params,
                          MagRejectionParams,
                          RestDetector::Params,
                          SensorFixedField::Params,
                          FilterTimingParams {
  /// tau_acc: half-value time of the convergence towards the accelerometer's inclination, s. Larger trusts
  /// the gyro longer, smaller removes tilt drift faster. With the acceleration low-pass on (the default) the
  /// low-pass already removes the accelerations of human motion, and this correction's lag (1.4 tau_acc) adds to
  /// the low-pass's while gyro errors turn the almost inertial frame in fast motion. Default 0.3 s: shorter tilts
  /// better in simulated fast motion (docs/filters.md) but lets 1 g translations lean on the heading while the
  /// magnetometer is out beyond the gyro's own drift (test_clean_field_motion.cpp). About 2 s without the low-pass.
  double tau_acc_s = 0.3;
  /// tau_mag: half-value time of the heading convergence towards the magnetometer, s. Larger rides out
  /// undetected magnetic disturbances longer. Default 4 s, the optimum on the eight BROAD trials.
  double tau_mag_s = 4.0;
  /// zeta: aggressiveness of the integral bias estimate (overshoot measure); 0 disables bias estimation in
  /// motion. The integral's rate is zeta^2 / tau_acc (and zeta^2 / tau_mag). Default 0.775 (zeta^2 / tau_acc = 2 /s):
  /// a slow integral (time constant minutes) that tracks bias drift without absorbing the accelerations and
  /// disturbances of human motion.
  double zeta = 0.775;
  /// Largest inclination error one accelerometer correction acts on, rad: alpha_err,acc is clipped to this
  /// before k_acc is applied (not in the paper). Human motion brings accelerations of several g for tenths of
  /// a second; unclipped, each pulls the estimate by k_acc times up to 180 deg (a fast translation turns the estimate
  /// by tens of degrees). Clipped, a spike moves the estimate by at most max_acc_error_rad / (1.4 tau_acc) rad/s, like
  /// the bounded step of the GDA, while a true drift (small alpha) is corrected exactly as in the paper. Default 0.05
  /// rad (2.9 deg); pi = the paper's filter.
  double max_acc_error_rad = 0.05;
  /// Time constant of the acceleration low-pass, s; 0 = off (the paper's filter). Not in the paper: the
  /// specific force is rotated into an almost inertial frame (the gyro-only strapdown integral q_gyr), passed
  /// through a second-order Butterworth low-pass there (corner sqrt(2) / (2 pi tau)), and rotated back into
  /// the sensor frame before eqs. 7-10 use it (the idea of Laidig & Seel's VQF, 2023). In an inertial frame
  /// gravity is constant while the external acceleration of a body whose velocity stays bounded averages to
  /// zero, so the low-pass removes the accelerations of human motion without delaying true rotations (the
  /// gyro carries those into q_gyr). Default 3 s, the middle of the
  /// flat optimum on the eight BROAD trials.
  double acc_lowpass_tau_s = 3.0;
  /// 1 = while the sensor is still (every gyro component below bias_omega_min_rad_s for bias_min_static_s),
  /// the bias estimate also follows the raw rate through the low-pass of Fan eqs. 11-12 (GyroBiasLowPass);
  /// 0 = the paper's integral estimate only. The integral action learns a bias in minutes at human-motion
  /// zeta; real recordings start with a bias that rest removes in seconds. Default 1.
  double rest_bias_lowpass = 1.0;
  /// The bias estimate is clamped to this magnitude per axis, rad/s (a safety net against runaway on bad
  /// data). Default 0.1 rad/s (5.7 deg/s).
  double max_gyro_bias_rad_s = 0.1;
  /// The detector's reference field (magnitude and dip) is the mean over this long after the start-up, with the
  /// estimated vertical, s; the magnetometer is used unchecked meanwhile. One reading would carry its noise, and a
  /// start in motion its wrong vertical, into every later decision. Default 0.5 s: the detector goes on averaging
  /// the clean field itself (mag_reference_tau_s), so this needs only outlast a few readings' noise
  /// (a longer one takes in a magnet that arrives soon after the start, as in Fan et al.'s test B).
  double mag_reference_s = 0.5;
  // The detector (MagDisturbanceDetector::Params) tolerates the magnetometer's lag while the sensor turns
  // (mag_latency_s, fed with the bias-corrected rate; each reading is also brought forward by it before use), and
  // after mag_accept_after_s of rejection uses the magnetometer again with tau_mag lengthened by
  // 1 / mag_reduced_gain, so the heading never drifts without bound. A field fixed to the sensor that the gyro
  // confirms (SensorFixedField::Params) is subtracted from each reading before the detector and the correction see
  // it; when it changes, the detector learns its reference afresh.
};

/// Everything the Seel-Ruppin filter keeps between samples.
struct SeelRuppinState {
  Quat q = Quat::Identity();        ///< sensor-to-earth
  Vec3 gyro_bias = Vec3::Zero();    ///< sensor frame, rad/s; the paper's b is -gyro_bias (eq. 14 adds b)
  Quat q_gyr = Quat::Identity();    ///< sensor-to-inertial: strapdown integration only (acc low-pass, mag offset)
  Vec3 acc_lp_y = Vec3::Zero();     ///< acc low-pass output, inertial frame, m/s^2
  Vec3 acc_lp_rate = Vec3::Zero();  ///< its time derivative, m/s^3 (the second state of the low-pass)
  double acc_lp_warmup_s = 0.0;     ///< time the low-pass has run; below tau it outputs the running mean
  double acc_lp_count = 0.0;        ///< samples in the running mean
  Vec3 acc_lp_mean = Vec3::Zero();  ///< running mean of the start-up, inertial frame, m/s^2
  bool heading_known = false;       ///< false after an initialisation without magnetometer
  std::uint64_t last_mag_ns = 0;    ///< timestamp of the last used magnetometer reading
  bool mag_learning = true;         ///< averaging the reference field for the disturbance detector
  std::uint64_t mag_learning_since_ns = 0;
  double mag_norm_sum = 0.0;  ///< uT, over the readings of the learning period
  double mag_dip_sum = 0.0;   ///< rad
  double mag_learning_count = 0.0;
  RestDetector rest;                    ///< still-sensor detection (flags().resting, the bias updates' gate)
  GyroBiasLowPass bias_lowpass;         ///< the rest bias low-pass (rest_bias_lowpass), seeded from gyro_bias
  MagDisturbanceDetector mag_detector;  ///< magnetometer rejection
  SensorFixedField mag_offset;          ///< the field fixed to the sensor, learned against q_gyr
  FilterFlags flags;
};

class SeelRuppinFilter final : public FilterBase<SeelRuppinParams, SeelRuppinState> {
 public:
  /// Quantities derived once from Params.
  struct Coefficients {
    double tau_acc_14 = 0.0;        ///< 1.4 tau_acc, s
    double tau_mag_14 = 0.0;        ///< 1.4 tau_mag, s
    double tau_start_mag_14 = 0.0;  ///< 1.4 min(tau_mag, tau_acc): the heading correction during the start-up, s
    double bias_factor_acc = 0.0;   ///< zeta^2 / (160 tau_acc), 1/s
    double bias_factor_mag = 0.0;   ///< zeta^2 / (160 tau_mag), 1/s
    std::uint64_t mag_reference_ns = 0;
    bool acc_clip_test = false;      ///< max_acc_error_rad < pi: clipping can be decided without atan2
    double sin_max_acc_error = 0.0;  ///< sin(max_acc_error_rad)
    double cos_max_acc_error = 0.0;  ///< cos(max_acc_error_rad)
    /// tan^2 of the largest error the series path of correct_acc takes: min(0.1, tan(max_acc_error_rad))^2
    double small_acc_error_tan2 = 0.0;
    bool acc_lowpass = false;        ///< acc_lowpass_tau_s > 0
    bool gyro_integral = false;      ///< q_gyr is kept: for the acc low-pass or the sensor-fixed field
    double acc_lowpass_fc_hz = 0.0;  ///< sqrt(2) / (2 pi tau): the Butterworth corner frequency
  };

  /// Throws std::invalid_argument on an out-of-range parameter. use_magnetometer = false is "seel_ruppin6": the
  /// heading is taken from the magnetometer at the start only (when there is one), as IECF6's.
  explicit SeelRuppinFilter(const Params& params, bool use_magnetometer = true);
  SeelRuppinFilter() : SeelRuppinFilter(Params{}) {}

  // Besides the interface's rejections, update() rejects a sample with a value no sensor can produce (|acc| > 1e4
  // m/s^2, |gyr| > 1e4 rad/s, |mag| > 1e5 uT) without touching the state.

  const Coefficients& coefficients() const { return coeff_; }

 private:
  UpdateResult start(const ImuSample& s) override;
  UpdateResult step(const ImuSample& s, double dt) override;
  /// The rotation vector of eq. 10 (k alpha times the axis), for the earth vertical r_acc in sensor coordinates.
  Vec3 acc_correction(const Vec3& acc, const Vec3& r_acc, double dt);
  /// The rotation vector of eq. 12 for the reading mag of sample s (zero when it is not used).
  Vec3 mag_correction(const ImuSample& s, const Vec3& mag, const Vec3& r_acc, double rate_rad_s, double dt);
  /// Starts learning the detector's reference field at t_ns.
  void start_mag_reference(std::uint64_t t_ns);
  /// The disturbance decision for one reading (false while the reference is being learned).
  bool mag_disturbed(std::uint64_t t_ns, const Vec3& mag, const Vec3& up, double rate_rad_s, double dt);

  /// k_i = dt / (1.4 tau_i + dt) for the last dt seen (dt is nearly always the same from sample to sample).
  struct GainCache {
    double cached_dt = -1.0;
    double k = 0.0;
    double gain(double dt, double tau_14);
  };

  bool use_magnetometer_;
  Coefficients coeff_;
  /// The Butterworth's transition matrix over the last dt seen (its state is dt-independent, see update()).
  struct LowPassCache {
    double cached_dt = -1.0;
    double p00 = 0.0, p01 = 0.0, p10 = 0.0, p11 = 0.0;
    void update(double dt, double fc_hz);
  };
  Vec3 lowpass_acc(const Vec3& acc, double dt);

  // Caches of functions of dt alone, recomputed when dt changes: not state (a restored filter recomputes them).
  GainCache acc_gain_;
  LowPassCache acc_lp_;
  GainCache mag_gain_;
  GainCache start_mag_gain_;
};

/// Factory entries: "seel_ruppin" (9D) and "seel_ruppin6" (6D), with the Params fields as parameter names.
std::unique_ptr<OrientationFilter> make_seel_ruppin_filter(const FilterSpec& spec);
std::unique_ptr<OrientationFilter> make_seel_ruppin6_filter(const FilterSpec& spec);

}  // namespace bsn::fusion
