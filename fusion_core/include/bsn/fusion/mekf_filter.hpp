// The multiplicative (indirect) Kalman filter of Nez et al. 2018, Appendix B, with gyro-bias state:
//  - prediction after Trawny & Roumeliotis: the quaternion integrator with the 1/48 commutator term, the
//    closed-form transition matrix Phi and discrete process noise Q_d of the error state [dtheta, db];
//  - Suh's two-step update: the accelerometer corrects attitude and bias, then the magnetometer corrects the yaw
//    only, through the gain projection r3 r3^T and the covariance truncated to its attitude block;
//  - Q and R from sigma_g, sigma_bg, sigma_a, sigma_m, with the paper's Table 3 as presets;
//  - an adaptive variant ("mekf_adaptive") that picks a set by motion intensity (Table 3 by default, or the user's
//    own per-class sets, e.g. from `bsn tune --by-intensity`), from the instantaneous
//    acceleration and angular rate, and never switches twice within min_switch_interval_s (10 s in the paper).
//    Each set is used only within the range of Table 1 it was identified on, a change is confirmed on the highest
//    class seen over switch_confirm_s, the sets' per-sample sigma_a and sigma_m are scaled from 128 Hz to the
//    actual rate, and entering a stiff set caps the bias covariance, so that the bias cannot absorb external
//    acceleration while a set is locked in.
// Nez work in NED with a JPL-style error; here everything is in the project's convention (ENU, Hamilton,
// sensor-to-earth q) and the error state is the sensor-frame rotation vector: q_true = q_est * exp(dtheta).
// With that choice the error dynamics, Phi, Q_d and H are the paper's, and r3 is the earth vertical expressed in
// the sensor frame. Magnetometer rejection (MagneticRAdaption, the shared MagDisturbanceDetector) as in the EKF:
// low-passed magnitude and dip, lag-tolerant dip test, a steady new field adopted after 20 s, the reading used again
// at four times its variance after 60 s of rejection; while it is rejected the accelerometer update drops P's
// correlations of the heading and of the bias with the tilt, so it turns neither the heading nor the bias, and P
// stays consistent with what it did. At rest the gyro reading measures the bias directly (a zero-rate update,
// rest_bias_update; not in Nez).
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string_view>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/kalman_params.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/r_adaption.hpp"
#include "bsn/fusion/rest_detector.hpp"

