#include "bsn/fusion/mekf_filter.hpp"

#include <array>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/start_orientation.hpp"
#include "kalman_support.hpp"

namespace bsn::fusion {
namespace {

using kalman_support::skew;
using mekf::Mat3;
using mekf::Mat6;

using P = MekfFilter::Params;
constexpr auto kParams = join_param_fields(std::to_array<ParamField<P>>({
                                               {"preset", &P::preset},
                                               {"sigma_g", &P::sigma_g},
                                               {"sigma_bg", &P::sigma_bg},
                                               {"sigma_a", &P::sigma_a},
                                               {"sigma_m", &P::sigma_m},
                                               {"static_gyr_rad_s", &P::static_gyr_rad_s},
                                               {"static_acc_m_s2", &P::static_acc_m_s2},
                                               {"slow_gyr_rad_s", &P::slow_gyr_rad_s},
                                               {"slow_acc_m_s2", &P::slow_acc_m_s2},
                                               {"intermediate_gyr_rad_s", &P::intermediate_gyr_rad_s},
                                               {"intermediate_acc_m_s2", &P::intermediate_acc_m_s2},
                                               {"intensity_hold_s", &P::intensity_hold_s},
                                               {"min_switch_interval_s", &P::min_switch_interval_s},
                                               {"switch_confirm_s", &P::switch_confirm_s},
                                               {"immediate_up_switch", &P::immediate_up_switch},
                                               {"intensity_from_residual", &P::intensity_from_residual},
                                               {"table_rate_hz", &P::table_rate_hz},
                                               {"rest_bias_update", &P::rest_bias_update},
                                           }),
                                           kalman_init_param_fields<P>(), mag_rejection_param_fields<P>(),
                                           timing_param_fields<P>(), rest_param_fields<P>());

// Below this rotation angle per step the closed forms lose digits to cancellation; their Taylor series are used.
constexpr double kSeriesAngle = 0.05;

int preset_index(std::string_view filter, double preset) {
  if (!(preset == 0.0 || preset == 1.0 || preset == 2.0 || preset == 3.0)) {
    throw std::invalid_argument(std::string(filter) +
                                ": parameter preset must be 0 (static), 1 (slow), 2 "
                                "(intermediate) or 3 (fast), got " +
                                std::to_string(preset));
  }
  return static_cast<int>(preset);
}

// mekf_adaptive's per-class parameters, sigma_<g|bg|a|m>_<class>: sets the value and returns true, or returns false
// for a name not of that form. Throws std::invalid_argument for that form with an unknown class.
bool bind_class_parameter(const std::string& key, double value, std::array<MekfNoise, 4>& sets) {
  static constexpr std::array<std::pair<std::string_view, double MekfNoise::*>, 4> kSigmas = {{
      {"sigma_g_", &MekfNoise::sigma_g},
      {"sigma_bg_", &MekfNoise::sigma_bg},
      {"sigma_a_", &MekfNoise::sigma_a},
      {"sigma_m_", &MekfNoise::sigma_m},
  }};
  for (const auto& [prefix, field] : kSigmas) {
    if (!key.starts_with(prefix)) continue;
    const std::string_view cls = std::string_view(key).substr(prefix.size());
    for (std::size_t c = 0; c < kIntensityNames.size(); ++c) {
      if (cls == kIntensityNames[c]) {
        sets[c].*field = value;
        return true;
      }
    }
    throw std::invalid_argument("mekf_adaptive: parameter '" + key + "' names no intensity class '" + std::string(cls) +
                                "' (the classes of Nez Table 1: static, slow, intermediate, fast)");
  }
  return false;
}

}  // namespace

namespace {

// Theta, Psi and Q_d of the prediction as 3x3 blocks (Phi = [Theta Psi; 0 I], Q_d = [q11 q12; q12^T q22 I]), from
// one set of closed-form coefficients shared by both.
struct PredictionBlocks {
  Mat3 theta, psi, q11, q12;
  double q22;
};

PredictionBlocks prediction_blocks(const Vec3& w, double T, double sigma_g, double sigma_bg) {
  const double wn = w.norm();
  const double u = wn * T;
  // s1 = sin(u)/|w|, c1 = (1 - cos u)/|w|^2, a1 = (u - sin u)/|w|^3, a2 = (u^2/2 - 1 + cos u)/|w|^4,
  // a3 = (u^3/3 - 2u + 2 sin u)/|w|^5.
  double s1, c1, a1, a2, a3;
  if (u < kSeriesAngle) {
    const double u2 = u * u, T2 = T * T, T3 = T2 * T;
    // Coefficients written as products with constant reciprocals: a division by a constant is not folded.
    s1 = T * (1.0 - u2 * (1.0 / 6.0) + u2 * u2 * (1.0 / 120.0));
    c1 = T2 * (0.5 - u2 * (1.0 / 24.0) + u2 * u2 * (1.0 / 720.0));
    a1 = T3 * (1.0 / 6.0 - u2 * (1.0 / 120.0) + u2 * u2 * (1.0 / 5040.0));
    a2 = T3 * T * (1.0 / 24.0 - u2 * (1.0 / 720.0) + u2 * u2 * (1.0 / 40320.0));
    a3 = T3 * T2 * (1.0 / 60.0 - u2 * (1.0 / 2520.0) + u2 * u2 * (1.0 / 181440.0));
  } else {
    const double w2 = wn * wn, sin_u = std::sin(u), cos_u = std::cos(u);
    s1 = sin_u / wn;
    c1 = (1.0 - cos_u) / w2;
    a1 = (u - sin_u) / (w2 * wn);
    a2 = (0.5 * u * u - 1.0 + cos_u) / (w2 * w2);
    a3 = (u * u * u / 3.0 - 2.0 * u + 2.0 * sin_u) / (w2 * w2 * wn);
  }
  const Mat3 W = skew(w);
  Mat3 W2 = w * w.transpose();  // [w x]^2 = w w^T - |w|^2 I
  W2.diagonal().array() -= wn * wn;
  const Mat3 I = Mat3::Identity();
  const double g2 = sigma_g * sigma_g, b2 = sigma_bg * sigma_bg;
  PredictionBlocks out;
  out.theta = I - s1 * W + c1 * W2;
  out.psi = -(T * I - c1 * W + a1 * W2);
  out.q11 = g2 * T * I + b2 * (I * (T * T * T * (1.0 / 3.0)) + a3 * W2);
  out.q12 = -b2 * (I * (T * T / 2.0) - a1 * W + a2 * W2);
  out.q22 = b2 * T;
  return out;
}

// mekf::integrate without the final normalisation (the caller normalises once per update).
Quat integrate_unnormalised(const Quat& q, const Vec3& w_prev, const Vec3& w_now, double T) {
  const Vec3 w_mean = 0.5 * (w_prev + w_now);
  Quat dq = exp_rotation_vector(w_mean * T);
  // Second Magnus term for a rate varying linearly over the step (the paper's 1/48 commutator term).
  dq.vec() += (T * T * (1.0 / 24.0)) * w_prev.cross(w_now);
  return q * dq;
}

}  // namespace

namespace mekf {

Quat integrate(const Quat& q, const Vec3& w_prev, const Vec3& w_now, double T) {
  return kalman_support::unit(integrate_unnormalised(q, w_prev, w_now, T));
}

Mat6 transition(const Vec3& w, double T) {
  const PredictionBlocks b = prediction_blocks(w, T, 0.0, 0.0);
  Mat6 phi = Mat6::Identity();
  phi.topLeftCorner<3, 3>() = b.theta;
  phi.topRightCorner<3, 3>() = b.psi;
  return phi;
}

Mat6 process_noise(const Vec3& w, double T, double sigma_g, double sigma_bg) {
  const PredictionBlocks b = prediction_blocks(w, T, sigma_g, sigma_bg);
  Mat6 q;
  q.topLeftCorner<3, 3>() = b.q11;
  q.topRightCorner<3, 3>() = b.q12;
  q.bottomLeftCorner<3, 3>() = b.q12.transpose();
  q.bottomRightCorner<3, 3>() = b.q22 * Mat3::Identity();
  return q;
}

}  // namespace mekf

MekfFilter::MekfFilter(const Params& params, bool adaptive)
    : FilterBase(adaptive ? "mekf_adaptive" : "mekf", params), adaptive_(adaptive) {
  state_.r_adaption = MagneticRAdaption(params.thresholds());
  const std::string_view n = adaptive ? "mekf_adaptive" : "mekf";
  coeff_.start_intensity = preset_index(n, params.preset);
  const char* names[] = {"sigma_g", "sigma_bg", "sigma_a", "sigma_m"};
  for (std::size_t c = 0; c < params.sets.size(); ++c) {
    const MekfNoise& set = params.sets[c];
    const double values[] = {set.sigma_g, set.sigma_bg, set.sigma_a, set.sigma_m};
    for (int i = 0; i < 4; ++i) {
      require_positive(n, values[i], (std::string(names[i]) + "_" + std::string(kIntensityNames[c])).c_str());
    }
  }
  coeff_.sets = params.sets;
  coeff_.noise = adaptive ? coeff_.sets[static_cast<std::size_t>(coeff_.start_intensity)]
                          : kNezTable3[static_cast<std::size_t>(coeff_.start_intensity)];
  const double overrides[] = {params.sigma_g, params.sigma_bg, params.sigma_a, params.sigma_m};
  double* targets[] = {&coeff_.noise.sigma_g, &coeff_.noise.sigma_bg, &coeff_.noise.sigma_a, &coeff_.noise.sigma_m};
  for (int i = 0; i < 4; ++i) {
    require_non_negative(n, overrides[i], names[i]);
    if (overrides[i] > 0.0) {
      if (adaptive) {
        throw std::invalid_argument("mekf_adaptive: parameter " + std::string(names[i]) +
                                    " cannot be set; the adaptive filter has one set per intensity class (set " +
                                    names[i] + "_<static|slow|intermediate|fast>)");
      }
      *targets[i] = overrides[i];
    }
  }
  check_kalman_init(n, params);
  kalman_support::check_shared_params(n, params);
  require_positive(n, params.static_gyr_rad_s, "static_gyr_rad_s");
  require_positive(n, params.static_acc_m_s2, "static_acc_m_s2");
  require_positive(n, params.slow_gyr_rad_s, "slow_gyr_rad_s");
  require_positive(n, params.slow_acc_m_s2, "slow_acc_m_s2");
  require_positive(n, params.intermediate_gyr_rad_s, "intermediate_gyr_rad_s");
  require_positive(n, params.intermediate_acc_m_s2, "intermediate_acc_m_s2");
  require_non_negative(n, params.intensity_hold_s, "intensity_hold_s");
  require_non_negative(n, params.min_switch_interval_s, "min_switch_interval_s");
  require_non_negative(n, params.switch_confirm_s, "switch_confirm_s");
  require_non_negative(n, params.table_rate_hz, "table_rate_hz");
  require_switch(n, params.immediate_up_switch, "immediate_up_switch");
  require_switch(n, params.intensity_from_residual, "intensity_from_residual");
  require_switch(n, params.rest_bias_update, "rest_bias_update");
  if (!(params.static_gyr_rad_s < params.slow_gyr_rad_s && params.slow_gyr_rad_s < params.intermediate_gyr_rad_s &&
        params.static_acc_m_s2 < params.slow_acc_m_s2 && params.slow_acc_m_s2 < params.intermediate_acc_m_s2)) {
    throw std::invalid_argument(std::string(n) + ": intensity thresholds must increase static < slow < intermediate");
  }
  coeff_.intensity_hold_ns = seconds_to_ns(params.intensity_hold_s);
  coeff_.min_switch_interval_ns = seconds_to_ns(params.min_switch_interval_s);
  coeff_.switch_confirm_ns = seconds_to_ns(params.switch_confirm_s);
  coeff_.bias_cap_time_s = std::max(params.min_switch_interval_s, 1.0);
  state_.intensity = coeff_.start_intensity;
  state_.rest = RestDetector(params);  // after the checks above, so their errors name the filter
  keep_fresh_state();
}

MekfNoise MekfFilter::noise() const {
  return adaptive_ ? coeff_.sets[static_cast<std::size_t>(state_.intensity)] : coeff_.noise;
}

UpdateResult MekfFilter::start(const ImuSample& s) {
  const std::optional<StartOrientation> initial = start_orientation(s);
  if (!initial) return UpdateResult::kRejected;
  const State before = state_;
  const double walk_var_per_s = noise().sigma_bg * noise().sigma_bg;  // of the set in use before the gap
  clear();
  const double gap_s = static_cast<double>(s.timestamp_ns - clock().last_ns) * 1e-9;
  kalman_support::start_with_bias(state_, initialised() ? &before : nullptr, *initial, s, walk_var_per_s, gap_s,
                                  params_.init_bias_sigma_rad_s * params_.init_bias_sigma_rad_s);
  state_.p.topLeftCorner<3, 3>().diagonal().setConstant(params_.init_attitude_sigma_rad *
                                                        params_.init_attitude_sigma_rad);
  state_.last_switch_ns = s.timestamp_ns;
  state_.flags = start_flags(s.has_mag && !initial->with_mag);
  return UpdateResult::kInitialised;
}

int MekfFilter::classify(const ImuSample& s) const {
  double ext = s.has_acc ? std::abs(s.acc.norm() - kGravity) : 0.0;
  if (s.has_acc && params_.intensity_from_residual != 0.0) {
    ext = std::max(ext, (s.acc - kGravity * earth_axis_in_sensor(state_.q, 2)).norm());
  }
  const double rate = s.has_gyr ? (s.gyr - state_.bias).norm() : 0.0;
  auto level = [](double v, double t0, double t1, double t2) { return v < t0 ? 0 : v < t1 ? 1 : v < t2 ? 2 : 3; };
  return std::max(level(ext, params_.static_acc_m_s2, params_.slow_acc_m_s2, params_.intermediate_acc_m_s2),
                  level(rate, params_.static_gyr_rad_s, params_.slow_gyr_rad_s, params_.intermediate_gyr_rad_s));
}

void MekfFilter::adapt(const ImuSample& s) {
  const std::uint64_t t = s.timestamp_ns;
  const auto c = static_cast<std::size_t>(classify(s));
  state_.class_seen[c] = true;
  state_.class_seen_ns[c] = t;
  int candidate = 0;
  for (int k = 3; k >= 0; --k) {
    const auto i = static_cast<std::size_t>(k);
    if (state_.class_seen[i] && t - state_.class_seen_ns[i] <= coeff_.intensity_hold_ns) {
      candidate = k;
      break;
    }
  }
  // A change is confirmed only after the intensity has differed from the set in use for switch_confirm_s; the new
  // set is the highest class seen in that time. Motion starts gently, and a set chosen on its first samples
  // would be locked in for min_switch_interval_s however intense the motion then becomes.
  if (candidate == state_.intensity) {
    state_.differing = false;
    return;
  }
  if (candidate > state_.intensity && params_.immediate_up_switch != 0.0) {
    // A looser set at once (see immediate_up_switch): it is never stiffer than the motion's own class.
    switch_set(candidate, t);
    return;
  }
  if (!state_.differing) {
    state_.differing = true;
    state_.differing_since_ns = t;
    state_.differing_max = candidate;
  }
  state_.differing_max = std::max(state_.differing_max, candidate);
  if (t - state_.differing_since_ns >= coeff_.switch_confirm_ns &&
      t - state_.last_switch_ns >= coeff_.min_switch_interval_ns) {
    switch_set(state_.differing_max, t);
  }
}

void MekfFilter::switch_set(int intensity, std::uint64_t t) {
  state_.intensity = intensity;
  state_.last_switch_ns = t;
  // Entering the static or slow set (sigma_a = 0.2 m/s^2, identified on motion below 0.05 g): the bias
  // covariance built up under the old set (under the static set's loose gyro the bias is not observable, so it
  // keeps its initial variance) is inconsistent with the stiff new set, which would give the bias a large gain
  // and let it absorb external acceleration (on BROAD up to several rad/s). It is capped at what the new set's
  // random walk accumulates over one switch interval, by the congruence D P D (D scales the bias rows and
  // columns), which keeps P positive definite.
  const double sigma_bg = coeff_.sets[static_cast<std::size_t>(state_.intensity)].sigma_bg;
  const double cap = sigma_bg * sigma_bg * coeff_.bias_cap_time_s;
  const double largest = state_.p.bottomRightCorner<3, 3>().diagonal().maxCoeff();
  if (state_.intensity <= static_cast<int>(MotionIntensity::kSlow) && largest > cap) {
    const double d = std::sqrt(cap / largest);
    state_.p.bottomRows<3>() *= d;
    state_.p.rightCols<3>() *= d;
  }
  state_.differing = false;
  ++state_.switches;
}

void MekfFilter::update_accelerometer(const Vec3& acc, const MekfNoise& n, bool keep_heading) {
  // H = [[z x] 0] and R = sigma_a^2 I (diagonal): the three rows are processed one at a time against the same
  // linearisation, which is the batch update K = P H^T S^-1, P <- P - K H P (Nez B.2) up to rounding, without
  // inverting S. Each row: P <- P - (P h^T)(P h^T)^T / s, symmetric by construction.
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  const Vec3 z_hat = kGravity * earth_axis_in_sensor(state_.q, 2);
  if (keep_heading) {
    // The accelerometer cannot see a rotation about the vertical (h is perpendicular to it); it would still turn the
    // heading through the correlations in P, and with the magnetometer out nothing turns it back: under external
    // accelerations the heading then drifts faster than the gyro's own error (simulated translation at 1 g: 14 deg
    // against 11 deg of gyro-only drift; BROAD's fast translation: 38 deg). The bias likewise: without the
    // magnetometer its vertical part is unobservable, and external accelerations pull its horizontal part, which the
    // next turn of the sensor makes vertical. So while the magnetometer is rejected the update leaves the heading
    // and the bias alone: their correlations with the tilt are dropped, P <- (I - E) P (I - E) + E P E with E the
    // projector onto the vertical of the attitude error and onto the bias (positive semidefinite by construction,
    // only less certain, and consistent with what the update then does).
    const Vec3 u = z_hat * (1.0 / kGravity);
    Eigen::Matrix<double, 6, 6> e = Eigen::Matrix<double, 6, 6>::Zero();
    e.topLeftCorner<3, 3>() = u * u.transpose();
    e.bottomRightCorner<3, 3>() = Mat3::Identity();
    const Eigen::Matrix<double, 6, 6> rest = Eigen::Matrix<double, 6, 6>::Identity() - e;
    state_.p = rest * state_.p * rest + e * state_.p * e;
  }
  const Mat3 hx = skew(z_hat);
  const Vec3 residual = acc - z_hat;
  const double r = n.sigma_a * n.sigma_a;
  Vec6 dx = Vec6::Zero();
  for (int i = 0; i < 3; ++i) {
    const Vec3 h = hx.row(i).transpose();
    const Vec6 ph = state_.p.leftCols<3>() * h;
    const double s = h.dot(ph.head<3>()) + r;
    const Vec6 k = ph * (1.0 / s);
    dx += k * (residual(i) - h.dot(dx.head<3>()));
    state_.p.noalias() -= k * ph.transpose();
  }
  // Product of unit quaternions: unit up to rounding; update() normalises once at the end.
  state_.q = state_.q * exp_rotation_vector(dx.head<3>());
  state_.bias += dx.tail<3>();
}

void MekfFilter::update_magnetometer(const ImuSample& s, const MekfNoise& n, double dt) {
  state_.flags.mag_rejected = false;
  if (state_.h_ref.isZero()) {
    // Initialised without a usable magnetometer: the first usable one sets the heading and the reference.
    const Vec3 up = state_.q.conjugate() * Vec3::UnitZ();
    if (!kalman_support::acc_mag_usable(up, s.mag)) {
      state_.flags.mag_rejected = true;
      return;
    }
    kalman_support::take_first_heading(state_, s.mag);
    return;
  }
  const Mat3 to_sensor = state_.q.toRotationMatrix().transpose();
  const Vec3 r3 = to_sensor.col(2);  // earth vertical in the sensor frame
  double mag_variance_factor = 1.0;  // > 1 for a field used after a long rejection (RejectionBudget)
  if (params_.mag_rejection != 0.0) {
    const double rate = s.has_gyr ? (s.gyr - state_.bias).cross(r3).norm() : 0.0;  // horizontal rate
    mag_variance_factor = state_.r_adaption.update(s.timestamp_ns, s.mag, r3, state_.h_ref_judged, rate, dt);
    if (!std::isfinite(mag_variance_factor)) {
      state_.flags.mag_rejected = true;
      return;
    }
  }
  const Vec3 z_hat = to_sensor * state_.h_ref;
  const Mat3 hm = skew(z_hat);
  const Mat3 p_att = state_.p.topLeftCorner<3, 3>();  // Suh: the covariance truncated to the attitude block
  const double r = n.sigma_m * n.sigma_m * mag_variance_factor;
  const Mat3 hm_p = hm * p_att;
  Mat3 s_m = hm_p * hm.transpose();
  s_m.diagonal().array() += r;
  // Suh's gain projection: only the rotation about the vertical survives, the bias is untouched. The gain
  // r3 r3^T P_att hm^T S^-1 is the rank-1 r3 u^T with u = S^-1 hm P_att r3 (S and P_att symmetric).
  const Vec3 u = s_m.inverse() * (hm_p * r3);
  const Vec3 dtheta = r3 * u.dot(s.mag - z_hat);
  state_.q = state_.q * exp_rotation_vector(dtheta);  // normalised at the end of update()
  // Joseph form with the full covariance, exact for this (suboptimal) gain: I - K H = [G 0; 0 I] with
  // G = I - r3 w^T, w = hm^T u. Then G A G^T + r K K^T = A - r3 (A w)^T - (A w) r3^T + (w^T A w + r u^T u) r3 r3^T
  // and G B = B - r3 (B^T w)^T: rank-1 corrections only.
  const Vec3 w = hm.transpose() * u;
  const Vec3 aw = p_att * w;
  state_.p.topLeftCorner<3, 3>() +=
      (w.dot(aw) + r * u.squaredNorm()) * r3 * r3.transpose() - r3 * aw.transpose() - aw * r3.transpose();
  const Eigen::RowVector3d wb = w.transpose() * state_.p.topRightCorner<3, 3>();
  state_.p.topRightCorner<3, 3>() -= r3 * wb;
  state_.p.bottomLeftCorner<3, 3>() = state_.p.topRightCorner<3, 3>().transpose();
}

// Flattened: the steps it calls and their small fixed-size Eigen products are inlined into one function (Eigen's
// products are otherwise calls of their own, which cost more than their arithmetic); inlining changes no arithmetic.
[[gnu::flatten]] UpdateResult MekfFilter::step(const ImuSample& s_in, double dt) {
  ImuSample s_fwd = s_in;
  s_fwd.mag = mag_at_gyro_time(s_in, state_.bias, params_.mag_latency_s);  // the magnetometer's own delay
  const ImuSample& s = s_fwd;
  state_.flags.reinitialised = false;
  if (adaptive_) adapt(s);
  MekfNoise n = noise();
  if (adaptive_ && params_.table_rate_hz > 0.0) {
    // R is per sample: at f Hz the same information per second as at table_rate_hz needs R * f / table_rate_hz.
    const double k = std::sqrt(1.0 / (dt * params_.table_rate_hz));
    n.sigma_a *= k;
    n.sigma_m *= k;
  }

  // Prediction (Nez B.1): bias random walk, quaternion integrator, closed-form Phi and Q_d.
  const Vec3 w_now = s.has_gyr ? Vec3(s.gyr - state_.bias) : Vec3::Zero();
  const Vec3 w_prev = state_.have_w_prev ? state_.w_prev : w_now;
  state_.q = integrate_unnormalised(state_.q, w_prev, w_now, dt);  // |q| = 1 + O(T^3): normalised below
  const Vec3 w_mean = 0.5 * (w_prev + w_now);
  // P <- Phi P Phi^T + Q_d on 3x3 blocks: Phi = [Theta Psi; 0 I], P = [A B; B^T C].
  const PredictionBlocks blocks = prediction_blocks(w_mean, dt, n.sigma_g, n.sigma_bg);
  const Mat3& theta = blocks.theta;
  const Mat3& psi = blocks.psi;
  const Mat3 pa = state_.p.topLeftCorner<3, 3>(), pb = state_.p.topRightCorner<3, 3>();
  const Mat3 m = theta * pb + psi * state_.p.bottomRightCorner<3, 3>();
  const Mat3 n_top = theta * pa + psi * pb.transpose();
  // A' = n_top theta^T + m psi^T + q11 is symmetric: its lower triangle is computed and mirrored.
  for (int j = 0; j < 3; ++j) {
    for (int i = j; i < 3; ++i) {
      const double a_ij = n_top.row(i).dot(theta.row(j)) + m.row(i).dot(psi.row(j)) + blocks.q11(i, j);
      state_.p(i, j) = a_ij;
      state_.p(j, i) = a_ij;
    }
  }
  state_.p.topRightCorner<3, 3>() = m + blocks.q12;
  state_.p.bottomLeftCorner<3, 3>() = state_.p.topRightCorner<3, 3>().transpose();
  state_.p.bottomRightCorner<3, 3>().diagonal().array() += blocks.q22;

  state_.flags.resting = state_.rest.update(s);
  if (state_.flags.resting && params_.rest_bias_update != 0.0) {
    // At rest the reading is the bias plus the set's gyro white noise of this step (see rest_bias_update).
    const Eigen::Matrix<double, 6, 1> dx =
        kalman_support::zero_rate_update<6>(state_.p, s.gyr - state_.bias, n.sigma_g * n.sigma_g / dt);
    state_.q = state_.q * exp_rotation_vector(dx.head<3>());  // normalised at the end of update()
    state_.bias += dx.tail<3>();
  }

  // Update step 1: the accelerometer corrects attitude and bias.
  // The magnetometer's last decision (it is judged after this update): rejected means keep the heading.
  if (s.has_acc && s.acc.squaredNorm() > 1e-12) {
    update_accelerometer(s.acc, n, s.has_mag && state_.flags.mag_rejected && params_.mag_rejection != 0.0);
  }
  state_.w_prev = s.has_gyr ? Vec3(s.gyr - state_.bias) : Vec3::Zero();
  state_.have_w_prev = s.has_gyr;

  // Update step 2: the magnetometer corrects the yaw only.
  if (s.has_mag) {
    update_magnetometer(s, n, dt);
  } else {
    state_.flags.mag_rejected = false;
  }

  const double q_squared_norm = state_.q.squaredNorm();
  kalman_support::condition_covariance(state_.p, 1e-18, 1e6);
  if (!(q_squared_norm > 0.0 && std::isfinite(q_squared_norm)) || !state_.bias.allFinite() || !state_.p.allFinite()) {
    // Only absurd finite input (rates around 1e100 rad/s and beyond) gets here: start afresh rather than pass NaN on.
    reset();
    return UpdateResult::kRejected;
  }
  state_.q = kalman_support::unit(state_.q);
  state_.flags.initialising = within_init_period(s.timestamp_ns);
  return UpdateResult::kUpdated;
}

std::unique_ptr<OrientationFilter> make_mekf_filter(const FilterSpec& spec) {
  return std::make_unique<MekfFilter>(bind_parameters("mekf", spec, kParams), false);
}

std::unique_ptr<OrientationFilter> make_mekf_adaptive_filter(const FilterSpec& spec) {
  // The per-class sets are bound here, the other parameters by the shared table.
  P params;
  FilterSpec rest{spec.name, {}};
  for (const auto& [key, value] : spec.parameters) {
    if (!bind_class_parameter(key, value, params.sets)) rest.parameters.emplace_back(key, value);
  }
  try {
    params = bind_parameters("mekf_adaptive", rest, kParams, params);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string(e.what()) +
                                "; the sets per class are sigma_<g|bg|a|m>_<static|slow|intermediate|fast>");
  }
  return std::make_unique<MekfFilter>(params, true);
}

}  // namespace bsn::fusion
