#include "bsn/fusion/r_adaption.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace bsn::fusion {
namespace {

void require(bool ok, const char* what) {
  if (!ok) throw std::invalid_argument(std::string("MagneticRAdaption: ") + what);
}

// Sine of the dip of m below the horizontal plane whose unit upward normal is up, positive downwards, for
// |m| = m_norm: -m.up / |m| clamped to [-1, 1]; 0 for a zero field.
double sine_of_dip(const Vec3& m, const Vec3& up, double m_norm) {
  return m_norm > 0.0 ? std::clamp(-m.dot(up) / m_norm, -1.0, 1.0) : 0.0;
}

}  // namespace

MagneticRAdaption::MagneticRAdaption(const Params& params) : params_(params) {
  require(params.magnitude_exit > 0.0 && params.magnitude_exit <= params.magnitude_enter &&
              std::isfinite(params.magnitude_enter),
          "need 0 < magnitude_exit <= magnitude_enter (finite)");
  require(
      params.dip_exit_rad > 0.0 && params.dip_exit_rad <= params.dip_enter_rad && std::isfinite(params.dip_enter_rad),
      "need 0 < dip_exit_rad <= dip_enter_rad (finite)");
  require(params.min_clean_s >= 0.0 && params.min_clean_s < 1e6, "need 0 <= min_clean_s < 1e6");
  require(params.latency_s >= 0.0 && params.latency_s < 1.0, "need 0 <= latency_s < 1");
  require(params.accept_after_s > 0.0 && params.accept_after_s < 1e9, "need 0 < accept_after_s < 1e9");
  require(params.reduced_gain > 0.0 && params.reduced_gain <= 1.0, "need 0 < reduced_gain <= 1");
  min_clean_ns_ = seconds_to_ns(params.min_clean_s);
  constexpr double kPi = 3.14159265358979323846;
  cos_dip_enter_ = params.dip_enter_rad < kPi ? std::cos(params.dip_enter_rad) : -2.0;
  cos_dip_exit_ = params.dip_exit_rad < kPi ? std::cos(params.dip_exit_rad) : -2.0;
}

MagneticRAdaption::Reference MagneticRAdaption::Reference::of(const Vec3& m, const Vec3& up) {
  Reference ref;
  ref.norm = m.norm();
  ref.sin_dip = sine_of_dip(m, up, ref.norm);
  ref.cos_dip = std::sqrt(1.0 - ref.sin_dip * ref.sin_dip);
  return ref;
}

double MagneticRAdaption::update(std::uint64_t t_ns, const Vec3& m, const Vec3& up, const Reference& ref,
                                 double rate_rad_s, double dt_s) {
  const double m_norm = m.norm();
  const double s = sine_of_dip(m, up, m_norm);
  // cos(dip - dip_ref) from both sines (both cosines are >= 0).
  const double cos_dev = std::sqrt(std::max(0.0, 1.0 - s * s)) * ref.cos_dip + s * ref.sin_dip;
  const double tolerance = lag_dip_tolerance(rate_rad_s, (std::isfinite(dt_s) ? dt_s : 0.0) + params_.latency_s);
  double factor = 0.0;
  if (tolerance > 0.0 && std::isfinite(tolerance) && cos_dev < cos_dip_exit_) {
    // Turning, and outside the inner dip band: judge on the angle with both thresholds widened by the lag.
    const double dev = std::acos(std::clamp(cos_dev, -1.0, 1.0));
    factor = update(t_ns, m_norm / ref.norm,
                    dev > params_.dip_enter_rad + tolerance  ? params_.dip_enter_rad + 1.0
                    : dev < params_.dip_exit_rad + tolerance ? 0.0
                                                             : 0.5 * (params_.dip_enter_rad + params_.dip_exit_rad));
  } else {
    factor = update_from_cosine(t_ns, m_norm / ref.norm, cos_dev);
  }
  const double dt = last_ns_ != 0 && t_ns > last_ns_ ? static_cast<double>(t_ns - last_ns_) * 1e-9 : 0.0;
  last_ns_ = t_ns;
  if (budget_.update(dt, disturbed_, params_.accept_after_s)) {
    factor = 1.0 / (params_.reduced_gain * params_.reduced_gain);  // used again, with a reduced gain
  }
  return factor;
}

double MagneticRAdaption::update(std::uint64_t t_ns, double magnitude_ratio, double dip_deviation_rad) {
  const double dip_dev = std::abs(dip_deviation_rad);
  return judge(t_ns, magnitude_ratio, std::isfinite(dip_dev), dip_dev > params_.dip_enter_rad,
               dip_dev < params_.dip_exit_rad);
}

double MagneticRAdaption::update_from_cosine(std::uint64_t t_ns, double magnitude_ratio, double cos_dip_deviation) {
  return judge(t_ns, magnitude_ratio, std::isfinite(cos_dip_deviation),
               cos_dip_deviation<cos_dip_enter_, cos_dip_deviation> cos_dip_exit_);
}

double MagneticRAdaption::judge(std::uint64_t t_ns, double magnitude_ratio, bool finite, bool dip_over_enter,
                                bool dip_under_exit) {
  const double magnitude_dev = std::abs(magnitude_ratio - 1.0);
  if (!finite || !std::isfinite(magnitude_dev) || magnitude_dev > params_.magnitude_enter || dip_over_enter) {
    disturbed_ = true;
    clean_since_valid_ = false;
  } else if (disturbed_) {
    const bool clean = magnitude_dev < params_.magnitude_exit && dip_under_exit;
    if (!clean) {
      clean_since_valid_ = false;  // between the thresholds: still disturbed, the clean clock restarts
    } else if (!clean_since_valid_) {
      clean_since_valid_ = true;
      clean_since_ns_ = t_ns;
    }
    if (clean_since_valid_ && t_ns >= clean_since_ns_ && t_ns - clean_since_ns_ >= min_clean_ns_) {
      disturbed_ = false;
      clean_since_valid_ = false;
    }
  }
  return disturbed_ ? kInfiniteVariance : 1.0;
}

}  // namespace bsn::fusion