namespace bsn::fusion {

/// One set of Kalman parameters (Nez §2.4): Q_c = diag(sigma_g^2 I, sigma_bg^2 I), R_a = sigma_a^2 I,
/// R_m = sigma_m^2 I.
struct MekfNoise {
  double sigma_g = 0.0;   ///< gyro noise (global error), rad/s per sqrt(Hz): Q_11 grows by sigma_g^2 * T
  double sigma_bg = 0.0;  ///< gyro bias random walk, rad/s per sqrt(s): Q_22 = sigma_bg^2 * T
  double sigma_a = 0.0;   ///< accelerometer global error (noise + external acceleration), m/s^2
  double sigma_m = 0.0;   ///< magnetometer global error (noise + disturbance), uT
};

/// Nez et al. Table 3 (identified at 128 Hz on APDM Opal sensors), index = intensity.
enum class MotionIntensity : int { kStatic = 0, kSlow = 1, kIntermediate = 2, kFast = 3 };
/// The classes' names, index = intensity: the suffix of mekf_adaptive's per-class parameters (sigma_a_fast).
inline constexpr std::array<std::string_view, 4> kIntensityNames = {"static", "slow", "intermediate", "fast"};
inline constexpr std::array<MekfNoise, 4> kNezTable3 = {{
    {0.1, 1e-4, 0.2, 10.0},    // static
    {1e-3, 1e-4, 0.2, 1.5},    // slow
    {1e-2, 1e-3, 8.0, 4.0},    // intermediate
    {6e-3, 3e-5, 10.0, 45.0},  // fast
}};
/// mekf_adaptive's default sets: Table 3 with the static set's gyro error taken from the slow set (1e-3 instead of
/// 0.1 rad/s/sqrt(Hz)). A gyro's global error (noise plus scale and misalignment errors, which grow with the rate)
/// cannot be larger at rest than in slow motion; with 0.1 the static set's heading follows the magnetometer with a
/// time constant of sqrt(R_m / Q_g) = (sigma_m / |h_horizontal|) / (sigma_g sqrt(f)) = 0.44 s (10 uT, 20 uT, 128 Hz),
/// shorter than the time a magnet approaching a resting sensor needs to cross the detector's thresholds; with 1e-3 it
/// is 44 s.
inline constexpr std::array<MekfNoise, 4> kAdaptiveDefaultSets = {{
    {kNezTable3[1].sigma_g, kNezTable3[0].sigma_bg, kNezTable3[0].sigma_a, kNezTable3[0].sigma_m},  // static
    kNezTable3[1],
    kNezTable3[2],
    kNezTable3[3],
}};

namespace mekf {

using Mat3 = Eigen::Matrix3d;
using Mat6 = Eigen::Matrix<double, 6, 6>;

/// Quaternion integrator of Nez eq. B (Trawny & Roumeliotis): rates w_prev at the start and w_now at the end of a
/// step of T seconds, assumed linear in between. q_next = q * [exp(w_mean T) + (0, T^2/24 w_prev x w_now)], i.e.
/// the first two Magnus terms; the second is the paper's 1/48 (Omega(w_k) Omega(w_k-1) - Omega(w_k-1) Omega(w_k))
/// T^2 written for Hamilton sensor-to-earth quaternions. Returns a unit quaternion.
Quat integrate(const Quat& q, const Vec3& w_prev, const Vec3& w_now, double T);

/// Closed-form transition matrix of the error state [dtheta, db] for a constant rate w over T seconds:
/// Phi = [Theta Psi; 0 I], Theta = exp(-[w x] T), Psi = -integral_0^T exp(-[w x] s) ds.
Mat6 transition(const Vec3& w, double T);

/// Closed-form discrete process noise Q_d = integral_0^T Phi(s) G Q_c G^T Phi(s)^T ds for the same step.
Mat6 process_noise(const Vec3& w, double T, double sigma_g, double sigma_bg);

}  // namespace mekf

/// The MEKF's parameters: own fields below (the adaptive variant's at the end); initial covariance, R-adaption, rest
/// flag and timing come from the base structs (documented there). max_gap_s must be <= 60 s. A restart after a gap
/// keeps the bias and its covariance block (see kalman_support::grow_over_gap) and starts again from the preset's noise
/// set.
struct MekfParams : KalmanInitParams, MagRejectionParams, RestDetector::Params, FilterTimingParams {
  /// Table 3 set used for Q and R: 0 static, 1 slow, 2 intermediate, 3 fast. For "mekf_adaptive" the set it starts
  /// with. Default 3 (fast): Table 3 was identified on other sensors at 128 Hz and R is per sample, so the sets that
  /// trust the accelerometer more are too stiff at higher rates and in fast motion (the best on the BROAD trials).
  double preset = 3.0;
  /// Overrides of the preset's values (MekfNoise has the meaning and units); 0 = take the preset's value.
  /// Not allowed for "mekf_adaptive", which has one set per class (below). Defaults 0.
  double sigma_g = 0.0;
  double sigma_bg = 0.0;
  double sigma_a = 0.0;
  double sigma_m = 0.0;
  /// 1 = while the rest detector reports rest (rest_* parameters), the raw gyro reading measures the bias on all
  /// three axes (the true rate is zero): a zero-rate update with the set's gyro noise per sample, sigma_g^2 / dt, as
  /// its variance; it adds a measurement and leaves Q and R as the presets have them. 0 = Nez's filter, in which only
  /// the accelerometer corrects the bias, so the bias along the vertical turns the heading until the body tilts it
  /// into the horizontal. Default 1.
  double rest_bias_update = 1.0;
  // Adaptive variant only. Intensity thresholds at the upper end (mean + 1 standard deviation) of the classes of
  // Nez Table 1 (slow 0.03 +- 0.02 g / 40 +- 20 deg/s, intermediate 0.7 +- 0.5 g / 300 +- 150 deg/s): each set is
  // used only for motion within the range it was identified on. Static is below rest-like thresholds. A
  // sample's class is the higher of its acceleration class and its rate class. (The midpoints between the class
  // means, 170 deg/s and 0.365 g, put most of BROAD's motion into the slow class, whose stiff set then lets
  // external acceleration into the bias.)
  /// Below both static thresholds the sample is static: |gyr| < 0.1 rad/s (5.7 deg/s) and | |acc| - g | <
  /// 0.3 m/s^2. Defaults 0.1 rad/s and 0.3 m/s^2.
  double static_gyr_rad_s = 0.1;
  double static_acc_m_s2 = 0.3;
  /// Upper bounds of the slow class: 60 deg/s = 1.047 rad/s, 0.05 g = 0.49 m/s^2 (of external acceleration
  /// | |acc| - g |).
  double slow_gyr_rad_s = 1.047;
  double slow_acc_m_s2 = 0.49;
  /// Upper bounds of the intermediate class: 450 deg/s = 7.854 rad/s, 1.2 g = 11.77 m/s^2.
  double intermediate_gyr_rad_s = 7.854;
  double intermediate_acc_m_s2 = 11.77;
  /// The intensity is the highest instantaneous class seen within this window, s, so that a single quiet sample
  /// in the middle of a movement does not count as a calmer class. 0 = purely instantaneous. Default 0.5 s.
  double intensity_hold_s = 0.5;
  /// Minimum time between two changes of the parameter set, s (Nez §2.6: 10 s). Default 10 s.
  double min_switch_interval_s = 10.0;
  /// A change of set is made only once the intensity has differed from the set in use for this long, s, and then to
  /// the highest class seen meanwhile: motion starts gently, and a set chosen on its first samples would be locked in
  /// for min_switch_interval_s. 0 = at the first differing sample. Default 0.5 s (shorter chatters, longer keeps the
  /// old set too long at motion onset).
  double switch_confirm_s = 0.5;
  /// 1 = a change to a more intense class (a looser set) is made at once, without switch_confirm_s and
  /// min_switch_interval_s; 0 = Nez's rule in both directions. Default 1: those two rules guard against chattering,
  /// but they would also keep a stiff set through a movement beyond the range it was identified on (Table 1), where
  /// it is wrong, not merely noisy. Calming down still waits for both.
  double immediate_up_switch = 1.0;
  /// 1 = a sample's external acceleration is the larger of | |acc| - g | and the accelerometer's residual against the
  /// gravity the current orientation predicts, |acc - R^T g e_z|; 0 = | |acc| - g | alone, as Nez. Default 1: the
  /// norm is only a lower bound (a horizontal acceleration a changes it by sqrt(g^2 + a^2) - g), so up to 2.4 m/s^2
  /// sideways would count as static and tilt the static set's sigma_a of 0.2 m/s^2.
  double intensity_from_residual = 1.0;
  /// Sample rate at which Table 3 was identified, Hz (Nez: 128 Hz). sigma_a and sigma_m are per-sample values,
  /// so at f Hz the adaptive filter scales them by sqrt(f / table_rate_hz): the accelerometer and magnetometer
  /// then carry the same information per second as in the paper. 0 = use them as they are. Default 128.
  double table_rate_hz = 128.0;
  /// The adaptive variant's set per intensity class (MekfNoise has the meaning and units; each must be finite and
  /// > 0), named sigma_<g|bg|a|m>_<class>, e.g. sigma_a_fast. Defaults: Nez Table 3 (identified on APDM Opal
  /// sensors at 128 Hz) with the static set's gyro error from the slow set (kAdaptiveDefaultSets says why);
  /// `bsn tune --by-intensity` identifies a sensor's own. Only "mekf_adaptive" takes them ("mekf" uses preset and
  /// the overrides above).
  std::array<MekfNoise, 4> sets = kAdaptiveDefaultSets;
};

/// Everything the MEKF keeps between samples.
struct MekfState {
  Quat q = Quat::Identity();              ///< sensor-to-earth
  Vec3 bias = Vec3::Zero();               ///< gyro bias, sensor frame, rad/s
  mekf::Mat6 p = mekf::Mat6::Identity();  ///< error-state covariance of [dtheta (rad), db (rad/s)]
  Vec3 w_prev = Vec3::Zero();             ///< bias-corrected rate at the previous sample, rad/s
  bool have_w_prev = false;
  Vec3 h_ref = Vec3::Zero();                  ///< earth-frame (ENU) magnetic reference, uT; zero = not known yet
  MagneticRAdaption::Reference h_ref_judged;  ///< magnitude and dip of h_ref for the R-adaption
  int intensity = 1;                          ///< index into Coefficients::sets in use
  std::uint64_t last_switch_ns = 0;
  std::array<std::uint64_t, 4> class_seen_ns{};  ///< last time each intensity class was observed
  std::array<bool, 4> class_seen{};
  int switches = 0;                      ///< number of parameter-set switches since initialisation
  bool differing = false;                ///< the intensity currently differs from the set in use
  std::uint64_t differing_since_ns = 0;  ///< since when
  int differing_max = 0;                 ///< highest class seen since then
  RestDetector rest;                     ///< still-sensor detection (flags().resting, the bias updates' gate)
  MagneticRAdaption r_adaption;          ///< magnetometer variance by its disturbance
  FilterFlags flags;
};

class MekfFilter final : public FilterBase<MekfParams, MekfState> {
 public:
  struct Coefficients {
    MekfNoise noise;                ///< the fixed set (non-adaptive) or the starting set (adaptive)
    std::array<MekfNoise, 4> sets;  ///< the adaptive variant's set per class (Params::sets, checked)
    std::uint64_t intensity_hold_ns = 0;
    std::uint64_t min_switch_interval_ns = 0;
    std::uint64_t switch_confirm_ns = 0;
    double bias_cap_time_s = 10.0;  ///< at a switch the bias variance is capped at sigma_bg^2 times this, s
    int start_intensity = 1;
  };

