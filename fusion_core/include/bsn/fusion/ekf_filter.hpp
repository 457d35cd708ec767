// The extended Kalman filter with the 7-state [q0..q3, b_wx..b_wz] of Fan et al. 2018 §2.4.2 (eq. 13): the
// quaternion is propagated with the bias-corrected gyro, the bias is a random walk, and the accelerometer and the
// magnetometer are fused in ONE measurement update against gravity and a predefined earth field. Because of that
// joint update a magnetic disturbance also tilts the estimate (Fan §2.4.2, test B): this is the reference the
// decoupled filters (MEKF, DLKF) are compared with. The earth field reference is taken at initialisation from the
// first accelerometer + magnetometer sample. The accelerometer's variance grows with the external acceleration its
// residual shows, up to acc_variance_cap times sigma_a^2 (not in Fan). Magnetometer rejection (MagneticRAdaption, the
// shared MagDisturbanceDetector): low-passed magnitude and dip, dip thresholds widened by the horizontal rate times the
// magnetometer's lag, a steady new field adopted after 20 s, a reading used again at four times its variance after
// 60 s of rejection, and while it is rejected an accelerometer-only update keeps its tilt part only (no turn about the
// vertical) and leaves the bias as it is (a Schmidt "consider" update), so the heading degrades like the gyro's own
// drift, never faster. At rest the gyro reading measures the bias directly (a zero-rate update, rest_bias_update; not
// in Fan).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string_view>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/kalman_params.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/r_adaption.hpp"
#include "bsn/fusion/rest_detector.hpp"

namespace bsn::fusion {

namespace ekf {
using Mat7 = Eigen::Matrix<double, 7, 7>;
}  // namespace ekf

/// The EKF's parameters: own fields below; initial covariance, R-adaption, rest flag and timing come from the base
/// structs (documented there). max_gap_s must be <= 60 s. A restart after a gap keeps the bias and its covariance block
/// (see kalman_support::grow_over_gap).
struct EkfParams : KalmanInitParams, MagRejectionParams, RestDetector::Params, FilterTimingParams {
  /// Gyro white noise, rad/s per sqrt(Hz): the rotation-angle variance grows by sigma_g^2 * dt per step.
  /// Default 1e-3 (Nez Table 3, slow).
  double sigma_g = 1e-3;
  /// Gyro bias random walk, rad/s per sqrt(s). Default 1e-4 (Nez Table 3, slow).
  double sigma_bg = 1e-4;
  /// Accelerometer measurement noise (including external acceleration), m/s^2. Default 2: external accelerations
  /// and small disturbances in human motion are far above sensor noise (Nez's slow set, 0.2, is too stiff for them).
  double sigma_a = 2.0;
  /// Magnetometer measurement noise (including small disturbances), uT. Default 10 (see sigma_a).
  double sigma_m = 10.0;
  /// The accelerometer variance of a sample is sigma_a^2 + |r|^2, r = acc - R(q)^T g its residual, but at most this
  /// factor times sigma_a^2; 1 = sigma_a^2 always (Fan's fixed R). Default 2 (sigma at most x1.4): a sample that
  /// carries a large external acceleration is trusted less, while the cap keeps the filter from going blind through
  /// a long shaking motion that averages out.
  double acc_variance_cap = 2.0;
  /// 1 = while the rest detector reports rest (rest_* parameters), the raw gyro reading measures the bias on all
  /// three axes (the true rate is zero): a zero-rate update with the gyro noise per sample, sigma_g^2 / dt, as its
  /// variance; 0 = Fan's filter. Default 1: otherwise the bias along the vertical is observed only through the
  /// magnetometer, and with that rejected external accelerations pull it once the body moves.
  double rest_bias_update = 1.0;
};

/// Everything the EKF keeps between samples.
struct EkfState {
  Quat q = Quat::Identity();                  ///< sensor-to-earth
  Vec3 bias = Vec3::Zero();                   ///< gyro bias, sensor frame, rad/s
  ekf::Mat7 p = ekf::Mat7::Identity();        ///< covariance of [q (w, x, y, z), b (rad/s)]
  Vec3 h_ref = Vec3::Zero();                  ///< predefined earth field (ENU), uT; zero = not known yet
  MagneticRAdaption::Reference h_ref_judged;  ///< magnitude and dip of h_ref for the R-adaption
  Vec3 gyr_prev = Vec3::Zero();               ///< raw gyro reading of the previous sample, rad/s
  bool have_gyr_prev = false;
  RestDetector rest;             ///< still-sensor detection (flags().resting, the bias updates' gate)
  MagneticRAdaption r_adaption;  ///< magnetometer variance by its disturbance
  FilterFlags flags;
};

class EkfFilter final : public FilterBase<EkfParams, EkfState> {
 public:
  using Mat7 = ekf::Mat7;
  using Mat6 = Eigen::Matrix<double, 6, 6>;

  struct Coefficients {
    double var_a = 0.0;        ///< sigma_a^2
    double var_a_max = 0.0;    ///< acc_variance_cap * sigma_a^2
    double var_m = 0.0;        ///< sigma_m^2
    double var_g_per_s = 0.0;  ///< sigma_g^2: a gyro reading's variance is this / dt
  };

  explicit EkfFilter(const Params& params);
  EkfFilter() : EkfFilter(Params{}) {}

  /// The filter's own 7x7 covariance of [q, b].
  const Mat7& covariance() const { return state_.p; }
  /// The same uncertainty as a 6x6 covariance of [dtheta (sensor-frame rotation vector, rad), db (rad/s)], with
  /// q_true = q * exp(dtheta): dtheta = 2 Xi(q)^T dq.
  Mat6 error_covariance() const;

 private:
  UpdateResult start(const ImuSample& s) override;
  UpdateResult step(const ImuSample& s, double dt) override;
  /// What judge_magnetometer() decided for the sample, and the earth-to-sensor rotation after it (which may have
  /// set the heading).
  struct MagnetometerUse {
    bool use = false;
    double variance_factor = 1.0;  ///< > 1 for a field used after a long rejection (RejectionBudget)
    Eigen::Matrix3d to_sensor = Eigen::Matrix3d::Identity();
  };
  /// step(): the prediction with the gyro, the magnetometer's judgement (and the first heading of a start without
  /// it), the joint or single-sensor correction, the covariance's projection onto the unit quaternions.
  void predict(const ImuSample& s, double dt);
  MagnetometerUse judge_magnetometer(const ImuSample& s, double dt);
  void update_accelerometer_and_magnetometer(const ImuSample& s, const MagnetometerUse& mag);
  void project_covariance_to_unit_norm();
  /// The zero-rate update of rest_bias_update, out of line: it runs at rest only, and inlined into step() it costs
  /// the update in motion instructions (ekf: +1.3 %).
  [[gnu::noinline]] void learn_bias_at_rest(const Vec3& gyr, double dt);
  /// Kalman correction for a measurement whose Jacobian is [h_q 0]: it depends on the quaternion only. With
  /// hold_bias the bias is a "consider" state (Schmidt): its gain is zero, so the bias and its variance stay as
  /// they are, while the quaternion's gain and covariance account for the bias's uncertainty.
  template <int M>
  void correct(const Eigen::Matrix<double, M, 1>& residual, const Eigen::Matrix<double, M, 4>& h_q,
               const Eigen::Matrix<double, M, 1>& variances, bool hold_bias = false);

  Coefficients coeff_;
};

std::unique_ptr<OrientationFilter> make_ekf_filter(const FilterSpec& spec);

}  // namespace bsn::fusion