  /// adaptive = false: "mekf", fixed set; true: "mekf_adaptive". Throws std::invalid_argument on bad parameters.
  MekfFilter(const Params& params, bool adaptive);
  MekfFilter() : MekfFilter(Params{}, false) {}

  /// Error-state covariance of [dtheta (sensor frame, rad), db (rad/s)].
  const mekf::Mat6& covariance() const { return state_.p; }
  /// The intensity class whose set is in use (0..3).
  int intensity() const { return state_.intensity; }
  /// The adaptive variant's sets per class (Table 3 unless set).
  const std::array<MekfNoise, 4>& sets() const { return coeff_.sets; }
  /// The noise set in use.
  MekfNoise noise() const;

 private:
  UpdateResult start(const ImuSample& s) override;
  UpdateResult step(const ImuSample& s, double dt) override;
  int classify(const ImuSample& s) const;
  void adapt(const ImuSample& s);
  /// Makes `intensity` the set in use at t (both switch rules end here).
  void switch_set(int intensity, std::uint64_t t);
  void update_accelerometer(const Vec3& acc, const MekfNoise& n, bool keep_heading);
  void update_magnetometer(const ImuSample& s, const MekfNoise& n, double dt);

  bool adaptive_;
  Coefficients coeff_;
};

/// Factory entries: "mekf" (fixed set) and "mekf_adaptive", with the Params fields as parameter names (the sets' as
/// sigma_<g|bg|a|m>_<class>; a name of that form with an unknown class is an error naming the classes).
std::unique_ptr<OrientationFilter> make_mekf_filter(const FilterSpec& spec);
std::unique_ptr<OrientationFilter> make_mekf_adaptive_filter(const FilterSpec& spec);

}  // namespace bsn::fusion
